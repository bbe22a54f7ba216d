"""What a sweep point shares with the points before it (issue 20, the cost of a sweep point):
the period grid, the signals' values and the basis on it, the tables of the offsets' pieces,
the uniqueness analysis of its friction, a record's slips, the dense Jacobian of the last
accepted Newton step. Each is the same computation done once, so every number of a point
computed after others equals the number computed from scratch; these tests compare the two
exactly (the same code on the same inputs: equality, not a tolerance), and check that nothing
shared can be changed through what a caller receives."""

import numpy as np
import pytest

import crawlsim.gait.uniqueness as uniqueness
import crawlsim.integrate.limit as limit_module
import crawlsim.model.offsets as offsets
import crawlsim.model.process as process_module
from crawlsim.analysis.run import simulate
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.gait.signals import Constant, Cosine
from crawlsim.integrate.stepping import make_stepper
from crawlsim.model.offsets import Basis, PiecewiseOffsets
from crawlsim.model.process import compile_gait, period_grid
from crawlsim.study import sweep as sweeps
from crawlsim.study.points import run_points

from .conftest import GAITS

P4 = GAITS / "peristalsis-4.yaml"


def _forget_shared() -> None:
    """Empty every table a sweep point shares with the points before it."""
    uniqueness._ANALYSED.clear()
    offsets._GRID_VALUES.clear()
    process_module._GRIDS.clear()
    process_module._ON_GRID.clear()
    limit_module._formed = None


def _rows(table) -> list:
    return [r.to_json() for r in table.rows]


@pytest.mark.parametrize(
    "axes", [["links.1.phase=0:1:9"], ["links.1.phase=0:1:3", "links.2.phase=0:1:3"], ["friction.backward=0.5:3:6"]]
)
def test_a_sweeps_rows_equal_each_point_computed_from_scratch(axes):
    """The rows of a sweep (exact integrator; the Newton points and the invalid ones of the
    friction axis, where g_J vanishes, included) equal those of the same points each computed
    with nothing shared."""
    gait = with_simulation(load_gait(P4), steps_per_period=200, integrator="exact")
    grid = sweeps.make_grid(gait, axes)
    shared = _rows(sweeps.sweep(grid))
    alone = []
    for i in range(grid.size):
        _forget_shared()
        alone.extend(r.to_json() for r in run_points(grid, [i]))
    assert shared == alone
    assert any(r["limit"] == "newton" for r in shared) or axes[0].startswith("friction")
    if axes[0].startswith("friction"):
        assert [r["status"] for r in shared].count("invalid") == 2  # mu^- = 1 and 3


def test_a_run_without_the_running_frame_keeps_every_other_number():
    """``running_frame=False`` (a sweep row's run) leaves out the limit period in the running
    frame and changes no number of the summary."""
    process = compile_gait(with_simulation(load_gait(P4), steps_per_period=200))
    full = simulate(process, integrator="exact", history=False, series=False)
    row = simulate(process, integrator="exact", history=False, series=False, running_frame=False)
    drop = {"wall_time"}
    assert {k: v for k, v in full.summary().items() if k not in drop} == {
        k: v for k, v in row.summary().items() if k not in drop
    }
    assert row.limit.x is None and row.limit.slip is None and full.limit.slip is not None
    assert np.array_equal(row.limit.w, full.limit.w)


def test_the_period_grid_is_a_copy_of_its_own():
    """A caller that writes into its grid does not change the next caller's."""
    grid = period_grid(10, [0.25])
    expected = grid.copy()
    grid[:] = -1.0
    again = period_grid(10, [0.25])
    assert np.array_equal(again, expected) and 0.25 in again and again[-1] == 1.0


