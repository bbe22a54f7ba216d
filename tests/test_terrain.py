"""Ground that changes under the crawler (docs/model.md §8): closed forms, invariances, the
energy balance, catch-up's order, and the refusals of bad terrain.

**The two-block closed form.** Two blocks, one link L(t) = 1 + 0.3 sin 2 pi t (T = 1), k = 10,
forward-only friction (mu^- = 100: no block ever slips back), start stress-free at x = (0, 1),
forward threshold a(x) = a0 before x = 2 and a1 after (the closure, max(a0, a1), at x = 2).
With z = x2 - x1 and sigma = k (L - z): the front block slips forward only at sigma = a(x2), the
rear one only at -sigma = a(x1). The motion is rate-independent, so each period is the sequence
of L's extremes 1 -> 1.3 -> 0.7 -> 1 and z a play operator of L with a band that moves with the
blocks:

* while L rises, z = max(z, L - a(x2)/k): the front block slides with the lower edge of the
  band. Where it reaches x = 2 (at L = L_s + 2 - x2, L_s where it started) onto rougher ground
  (a1 > a0) it is held there until L - a1/k reaches z; onto smoother ground (a1 < a0) its force
  a0 exceeds a1 and it slides on at once until sigma = a1: z jumps by (a0 - a1)/k;
* while L falls, z = min(z, L + a(x1)/k): the rear block slides, and at x = 2 likewise.

`_closed_form` evaluates exactly this, period by period: each displacement is a sum of
differences of the numbers 1, 1.3, 0.7, 2 and a/k, so it holds to roundoff. Step up and step
down differ: a step up holds a block while its force grows (no jump), a step down releases it
at once (a jump, whose energy beyond the friction work is a jump loss): not mirror images.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import crawlsim
from crawlsim.analysis.energy import period_energy
from crawlsim.errors import DegenerateModelError, GaitError
from crawlsim.integrate.stepping import make_stepper
from crawlsim.model.process import compile

from .conftest import GAITS, make_gait


def _step_gait(a0: float, a1: float, **extra) -> crawlsim.Gait:
    doc = {
        "name": f"step-{a0:g}-{a1:g}",
        "blocks": 2,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 0.25}],
        "friction": {"forward": a0, "backward": 100.0},
        "terrain": {"patches": [{"from": 2.0, "forward": a1 / a0, "backward": 1.0}]},
        "simulation": {"steps_per_period": 1000, "max_periods": 40},
    }
    doc.update(extra)
    return make_gait(doc)


def _closed_form(a0: float, a1: float, periods: int, k: float = 10.0) -> list[float]:
    """The displacement of each period of the step at x = 2 (module docstring)."""
    return _play(np.array([2.0]), np.array([a0, a1]), periods, k)


def _play(bounds: np.ndarray, thresholds: np.ndarray, periods: int, k: float = 10.0) -> list[float]:
    """The displacement of each period on forward thresholds ``thresholds[c]`` in the cells
    between ``bounds`` (module docstring): a block reaching a boundary with force F goes on
    while the ground beyond is smoother than F, its force falling by k per unit of slide."""
    x = [0.0, 1.0]

    def a(i: int) -> float:  # the threshold under block i: the closure at a boundary
        c = int(np.searchsorted(bounds, x[i]))
        if c < len(bounds) and bounds[c] == x[i]:
            return float(max(thresholds[c], thresholds[c + 1]))
        return float(thresholds[c])

    def move(i: int, L: float, L_end: float) -> None:
        # block i slides while L moves towards L_end (front: L rising, rear: L falling)
        s = 1.0 if i == 1 else -1.0
        while True:
            z = x[1] - x[0]
            start = z + s * a(i) / k  # L where block i starts to slide
            if s * (L_end - start) <= 0:
                return
            L = start if s * (start - L) > 0 else L
            c = int(np.searchsorted(bounds, x[i], side="right"))  # the next boundary ahead
            if c < len(bounds) and x[i] + s * (L_end - L) > bounds[c]:
                force = a(i)
                L += s * (bounds[c] - x[i])
                x[i] = float(bounds[c])
                while thresholds[c + 1] < force:  # the slide onto smoother ground, L held
                    ahead = bounds[c + 1] if c + 1 < len(bounds) else math.inf
                    stop = x[i] + (force - thresholds[c + 1]) / k
                    if stop < ahead:
                        x[i] = stop
                        break
                    force -= k * (ahead - x[i])
                    x[i], c = float(ahead), c + 1
                continue
            x[i] += s * (L_end - L)
            return

    out = []
    for _ in range(periods):
        before = sum(x) / 2
        move(1, 1.0, 1.3)
        move(0, 1.3, 0.7)
        move(1, 0.7, 1.0)
        out.append(sum(x) / 2 - before)
    return out


@pytest.mark.parametrize("a0, a1", [(1.0, 2.0), (2.0, 1.0)], ids=["step-up", "step-down"])
def test_two_block_step_closed_form(a0, a1):
    result = crawlsim.simulate(_step_gait(a0, a1))
    d = result.history.displacement
    expected = _closed_form(a0, a1, len(d))
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-12)
    assert result.history.terrain is not None and result.history.terrain.regime == "one-ground"
    assert result.v0 == pytest.approx(0.6 - 2 * a1 / 10.0, abs=1e-12)  # the ground after the step
    # each block crosses x = 2 once, forward; a step up holds them there first, a step down never
    crossings = result.history.terrain.crossings
    assert sorted(crossings[:, 1]) == [0, 1] and np.all(crossings[:, 2] == 2.0) and np.all(crossings[:, 3] == 1)
    assert (len(result.history.terrain.holds) > 0) == (a1 > a0)
    assert (result.energy.jump_loss == 0.0) and result.energy.balance_residual == pytest.approx(0, abs=1e-14)


def test_step_up_and_down_are_not_mirror_images():
    up, down = _closed_form(1.0, 2.0, 12), _closed_form(2.0, 1.0, 12)
    assert up[-1] == pytest.approx(0.2) and down[-1] == pytest.approx(0.4)
    assert not np.allclose(up, down[::-1])
    assert sum(1 for d in up if 0.2 < d < 0.4) != sum(1 for d in down if 0.2 < d < 0.4)


def _ground_gait(patches: list[dict], mu: float = 2.0, **extra) -> crawlsim.Gait:
    return _step_gait(mu, mu, terrain={"patches": patches}, **extra)


def test_a_slide_across_smoother_cells_is_one_step_down():
    """Onto ever smoother cells [2, 2.02), [2.02, 2.04), [2.04, oo) (thresholds 1.2, 1.1, 1) each
    block slides on, stage after stage, to where a single step down to 1 takes it."""
    cells = [
        {"from": 2.0, "to": 2.02, "forward": 0.6, "backward": 1.0},
        {"from": 2.02, "to": 2.04, "forward": 0.55, "backward": 1.0},
        {"from": 2.04, "forward": 0.5, "backward": 1.0},
    ]
    result = crawlsim.simulate(_ground_gait(cells))
    d = result.history.displacement
    np.testing.assert_allclose(d, _closed_form(2.0, 1.0, len(d)), rtol=0, atol=1e-12)
    assert len(result.history.terrain.crossings) == 6  # each block over three boundaries


def test_a_slide_stops_at_rougher_ground():
    """Onto a smoother strip [2, 2.05) (threshold 1) before rougher ground (3): the slide of 0.1
    stops at 2.05, where the block is held with force 1.5 until it reaches 3."""
    cells = [
        {"from": 2.0, "to": 2.05, "forward": 0.5, "backward": 1.0},
        {"from": 2.05, "forward": 1.5, "backward": 1.0},
    ]
    result = crawlsim.simulate(_ground_gait(cells))
    d = result.history.displacement
    np.testing.assert_allclose(d, _play(np.array([2.0, 2.05]), np.array([2.0, 1.0, 3.0]), len(d)), rtol=0, atol=1e-12)
    # both blocks end held at 2.05, where a stroke of 0.6 cannot reach 3 + 3 (k = 10): stopped
    assert result.history.terrain.regime == "locked" and result.history.terrain.lock == (1, 0) and result.v0 == 0.0
    assert [tuple(h[:2]) for h in result.history.terrain.holds] == [(1, 2.05), (0, 2.05)]
    assert math.isnan(result.history.terrain.holds[-1, 3])  # still held at the end


def _wave(blocks: int, **extra) -> dict:
    """A wave of N blocks: links L_i = 1 + 0.3 cos 2 pi (t - i/N), friction forward 1, backward 2."""
    doc = {
        "blocks": blocks,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / blocks} for i in range(blocks - 1)],
        "friction": {"forward": 1.0, "backward": 2.0},
        "simulation": {"steps_per_period": 400, "max_periods": 5},
    }
    doc.update(extra)
    return doc


def _periods(gait: crawlsim.Gait, integrator: str, count: int) -> list:
    stepper = make_stepper(compile(gait), integrator)
    return [stepper.step_period() for _ in range(count)]


@pytest.mark.parametrize("blocks", [2, 4, 10])
@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_far_from_every_boundary_the_ground_under_the_crawler_is_all_there_is(blocks, integrator):
    """A boundary at x = 1000, never reached: each period's displacement is that of uniform
    ground with the friction of the ground under the crawler (factors 1.6 and 1.3)."""
    ground = make_gait(_wave(blocks, terrain={"patches": [{"to": 1000.0, "forward": 1.6, "backward": 1.3}]}))
    uniform = make_gait(_wave(blocks, friction={"forward": 1.6, "backward": 2.6}))
    for a, b in zip(_periods(ground, integrator, 4), _periods(uniform, integrator, 4)):
        assert a.ground is not None and not len(a.ground)
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            period_energy(compile(ground), a).dissipation, period_energy(compile(uniform), b).dissipation, rtol=1e-12
        )


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize("name", ["peristalsis-4", "anchoring-2", "climbing-3", "inching-2-towing"])
def test_factor_one_is_no_terrain_bit_for_bit(name, integrator):
    """A terrain of factor 1 is uniform ground: the same run to the last bit. And the terrain's
    own path (positions tracked, each row's offsets and friction refreshed with the factor under
    its block, boundaries sought) gives the bits of uniform ground while the ground under the
    blocks has factor 1 (a boundary at x = 1000 beyond it)."""
    gait = crawlsim.load_gait(GAITS / f"{name}.yaml").replace("simulation.integrator", integrator)
    flat = gait.replace("simulation.integrator", integrator)
    one = make_gait({**gait.document, "terrain": {"patches": [{"forward": 1.0, "backward": 1.0}]}})
    a, b = crawlsim.simulate(flat).summary(), crawlsim.simulate(one).summary()
    assert {k: v for k, v in a.items() if k != "wall_time"} == {k: v for k, v in b.items() if k != "wall_time"}
    far = make_gait({**gait.document, "terrain": {"patches": [{"from": 1000.0, "forward": 2.0, "backward": 2.0}]}})
    process, flat_process = compile(far), compile(flat)
    for r, s in zip(_periods(far, integrator, 3), _periods(flat, integrator, 3)):
        for field in ("w", "multipliers", "x"):
            np.testing.assert_array_equal(getattr(r, field), getattr(s, field))
        e, f = period_energy(process, r), period_energy(flat_process, s)
        assert (e.work, e.dissipation, e.jump_loss, e.load_work) == (f.work, f.dissipation, f.jump_loss, f.load_work)


TERRAINS = {
    "step-up": _step_gait(1.0, 2.0),
    "step-down": _step_gait(2.0, 1.0),
    "stripes": make_gait(
        _wave(4, terrain={"repeat": 1.0, "patches": [{"from": 0.3, "to": 0.6, "forward": 0.7, "backward": 1.3}]})
    ),
    "patch-backward": make_gait(
        _wave(
            3,
            friction={"forward": 1.0, "backward": 2.5},
            terrain={"patches": [{"from": 1.5, "to": 2.5, "forward": 1.2, "backward": 0.4}]},
        )
    ),
}


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize("name", sorted(TERRAINS))
def test_the_energy_balance_closes_on_every_period(name, integrator):
    """W = D + J + W_load + E(end) - E(start) on every period, crossings, holds and slides
    included: the exact ledger (closed forms on the pieces, each slide a jump), and catch-up's
    discrete one (each step a projection with the factors where it starts, its dissipation at
    them)."""
    gait = TERRAINS[name]
    process = compile(gait)
    crossed = 0
    for record in _periods(gait, integrator, 8):
        e = period_energy(process, record)
        assert abs(e.residual - e.energy_change) <= 1e-13 * e.scale
        crossed += len(record.ground)
    assert crossed > 0
    # W = D + J (+ catch-up's loss) on the ground the run ends on, the terrain's friction in D
    result = crawlsim.simulate(gait.replace("simulation.max_periods", 60, "simulation.integrator", integrator))
    assert abs(result.energy.balance_residual) <= 1e-12 * max(1.0, result.energy.actuator_work)


@pytest.mark.parametrize("name", ["stripes", "patch-backward"])
def test_catch_up_converges_to_the_exact_run_at_first_order(name):
    """The catch-up step takes the factors of the ground where it starts: a block passes a
    boundary by at most one step's slip with the old ones, an error O(h) (its constant irregular
    in h, as the crossings fall anywhere in a step). Fitted over T/100 .. T/3200, the barycentre
    after six periods approaches the exact run's at order 1."""
    gait = TERRAINS[name]
    exact = np.array([r.x[-1].mean() for r in _periods(gait, "exact", 6)])
    steps = [100, 200, 400, 800, 1600, 3200]
    errors = []
    for G in steps:
        records = _periods(gait.replace("simulation.steps_per_period", G), "catch-up", 6)
        errors.append(np.max(np.abs(np.array([r.x[-1].mean() for r in records]) - exact)))
    order = np.polyfit(np.log(steps), -np.log(errors), 1)[0]
    assert 0.8 <= order <= 1.5, (order, errors)
    assert errors[-1] < 2e-3 * 100 / 3200 * 10


