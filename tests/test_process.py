"""Generic polyhedral sweeping processes (``kind: sweeping-process``, docs/model.md §5): validation,
compilation, the shared engine, the results file and LICQ warnings."""

import json
import re
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from crawlsim.api import run
from crawlsim.cli import main
from crawlsim.errors import DegenerateModelError, GaitError, LicqWarning
from crawlsim.gait.document import Gait, ProcessSpec, load_gait, parse_gait
from crawlsim.gait.process_spec import recession_direction
from crawlsim.io.runread import read_results
from crawlsim.model.process import compile, compile_gait, compile_process
from crawlsim.projection.adapter import ExactProjector
from crawlsim.study.paper import acute_angle_document

from .conftest import GAITS

ACUTE = GAITS / "paper" / "acute-angle.yaml"


def process(doc: dict, source: str = "p.yaml"):
    return parse_gait(yaml.safe_dump(doc), source=source)


def acute(**changes) -> dict:
    doc = acute_angle_document(alpha=1.0, period=1.0, start=0.1, steps=16, max_periods=100)
    doc.update(changes)
    return doc


def test_a_process_file_builds_a_process_spec_and_compiles_to_its_own_data():
    """C(t) = C0 - l(t): offsets (l2, -l2, beta) with l2 = t on [0, T/2], T - t after (docs/model.md, Correction 2);
    alpha = 1, T = 1, beta = 1."""
    spec = load_gait(ACUTE)
    assert isinstance(spec, ProcessSpec) and spec.normals.shape == (3, 2)
    p = compile_process(spec, steps_per_period=7)
    assert p.crawler is None and p.blocks == 0
    assert 0.5 in p.times  # the kink of l(t) is a grid point although 7 is odd
    l2 = np.where(p.times <= 0.5, p.times, 1.0 - p.times)
    assert np.allclose(p.offsets, np.column_stack([l2, -l2, np.full_like(l2, 1.0)]), atol=1e-15, rtol=0)
    assert np.array_equal(p.metric, np.eye(2)) and np.array_equal(p.initial, [0.1, 0.0])
    assert np.allclose(p.offset_pieces.evaluate([0.25, 0.75]), [[0.25, -0.25, 1], [0.25, -0.25, 1]])
    assert np.allclose(p.offset_pieces.evaluate([0.25, 0.75], order=1), [[1, -1, 0], [-1, 1, 0]])
    assert np.allclose(p.breakpoints, [0.0, 0.5])


def test_compile_dispatches_on_the_kind(gaits_dir):
    gait = load_gait(gaits_dir / "inching-2.yaml")
    assert isinstance(gait, Gait) and compile(gait).crawler is not None
    assert np.array_equal(compile(gait, 50).offsets, compile_gait(gait, 50).offsets)
    assert compile(load_gait(ACUTE)).crawler is None


