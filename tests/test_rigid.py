"""The rigid limit k -> infinity (crawlsim/analysis/rigid.py, docs/model.md §7) against closed
forms, elastic runs and the model's invariances.

Derivation of the closed forms. With rigid links block j moves at u + c_j(t), c_j the sum of the
link rates before it, and in the order of decreasing c_j the resting block is the first at which
G_k = (sum of mu+ over the k fastest) - (sum of mu- over the others) turns positive. With the
same friction on every block G_k = k mu+ - (N - k) mu-.

* N = 3, mu- > 2 mu+: G_1, G_2 < 0 < G_3, so the slowest block rests and u = max_j (-c_j). With
  L_1 = 1 + A cos 2 pi t/T and L_2 = 1 + A cos 2 pi (t/T - phi), theta = 2 pi t/T:
  -c_j = (2 pi A / T) <e(theta), p_j> with e = (cos, sin), p_1 = 0, p_2 = (0, 1) and
  p_3 = p_2 + (-sin 2 pi phi, cos 2 pi phi). So u is (2 pi A / T) times the support function of
  the triangle p_1 p_2 p_3, and by Cauchy's formula (the integral of a convex polygon's support
  function over the circle is its perimeter) the displacement per period is
  d = A (|p_2| + |p_3 - p_2| + |p_3|) = A (2 + 2 |cos pi phi|), v0 = d / T. With mu+ > 2 mu-
  the fastest block rests instead and d = -A (2 + 2 |cos pi phi|).
* Odd N, isotropic friction (mu+ = mu- on each block, without ties): the resting block is the
  weighted median of the c_j, and single-harmonic links give c_j(t + T/2) = -c_j(t); the
  median of negated values is the negated median, so u(t + T/2) = -u(t) and v0 = 0 for every
  phase lag.
"""

import dataclasses
import json
import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import crawlsim
from crawlsim.analysis.rigid import rigid_limit
from crawlsim.cli import main
from crawlsim.errors import DegenerateModelError
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.signals import Constant

from .conftest import GAITS, make_gait


def wave(amplitudes, phases, friction, period=1.0, **extra):
    """Cosine links L_i = 1 + A_i cos 2 pi (t/T - phi_i) on len(amplitudes) + 1 blocks."""
    links = [
        {"kind": "cosine", "mean": 1.0, "amplitude": float(a), "phase": float(p)} for a, p in zip(amplitudes, phases)
    ]
    doc = {"blocks": len(links) + 1, "period": period, "stiffness": 10.0, "links": links, "friction": friction}
    return make_gait({**doc, **extra})


@pytest.mark.parametrize("phase", [0.0, 0.1, 1 / 3, 0.5, 0.77])
@pytest.mark.parametrize(
    "amplitude,period,mu", [(0.3, 1.0, (1.0, 3.0)), (0.1, 2.5, (0.5, 10.0)), (0.2, 0.7, (3.0, 1.0))]
)
def test_three_blocks_with_one_direction_dominant(phase, amplitude, period, mu):
    """N = 3 with mu- > 2 mu+ (or mu+ > 2 mu-): v0 = +-A (2 + 2 |cos pi phi|) / T (module docstring)."""
    forward, backward = mu
    gait = wave([amplitude] * 2, [0.0, phase], {"forward": forward, "backward": backward}, period)
    result = rigid_limit(gait)
    sign = 1.0 if backward > 2 * forward else -1.0
    exact = sign * amplitude * (2 + 2 * abs(math.cos(math.pi * phase))) / period
    assert result.v0 == pytest.approx(exact, abs=1e-12)
    assert abs(result.v0 - exact) <= result.v0_error_estimate + 4e-16 * abs(exact)
    assert result.status == "closed-form"


def test_the_issue_example_is_the_limit_of_elastic_runs():
    """A = 0.3, mu+ = 1, mu- = 3, phase lag 1/3: the elastic v0 is 0.84, 0.894 and 0.8994 at
    k = 1e2, 1e3, 1e4 (issue 34), and v0_inf = 0.3 (2 + 1) = 0.9."""
    gait = wave([0.3, 0.3], [0.0, 1 / 3], {"forward": 1.0, "backward": 3.0})
    assert rigid_limit(gait).v0 == pytest.approx(0.9, abs=1e-12)
    for k, v0 in ((1e2, 0.84), (1e3, 0.894), (1e4, 0.8994)):
        assert crawlsim.run(gait.replace("stiffness", k), history=False).v0 == pytest.approx(v0, abs=1e-9)