BAD = {
    "overlapping": (
        {
            "patches": [
                {"from": 0, "to": 2, "forward": 2, "backward": 2},
                {"from": 1, "to": 3, "forward": 3, "backward": 3},
            ]
        },
        "terrain.patches[1].from",
    ),
    "unsorted": (
        {
            "patches": [
                {"from": 4, "to": 5, "forward": 2, "backward": 2},
                {"from": 1, "to": 3, "forward": 3, "backward": 3},
            ]
        },
        "terrain.patches[1].from",
    ),
    "non-positive factor": (
        {"patches": [{"from": 1, "to": 2, "forward": 0, "backward": 2}]},
        "terrain.patches[0].forward",
    ),
    "non-finite factor": (
        {"patches": [{"from": 1, "to": 2, "forward": 2, "backward": math.inf}]},
        "terrain.patches[0].backward",
    ),
    "to <= from": ({"patches": [{"from": 2, "to": 2, "forward": 2, "backward": 2}]}, "terrain.patches[0].to"),
    "non-positive repeat": ({"repeat": 0, "patches": []}, "terrain.repeat"),
    "outside repeat": (
        {"repeat": 3, "patches": [{"from": 2, "to": 4, "forward": 2, "backward": 2}]},
        "terrain.patches[0].to",
    ),
    "open in repeat": ({"repeat": 3, "patches": [{"from": 2, "forward": 2, "backward": 2}]}, "terrain.patches[0].to"),
    "too many patches": (
        {"patches": [{"from": i, "to": i + 0.5, "forward": 2, "backward": 2} for i in range(1001)]},
        "terrain.patches",
    ),
    "a misspelt key": ({"patches": [{"form": 1, "to": 2, "forward": 2, "backward": 2}]}, "terrain.patches[0].form"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_terrain_is_refused_naming_the_key(case, tmp_path):
    """Before any computation: exit code 2, one line naming the file and the key, no output."""
    import yaml

    terrain, key = BAD[case]
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({**_wave(4), "terrain": terrain}).replace("inf", ".inf"))
    out = tmp_path / "out.h5"
    done = subprocess.run(
        [sys.executable, "-m", "crawlsim", "run", str(path), "-o", str(out)], capture_output=True, text=True
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"Error: {path}: {key}:"), lines
    assert "Traceback" not in done.stderr and not out.exists()


def test_the_uniqueness_condition_is_checked_on_the_ground_the_blocks_reach():
    """Three blocks (mu+ = 1, mu- = 2.5) crossing onto ground that scales mu- by 0.8: with block 3
    on it, g_J = 1 + 1 - 2 = 0 for J = {1, 2}: the model does not determine the motion there,
    and the run stops with the time and the ground (exit code 2 on the command line)."""
    gait = make_gait(
        _wave(
            3,
            friction={"forward": 1.0, "backward": 2.5},
            terrain={"patches": [{"from": 2.5, "forward": 1.0, "backward": 0.8}]},
        )
    )
    with pytest.raises(
        DegenerateModelError,
        match=r"terrain: on the terrain the uniqueness condition .*: blocks 1-2 on 1/1; block 3 on 1/0.8: ",
    ):
        crawlsim.simulate(gait.replace("simulation.max_periods", 20))
    with pytest.raises(GaitError, match="terrain: on the terrain the uniqueness condition"):  # on it at once
        make_gait({**gait.document, "terrain": {"patches": [{"from": 2.1, "forward": 1.0, "backward": 0.8}]}})


def test_sensitivities_on_the_ground_a_run_settles_on_and_refused_elsewhere():
    """Past the step down the crawler runs on ground of threshold a mu+ = 1 (a = 0.5, mu+ = 2):
    v0 = 0.6 - 2 a mu+ / k, so dv0/dmu+ = -2 a / k = -0.1 and dv0/dk = 2 a mu+ / k^2 = 0.02
    (exact). On stripes the run does not settle on one ground: refused, with the reason."""
    result = crawlsim.sensitivity(_step_gait(2.0, 1.0), ["friction.forward", "stiffness"])
    assert result["friction.forward"].v0.value == pytest.approx(-0.1, abs=1e-12)
    assert result["stiffness"].v0.value == pytest.approx(0.02, abs=1e-12)
    with pytest.raises(GaitError, match="terrain: sensitivities are not defined here: .* non-smooth"):
        crawlsim.sensitivity(TERRAINS["stripes"].replace("simulation.max_periods", 30), ["stiffness"])


def test_the_rigid_limit_refuses_ground_that_changes():
    with pytest.raises(GaitError, match="terrain: the rigid limit .* not periodic"):
        crawlsim.rigid_limit(_step_gait(1.0, 2.0))
    uniform = make_gait(
        _wave(3, friction={"forward": 1.0, "backward": 2.5}, terrain={"patches": [{"forward": 2.0, "backward": 2.0}]})
    )
    scaled = make_gait(_wave(3, friction={"forward": 2.0, "backward": 5.0}))
    assert crawlsim.rigid_limit(uniform).v0 == pytest.approx(crawlsim.rigid_limit(scaled).v0, abs=1e-14)


def test_the_results_file_holds_the_ground_the_crossings_and_the_holds(tmp_path):
    import h5py

    result = crawlsim.api.run(_step_gait(1.0, 2.0), output=tmp_path / "up.h5")
    with h5py.File(tmp_path / "up.h5") as f:
        g = f["terrain"]
        assert list(g["position"]) == [2.0] and list(g["forward"]) == [1.0, 2.0] and g.attrs["regime"] == "one-ground"
        assert list(g["crossing_block"]) == [2, 1] and list(g["crossing_position"]) == [2.0, 2.0]
        assert list(g["hold_block"]) == [2, 1] and np.all(np.isfinite(g["hold_end"][:]))
    back = crawlsim.open_run(tmp_path / "up.h5")
    np.testing.assert_array_equal(back.history.terrain.crossings, result.history.terrain.crossings)
    np.testing.assert_array_equal(back.history.terrain.held_periods, result.history.terrain.held_periods)
    assert list(result.history.terrain.held_periods) == [2, 5, 6]


def test_validate_explain_and_info_know_the_ground(tmp_path):
    import yaml

    path = tmp_path / "up.yaml"
    path.write_text(yaml.safe_dump(_step_gait(1.0, 2.0).document))
    explain = subprocess.run(
        [sys.executable, "-m", "crawlsim", "validate", "--explain", str(path)], capture_output=True, text=True
    )
    assert (
        "terrain: 1 boundary at x = 2; factors (forward/backward) of the cells between them 1/1, 2/1" in explain.stdout
    )
    assert "a priori: on terrain the motion repeats only once every block is on one ground" in explain.stdout
    crawlsim.api.run(_step_gait(1.0, 2.0), output=tmp_path / "up.h5")
    info = subprocess.run(
        [sys.executable, "-m", "crawlsim", "info", str(tmp_path / "up.h5")], capture_output=True, text=True
    )
    assert "terrain                  1 boundary; one-ground; 2 crossings, 2 holds" in info.stdout


def test_a_motion_locked_to_stripes_moves_m_stripes_in_n_periods():
    """gaits/terrain/stripes-2.yaml: the state repeats every 8 periods, 3 stripes (repeat 1)
    on: v0 = 3/8, finite-time, to roundoff."""
    result = crawlsim.simulate(crawlsim.load_gait(GAITS / "terrain" / "stripes-2.yaml"))
    assert result.history.terrain.regime == "locked" and result.history.terrain.lock == (8, 3)
    assert result.v0 == pytest.approx(3 / 8, abs=1e-12) and result.estimate.error_estimate < 1e-11
    assert str(result.convergence) == "finite-time"


def test_the_long_run_average_on_stripes_holds_within_its_estimate():
    """Not locked (the four-block wave of peristalsis-4 on stripes 0.3 wide every 1, factors 0.7
    and 1.3): the average over the second half of a run of 150 periods lies within its estimate
    of that of 1200 periods (whose own estimate is smaller)."""
    document = crawlsim.load_gait(GAITS / "peristalsis-4.yaml").document
    stripes = {"repeat": 1.0, "patches": [{"from": 0.3, "to": 0.6, "forward": 0.7, "backward": 1.3}]}
    gait = make_gait({**document, "terrain": stripes})
    short = crawlsim.simulate(gait.replace("simulation.max_periods", 150))
    long = crawlsim.simulate(gait.replace("simulation.max_periods", 1200))
    assert short.history.terrain.regime == long.history.terrain.regime == "quasi-periodic"
    assert long.estimate.error_estimate < short.estimate.error_estimate
    assert abs(short.v0 - long.v0) <= short.estimate.error_estimate


@settings(max_examples=12)
@example(blocks=5, repeat=1.3, cuts=[0.0625, 0.5], factors=[1.5] + [1.0] * 7)  # uniqueness fails on the way
@given(
    blocks=st.integers(2, 5),
    repeat=st.sampled_from([0.0, 0.7, 1.3]),
    cuts=st.lists(st.floats(0.02, 0.9), min_size=2, max_size=8),
    factors=st.lists(st.floats(0.3, 2.5), min_size=8, max_size=8),
)
def test_random_ground_runs_certified_with_its_energy_balanced(blocks, repeat, cuts, factors):
    """Random patches under a random wave: every period certified (the kernel's samples and
    slides), the energy balance closed, and after every crossing the block on the side it
    crossed to."""
    edges = np.cumsum(cuts) + (0.0 if repeat else 0.5)
    if repeat:
        edges = edges[edges < repeat]
    patches = [
        {"from": float(a), "to": float(b), "forward": factors[i % 8], "backward": factors[(i + 3) % 8]}
        for i, (a, b) in enumerate(zip(edges[::2], edges[1::2]))
    ]
    doc = _wave(blocks, terrain={"patches": patches, **({"repeat": repeat} if repeat else {})})
    try:
        gait = make_gait(doc)
    except GaitError:
        return  # the uniqueness condition fails on the ground the blocks start on
    try:
        records = _periods(gait, "exact", 5)
    except DegenerateModelError:
        return  # it fails on ground they reach
    for record in records:
        e = record.energy
        assert abs(e.residual - e.energy_change) <= 1e-12 * max(e.scale, 1.0)
        events = record.events
        for t, i, g, kind, s in [] if record.ground is None else record.ground:
            if kind != 1:  # crossings
                continue
            k = int(np.searchsorted(events.t, t, side="right")) - 1
            assert s * (events.x[k, int(i)] - gait.terrain.boundary(int(g))) >= -1e-9


def test_stall_on_terrain_where_the_crawler_no_longer_gets_across():
    """inching-2-towing (mu+ = 1, mu- = 2, k = 10, stroke 0.6) towing P on its rear block,
    toward ground from x = 1.5 of factors 1.3 and 1.2. With the front block on it and the rear one
    not, the front slips forward at sigma = 1.3 and the rear backward at 2 - P: for P > 0.7 the
    extension pushes the rear block back instead of the front one forward, and the crawler stops
    at the boundary (docs/model.md §6 with the ground's thresholds). So the stall force is -0.7,
    where the uniqueness condition fails on the mixed ground (a jump), below the stall of either
    ground alone."""
    document = crawlsim.load_gait(GAITS / "inching-2-towing.yaml").document
    gait = make_gait({**document, "terrain": {"patches": [{"from": 1.5, "forward": 1.3, "backward": 1.2}]}})
    found = crawlsim.stall(gait, force="loads.force.0")
    assert abs(found.value + 0.7) <= found.error_estimate + 1e-12 and found.error_estimate < 1e-8
    assert found.cause == "jump"


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_check_every_step_is_refused_on_terrain(integrator, tmp_path):
    """Clarabel's check of every step projects onto the sets of uniform ground: on terrain it is
    refused (exit code 2, one line), with no file written."""
    out = tmp_path / "c.h5"
    argv = ["run", str(GAITS / "terrain" / "step-up-2.yaml"), "--check-every-step", "--integrator", integrator]
    done = subprocess.run([sys.executable, "-m", "crawlsim", *argv, "-o", str(out)], capture_output=True, text=True)
    assert done.returncode == 2 and "without --check-every-step" in done.stderr and not out.exists()