def test_signal_values_holding_a_zero_are_not_shared():
    """0.0 and -0.0 are equal, and so are Constant(0.0) and Constant(-0.0); their values differ
    in the sign of zero, which a shared column would lose."""
    _forget_shared()
    u, key = process_module._shared_grid(8, [])
    plus = process_module._on_grid([Constant(0.0)], u, key)
    minus = process_module._on_grid([Constant(-0.0)], u, key)
    assert not np.signbit(plus).any() and np.signbit(minus).all()
    one = process_module._on_grid([Constant(2.0), Cosine(1.0, 0.5, 0.25)], u, key)
    assert (Constant(2.0), key) in process_module._ON_GRID  # no zero: shared
    one[:] = 0.0  # the caller's array, not the shared column
    again = process_module._on_grid([Cosine(1.0, 0.5, 0.25), Constant(2.0)], u, key)
    assert np.array_equal(again[:, 1], np.full(u.size, 2.0))
    assert np.array_equal(again[:, 0], Cosine(1.0, 0.5, 0.25)(u))


def test_basis_values_on_a_grid_are_the_computed_ones_and_a_copy():
    basis = Basis(linear=True, harmonics=2)
    u = np.linspace(0.0, 1.0, 201)
    first = basis.values(u, 1)
    assert np.array_equal(first, basis._values(u, 1))
    first[:] = 0.0
    assert np.array_equal(basis.values(u, 1), basis._values(u, 1))
    assert np.array_equal(basis.values(u[:10]), basis._values(u[:10], 0))  # not shared


def test_recombined_offsets_share_the_tables_and_map_by_their_own_combine():
    """The energy ledger's view of a process's offsets (`PiecewiseOffsets.recombined`): the
    signals' own coefficients, equal to those of offsets tabulated anew, while the process's
    keep theirs; the shared tables are read-only."""
    gait = load_gait(GAITS / "anchoring-2.yaml")  # piecewise-linear link, steps friction
    pieces = compile_gait(gait, 40).offset_pieces
    signals = pieces.recombined(lambda c: c)
    fresh = PiecewiseOffsets(pieces.signals, lambda c: c, pieces.edges)
    for p in range(pieces.pieces):
        assert np.array_equal(signals.coefficients(p), fresh.coefficients(p))
        assert np.array_equal(pieces.coefficients(p), pieces.combine(fresh.coefficients(p)))
        assert not np.array_equal(pieces.coefficients(p), signals.coefficients(p))
    with pytest.raises(ValueError):
        signals._values[0, 0] = 1.0


def test_a_records_slips_are_formed_once_and_read_only():
    process = compile_gait(with_simulation(load_gait(P4), steps_per_period=100))
    record = make_stepper(process, "exact").step_period()
    slips = record.slips
    assert slips is record.slips and np.array_equal(slips, np.diff(record.x, axis=0))
    with pytest.raises(ValueError):
        slips[0, 0] = 1.0


def test_the_uniqueness_analysis_is_remembered_by_friction():
    """Friction that violates the condition and friction that satisfies it, in turns: each
    answer is its own friction's."""
    bad = ((Constant(1.0),) * 4, (Constant(1.0),) * 4)  # g_J = 0 for |J| = 2
    good = ((Constant(1.0),) * 4, (Constant(2.0),) * 4)
    uniqueness._ANALYSED.clear()
    for _ in range(2):
        found = uniqueness.analyse(*bad)
        assert found is not None and found.violations[0].subset.sum() == 2
        assert uniqueness.analyse(*good) is None
    assert len(uniqueness._ANALYSED) == 2


def test_the_contraction_rate_is_that_of_the_last_accepted_steps_jacobian():
    """The rate read from the Jacobian newton_step formed equals the one formed again."""
    gait = with_simulation(load_gait(P4), steps_per_period=200)
    grid = sweeps.make_grid(gait, ["links.1.phase=0:1:12"])
    process = compile_gait(grid.gait(1))  # phase lag 1/11: an asymptotic limit
    stepper = make_stepper(process, "exact")
    solution = limit_module.solve_limit(process, stepper, tolerance=1e-12, max_periods=200)
    assert solution.converged and solution.newton_steps >= 1
    formed = limit_module._formed
    assert formed is not None
    again = limit_module.jacobian(formed[0], formed[1])
    assert np.array_equal(formed[2], again)
    assert solution.jacobian_rate == limit_module.subdominant_rate(again)