@pytest.mark.parametrize("blocks", [3, 5, 7])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_odd_median_gaits_do_not_move(blocks, seed):
    """Odd N, isotropic friction, single-harmonic links: v0_inf = 0 for every phase lag
    (module docstring), with equal friction on every block and with random per-block levels."""
    rng = np.random.default_rng(seed)
    amplitudes, phases = rng.uniform(0.05, 0.4, blocks - 1), rng.uniform(0, 1, blocks - 1)
    same = wave(amplitudes, phases, {"forward": 1.5, "backward": 1.5})
    levels = rng.uniform(0.5, 2.0, blocks)
    each = wave(amplitudes, phases, [{"forward": float(m), "backward": float(m)} for m in levels])
    for gait in (same, each):
        assert rigid_limit(gait).v0 == pytest.approx(0.0, abs=1e-12)


def brute_force_v0(gait, samples=200_001):
    """v0_inf by the trapezoid rule on u(t) = -c_m(t), the resting block by the rule itself."""
    u = np.linspace(0.0, 1.0, samples)
    rates = np.column_stack([s.rate(u) for s in gait.links])
    c = np.hstack([np.zeros((samples, 1)), np.cumsum(rates, axis=1)])
    plus = np.column_stack([s(u) for s in gait.forward])
    minus = np.column_stack([s(u) for s in gait.backward])
    order = np.argsort(-c, axis=1)
    g = np.cumsum(np.take_along_axis(plus + minus, order, axis=1), axis=1) - minus.sum(axis=1)[:, None]
    resting = order[np.arange(samples), np.argmax(g > 0, axis=1)]
    velocity = -c[np.arange(samples), resting]
    return float(np.sum(0.5 * (velocity[1:] + velocity[:-1]) * np.diff(u))) / gait.period


def test_several_harmonics_by_certified_sampling():
    """Fourier links have no closed-form crossings: the sampled search agrees with a dense
    trapezoid rule (u is continuous with constant friction: its error is O(h^2))."""
    links = [
        {"kind": "fourier", "mean": 1.0, "cos": [0.2, 0.05, 0.03], "sin": [0.0, 0.04]},
        {"kind": "fourier", "mean": 1.0, "cos": [0.1, -0.06], "sin": [0.15], "phase": 0.3},
        {"kind": "cosine", "mean": 1.0, "amplitude": 0.25, "phase": 0.6},
    ]
    friction = [{"forward": 1.0, "backward": 2.5}, {"forward": 0.7, "backward": 1.9}] * 2
    gait = make_gait({"blocks": 4, "period": 1.5, "stiffness": 10.0, "links": links, "friction": friction})
    result = rigid_limit(gait)
    assert result.status == "sampled"
    assert result.v0 == pytest.approx(brute_force_v0(gait), abs=1e-8)
    assert result.v0_error_estimate < 1e-12


def corpus_gait(seed):
    """A random gait of 2 to 5 blocks with per-block friction some of which varies in time."""
    gait = random_gait(seed, blocks=(2, 5))
    assert isinstance(gait.document["friction"], list)
    assert not all(isinstance(s, Constant) for s in gait.forward + gait.backward)
    return gait


@pytest.mark.parametrize("seed", [0, 2, 4, 6, 17])
def test_elastic_runs_approach_the_rigid_limit_at_first_order(seed):
    """Elastic runs at k = 1e2 ... 1e6 approach v0_inf with order 1 in 1/k (the elastic range
    of the links, about mu / k, is what the stroke loses to the springs): the observed order
    between consecutive k of the last three is 1 to within 0.05. The five gaits mix cosine,
    Fourier, piecewise-linear and steps links with cosine and steps friction per block."""
    gait = corpus_gait(seed)
    rigid = rigid_limit(gait)
    errors = [
        abs(crawlsim.run(gait.replace("stiffness.*", k), history=False).v0 - rigid.v0) for k in 10.0 ** np.arange(2, 7)
    ]
    orders = -np.diff(np.log10(errors))
    assert np.all(np.abs(orders[-2:] - 1.0) < 0.05), orders
    assert errors[-1] < 1e-4


def scaled_document(length=1.0, friction=1.0, period=1.0, shift=0.0):
    """A four-block gait of every signal kind with loads: lengths, friction (and with it the
    loads), period and a time shift of every signal as parameters."""
    links = [
        {"kind": "cosine", "mean": length, "amplitude": 0.3 * length, "phase": 0.1 + shift},
        {
            "kind": "fourier",
            "mean": length,
            "cos": [0.2 * length, 0.05 * length],
            "sin": [0.1 * length],
            "phase": shift,
        },
        {"kind": "piecewise-linear", "times": [0, 0.3, 1], "values": [length, 1.4 * length, length], "phase": shift},
    ]
    f = friction
    return {
        "blocks": 4,
        "period": period,
        "stiffness": 10.0,
        "links": links,
        "friction": [
            {"forward": f, "backward": {"kind": "cosine", "mean": 2.5 * f, "amplitude": 0.5 * f, "phase": shift}},
            {"forward": 0.8 * f, "backward": 2.0 * f},
            {
                "forward": {"kind": "steps", "times": [0, 0.5], "values": [f, 2 * f], "phase": shift},
                "backward": 3.0 * f,
            },
            {"forward": 1.2 * f, "backward": 2.2 * f},
        ],
        "loads": {"force": [0.0, -0.3 * f, 0.0, 0.1 * f], "slope": {"angle": 5.0, "weight": 0.5 * f}},
    }


