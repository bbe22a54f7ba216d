"""The periodic-limit solver (crawlsim.integrate.limit): Newton on F(w) = P(w) - w against plain
iteration, on gaits that converge only asymptotically, at a kink of the period map, on a family
of periodic solutions, and when max_periods runs out; and what the results file records.

Gaits (cheap sizes):

* square-wave retrograde peristalsis of N blocks: link i contracted to 1 - 0.3 on
  [i/(N-1), (i+1)/(N-1)) of the period, at rest length otherwise; k = 10, friction forward 1 /
  backward 2.13. c(t) is piecewise constant, so both integrators step it by the same projections
  at the jumps, and the period map is piecewise affine with contraction 1/4 at N = 4, 1/2 at
  N = 5, 3/4 at N = 7 (measured below, from the true iterates and from the Jacobian);
* the retrograde cosine wave of 6 blocks (phase i/(N-1), k = 10, forward 1 / backward 2.13);
* the paper's acute angle at alpha = 0.5 (Section 5.2): on the edge z2 = 0 the Poincare map is
  z1 -> (alpha^2 gamma + z1) / (alpha^2 + 1) for z1 < gamma and the identity beyond, gamma =
  T / (2 alpha) = 1: rate 1/(1 + alpha^2) = 0.8, and the fixed point (gamma, 0) sits on the kink.
"""

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from crawlsim.analysis.convergence import RATE_WINDOW
from crawlsim.analysis.run import simulate
from crawlsim.cli import main
from crawlsim.errors import InputError
from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.limit import (
    ATTEMPTS,
    NEWTON,
    PLAIN,
    PLAIN_PERIODS,
    REJECTED,
    jacobian,
    solve_limit,
    subdominant_rate,
)
from crawlsim.integrate.stepping import make_stepper
from crawlsim.io.runread import read_results
from crawlsim.model.process import compile as compile_gait
from crawlsim.study.paper import acute_angle_document

INTEGRATORS = ("exact", "catch-up")


def square_document(N, steps=20, max_periods=2000):
    width = 1.0 / (N - 1)
    return {
        "name": f"square-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [
            {"kind": "steps", "times": [0.0, width], "values": [0.7, 1.0], "phase": i * width} for i in range(N - 1)
        ],
        "friction": {"forward": 1.0, "backward": 2.13},
        "simulation": {"steps_per_period": steps, "max_periods": max_periods},
    }


def wave_document(N, steps=100, max_periods=2000):
    return {
        "name": f"wave-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / (N - 1)} for i in range(N - 1)],
        "friction": {"forward": 1.0, "backward": 2.13},
        "simulation": {"steps_per_period": steps, "max_periods": max_periods},
    }


def single_link_document(steps=100):
    """Three blocks, link 1 actuated (amplitude 0.12), link 2 passive: below the threshold of
    motion, so the crawler sticks in its limit period."""
    return {
        "name": "single-link",
        "blocks": 3,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.12}, 1.0],
        "friction": {"forward": 1.0, "backward": 1.5},
        "simulation": {"steps_per_period": steps, "max_periods": 400},
    }


GAITS = {
    "square-4": lambda: square_document(4),
    "square-5": lambda: square_document(5),
    "square-7": lambda: square_document(7),
    "wave-6": lambda: wave_document(6),
    "acute-0.5": lambda: acute_angle_document(alpha=0.5, steps=64, max_periods=2000),
}


def process_of(document):
    return compile_gait(gait_from_document(document, document["name"]))


def periods_simulated(result):
    return result.effort.steps // result.steps_per_period


def metric_distance(process, a, b):
    """max over the grid of |a(t) - b(t)|_M, relative to max |b(t)|_M."""

    def norm(W):
        return np.sqrt(np.sum(W * process.polyhedron.metric_times(W), axis=-1))

    return float(np.max(norm(a - b)) / np.max(norm(b)))


