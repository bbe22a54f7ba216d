"""Run a sweeping process to its periodic regime and measure it (docs/model.md §4).

The paper's Theorem th:attractor: from any admissible start, ``w(. + qT)`` converges in
W^{1,2}(t0, t0+T) to a T-periodic solution, and the slip rates converge in L^2; for crawlers
(Theorem th:speed) the average velocity v0 exists and does not depend on the start.

`simulate` steps the true iterates period by period from the initial state: the history of
Poincare steps ``|w(t0+(q+1)T) - w(t0+qT)|``, displacements and distances to the limit period.
How the limit itself is found is ``limit``:

* ``"iterate"``: the iterates run until the Poincare step is at most
  ``tolerance * max(|w|, scale)`` (or ``max_periods``); the last period is the limit;
* ``"newton"`` (the default): after `crawlsim.integrate.limit.PLAIN_PERIODS` plain periods (gaits that are
  periodic after a period or two stop there, at no extra cost), the periodic-limit solver of
  `crawlsim.integrate.limit` finds the limit directly and verifies it by one plain period; the history
  then goes on only until the iterates reach that verified limit (to the tolerance), become
  periodic themselves (their Poincare step at the tolerance: on another member of a family of
  periodic solutions, which is then the limit), or ``max_periods``; with ``history=False`` (v0
  alone: `crawlsim velocity`, sweeps) it stops at the verified limit.

The convergence is classified from the true iterates:

* **finite-time** from period q when the Poincare step falls to the tolerance in one jump, by a
  factor of more than `FINITE_JUMP` (a geometric contraction that fast cannot be told from exact
  periodicity in double precision); ``periodic_from`` is that q;
* **asymptotic** otherwise, with the contraction rate fitted to the tail of the Poincare steps
  (with the solver, also the rate read from the Jacobian at the limit, ``jacobian_rate``);
* **not-converged** when ``max_periods`` ran out before the limit was found.

The distances of each period to the limit period (W^{1,2}, sup, and the L^2 distance of the
slip rates) are computed at the end, against the limit the run settled on; until then the
periods wait on disk, so a long run's memory stays bounded (`crawlsim.analysis.convergence`).

`simulate` is a driver (`_drive`: the periods, the solver, the history) followed by the analysis
of what it produced (`_analyse`: convergence, v0 and its error, energy); the result carries a
`RunStatus` and a message saying what to change when the run did not succeed.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from crawlsim.analysis.convergence import (
    DISTANCES,
    RATE_WINDOW,
    History,
    RateFit,
    approaching,
    classify_convergence,
    displacement_roundoff,
    fit_contraction_rate,
    period_iteration_error,
    settled_elsewhere,
)
from crawlsim.analysis.energy import EnergyLedger, period_dissipation, period_energy
from crawlsim.analysis.energy import ledger as energy_ledger
from crawlsim.analysis.report import grid_note, result_html, result_repr, run_message, verdict_rate
from crawlsim.analysis.terrain import GroundWatch, TerrainReport
from crawlsim.errors import CrawlsimError
from crawlsim.gait.settings import effective_tolerance
from crawlsim.integrate.limit import PLAIN_PERIODS, LimitSolution, solve_limit
from crawlsim.integrate.stepping import PeriodRecord, make_stepper, positions_of
from crawlsim.model.process import SweepingProcess
from crawlsim.status import Convergence, LimitMethod, RunStatus

#: How the periodic limit is found: the solver of `crawlsim.integrate.limit`, or plain iteration.
LIMIT_METHODS = tuple(LimitMethod)


@dataclass(frozen=True, eq=False)
class ConvergenceHistory:
    """Per-period measurements, one entry per simulated period q = 0, 1, ...; on terrain also
    what the run met on the ground (`crawlsim.analysis.terrain.TerrainReport`)."""

    period: np.ndarray
    displacement: np.ndarray  # y(t0+(q+1)T) - y(t0+qT); NaN for generic processes
    velocity: np.ndarray  # displacement / T
    poincare_step: np.ndarray  # |w(t0+(q+1)T) - w(t0+qT)|
    w12_distance: np.ndarray  # W^{1,2}(period) distance of w to the final period
    sup_distance: np.ndarray  # sup distance of w to the final period
    slip_l2_distance: np.ndarray  # L^2 distance of the slip rates (multiplier rates) to the final period
    dissipation: np.ndarray  # energy dissipated by friction in the period; NaN for generic
    # On terrain (docs/model.md §8): how the run settled, the crossings and the holds.
    terrain: TerrainReport | None = None


@dataclass(frozen=True, eq=False)
class LimitPeriod:
    """The final period, taken as the periodic limit: times relative to its start."""

    start: float
    t: np.ndarray  # (G+1,) in [0, T]
    w: np.ndarray  # (G+1, n)
    multipliers: np.ndarray  # (G, m)
    x: np.ndarray | None = None  # (G+1, N) positions in the running frame x - y(start) - v0 (t - start)
    shape: np.ndarray | None = None  # (G+1, N-1) z = D x
    stress: np.ndarray | None = None  # (G+1, N-1) sigma = K (L - z)
    slip: np.ndarray | None = None  # (G, N) int8: +1 forward slip, -1 backward slip, 0 stick
    slip_rate: np.ndarray | None = None  # (G, N) dx / dt on each step


@dataclass(frozen=True)
class V0Estimate:
    """A crawler's v0 with an error estimate that bounds its true error (docs/model.md §4): the
    period iteration's part (the roundoff of the period's slips, the tail still to come, or the
    residual of the verified limit) plus the time step's (none for the exact integrator; for
    catch-up measured against the exact integrator, None with the reason where it cannot be).
    The estimate is None, and ``reason`` says why, where the time step's part is unknown."""

    value: float
    error_estimate: float | None
    period_iteration: float
    time_step: float | None
    reason: str | None
    displacement: float  # per period: y(t0+(q+1)T) - y(t0+qT) of the limit period