def test_invariances():
    """As for the elastic model: v0 T does not depend on T (rate independence), nor v0 on a
    common factor of friction and loads, nor on a time shift of every signal; lengths scaled by
    s scale v0 by s; and the stiffness does not enter at all."""
    base = rigid_limit(make_gait(scaled_document()))
    assert base.status == "sampled" and abs(base.v0) > 0.05
    for changed, factor in (
        (scaled_document(period=3.7), 1 / 3.7),
        (scaled_document(friction=4.2), 1.0),
        (scaled_document(shift=0.37), 1.0),
        (scaled_document(length=2.5), 2.5),
        ({**scaled_document(), "stiffness": [1.0, 50.0, 7.0]}, 1.0),
    ):
        assert rigid_limit(make_gait(changed)).v0 == pytest.approx(factor * base.v0, abs=1e-12)


def test_the_resting_block_of_an_anchoring_gait():
    """anchoring-2: the rear block grips while the link extends (first half), the front block
    while it contracts; v0_inf is the stroke, 0.4."""
    result = crawlsim.rigid_limit(GAITS / "anchoring-2.yaml")
    assert result.v0 == pytest.approx(0.4, abs=1e-14)
    np.testing.assert_allclose(result.times, [0.0, 0.5, 1.0], atol=1e-12)
    assert list(result.resting) == [1, 2]


def test_a_jump_of_a_link_moves_the_body_at_once():
    """A link that steps from 1 to 1.5 at T/4 and back at 3T/4, with the rear block gripping at
    the first jump and the front one at the second (friction switched at the same instants):
    the front block jumps 0.5 forward, then the rear block follows. d = 0.5, no motion between."""
    doc = {
        "blocks": 2,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "steps", "times": [0, 0.25, 0.75], "values": [1.0, 1.5, 1.0]}],
        "friction": [
            {"forward": 1.0, "backward": {"kind": "steps", "times": [0, 0.25, 0.75], "values": [0.5, 3.0, 0.5]}},
            {"forward": {"kind": "steps", "times": [0, 0.25, 0.75], "values": [3.0, 0.5, 3.0]}, "backward": 2.0},
        ],
    }
    result = rigid_limit(make_gait(doc))
    assert result.v0 == pytest.approx(0.5, abs=1e-14)
    jumps = np.flatnonzero(np.diff(result.times) == 0)
    assert list(result.resting[jumps]) == [1, 2]


def test_a_tie_is_refused_with_its_reason(tmp_path):
    """Four blocks of equal isotropic friction: two blocks forward and two backward balance, so
    the motion is not determined; the gait file is refused (exit code 2) by the uniqueness
    condition, and a gait that skipped it by `rigid_limit` itself, naming J and the times."""
    doc = {**yaml.safe_load((GAITS / "peristalsis-4.yaml").read_text()), "friction": {"forward": 1.0, "backward": 1.0}}
    tied = tmp_path / "tied.yaml"
    tied.write_text(yaml.safe_dump(doc))
    out = CliRunner().invoke(main, ["velocity", str(tied), "--rigid"])
    assert out.exit_code == 2 and "uniqueness condition violated" in out.output
    assert "Traceback" not in out.output
    gait = crawlsim.load_gait(GAITS / "peristalsis-4.yaml")
    unchecked = dataclasses.replace(gait, forward=(Constant(1.0),) * 4, backward=(Constant(1.0),) * 4)
    with pytest.raises(DegenerateModelError, match=r"rigid limit is not unique at t in \[.*J = \{"):
        rigid_limit(unchecked)