@pytest.fixture(scope="module")
def runs():
    """Newton (tolerance 1e-12) and plain iteration to the roundoff floor (1e-13: its tail,
    about 1e-13 / (1 - rate) <= 5e-13 relative, is below what is asserted), and plain iteration
    at 1e-12 for the period counts, for every gait and integrator."""
    out = {}
    for name, make in GAITS.items():
        process = process_of(make())
        for integrator in INTEGRATORS:
            kw = dict(max_periods=2000, integrator=integrator, history=False)
            out[name, integrator] = (
                process,
                simulate(process, tolerance=1e-12, limit="newton", **kw),
                simulate(process, tolerance=1e-13, limit="iterate", **kw),
                simulate(process, tolerance=1e-12, limit="iterate", **kw),
            )
    return out


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("name", list(GAITS))
def test_newton_and_iteration_find_the_same_limit(runs, name, integrator):
    process, newton, reference, _ = runs[name, integrator]
    assert newton.converged and reference.converged
    assert newton.solver.method == "newton" and newton.solver.newton_steps >= 1
    if newton.v0 is not None:
        assert abs(newton.v0 - reference.v0) <= 1e-11 * abs(reference.v0)
    assert metric_distance(process, newton.limit.w, reference.limit.w) <= 1e-10
    # the verified period is periodic to the tolerance
    assert newton.solver.residuals[-1] <= 1e-12


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("name", ["square-7", "acute-0.5"])
def test_newton_simulates_ten_times_fewer_periods_when_the_rate_exceeds_one_half(runs, name, integrator):
    _, newton, _, plain = runs[name, integrator]
    assert plain.rate.rate > 0.5
    assert periods_simulated(plain) >= 10 * periods_simulated(newton)


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("name, rate", [("square-4", 0.25), ("square-5", 0.5), ("square-7", 0.75), ("acute-0.5", 0.8)])
def test_jacobian_rate_agrees_with_the_true_iterates(runs, name, rate, integrator):
    """The contraction rate of the true iterates is a least-squares fit of log(step) over the
    last periods whose relative steps exceed 1e-10 (each carries a roundoff of about
    eps / 1e-10 ~ 2e-6 of itself), so it is good to ~1e-5 once the subdominant modes have
    decayed; the Jacobian's rate is an eigenvalue of an exact product of projectors. For these
    piecewise-affine maps they agree to 1e-4, and both equal the rates the module docstring
    lists (1/(1 + alpha^2) = 0.8 for the acute angle)."""
    _, newton, _, plain = runs[name, integrator]
    assert newton.solver.jacobian_rate == pytest.approx(plain.rate.rate, rel=1e-4)
    assert newton.solver.jacobian_rate == pytest.approx(rate, rel=1e-4)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_fixed_point_on_a_kink_of_the_map(runs, integrator):
    """The acute angle at alpha = 0.5: the edge map is affine with slope 0.8 below gamma = 1 and
    the identity beyond, so its fixed point (gamma, 0) is a kink. Newton on the lower piece
    lands on it exactly in one step (the piece is affine), verified by one plain period."""
    process, newton, _, _ = runs["acute-0.5", integrator]
    assert newton.limit.w[0] == pytest.approx([1.0, 0.0], abs=1e-12)
    assert newton.solver.newton_steps == 1
    # 2 true iterates, then the Newton period, which is also the verifying one
    assert periods_simulated(newton) == 3
    # the limit period's own Jacobian is the identity piece (no eigenvalue below 1); the rate
    # reported is that of the piece the iterates approach through
    stepper = make_stepper(process, integrator)
    stepper.reset(newton.limit.w[0])
    record = stepper.step_period()
    assert subdominant_rate(jacobian(process.polyhedron, record.visited)) == pytest.approx(0.0, abs=1e-12)
    assert newton.solver.jacobian_rate == pytest.approx(0.8, rel=1e-12)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_family_of_periodic_solutions(integrator):
    """Below its threshold of motion the single-link crawler sticks in its limit period: every
    state near the limit is periodic too (Theorem th:speed: the periodic solutions form a
    family sharing one derivative, here zero), so J - I vanishes at the limit and the fixed
    point is not isolated; the limit depends on the initial state. Newton's minimal-norm step
    still lands on a periodic solution, with v0 = 0 (no net motion: the crawler sticks), and
    that solution has the derivative of the true iterates' limit."""
    document = single_link_document()
    process = process_of(document)
    newton = simulate(process, integrator=integrator, limit="newton", history=False)
    plain = simulate(process, integrator=integrator, limit="iterate", history=False, tolerance=1e-13)
    assert newton.solver.method == "newton" and newton.solver.residuals[-1] <= 1e-12
    assert abs(newton.v0) <= newton.estimate.error_estimate and newton.estimate.error_estimate < 1e-12
    # the family: the Jacobian of the limit period is the identity (J - I = 0, every
    # eigenvalue 1) ...
    stepper = make_stepper(process, integrator)
    stepper.reset(newton.limit.w[0])
    J = jacobian(process.polyhedron, stepper.step_period().visited)
    np.testing.assert_allclose(J, np.eye(2), atol=1e-12)
    # ... and the limit depends on the start: the solver from a shifted start finds another
    # periodic solution (in one plain period, then a Newton step that changes nothing)
    shifted = newton.limit.w[0] + np.array([1e-2, 0.0])
    other = solve_limit(process, make_stepper(process, integrator), tolerance=1e-12, max_periods=10, start=shifted)
    assert other.converged and other.periods <= 3
    assert np.max(np.abs(other.w - newton.limit.w[0])) > 1e-3
    stepper.reset(other.w)
    np.testing.assert_allclose(stepper.step_period().w[-1], other.w, atol=1e-12)
    # with the same derivative (Theorem th:speed) as the true iterates' limit
    for a in (other.record.w, plain.limit.w):
        np.testing.assert_allclose(np.diff(a, axis=0), np.diff(newton.limit.w, axis=0), atol=1e-11)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_iterates_periodic_on_another_member_of_a_family_stop_the_run(integrator):
    """Issue 19, item 6. tests/data/family-10.yaml (10 blocks, piecewise-linear backward
    friction) settles into a family of periodic solutions: v0 = 0, the members differ by the
    stresses of links whose blocks never slip (a direction delta with B_A delta = 0 for every set
    A visited, so J delta = delta). The solver's minimal-norm Newton step lands on one member; the
    true iterates contract by 1/4 a period onto another (about 1e-3 away). The history used to follow
    them until they reached the solver's member, which they never do: their Poincare step fell
    to 0.000e+00 and the run went on to max_periods. A Poincare step at the tolerance is
    convergence: the run stops there, and its limit is the iterates' own periodic solution."""
    from pathlib import Path

    from crawlsim.gait.document import load_gait

    gait = load_gait(Path(__file__).parent / "data" / "family-10.yaml")
    process = compile_gait(gait)
    max_periods = gait.simulation.max_periods
    run = simulate(process, integrator=integrator, max_periods=max_periods, tolerance=1e-12)
    assert run.converged and run.periods < max_periods // 2
    steps = run.history.poincare_step
    assert steps[-1] / max(float(np.linalg.norm(run.limit.w[-1])), process.scale) <= 1e-12
    # the distances are measured against the limit the iterates settled on: they reach it
    assert run.history.sup_distance[-1] == pytest.approx(0.0, abs=1e-12)
    assert run.history.w12_distance[-1] == pytest.approx(0.0, abs=1e-12)
    # the limit is a periodic solution (one more period from its start changes nothing) ...
    stepper = make_stepper(process, integrator)
    stepper.reset(run.limit.w[0])
    np.testing.assert_allclose(stepper.step_period().w[-1], run.limit.w[0], atol=1e-10)
    # ... of a family: the solver alone (v0 only) verifies another member, with v0 = 0 as well
    solver = simulate(process, integrator=integrator, max_periods=max_periods, tolerance=1e-12, history=False)
    assert solver.solver.method == "newton"
    assert np.max(np.abs(solver.limit.w[0] - run.limit.w[0])) > 1e-4
    for r in (run, solver):
        assert abs(r.v0) <= r.estimate.error_estimate < 1e-11