@dataclass(frozen=True)
class LimitSolver:
    """How the limit was found: the periodic-limit solver (``newton``: its accepted Newton
    steps, the periods it simulated with the verifying one, their relative Poincare steps and
    kinds, `crawlsim.integrate.limit.PLAIN`, ``NEWTON`` or ``REJECTED``, and the contraction
    rate read from the Jacobian at the limit) or the iterates themselves (``iterate``)."""

    method: LimitMethod = LimitMethod.ITERATE
    newton_steps: int = 0
    periods: int = 0
    residuals: np.ndarray | None = None
    kinds: np.ndarray | None = None
    jacobian_rate: float | None = None


@dataclass(frozen=True)
class ExactVerdict:
    """For a catch-up run measured against the exact integrator: the exact integrator's verdict
    and rate (`exact_verdict`), and the note the summary prints where catch-up's verdict depends
    on the time grid (`crawlsim.analysis.report.grid_note`)."""

    convergence: Convergence
    rate: float | None
    note: str | None = None


@dataclass(frozen=True)
class Effort:
    """What a run took: the steps of every period simulated (the solver's included), the
    projections Clarabel solved, and the wall time in seconds."""

    steps: int
    clarabel_calls: int
    wall_time: float


@dataclass(frozen=True, eq=False, repr=False)
class RunResult:
    """Everything `simulate` measured, in groups; ``summary()`` is the JSON-ready part.

    ``status`` is the outcome and ``message`` says what to change when it is not
    `RunStatus.SUCCESSFUL` (diffrax's manner); ``estimate`` (v0 and its error) and ``energy``
    (the energy ledger of the limit period, `crawlsim.analysis.energy.EnergyLedger`) are None
    for a generic sweeping process, which has no velocity; ``rate`` is the contraction rate
    fitted to the Poincare steps (None for finite-time convergence)."""

    name: str
    integrator: str
    status: RunStatus
    message: str
    period: float
    periods: int
    convergence: Convergence
    periodic_from: int | None
    estimate: V0Estimate | None
    energy: EnergyLedger | None
    rate: RateFit | None
    solver: LimitSolver
    exact: ExactVerdict | None
    effort: Effort
    history: ConvergenceHistory
    limit: LimitPeriod

    @property
    def v0(self) -> float | None:
        """v0 (``estimate.value``); None for a generic sweeping process."""
        return None if self.estimate is None else self.estimate.value

    @property
    def steps_per_period(self) -> int:
        """Steps of the period's grid (breakpoints included): those of the limit period."""
        return len(self.limit.t) - 1

    @property
    def converged(self) -> bool:
        """Whether the run reached its periodic regime (finite-time or asymptotic)."""
        return self.convergence != Convergence.NOT_CONVERGED

    def __repr__(self) -> str:
        return result_repr(self)

    def _repr_html_(self) -> str:
        return result_html(self)

    def summary(self) -> dict[str, Any]:
        """The JSON-ready numbers, flat, statuses as their strings."""
        e, energy, rate, solver, exact = self.estimate, self.energy, self.rate, self.solver, self.exact
        return {
            "name": self.name,
            "integrator": self.integrator,
            "status": str(self.status),
            "message": self.message,
            "v0": self.v0,
            "v0_error_estimate": None if e is None else e.error_estimate,
            "v0_error_period_iteration": None if e is None else e.period_iteration,
            "v0_error_time_step": None if e is None else e.time_step,
            "v0_error_reason": None if e is None else e.reason,
            "displacement_per_period": None if e is None else e.displacement,
            "dissipation_error_estimate": None if energy is None else energy.dissipation_error_estimate,
            "convergence": str(self.convergence),
            "periodic_from": self.periodic_from,
            "contraction_rate": None if rate is None else rate.rate,
            "contraction_rate_error": None if rate is None else rate.error,
            "contraction_rate_periods": 0 if rate is None else rate.periods,
            "jacobian_rate": solver.jacobian_rate,
            "exact_convergence": None if exact is None else str(exact.convergence),
            "exact_rate": None if exact is None else exact.rate,
            "grid_note": None if exact is None else exact.note,
            "periods": self.periods,
            "steps_per_period": self.steps_per_period,
            "dissipation_per_period": None if energy is None else energy.dissipation,
            "cost_of_transport": None if energy is None else energy.cost_of_transport,
            "limit_method": str(solver.method),
            "limit_newton_steps": solver.newton_steps,
            "limit_periods": solver.periods,
            "clarabel_calls": self.effort.clarabel_calls,
            "steps": self.effort.steps,
            "wall_time": self.effort.wall_time,
            "actuator_work_per_period": None if energy is None else energy.actuator_work,
            "jump_loss_per_period": None if energy is None else energy.jump_loss,
            "discretisation_loss_per_period": None if energy is None else energy.discretisation_loss,
            "load_work_per_period": None if energy is None else energy.load_work,
            "energy_balance_residual": None if energy is None else energy.balance_residual,
            "cost_of_transport_bound": None if energy is None else energy.cost_of_transport_bound,
            "efficiency": None if energy is None else energy.efficiency,
            "final_poincare_step": float(self.history.poincare_step[-1]),
            **({} if self.history.terrain is None else {"terrain": self.history.terrain.summary()}),
        }


