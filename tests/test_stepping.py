"""Catch-up stepping: the fast paths change nothing, every example gait runs, convergence facts."""

import numpy as np
import pytest

from crawlsim.analysis.run import simulate
from crawlsim.api import run
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.integrate.stepping import (
    STEPPERS,
    CatchUpStepper,
    PeriodStepper,
    make_stepper,
    stepper_class,
)
from crawlsim.model.process import compile_gait, period_grid

from .conftest import GAITS, iterated_examples, make_gait, two_block

EXAMPLES = iterated_examples()


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_fast_paths_agree_with_clarabel_at_every_step(path):
    gait = with_simulation(load_gait(path), steps_per_period=200, max_periods=6)
    process = compile_gait(gait)
    fast = CatchUpStepper(process)
    slow = CatchUpStepper(process, check_every_step=True)
    for _ in range(3):
        a, b = fast.step_period(), slow.step_period()
        assert np.max(np.abs(a.x - b.x)) <= 1e-12
        assert np.max(np.abs(a.w - b.w)) <= 1e-12 * process.scale
        assert np.max(np.abs(a.multipliers - b.multipliers)) <= 1e-12
    assert slow.projector.clarabel_calls == 3 * process.steps
    assert fast.projector.clarabel_calls < slow.projector.clarabel_calls / 5


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_every_example_gait_runs_and_converges(path):
    gait = with_simulation(load_gait(path), steps_per_period=200)
    res = run(gait)
    assert res.converged
    assert np.isfinite(res.v0)
    # The limit period is periodic: its end state is its start state.
    assert np.allclose(res.limit.w[-1], res.limit.w[0], atol=1e-10 * np.max(np.abs(res.limit.w)))
    # Barycentre of the running frame returns to zero after one period.
    assert abs(np.mean(res.limit.x[-1])) < 1e-10
    # The distances to the limit period vanish at the final period.
    assert res.history.w12_distance[-1] == 0 and res.history.slip_l2_distance[-1] == 0
    # Dissipation is non-negative and equals sum mu |dx| of the limit period.
    assert res.energy.dissipation >= 0


def test_stress_stays_admissible_and_slips_only_at_the_friction_limit():
    gait = with_simulation(load_gait(GAITS / "smooth-friction-3.yaml"), steps_per_period=300)
    process = compile_gait(gait)
    res = simulate(process, max_periods=10)
    N = process.blocks
    stress = res.limit.stress
    force = np.zeros((len(stress), N))
    force[:, :-1] -= stress
    force[:, 1:] += stress
    mu = process.crawler.friction
    tol = 1e-12 * process.scale
    assert np.all(force <= mu[:, :N] + tol) and np.all(force >= -mu[:, N:] - tol)
    slip = res.limit.slip
    fwd, bwd = slip == 1, slip == -1
    assert np.allclose(force[1:][fwd], mu[1:, :N][fwd], atol=1e-10)
    assert np.allclose(force[1:][bwd], -mu[1:, N:][bwd], atol=1e-10)


def _single_link(amplitude):
    """Three blocks, only link 1 actuated: below the threshold of motion."""
    return make_gait(
        {
            "blocks": 3,
            "period": 1.0,
            "stiffness": 10.0,
            "links": [{"kind": "cosine", "mean": 1.0, "amplitude": amplitude}, 1.0],
            "friction": {"forward": 1.0, "backward": 1.5},
            "simulation": {"steps_per_period": 200, "max_periods": 200},
        }
    )


def test_asymptotic_convergence_is_not_cut_short():
    """A single actuated link settles only geometrically (docs/model.md §4). Exact projections keep
    the decay going down to the tolerance, so the verdict is 'asymptotic' with a steady rate."""
    res = run(with_simulation(_single_link(0.12), limit="iterate"))  # the iterates all the way
    assert res.convergence == "asymptotic"
    steps = res.history.poincare_step
    ratios = steps[3:] / steps[2:-1]
    assert np.ptp(ratios) < 1e-3  # geometric all the way down to ~1e-12
    assert res.rate.rate == pytest.approx(ratios[-1], rel=1e-3)
    assert res.history.poincare_step[-1] <= 1e-12 * np.max(np.abs(res.limit.w)) * 10
    assert abs(res.v0) <= 10 * res.estimate.error_estimate + 1e-14
    w12 = res.history.w12_distance
    assert np.all(np.diff(w12[2:]) < 0)  # W^{1,2} convergence of the periods


def test_not_converged_is_reported():
    """Plain iteration stops at max_periods before this slowly converging gait settles; with
    no period left after the plain ones the periodic-limit solver cannot run either: both
    report not-converged after max_periods periods (one more period is enough for the
    solver here, whose first Newton step lands on the limit: tests/test_limit.py has a gait
    that needs more)."""
    for limit, periods in (("iterate", 5), ("newton", 2)):
        gait = with_simulation(_single_link(0.12), max_periods=periods, limit=limit)
        res = run(gait)
        assert res.convergence == "not-converged" and not res.converged
        assert res.periods == periods