def test_not_converged_within_max_periods_exits_3(tmp_path):
    """The wave contracts by ~0.87 per period: neither plain iteration nor the solver (with the
    one period left after the true iterates) verifies a limit in 3 periods."""
    import yaml

    gait = tmp_path / "wave-6.yaml"
    gait.write_text(yaml.safe_dump(wave_document(20, steps=40)))
    for limit in ("newton", "iterate"):
        out = tmp_path / f"{limit}.h5"
        r = CliRunner().invoke(main, ["run", str(gait), "--max-periods", "3", "--limit", limit, "-o", str(out)])
        assert r.exit_code == 3, r.output
        assert "NOT converged" in r.stdout
        assert_says_why(r.stderr, limit)
        data = read_results(out)
        assert data["attrs"]["convergence"] == "not-converged"
        assert data["limit_solver_attrs"]["method"] == "iterate"  # no verified limit
        for extra in ([], ["--json"]):
            r = CliRunner().invoke(main, ["velocity", str(gait), "--max-periods", "3", "--limit", limit, *extra])
            assert r.exit_code == 3, r.output
            assert_says_why(r.stderr, limit)


def assert_says_why(stderr, limit):
    """One line on stderr: the reason (max_periods ran out) and what to change."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert "max_periods = 3" in lines[0] and "--max-periods" in lines[0], lines[0]
    assert ("--limit newton" in lines[0]) == (limit == "iterate"), lines[0]
    assert "Traceback" not in stderr


def test_results_file_records_the_solver(tmp_path):
    """/limit/solver: the method, the Newton steps, the periods the solver simulated, its
    residual per period (dimension solver_period: the first is the last true iterate, where the
    solver starts) with what each period was, and both rates."""
    import yaml

    gait = tmp_path / "square-7.yaml"
    gait.write_text(yaml.safe_dump(square_document(7)))
    out = tmp_path / "square-7.h5"
    r = CliRunner().invoke(main, ["run", str(gait), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "limit found by           Newton on the period map" in r.output
    data = read_results(out)
    solver, attrs = data["limit_solver"], data["limit_solver_attrs"]
    assert attrs["method"] == "newton"
    kinds, residual = solver["kind"], solver["residual"]
    assert kinds[0] == PLAIN and set(kinds) <= {PLAIN, NEWTON, REJECTED}
    assert attrs["newton_steps"] == np.count_nonzero(kinds == NEWTON) >= 1
    assert attrs["periods"] == len(residual) - 1
    assert residual[-1] <= 1e-12 < residual[0]
    assert attrs["jacobian_rate"] == pytest.approx(0.75, rel=1e-4)
    assert attrs["contraction_rate"] == pytest.approx(data["attrs"]["contraction_rate"])
    np.testing.assert_array_equal(solver["solver_period"], np.arange(len(residual)))
    with h5py.File(out) as f:
        ds = f["limit/solver/kind"]
        assert ds.attrs["flag_meanings"] == "rejected_newton plain newton"
        assert ds.dims[0][0].name == "/limit/solver/solver_period"
        assert f["limit/solver/residual"].attrs["units"] == "1"
    xr = pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    with xr.open_datatree(out, engine="h5netcdf") as tree:
        ds = tree["limit/solver"].to_dataset()
        assert ds.residual.dims == ("solver_period",)
        assert ds.attrs["method"] == "newton"
    info = CliRunner().invoke(main, ["info", str(out)])
    assert info.exit_code == 0 and "limit found by           Newton" in info.output


def test_plain_iteration_is_recorded_as_such(tmp_path):
    """With --limit iterate the true iterates find the limit: method iterate, no solver
    periods."""
    import yaml

    gait = tmp_path / "square-4.yaml"
    gait.write_text(yaml.safe_dump(square_document(4)))
    out = tmp_path / "square-4.h5"
    r = CliRunner().invoke(main, ["run", str(gait), "--limit", "iterate", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "limit found by           plain iteration of the periods" in r.output
    data = read_results(out)
    assert data["limit_solver_attrs"]["method"] == "iterate"
    assert data["limit_solver_attrs"]["periods"] == 0
    assert data["limit_solver"]["residual"].size == 0
    assert np.isnan(data["limit_solver_attrs"]["jacobian_rate"])


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("max_periods", [2000, 10])
def test_limit_period_found_by_newton_continues_the_run(tmp_path, integrator, max_periods):
    """The limit period that Newton found is written as the period after the history: it starts
    when the trajectory ends (attribute start = periods * T), its positions have the shape of its
    state (z = D x, so diff(/limit/x) == /limit/shape, to the roundoff of summing 20 slips of
    order 1: 1e-12), and they continue the trajectory's barycentre. The history follows the
    iterates only for the periods a rate fit needs (they contract by 3/4 a period, 88 periods to
    1e-12) and stops there, also with max_periods 2000."""
    import yaml

    gait = tmp_path / "square-7.yaml"
    gait.write_text(yaml.safe_dump(square_document(7, max_periods=max_periods)))
    out = tmp_path / "square-7.h5"
    r = CliRunner().invoke(main, ["run", str(gait), "-o", str(out), "--integrator", integrator])
    assert r.exit_code == 0, r.output
    data = read_results(out)
    assert data["limit_solver_attrs"]["method"] == "newton"
    lim, T = data["limit"], data["attrs"]["period"]
    t = data["trajectory"]["t"]
    assert data["attrs"]["periods"] == (PLAIN_PERIODS + RATE_WINDOW + 1 if max_periods == 2000 else max_periods)
    assert data["limit_attrs"]["start"] == pytest.approx(data["attrs"]["periods"] * T)
    assert t[-1] == pytest.approx(data["limit_attrs"]["start"])
    np.testing.assert_allclose(np.diff(lim["x"], axis=1), lim["shape"], rtol=0, atol=1e-12)
    assert lim["x"][0].mean() == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_jacobian_matches_central_differences_of_the_period_map(integrator):
    """At the limit of the 10-block wave the period map is differentiable, and J (the
    projectors of the visited sets, and for the exact flow the saltation of each event where a
    friction limit is reached while another is released) is its derivative: central
    differences with h = 1e-7 carry an error of about eps |w| / h ~ 1e-8 (roundoff; the
    O(h^2) term vanishes on an affine piece), so they agree to 1e-6. For the exact flow the
    projectors alone are off by more than 1e-3: the times of those events move with the
    start."""
    from crawlsim.integrate.limit import Saltation, factors

    process = process_of(wave_document(10, steps=100))
    limit = simulate(process, integrator=integrator, history=False)
    w0 = limit.limit.w[0]
    stepper = make_stepper(process, integrator)
    stepper.reset(w0)
    record = stepper.step_period()
    J = jacobian(process.polyhedron, factors(process, record))
    h, n = 1e-7, len(w0)
    fd = np.empty((n, n))
    for k in range(n):
        e = np.zeros(n)
        e[k] = h
        stepper.reset(w0 + e)
        plus = stepper.step_period().w[-1]
        stepper.reset(w0 - e)
        fd[:, k] = (plus - stepper.step_period().w[-1]) / (2 * h)
    np.testing.assert_allclose(J, fd, atol=1e-6)
    swaps = [f for f in factors(process, record) if isinstance(f, Saltation)]
    if integrator == "exact":
        assert swaps
        assert np.max(np.abs(jacobian(process.polyhedron, record.visited) - fd)) > 1e-3
    else:
        assert not swaps
    # the rate of the Jacobian is the rate of the true iterates
    assert limit.solver.jacobian_rate == pytest.approx(subdominant_rate(fd), rel=1e-5)


def test_saltation_only_where_the_event_time_moves_with_the_start():
    """A random 10-block gait (`crawlsim.gait.corpus.random_gait`, seed 236: switched, cosine and
    constant friction per block) whose period has swaps at fixed times (the flow's set just
    after a jump of c, a release), and a hit that brings a second, already tight row with it
    while a third is released. Only hits move with
    the start, so only they carry a saltation; with one at every swap J was off by 0.3 and its
    rate was 0.975 where the true iterates contract by 0.657. Central differences (h = 1e-6,
    error eps |w| / h + O(h^2) with cosine offsets) along the faces the start lies on (the
    exact flow starts in K(0)) agree with J v to 1e-5 away from the limit."""
    from crawlsim.gait.corpus import random_gait
    from crawlsim.integrate.limit import factors

    process = compile_gait(random_gait(236, blocks=(2, 16)), 1000)
    stepper = make_stepper(process, "exact")
    for _ in range(5):
        record = stepper.step_period()
    w0 = record.w[-1].copy()
    stepper.reset(w0)
    record = stepper.step_period()
    swaps, before = [], process.polyhedron.empty
    for t in record.transitions:
        old, new = set(before.index.tolist()), set(t.active.index.tolist())
        if new - old and old - new:
            swaps.append((t.cause, len(new - old)))
        before = t.active
    # swaps at fixed times: the flow's set just after a jump (an edge), and a release
    assert ("edge", 1) in swaps and ("release", 1) in swaps
    # a hit that brings a second row with it (already tight) while a third is released
    assert ("hit", 2) in swaps
    poly = process.polyhedron
    J = jacobian(poly, factors(process, record))
    # the exact flow starts in K(0): perturb along the faces w0 lies on (null B_T, T tight)
    B = poly.apply(np.eye(poly.n)).T
    tight = B[process.offsets[0] - B @ w0 <= 1e-9]
    R = np.random.default_rng(7).standard_normal((4, poly.n))
    V = R - (np.linalg.pinv(tight) @ (tight @ R.T)).T
    h = 1e-6
    for v in V:
        stepper.reset(w0 + h * v)
        plus = stepper.step_period().w[-1]
        stepper.reset(w0 - h * v)
        fd = (plus - stepper.step_period().w[-1]) / (2 * h)
        np.testing.assert_allclose(J @ v, fd, atol=1e-5 * np.max(np.abs(v)))
    assert subdominant_rate(J) == pytest.approx(0.657, abs=1e-3)


def test_newton_through_a_kink_of_the_period_map():
    """A random 10-block gait (seed 237) of rate 0.975: the full Newton step crosses a kink of
    P and is rejected, but the Newton step from its candidate, with the Jacobian of that
    candidate's own period, is accepted. The exact solver needs 9 periods where plain
    iteration needs 262 (and 43 with only the shortened step), and its verified period is at
    the gait's tolerance."""
    from crawlsim.gait.corpus import random_gait

    gait = random_gait(237, blocks=(2, 12))
    process = compile_gait(gait, 1000)
    solution = solve_limit(
        process, make_stepper(process, "exact"), max_periods=300, tolerance=gait.simulation.tolerance
    )
    assert solution.converged and solution.residuals[-1] <= gait.simulation.tolerance
    kinds = solution.kinds.tolist()
    through = [i for i in range(1, len(kinds)) if kinds[i - 1] == REJECTED and kinds[i] == NEWTON]
    assert through
    assert solution.periods <= 12