@dataclass(frozen=True, eq=False)
class Settled:
    """A run with the period it settled on: its result, and the limit period's record on the
    process it is a period of, which exact sensitivities walk again
    (`crawlsim.analysis.sensitivity`, ``run=``) instead of searching the limit twice."""

    result: RunResult
    record: PeriodRecord
    process: SweepingProcess


Progress = Callable[[int, float], None]


@dataclass
class _Drive:
    """What the driver produced: the true iterates, the limit period the run settled on and,
    when the periodic-limit solver found it, its solution; the cost of the solver's periods."""

    log: History
    final: PeriodRecord
    solution: LimitSolution | None
    distances: dict[str, np.ndarray]
    clarabel_calls: int
    solver_periods: int
    ground: GroundWatch | None = None


def settle(
    process: SweepingProcess,
    *,
    max_periods: int = 1000,
    tolerance: float = 1e-12,
    integrator: str = "catch-up",
    check_every_step: bool = False,
    sink: Any = None,
    progress: Progress | None = None,
    limit: str = "newton",
    history: bool = True,
    time_step_error: bool = False,
    series: bool = True,
    running_frame: bool = True,
) -> Settled:
    """Step ``process`` to its periodic regime and analyse the run (module docstring): the
    result, and the limit period it settled on (`Settled`).

    ``sink.add_period(record)`` receives every period of the history as it is computed (the
    HDF5 writer streams the trajectory); ``progress(q, poincare_step_relative)`` is called after
    every period of the history.

    v0 carries an error estimate that bounds its true error, in two parts: the period iteration
    (roundoff of the period's slips, the tail still to come, or the residual of the verified
    limit) and the time step. The exact integrator has no time-step error; for catch-up it is
    measured (``time_step_error``) against the exact integrator's v0 for the same gait
    (`time_step_reference`), and left None where that cannot run.

    ``series=False`` keeps two per-period series of the history: the distances to the limit
    period (``w12_distance``, ``sup_distance``, ``slip_l2_distance``: empty) and the dissipation
    of each period (NaN); every other number is the same. A sweep's rows hold none of them, and
    keeping and measuring every period (each exact period's energy ledger) was a fifth of a
    point's cost. ``running_frame=False`` leaves ``limit`` without the limit period in the
    running frame (`limit_period`'s x, shape, stress, slip and slip_rate: None), which no row
    reads either.
    """
    if limit not in LIMIT_METHODS:
        raise ValueError(f"limit must be one of {', '.join(LIMIT_METHODS)}, got {limit!r}")
    began = _time.perf_counter()
    options = {"check_every_step": True} if check_every_step else {}
    tol = effective_tolerance(tolerance)
    drive = _drive(
        process,
        integrator,
        options,
        tol=tol,
        max_periods=max_periods,
        limit=limit,
        history=history,
        sink=sink,
        progress=progress,
        series=series,
    )
    result = _analyse(
        process,
        drive,
        integrator=integrator,
        tol=tol,
        reference=_reference(process, integrator, time_step_error, max_periods=max_periods, tolerance=tolerance),
        running_frame=running_frame,
    )
    status, message = _outcome(result, max_periods=max_periods, tolerance=tol, limit=limit)
    exact = None if result.exact is None else replace(result.exact, note=grid_note(result))
    effort = replace(result.effort, wall_time=_time.perf_counter() - began)
    return Settled(replace(result, status=status, message=message, exact=exact, effort=effort), drive.final, process)