def test_velocity_rigid_on_the_command_line():
    """``velocity --rigid`` prints v0 with the digits its estimate supports; --json the estimate
    and the resting block's intervals, which tile the period."""
    runner = CliRunner()
    out = runner.invoke(main, ["velocity", str(GAITS / "peristalsis-4.yaml"), "--rigid"])
    assert out.exit_code == 0 and float(out.output) == pytest.approx(0.3, abs=1e-13)
    out = runner.invoke(main, ["velocity", str(GAITS / "smooth-friction-3.yaml"), "--rigid", "--json"])
    summary = json.loads(out.output)
    assert summary["v0"] == pytest.approx(rigid_limit(crawlsim.load_gait(GAITS / "smooth-friction-3.yaml")).v0)
    intervals = summary["resting"]
    assert intervals[0]["start"] == 0.0 and intervals[-1]["end"] == 2.0
    assert all(a["end"] == b["start"] for a, b in zip(intervals, intervals[1:]))
    out = runner.invoke(main, ["velocity", str(GAITS / "inching-2.yaml"), "--rigid", "--sweep", "period=1:2:3"])
    assert out.exit_code == 2 and "--rigid" in out.output


def test_run_rigid_writes_draws_and_describes_it(tmp_path):
    """``run --rigid`` adds /rigid to the results file (the intervals tile the period), its
    figure to --plot, its v0 to the summary; ``info`` reports it with the uniqueness margin. A
    file without it has no rigid figure, and asking for one says how to get it (exit code 2)."""
    from crawlsim.io.runread import read_results

    runner = CliRunner()
    out = tmp_path / "p4.h5"
    args = ["run", str(GAITS / "peristalsis-4.yaml"), "--rigid", "--plot", "--json", "-q", "-o", str(out)]
    summary = json.loads(runner.invoke(main, args).output)
    assert summary["rigid"]["v0"] == pytest.approx(0.3, abs=1e-13)
    assert str(tmp_path / "p4-rigid.png") in summary["figures"]
    data = read_results(out)
    assert data["rigid_attrs"]["v0"] == summary["rigid"]["v0"]
    assert data["rigid"]["start"][0] == 0.0 and data["rigid"]["end"][-1] == 1.0
    np.testing.assert_array_equal(data["rigid"]["start"][1:], data["rigid"]["end"][:-1])
    assert list(data["rigid"]["resting_block"]) == [1, 3, 2, 1]
    text = runner.invoke(main, ["info", str(out)]).output
    assert "rigid limit v0           0.300000000000" in text
    assert "uniqueness margin        1, for J = {1, 2, 3} at t = 0; friction.forward from 1 to 0.666667" in text
    plain = tmp_path / "plain.h5"
    runner.invoke(main, ["run", str(GAITS / "inching-2.yaml"), "-q", "-o", str(plain)])
    missing = runner.invoke(main, ["plot", str(plain), "--only", "rigid"])
    assert missing.exit_code == 2 and "crawlsim run --rigid writes it" in missing.output


def test_sweep_figures_draw_the_asymptote_and_the_margin(tmp_path):
    """A stiffness sweep's figure draws v0_inf as its asymptote (here v0 T, the displacement per
    period, as the figure draws it); a friction sweep marks where the uniqueness margin reaches
    0 (peristalsis-4: 3 mu+ - mu- = 0 at friction.backward = 3, where v0 jumps)."""
    from crawlsim.io.sweepfile import read_sweep
    from crawlsim.plotting.sweeps import sweep_data_figure

    runner = CliRunner()
    gait = str(GAITS / "peristalsis-4.yaml")
    for sweep, name in (("stiffness=log:10:1000:3", "k.h5"), ("friction.backward=2.5:3.5:5", "f.h5")):
        out = runner.invoke(
            main, ["velocity", gait, "--sweep", sweep, "--steps-per-period", "100", "-q", "-o", str(tmp_path / name)]
        )
        assert out.exit_code == 0, out.output
    lines = {line.get_label(): line for line in sweep_data_figure(read_sweep(tmp_path / "k.h5")).axes[0].get_lines()}
    assert list(lines["rigid limit $k \\to \\infty$: 0.3"].get_ydata()) == pytest.approx([0.3, 0.3], abs=1e-13)
    lines = {line.get_label(): line for line in sweep_data_figure(read_sweep(tmp_path / "f.h5")).axes[0].get_lines()}
    assert list(lines["uniqueness margin 0: $v_0$ can jump"].get_xdata()) == pytest.approx([3.0, 3.0], abs=1e-9)


def test_a_rigid_limit_too_large_is_refused(monkeypatch):
    """The arrays of the rigid limit grow with the square of the blocks and with the crossings:
    beyond `MAX_ENTRIES` values the gait is refused with why (exit code 2), before allocating."""
    from crawlsim.analysis import rigid

    monkeypatch.setattr(rigid, "MAX_ENTRIES", 5000)
    out = CliRunner().invoke(main, ["velocity", str(GAITS / "earthworm-100.yaml"), "--rigid"])
    assert out.exit_code == 2 and "blocks: the rigid limit of 101 blocks would hold" in out.output