def test_rejected_candidates_back_off_and_cost_at_most_log2_periods(monkeypatch):
    """The safeguard with a Newton step that is always wrong (twice the distance, the wrong
    way: its candidate's Poincare step is larger, so every candidate is rejected). The solver
    then waits 1, 2, 4, ... plain periods after each rejected attempt (the full step, the step
    from its candidate and the shortened one), so it still finds the limit of plain iteration,
    with at most len(ATTEMPTS) (log2(periods) + 1) extra periods."""
    import crawlsim.integrate.limit as limit_module

    monkeypatch.setattr(limit_module, "newton_step", lambda poly, factors, F: -2.0 * F)
    process = process_of(square_document(5))
    plain = solve_limit(process, make_stepper(process, "exact"), tolerance=1e-12, max_periods=500, method="iterate")
    bad = solve_limit(process, make_stepper(process, "exact"), tolerance=1e-12, max_periods=500, plain=0)
    assert bad.converged and bad.newton_steps == 0 and bad.method == "iterate"
    rejected = np.flatnonzero(bad.kinds == REJECTED)
    # each attempt is every candidate of `ATTEMPTS`, all rejected; the plain periods between
    # two attempts: 1, 2, 4, ...
    tries = len(ATTEMPTS)
    attempts = rejected[::tries]
    assert len(rejected) % tries == 0
    np.testing.assert_array_equal(np.diff(rejected.reshape(-1, tries), axis=1), 1)
    gaps = np.diff(attempts) - tries
    np.testing.assert_array_equal(gaps, 2 ** np.arange(len(gaps)))
    assert bad.periods - plain.periods == len(rejected)
    assert len(attempts) <= np.log2(plain.periods) + 1
    np.testing.assert_allclose(bad.w, plain.w, rtol=0, atol=1e-13 * np.max(np.abs(plain.w)))