def simulate(process: SweepingProcess, **options: Any) -> RunResult:
    """The result of `settle` (its options) alone."""
    return settle(process, **options).result


def _drive(
    process: SweepingProcess,
    integrator: str,
    options: dict[str, Any],
    *,
    tol: float,
    max_periods: int,
    limit: str,
    history: bool,
    sink: Any,
    progress: Progress | None,
    series: bool = True,
) -> _Drive:
    """The true iterates, period by period, and the limit: plain iteration, or a few plain
    periods and then the periodic-limit solver, with the history following the iterates to it."""
    stepper = make_stepper(process, integrator, **options)
    log = History(process, series=series)
    solution: LimitSolution | None = None
    cost = (0, 0)  # periods simulated and Clarabel calls made by the limit solver
    watch = None if process.terrain is None else GroundWatch(process, tol)
    if watch is not None:  # on terrain the iterates alone, until they settle (docs/model.md §8)
        limit = LimitMethod.ITERATE
    try:
        # the true iterates; with the solver, only a few before it takes over
        budget = max_periods if limit == LimitMethod.ITERATE else min(max_periods, PLAIN_PERIODS)
        final = _iterate(log, stepper, budget, tol, sink, progress, watch)
        if final is None and limit == LimitMethod.NEWTON and len(log) < max_periods:
            final, solution, cost = _solve(
                process,
                integrator,
                options,
                log,
                stepper,
                tol=tol,
                max_periods=max_periods,
                history=history,
                sink=sink,
                progress=progress,
            )
        if final is None:  # plain iteration to the end (limit="iterate", or a solver failure)
            final = _iterate(log, stepper, max_periods, tol, sink, progress, watch) or log.last
        assert final is not None, "max_periods >= 1"
        if watch is not None:
            watch.conclude()
        log.set_limit(final)
        measured = log.distances() if series else {key: np.array([]) for key in DISTANCES}
    finally:
        log.close()
    if solution is not None:
        assert log.last is not None
        final = following(process, final, log.last)
    return _Drive(log, final, solution, measured, stepper.projector.clarabel_calls + cost[1], cost[0], watch)