def test_grid_contains_every_breakpoint():
    u = period_grid(10, [0.05, 0.5, 1 / 3, 0.3 + 1e-14])
    assert 0.05 in u and 0.5 in u and 1 / 3 in u
    assert np.all(np.diff(u) > 0) and u[0] == 0 and u[-1] == 1
    assert len(u) == 11 + 2  # 0.5 and 0.3 (merged) were already grid points


def test_check_every_step_matches_on_asymptotic_gait():
    gait = with_simulation(_single_link(0.12), max_periods=8)
    a = simulate(compile_gait(gait), max_periods=8)
    b = simulate(compile_gait(gait), max_periods=8, check_every_step=True)
    assert np.max(np.abs(a.history.poincare_step - b.history.poincare_step)) < 1e-12


def _isolated_crossing_gait(steps):
    """mu_1^+(t) - mu_2^-(t) = 0.5 cos(2 pi t) vanishes at the isolated instants t = 1/4, 3/4:
    allowed by the uniqueness check. At t = 1/4 the link contracts at its fastest, the link is
    in tension at sigma = -1 and both block 1 (forward) and block 2 (backward) are at their
    friction limits: the two active normals are dependent and the slips are not determined."""
    return make_gait(
        {
            "blocks": 2,
            "period": 1.0,
            "stiffness": 10.0,
            "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3}],
            "friction": [
                {"forward": {"kind": "cosine", "mean": 1.0, "amplitude": 0.5}, "backward": 2.0},
                {"forward": 1.0, "backward": 1.0},
            ],
            "simulation": {"steps_per_period": steps, "max_periods": 5, "integrator": "catch-up"},
        }
    )


def test_isolated_uniqueness_crossing_on_a_grid_time_is_refused_with_time_and_blocks():
    """mu1+(1/4) = 1 = mu2-: at t = 1/4 both blocks can be at a friction limit, so a catch-up step
    ending there has slips unique only up to a rigid translation: the model does not determine
    that step (exit code 2 on the command line, naming the time and the blocks)."""
    from crawlsim.errors import DegenerateModelError

    with pytest.raises(DegenerateModelError, match=r"t = 0\.25: J = \{1, 2\}"):
        run(_isolated_crossing_gait(100))
    # Off the grid the crossing is harmless: the gait runs.
    assert run(_isolated_crossing_gait(101)).converged


# -- the stepper contract and the registry of integrators ---------------------------------------


@pytest.mark.parametrize("name", sorted(STEPPERS))
def test_registered_integrators_follow_the_contract(name):
    """Every integrator is a `PeriodStepper` that implements `_step_impl` and inherits the
    public `step_period`, which numbers the periods; the registry says its order and whether
    it is exact (order 0 exactly when exact)."""
    entry = STEPPERS[name]
    cls = stepper_class(name)
    assert issubclass(cls, PeriodStepper)
    assert cls.step_period is PeriodStepper.step_period
    assert cls._step_impl is not PeriodStepper._step_impl
    assert entry.exact == (entry.order == 0)
    stepper = make_stepper(compile_gait(two_block(steps=50)), name)
    records = [stepper.step_period() for _ in range(3)]
    assert [r.index for r in records] == [0, 1, 2] and stepper.period_index == 3
    assert [r.start for r in records] == [0.0, 1.0, 2.0]


@pytest.mark.parametrize("name", sorted(STEPPERS))
@pytest.mark.parametrize("steps", [50, 200])
def test_registered_integrators_meet_the_two_block_closed_form(name, steps):
    """v0 of the two-block inching gait is 2 a - 2 mu+ / k (test_exact's closed form); each
    registered integrator's error is within its order: roundoff for an exact one, at most
    (2 a) h^order with h = 1 / steps otherwise."""
    amplitude, k, mu_plus = 0.3, 10.0, 1.0
    delta = 2 * amplitude - 2 * mu_plus / k
    stepper = make_stepper(compile_gait(two_block(amplitude, k, steps=steps)), name)
    record = [stepper.step_period() for _ in range(4)][-1]
    v0 = float(np.mean(record.x[-1] - record.x[0]))
    entry = STEPPERS[name]
    bound = 1e-12 if entry.exact else 2 * amplitude * (1.0 / steps) ** entry.order
    assert abs(v0 - delta) <= bound


def test_unknown_integrator_is_named():
    with pytest.raises(ValueError, match="unknown integrator 'rk4'; expected one of catch-up, exact"):
        make_stepper(compile_gait(two_block()), "rk4")