def test_matrix_free_products_and_step_match_the_dense_jacobian(monkeypatch):
    """Above `DENSE_JACOBIAN` unknowns the Newton step is solved by LSMR with products by J and
    J^T factor by factor: on a small exact-flow period (projectors and saltations) they are
    J v and J^T v of the dense J, and the LSMR step is the dense minimal-norm step."""
    import crawlsim.integrate.limit as limit_module
    from crawlsim.integrate.limit import apply_jacobian, apply_jacobian_transpose, factors, newton_step

    process = process_of(wave_document(10, steps=100))
    stepper = make_stepper(process, "exact")
    for _ in range(3):
        record = stepper.step_period()
    fs = factors(process, record)
    poly = process.polyhedron
    J = jacobian(poly, fs)
    V = np.random.default_rng(1).standard_normal((4, poly.n))
    np.testing.assert_allclose(apply_jacobian(poly, fs, V), V @ J.T, atol=1e-13)
    np.testing.assert_allclose(apply_jacobian_transpose(poly, fs, V), V @ J, atol=1e-13)
    F = record.w[-1] - record.w[0]
    dense = newton_step(poly, fs, F)
    monkeypatch.setattr(limit_module, "DENSE_JACOBIAN", 0)
    np.testing.assert_allclose(newton_step(poly, fs, F), dense, rtol=1e-8, atol=1e-10 * np.max(np.abs(dense)))