def _iterate(
    log: History,
    stepper: Any,
    budget: int,
    tol: float,
    sink: Any,
    progress: Progress | None,
    watch: GroundWatch | None = None,
) -> PeriodRecord | None:
    """Plain periods until the Poincare step reaches ``tol`` (on terrain: until the run settles,
    `crawlsim.analysis.terrain`; that period, the limit) or the history holds ``budget``
    periods (None)."""
    while len(log) < budget:
        record = log.add(stepper.step_period(), sink, progress)
        if watch is not None:
            watch.add(record)
            if watch.settled(log.rel_steps[-1]):
                return record
        elif log.rel_steps[-1] <= tol:
            return record
    return None


def _solve(
    process: SweepingProcess,
    integrator: str,
    options: dict[str, Any],
    log: History,
    stepper: Any,
    *,
    tol: float,
    max_periods: int,
    history: bool,
    sink: Any,
    progress: Progress | None,
) -> tuple[PeriodRecord | None, LimitSolution | None, tuple[int, int]]:
    """The periodic-limit solver from the last true iterate, then the history up to its limit:
    (the limit period or None when the solver failed, the solution or None when the iterates
    settled elsewhere, the solver's (periods, Clarabel calls))."""
    solver = make_stepper(process, integrator, **options)
    # the last true iterate is the solver's first period: not simulated twice
    solution = solve_limit(process, solver, tolerance=tol, first=log.last, max_periods=max_periods - len(log), plain=0)
    cost = (solution.periods, solver.projector.clarabel_calls)
    if not solution.converged:  # the solver's periods count against max_periods
        return None, None, cost
    log.set_limit(solution.record)
    # the history goes on until the iterates reach the verified limit, or are periodic
    # themselves (a Poincare step of 0 is convergence): where the periodic solutions form a
    # family (Theorem th:speed: they differ by constants of the directions no active set ever
    # sees), the iterates may settle on another member than the solver's, and would never
    # reach it. Their own is then the limit. It stops once it holds the periods a rate fit needs:
    # following slowly contracting iterates all the way is the cost the solver saves.
    end = len(log) + RATE_WINDOW + 1
    while history and len(log) < max_periods and not log.reached(tol):
        if len(log) >= end and approaching(log, tol, RATE_WINDOW):
            break
        record = log.add(stepper.step_period(), sink, progress)
        if settled_elsewhere(log, tol):
            return record, None, cost
    return solution.record, solution, cost


@dataclass
class _Motion:
    """A crawler's limit period: displacement, v0, dissipation and v0's period-iteration error."""

    displacement: float
    v0: float
    dissipation: float
    error: float


def verified_limit_error(process: SweepingProcess, final: PeriodRecord, steps: int) -> float:
    """The error of v0 from a verified limit period of ``steps`` steps: the steps' roundoff,
    and the period's residual |P(w) - w|, periodic to which it is: a shape mismatch of
    |F| / k_min (a length) bounds the displacement's."""
    c, slips = process.crawler, final.slips
    assert c is not None and slips is not None
    mean_abs_slip = float(np.sum(np.abs(slips))) / c.blocks
    roundoff = displacement_roundoff(process, steps, mean_abs_slip, len(final.transitions) or steps)
    return float((roundoff + shape_mismatch(process, final)) / process.period)