@pytest.mark.parametrize(
    "changes, keypath, words",
    [
        ({"normals": [[0, -1], [-1, 1], [1]]}, "normals[2]", "expected 2 numbers"),
        ({"normals": [[0, -1], [-1, 1], [0, 0]]}, "normals[2]", "nonzero normal"),
        ({"offsets": [0.0, 0.0]}, "offsets", "expected 3 offset signals"),
        ({"initial": [0.1, 0.0, 0.0]}, "initial", "expected 2 coordinates"),
        ({"metric": [[1, 0]]}, "metric", "expected 2 rows"),
        ({"metric": [[1, 0], [0]]}, "metric[1]", "expected 2 numbers"),
        ({"metric": [[1, 0.5], [0.4, 1]]}, "metric", "symmetric"),
        ({"metric": [[1, 2], [2, 1]]}, "metric", "smallest eigenvalue is -1"),
        ({"initial": [0.1, 0.3]}, "initial", "constraint 1 .* violated by 0.2"),
        ({"initial": [1.5, 0.0]}, "initial", "constraint 2 .* violated by 0.5"),
        (
            {"normals": [[0, -1], [-1, 1]], "offsets": [0.0, 0.0]},
            "normals",
            r"unbounded.*d = \(1, 0\).*compact.*allow_unbounded: true",
        ),
        ({"offsets": [0.0, 0.0, -1.0]}, "offsets", r"empty at t = 0 "),
        (
            {
                "offsets": [
                    {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": [0, 0.5, 0]},
                    {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": [0, -0.5, 0]},
                    {"kind": "piecewise-linear", "times": [0, 0.75, 1], "values": [2, -0.25, 2]},
                ]
            },
            "offsets",
            r"empty for t just after about 0.666667 .* and at t = 0.75 ",
        ),
        ({"kind": "sweeping-proces"}, "kind", "did you mean 'sweeping-process'"),
        ({"metrik": [[1, 0], [0, 1]]}, "metrik", "did you mean 'metric'"),
    ],
)
def test_bad_process_files_are_refused_naming_the_key(changes, keypath, words):
    with pytest.raises(GaitError) as info:
        process(acute(**changes))
    assert info.value.keypath == keypath
    assert info.value.source == "p.yaml"
    assert re.search(words, info.value.message), info.value.message


def test_emptiness_is_decided_between_breakpoints_and_on_the_grid_for_smooth_offsets():
    """Piecewise-linear offsets: C(t) nonempty at the breakpoints implies nonempty between them
    (the set {(t, z) : B z <= c(t)} is convex on a linear piece). A cosine offset is checked on
    the grid: z1 <= cos(2 pi t) - 0.5 and -z1 <= 0 is empty where cos(2 pi t) < 0.5, that is for
    t in (1/6, 5/6): the first grid time there with steps_per_period = 6 is 1/3."""
    doc = {
        "kind": "sweeping-process",
        "period": 1.0,
        "normals": [[1.0], [-1.0]],
        "offsets": [{"kind": "cosine", "mean": -0.5, "amplitude": 1.0}, 0.0],
        "initial": [0.0],
        "simulation": {"steps_per_period": 6},
    }
    with pytest.raises(GaitError, match=r"empty at t = 0.333333333333 "):
        process(doc)


def test_unbounded_sets_run_when_allowed():
    """One half-line z <= c(t), c = 1 - t on [0, 1/2] then back: the play operator, periodic
    after one period (Theorem th:1dim), with z(T) = min(z0, 1/2) = 1/2 from z0 = 0.8."""
    doc = {
        "kind": "sweeping-process",
        "period": 1.0,
        "normals": [[1.0]],
        "offsets": [{"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": [1, 0.5, 1]}],
        "initial": [0.8],
        "simulation": {"steps_per_period": 10, "max_periods": 5},
    }
    with pytest.raises(GaitError, match="unbounded"):
        process(doc)
    result = run(process({**doc, "allow_unbounded": True}))
    assert result.convergence == "finite-time" and result.periodic_from == 1
    assert result.limit.w[0, 0] == 0.5
    assert recession_direction(np.array([[1.0], [-1.0]])) is None


def test_process_run_reports_null_velocity_keys_on_the_command_line(tmp_path):
    runner = CliRunner()
    out = tmp_path / "acute.h5"
    res = runner.invoke(main, ["run", str(ACUTE), "-o", str(out), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    for key in (
        "v0",
        "v0_error_estimate",
        "displacement_per_period",
        "dissipation_per_period",
        "cost_of_transport",
        "periodic_from",
    ):
        assert summary[key] is None
    assert summary["convergence"] == "asymptotic"
    assert summary["contraction_rate"] == pytest.approx(0.5, rel=1e-4)
    text = runner.invoke(main, ["run", str(ACUTE), "-o", str(out)]).output
    assert "v0" not in text and "asymptotic, contraction rate 0.5 per period" in text
    assert text.startswith("process acute-angle:")


def test_a_bad_process_file_exits_2_and_writes_nothing(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(acute(initial=[0.1, 0.3])))
    res = CliRunner().invoke(main, ["run", str(bad), "-o", str(tmp_path / "bad.h5")])
    assert res.exit_code == 2
    assert "bad.yaml: initial: the initial point (0.1, 0.3) is outside C(0)" in res.output
    assert list(tmp_path.iterdir()) == [bad]


def test_reactions_are_the_multipliers_with_their_closed_form(tmp_path):
    """Period 0 from (z1, 0), alpha = 1, T = 1: the top face -z1 + z2 <= -l2 pushes the point
    until T/2 with total impulse (<b_2, z> - c_2(T/2)) / |b_2|^2 = (T/2 - alpha z1)/(1 + alpha^2)
    = 0.2, and the bottom face brings z2 back to 0 with the same impulse |z2(T/2)| / |b_1|^2.
    With save_every = 4 each row sums the multipliers since the previous saved point."""
    spec = process(acute(simulation={"steps_per_period": 16, "max_periods": 100}))
    one, four = tmp_path / "one.h5", tmp_path / "four.h5"
    result = run(spec, output=one)
    run(spec, output=four, save_every=4)
    data = read_results(one)
    assert data["attrs"]["kind"] == "sweeping-process"
    reaction = data["trajectory"]["reaction"]
    assert reaction.shape == (16 * result.periods + 1, 3)
    assert np.array_equal(reaction[0], np.zeros(3))
    period0 = reaction[1:17].sum(axis=0)
    assert period0 == pytest.approx([0.2, 0.2, 0.0], abs=1e-15)
    assert np.all(reaction >= 0)
    grouped = read_results(four)["trajectory"]["reaction"]
    assert np.allclose(grouped[1:], reaction[1:].reshape(-1, 4, 3).sum(axis=1), atol=1e-16, rtol=0)
    with h5py.File(one) as f:
        assert "x" not in f["trajectory"] and f.attrs["kind"] == "sweeping-process"


def test_crawler_files_say_crawler_and_have_no_reactions(tmp_path, gaits_dir):
    out = tmp_path / "c.h5"
    run(load_gait(gaits_dir / "inching-2.yaml"), output=out)
    data = read_results(out)
    assert data["attrs"]["kind"] == "crawler" and "reaction" not in data["trajectory"]


CORNER = {
    "kind": "sweeping-process",
    "name": "corner",
    "period": 1.0,
    "normals": [[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1]],
    "offsets": [
        {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": v}
        for v in ([1, 0.5, 1], [1, 1.5, 1], [1, 0.5, 1], [1, 1.5, 1], [2, 1, 2])
    ],
    "initial": [0.9, 0.9],
    "simulation": {"steps_per_period": 10, "max_periods": 10},
}


def test_licq_failure_of_a_process_is_a_warning_with_its_time_and_the_point_is_right():
    """The square [-1, 1]^2 translated by -(s, s), s rising to 1/2 and back, with the redundant
    face z1 + z2 <= 2 - 2 s through its corner: from (0.9, 0.9) the corner (1 - s, 1 - s)
    catches the point at s = 0.1 and carries it to (0.5, 0.5); three tight normals in the plane
    are dependent, and the point is still unique."""
    spec = process(CORNER)
    with pytest.warns(LicqWarning, match=r"LICQ fails at t = 0.1: .*\{0, 2, 4\}"):
        result = run(spec)
    assert result.limit.w[5] == pytest.approx([0.5, 0.5], abs=1e-15)
    assert result.convergence == "finite-time" and result.periodic_from == 1


def test_the_projector_reduces_a_dependent_set_only_when_asked():
    B = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    c = np.zeros(3)
    with pytest.raises(DegenerateModelError, match="linearly dependent"):
        ExactProjector.dense(B, np.eye(2), 1.0).project(np.array([1.0, 2.0]), c, time=0.25)
    projector = ExactProjector.dense(B, np.eye(2), 1.0, on_dependent="warn")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        proj = projector.project(np.array([1.0, 2.0]), c, time=0.25)
        projector.project(np.array([2.0, 1.0]), c, time=0.5)
    assert proj.point == pytest.approx([0.0, 0.0], abs=1e-15)
    poly = projector.polyhedron
    _, _, slack, tol = poly.solve_on(proj.active, np.array([1.0, 2.0]), c)
    assert poly.certify(slack, proj.multipliers, proj.active, tol).ok
    # M (z_trial - z) = B^T lambda with lambda >= 0: the reaction balances the push.
    assert B.T @ proj.multipliers == pytest.approx([1.0, 2.0], abs=1e-14)
    assert len([w for w in caught if issubclass(w.category, LicqWarning)]) == 1
    assert projector.licq_failures == {(0, 1, 2): (0.25, 2)}
    with pytest.raises(ValueError, match="on_dependent"):
        ExactProjector.dense(B, np.eye(2), 1.0, on_dependent="ignore")


@pytest.mark.parametrize("path", sorted((GAITS / "paper").glob("*.yaml")), ids=lambda p: p.stem)
def test_every_paper_file_runs(path):
    """Every file in gaits/paper runs (coarse grid): the cell and the crawler settle in finite
    time, the acute angle (rate 1/2) and the triangle (rate 1/8) only asymptotically."""
    from crawlsim.gait.document import with_simulation

    spec = with_simulation(load_gait(path), steps_per_period=60)
    result = run(spec)
    expected = {
        "acute-angle": ("asymptotic", 0.5),
        "triangle": ("asymptotic", 0.125),
        "cell-3": ("finite-time", None),
        "speed-peristalsis-4": ("finite-time", None),
    }
    kind, rate = expected[Path(path).stem]
    assert result.convergence == kind
    if rate is not None:
        assert result.rate.rate == pytest.approx(rate, rel=1e-3)
    assert (result.v0 is not None) == isinstance(spec, Gait)


def test_the_crawler_object_gives_stress_shape_forces_bounds_and_dissipation_in_closed_form():
    """For peristalsis-4 (k = 10, friction forward 1, backward 2 on every block): sigma = w + K L,
    z = -w / k, f = D^T sigma sums to zero, and the stress bounds are -min(i mu+, (N-i) mu-) and
    min(i mu-, (N-i) mu+) for link i (docs/model.md §1); a catch-up period's dissipation is the
    multipliers paid at their thresholds."""
    from crawlsim.analysis.energy import catch_up_energy
    from crawlsim.integrate.stepping import CatchUpStepper
    from crawlsim.model.crawler import Crawler, block_forces, stress_bounds

    gait = load_gait(GAITS / "peristalsis-4.yaml")
    p = compile_gait(gait, steps_per_period=64)
    crawler = p.crawler
    assert isinstance(crawler, Crawler) and crawler.blocks == 4 and p.blocks == 4
    record = CatchUpStepper(p).step_period()
    k = np.asarray(gait.stiffness)
    sigma = crawler.stress(record.w)
    np.testing.assert_allclose(
        sigma, k * (gait.lengths(p.times) - crawler.shape(record.w)), rtol=0, atol=1e-12 * np.max(np.abs(sigma))
    )
    np.testing.assert_allclose(crawler.shape(record.w), np.diff(record.x, axis=1), rtol=0, atol=1e-12)
    f = crawler.block_forces(record.w)
    np.testing.assert_allclose(f.sum(axis=1), 0.0, atol=1e-12)
    np.testing.assert_array_equal(f[:, 0], -sigma[:, 0])
    np.testing.assert_array_equal(block_forces(sigma), f)
    plus = gait.mu_plus(np.zeros(1))[0]
    minus = gait.mu_minus(np.zeros(1))[0]
    low, high = crawler.stress_bounds()
    behind_plus = np.cumsum(plus)[:-1]
    behind_minus = np.cumsum(minus)[:-1]
    np.testing.assert_allclose(low[0], -np.minimum(behind_plus, minus.sum() - behind_minus))
    np.testing.assert_allclose(high[0], np.minimum(behind_minus, plus.sum() - behind_plus))
    assert low.shape == high.shape == (p.steps + 1, 3) and np.all(low < 0) and np.all(high > 0)
    np.testing.assert_array_equal(stress_bounds(crawler.friction)[1], high)
    # friction is held at every grid time: -mu^- <= f <= mu^+ (to roundoff)
    scale = float(np.max(np.abs(crawler.friction)))
    assert np.all(f <= crawler.friction[:, :4] + 1e-12 * scale)
    assert np.all(-f <= crawler.friction[:, 4:] + 1e-12 * scale)
    # the ledger's dissipation is the crawler's, and the period balances W = D + J + dE
    energy = catch_up_energy(p, record)
    assert energy.dissipation == crawler.dissipation(record.multipliers) > 0
    assert abs(energy.residual - energy.energy_change) <= 1e-12 * energy.scale
    np.testing.assert_allclose(crawler.positions(record.w[-1], float(np.mean(record.x[-1]))), record.x[-1], atol=1e-12)