def test_newton_saves_the_periods_of_a_slow_contraction():
    """crawlsim.simulate(limit=...): on the 20-block wave, whose iterates contract by about 0.87
    a period (some 170 periods to 1e-12), the solver's run keeps the history only as long as a
    rate fit needs and the iterates head for its limit, a small fraction of plain iteration's
    periods; both find the same v0 within their estimates, and the rate printed is the
    Jacobian's at the limit, the asymptotic one that plain iteration fits at its end."""
    import crawlsim

    gait = gait_from_document(wave_document(20, steps=200), "wave-20")
    plain = crawlsim.simulate(gait, limit="iterate", keep_trajectory=False)
    solved = crawlsim.simulate(gait, limit="newton", keep_trajectory=False)
    assert plain.solver.method == "iterate" and solved.solver.method == "newton"
    assert solved.periods <= PLAIN_PERIODS + 3 * RATE_WINDOW < plain.periods / 4
    assert abs(solved.v0 - plain.v0) <= solved.estimate.error_estimate + plain.estimate.error_estimate
    assert solved.solver.jacobian_rate == pytest.approx(plain.rate.rate, rel=1e-3)
    assert f"contraction rate {solved.solver.jacobian_rate:.4g} per period (the Jacobian's" in str(solved)
    with pytest.raises(InputError, match="limit"):
        crawlsim.simulate(gait, limit="newtonian")