def shape_mismatch(process: SweepingProcess, final: PeriodRecord) -> float:
    """A period's residual |P(w) - w| as a length, max |w(T) - w(0)| / k_min: a shape that
    repeats to within it leaves the displacement uncertain by as much."""
    assert process.crawler is not None
    return float(np.abs(final.w[-1] - final.w[0]).max()) / float(process.crawler.stiffness.min())


def _motion(
    process: SweepingProcess, drive: _Drive, displacements: np.ndarray, convergence: Convergence, rate: float | None
) -> _Motion | None:
    """v0 of the limit period and the error of the period iteration: the residual of the
    verified period, or the roundoff and geometric tail of the iterates (None: no crawler)."""
    c = process.crawler
    if c is None:
        return None
    found = None if drive.ground is None else drive.ground.motion()
    if found is not None:  # locked to the ground, or its long-run average (docs/model.md §8)
        return _Motion(*found)
    final, T, G = drive.final, process.period, process.steps
    slips = final.slips
    assert final.x is not None and slips is not None
    d_final = float(np.mean(final.x[-1] - final.x[0]))
    roundoff = float(np.sum(np.abs(slips))) / c.blocks
    if drive.solution is not None:
        err = verified_limit_error(process, final, G)
    else:
        roundoff = displacement_roundoff(process, G, roundoff, len(final.transitions) or G)
        err = period_iteration_error(displacements, convergence, rate, roundoff, T)
    return _Motion(d_final, d_final / T, period_dissipation(process, final), err)


@dataclass
class _StepError:
    """Catch-up's time-step error of v0 and of the dissipation, measured against the exact
    integrator (zero for the exact integrator), or the reason it could not be measured."""

    v0: float | None = None
    dissipation: float | None = None
    reason: str | None = None


def _reference(
    process: SweepingProcess, integrator: str, wanted: bool, *, max_periods: int, tolerance: float
) -> RunResult | None | bool:
    """The exact integrator's run a catch-up run is measured against (`time_step_reference`);
    False when none is wanted (the exact integrator, or ``time_step_error`` off)."""
    if integrator == "exact" or not wanted or process.crawler is None:
        return False
    return time_step_reference(process, max_periods=max_periods, tolerance=tolerance)


def _step_error(
    process: SweepingProcess, motion: _Motion, integrator: str, reference: RunResult | None | bool
) -> _StepError:
    if integrator == "exact":
        return _StepError(0.0, 0.0)
    if reference is False:
        return _StepError()
    if isinstance(reference, RunResult) and reference.estimate is not None:
        e, energy = reference.estimate, reference.energy
        assert energy is not None
        return _StepError(
            abs(motion.v0 - e.value) + (e.error_estimate or 0.0),
            abs(motion.dissipation - energy.dissipation) + (energy.dissipation_error_estimate or 0.0),
        )
    # the period iteration's part alone bounds nothing: catch-up is O(h)
    reason = (
        "the exact integrator needs a closed form of c(t), which this gait has not"
        if process.offset_pieces is None
        else "the exact integrator's reference run failed"
    )
    return _StepError(reason=f"no error estimate: the catch-up time-step error could not be measured; {reason}")


def _energy(
    process: SweepingProcess, final: PeriodRecord, motion: _Motion, error: float | None, dissipation_error: float | None
) -> EnergyLedger | None:
    """The cost of transport (with loads, counting the work against them: docs/model.md §6)
    and the energy ledger of the limit period (`crawlsim.analysis.energy`)."""
    cot = None
    if error is not None:
        paid = motion.dissipation
        if process.crawler is not None and process.crawler.load is not None:
            paid += period_energy(process, final).load_work  # type: ignore[union-attr]
        cot = cost_of_transport(paid, motion.displacement, error, process.period)
    return energy_ledger(process, final, motion.displacement, cot, dissipation_error)


def _history_arrays(process: SweepingProcess, drive: _Drive) -> ConvergenceHistory:
    """The per-period measurements of the true iterates (NaN displacements for generic
    processes)."""
    log = drive.log
    Q = len(log) - 1
    crawler = process.crawler is not None
    displacement = np.array(log.displacements) if crawler else np.full(Q + 1, np.nan)
    dissipation = np.array(log.dissipations) if crawler else np.full(Q + 1, np.nan)
    return ConvergenceHistory(
        period=np.arange(Q + 1),
        displacement=displacement,
        velocity=displacement / process.period,
        poincare_step=np.array(log.steps),
        dissipation=dissipation,
        **drive.distances,
        terrain=None if drive.ground is None else drive.ground.report(),
    )


def _solver(solution: LimitSolution | None) -> LimitSolver:
    """How the limit was found: the periodic-limit solver's numbers, or plain iteration."""
    if solution is None:
        return LimitSolver()
    s = solution
    return LimitSolver(LimitMethod.NEWTON, s.newton_steps, s.periods, s.residuals, s.kinds, s.jacobian_rate)


def _analyse(
    process: SweepingProcess,
    drive: _Drive,
    *,
    integrator: str,
    tol: float,
    reference: RunResult | None | bool,
    running_frame: bool = True,
) -> RunResult:
    """What the driver's periods measure: the convergence and its rate, v0 and its error
    (period iteration plus time step), the cost of transport and the energy ledger."""
    watch = drive.ground
    since = 0  # on terrain: the periods on one ground
    if watch is not None and watch.regime == "one-ground":
        since = watch.quiet_since
    rel = np.array(drive.log.rel_steps)[since:]
    convergence, periodic_from = classify_convergence(rel, tol)
    periodic_from = None if periodic_from is None else periodic_from + since
    if watch is not None and watch.lock is not None:  # the motion repeats every n periods
        convergence, periodic_from = Convergence.FINITE_TIME, len(drive.log) - watch.lock[0]
    elif watch is not None and watch.regime != "one-ground":
        quasi = watch.regime == "quasi-periodic"
        convergence = Convergence.QUASI_PERIODIC if quasi else Convergence.NOT_CONVERGED
    if drive.solution is not None and convergence == Convergence.NOT_CONVERGED:
        # the limit is verified; the iterates approach it geometrically but had not reached it
        convergence = Convergence.ASYMPTOTIC
    fit = None if convergence == Convergence.FINITE_TIME else fit_contraction_rate(rel)
    hist = _history_arrays(process, drive)
    motion = _motion(process, drive, hist.displacement[since:], convergence, None if fit is None else fit.rate)
    estimate, energy = None, None
    if motion is not None:
        step = _step_error(process, motion, integrator, reference)
        err = motion.error if step.v0 is None else motion.error + step.v0
        diss_err = None
        if step.dissipation is not None and motion.v0:
            diss_err = abs(motion.dissipation) * motion.error / abs(motion.v0) + step.dissipation
        estimate = V0Estimate(
            motion.v0, None if step.reason else err, motion.error, step.v0, step.reason, motion.displacement
        )
        energy = _energy(process, drive.final, motion, err, diss_err)
    exact = exact_verdict(reference) if isinstance(reference, RunResult) else None
    return RunResult(
        name=process.name,
        integrator=integrator,
        status=RunStatus.SUCCESSFUL,
        message="",
        period=process.period,
        periods=len(drive.log),
        convergence=convergence,
        periodic_from=periodic_from,
        estimate=estimate,
        energy=energy,
        rate=fit,
        solver=_solver(drive.solution),
        exact=exact,
        effort=Effort((len(drive.log) + drive.solver_periods) * process.steps, drive.clarabel_calls, 0.0),
        history=hist,
        limit=limit_period(process, drive.final, None if motion is None else motion.v0, running_frame),
    )


def exact_verdict(reference: RunResult) -> ExactVerdict | None:
    """The exact integrator's verdict and rate from its reference run (`time_step_reference`),
    where it costs nothing more: that run stops at the verified limit without following the
    iterates to it, so its own classification is the true iterates' only when they reached the
    limit themselves (limit method iterate). When the solver found it, a Jacobian rate r > 0 at
    the limit means the iterates approach it geometrically, at that rate (asymptotic);
    otherwise the verdict is unknown (None) and nothing is claimed."""
    if reference.solver.method == LimitMethod.ITERATE:
        return ExactVerdict(reference.convergence, verdict_rate(reference))
    rate = reference.solver.jacobian_rate
    if rate is not None and rate > 0:
        return ExactVerdict(Convergence.ASYMPTOTIC, rate)
    return None


def _outcome(result: RunResult, *, max_periods: int, tolerance: float, limit: str) -> tuple[RunStatus, str]:
    """The status and the message saying what to change (empty when successful)."""
    if result.convergence == Convergence.NOT_CONVERGED:
        return RunStatus.MAX_PERIODS_REACHED, run_message(
            result, max_periods=max_periods, tolerance=tolerance, limit=limit
        )
    if result.estimate is not None and result.estimate.reason is not None:
        return RunStatus.NO_ERROR_ESTIMATE, result.estimate.reason
    return RunStatus.SUCCESSFUL, ""


def time_step_reference(process: SweepingProcess, *, max_periods: int, tolerance: float) -> RunResult | None:
    """The exact integrator's v0 for ``process`` (periodic-limit solver, no history): the
    reference a catch-up v0's time-step error is measured against; None where the exact
    integrator cannot run (no closed form of c(t), or it stops with an error)."""
    if process.offset_pieces is None:
        return None
    try:
        return simulate(
            process,
            max_periods=max_periods,
            tolerance=tolerance,
            integrator="exact",
            limit="newton",
            history=False,
            time_step_error=False,
        )
    except CrawlsimError:
        return None


def cost_of_transport(dissipation: float, displacement: float, v0_error: float, period: float) -> float | None:
    """Dissipation per distance travelled, or None when the net motion is not distinguishable
    from zero (within ten times its error)."""
    if abs(displacement) > 10 * v0_error * period + 1e-300:
        return dissipation / abs(displacement)
    return None


def following(process: SweepingProcess, limit: PeriodRecord, last: PeriodRecord) -> PeriodRecord:
    """The solver's verified period ``limit`` placed as the period after the history's ``last``:
    it starts when that period ends, its blocks at the positions of its shape (``limit.w[0]``)
    around the run's barycentre then. The history stops once the iterates reach the limit to the
    tolerance, so the run continues into it there; a history cut short by ``max_periods`` only
    approaches it, and the period is where the run would be if it had reached it."""
    if limit.x is None or last.x is None:
        return replace(limit, index=last.index + 1, start=last.start + process.period)
    x0 = positions_of(process, limit.w[0], float(np.mean(last.x[-1])))
    x = limit.x - limit.x[0] + x0
    return replace(limit, index=last.index + 1, start=last.start + process.period, x=x)


def limit_period(
    process: SweepingProcess, final: PeriodRecord, v0: float | None, running_frame: bool = True
) -> LimitPeriod:
    """The final period in the running frame: ``xbar(t) = xbar_0 + v0 (t - t0) + p(t)`` (with
    ``running_frame=False``, or for a generic process, the states and multipliers alone)."""
    t = process.times
    c = process.crawler
    if c is None or not running_frame:
        return LimitPeriod(final.start, t.copy(), final.w, final.multipliers)
    dx = final.slips
    assert final.x is not None and dx is not None and v0 is not None
    shape = c.shape(final.w)
    stress = c.stress(final.w)
    y0 = float(np.mean(final.x[0]))
    x_run = final.x - y0 - v0 * t[:, None]
    eps = 1e-12 * max(float(np.max(np.abs(dx))), 1e-300)
    # +1, -1 or 0 as int8: the two comparisons' bytes (True = 1) subtracted
    slip = (dx > eps).view(np.int8) - (dx < -eps).view(np.int8)
    return LimitPeriod(
        final.start,
        t.copy(),
        final.w,
        final.multipliers,
        x=x_run,
        shape=shape,
        stress=stress,
        slip=slip,
        slip_rate=dx / np.diff(t)[:, None],
    )
