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
periods wait on disk, so a long run's memory stays bounded.
"""

from __future__ import annotations

import math
import tempfile
import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from crawlsim.analysis.energy import ledger as energy_ledger
from crawlsim.analysis.energy import period_dissipation, period_energy
from crawlsim.integrate.stepping import PeriodRecord, make_stepper, positions_of
from crawlsim.model.process import SweepingProcess
from crawlsim.status import Convergence

#: How the periodic limit is found: the solver of `crawlsim.integrate.limit`, or plain iteration.
LIMIT_METHODS = ("newton", "iterate")

#: Relative Poincare steps below this are roundoff: a smaller tolerance is clamped to it.
ROUNDOFF_FLOOR = 1e-13
#: One-period drop of the Poincare step that counts as finite-time convergence.
FINITE_JUMP = 1e-4
#: Periods used to fit the contraction rate.
RATE_WINDOW = 8
#: Relative Poincare steps above this carry at most ~1e-6 relative roundoff (eps / step).
RATE_RELIABLE = 1e-10
#: The energy ledger's entries of the summary (`crawlsim.analysis.energy`).
ENERGY_KEYS = ("actuator_work_per_period", "jump_loss_per_period", "load_work_per_period",
               "energy_balance_residual",
               "cost_of_transport_bound", "efficiency")


@dataclass(frozen=True, eq=False)
class ConvergenceHistory:
    """Per-period measurements, one entry per simulated period q = 0, 1, ..."""

    period: np.ndarray
    displacement: np.ndarray  # y(t0+(q+1)T) - y(t0+qT); NaN for generic processes
    velocity: np.ndarray  # displacement / T
    poincare_step: np.ndarray  # |w(t0+(q+1)T) - w(t0+qT)|
    w12_distance: np.ndarray  # W^{1,2}(period) distance of w to the final period
    sup_distance: np.ndarray  # sup distance of w to the final period
    slip_l2_distance: np.ndarray  # L^2 distance of the slip rates (multiplier rates) to the final period
    dissipation: np.ndarray  # energy dissipated by friction in the period; NaN for generic


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


@dataclass(frozen=True, eq=False)
class RunResult:
    """Everything `simulate` measured. ``summary()`` is the JSON-ready part."""

    name: str
    period: float
    steps_per_period: int
    convergence: Convergence
    periods: int
    periodic_from: int | None
    contraction_rate: float | None
    v0: float | None
    v0_error_estimate: float | None
    displacement_per_period: float | None
    dissipation_per_period: float | None
    cost_of_transport: float | None
    history: ConvergenceHistory
    limit: LimitPeriod
    clarabel_calls: int
    wall_time: float
    steps: int = field(default=0)
    integrator: str = "catch-up"
    # The periodic-limit solver: how the limit was found ("newton" or "iterate"), its accepted
    # Newton steps, the periods it simulated (the verifying one included), its relative Poincare
    # steps, and the contraction rate read from the Jacobian at the limit.
    limit_method: str = "iterate"
    limit_newton_steps: int = 0
    limit_periods: int = 0
    limit_residuals: np.ndarray | None = None
    limit_kinds: np.ndarray | None = None  # per solver period: crawlsim.integrate.limit.PLAIN, NEWTON, REJECTED
    jacobian_rate: float | None = None
    v0_error_period_iteration: float | None = None
    v0_error_time_step: float | None = None
    # Why v0 has no error estimate although it has a value (v0_error_estimate None): a catch-up
    # run whose time-step error could not be measured against the exact integrator
    v0_error_reason: str | None = None
    # The dissipation's error: the period iteration's share (v0's relative one) plus, for
    # catch-up, its measured time-step error (None where that is not measured).
    dissipation_error_estimate: float | None = None
    # The energy ledger of the limit period (`crawlsim.analysis.energy`; None for generic processes):
    # actuator work, jump losses, the balance residual W - D - J, the least cost of transport
    # for this friction and direction, and the efficiency bound / cost_of_transport.
    actuator_work_per_period: float | None = None
    jump_loss_per_period: float | None = None
    energy_balance_residual: float | None = None
    cost_of_transport_bound: float | None = None
    efficiency: float | None = None
    # Work against the loads per period (docs/model.md §6); None without loads.
    load_work_per_period: float | None = None
    # The limit period itself, for exact sensitivities of this run (`crawlsim.analysis.sensitivity`)
    limit_record: PeriodRecord | None = field(default=None, repr=False, compare=False)

    @property
    def displacement_error_estimate(self) -> float | None:
        return None if self.v0_error_estimate is None else self.v0_error_estimate * self.period

    @property
    def cost_of_transport_error_estimate(self) -> float | None:
        """First-order propagation of the dissipation's and displacement's errors through
        their quotient (|d(D/d)| <= dD/|d| + D dd/d^2), widened by 1 % for the second-order
        term, which is below that wherever the cost of transport is printed at all."""
        cot, d = self.cost_of_transport, self.displacement_per_period
        dD, dd = self.dissipation_error_estimate, self.displacement_error_estimate
        if cot is None or d is None or dD is None or dd is None or d == 0:
            return None
        return 1.01 * (dD / abs(d) + cot * dd / abs(d))

    @property
    def converged(self) -> bool:
        return self.convergence != Convergence.NOT_CONVERGED

    def summary(self) -> dict:
        keys = ("name", "integrator", "v0", "v0_error_estimate", "v0_error_period_iteration",
                "v0_error_time_step", "v0_error_reason", "displacement_per_period", "dissipation_error_estimate",
                "convergence",
                "periodic_from", "contraction_rate", "jacobian_rate", "periods",
                "steps_per_period", "dissipation_per_period", "cost_of_transport",
                "limit_method", "limit_newton_steps", "limit_periods", "clarabel_calls",
                "steps", "wall_time") + ENERGY_KEYS
        out = {k: getattr(self, k) for k in keys}
        out["convergence"] = str(self.convergence)
        out["final_poincare_step"] = float(self.history.poincare_step[-1])
        return out


class _PeriodSpill:
    """Each period's w and multipliers, spilled to an anonymous temporary file.

    The distances to the limit period need every period and the final one, which is known only at
    the end; keeping them on disk keeps a long run's memory bounded.
    """

    def __init__(self):
        self._file = tempfile.TemporaryFile()
        self._shapes = None

    def add(self, rec: PeriodRecord):
        self._shapes = (rec.w.shape, rec.multipliers.shape)
        rec.w.tofile(self._file)
        rec.multipliers.tofile(self._file)

    def periods(self):
        (wshape, lshape) = self._shapes
        nw, nl = math.prod(wshape), math.prod(lshape)
        self._file.seek(0)
        while True:
            w = np.fromfile(self._file, count=nw)
            if w.size < nw:
                return
            lam = np.fromfile(self._file, count=nl)
            yield w.reshape(wshape), lam.reshape(lshape)

    def close(self):
        self._file.close()


def simulate(process: SweepingProcess, *, max_periods: int = 1000, tolerance: float = 1e-12,
             integrator: str = "catch-up", check_every_step: bool = False, sink=None,
             progress=None, limit: str = "newton", history: bool = True,
             time_step_error: bool = False) -> RunResult:
    """Step ``process`` to its periodic regime and analyse the run (module docstring).

    ``sink.add_period(record)`` receives every period of the history as it is computed (the
    HDF5 writer streams the trajectory); ``progress(q, poincare_step_relative)`` is called after
    every period of the history.

    v0 carries an error estimate that bounds its true error, in two parts: the period iteration
    (roundoff of the period's slips, the tail still to come, or the residual of the verified
    limit) and the time step. The exact integrator has no time-step error; for catch-up it is
    measured (``time_step_error``) against the exact integrator's v0 for the same gait
    (`time_step_reference`), and left None where that cannot run.
    """
    from crawlsim.integrate.limit import PLAIN_PERIODS, solve_limit

    if limit not in LIMIT_METHODS:
        raise ValueError(f"limit must be one of {', '.join(LIMIT_METHODS)}, got {limit!r}")
    began = _time.perf_counter()
    options = {"check_every_step": True} if check_every_step else {}
    stepper = make_stepper(process, integrator, **options)
    tol = effective_tolerance(tolerance)
    log = _History(process)
    final: PeriodRecord | None = None  # the limit period
    solution = None
    solver_cost = (0, 0)  # periods simulated and Clarabel calls made by the limit solver
    try:
        # the true iterates; with the solver, only a few before it takes over
        budget = max_periods if limit == "iterate" else min(max_periods, PLAIN_PERIODS)
        while len(log) < budget:
            record = log.add(stepper.step_period(), sink, progress)
            if log.rel_steps[-1] <= tol:
                final = record
                break
        if final is None and limit == "newton" and len(log) < max_periods:
            solver = make_stepper(process, integrator, **options)
            # the last true iterate is the solver's first period: not simulated twice
            solution = solve_limit(process, solver, tolerance=tol, first=log.last,
                                   max_periods=max_periods - len(log), plain=0)
            solver_cost = (solution.periods, solver.projector.clarabel_calls)
            if solution.converged:
                final = solution.record
                log.set_limit(final)
                # the history goes on until the iterates reach the verified limit, or are
                # periodic themselves (a Poincare step of 0 is convergence): where the periodic
                # solutions form a family (Theorem th:speed: they differ by constants of the
                # directions no active set ever sees), the iterates may settle on another member
                # than the solver's, and would never reach it. Their own is then the limit.
                while history and len(log) < max_periods and not log.reached(tol):
                    record = log.add(stepper.step_period(), sink, progress)
                    if _settled_elsewhere(log, tol):
                        final, solution = record, None
                        break
            else:  # the solver's periods count against max_periods: the history stops
                solution = None
        if final is None:  # plain iteration to the end (limit="iterate", or a solver failure)
            while len(log) < max_periods:
                record = log.add(stepper.step_period(), sink, progress)
                if log.rel_steps[-1] <= tol:
                    final = record
                    break
            if final is None:
                final = log.last
        assert final is not None, "max_periods >= 1"
        log.set_limit(final)
        distances = log.distances()
    finally:
        log.close()
    if solution is not None:
        assert log.last is not None
        final = following(process, final, log.last)

    T, G = process.period, process.steps
    rel = np.array(log.rel_steps)
    convergence, periodic_from = classify_convergence(rel, tol)
    if solution is not None and convergence == Convergence.NOT_CONVERGED:
        # the limit is verified; the iterates approach it geometrically but had not reached it
        convergence = Convergence.ASYMPTOTIC
    rate = None if convergence == Convergence.FINITE_TIME else contraction_rate(rel)
    Q = len(log) - 1
    displacement = np.array(log.displacements) if process.is_crawler else np.full(Q + 1, np.nan)
    dissipation = np.array(log.dissipations) if process.is_crawler else np.full(Q + 1, np.nan)
    hist = ConvergenceHistory(
        period=np.arange(Q + 1), displacement=displacement, velocity=displacement / T,
        poincare_step=np.array(log.steps), dissipation=dissipation, **distances)

    v0: float | None = None
    err: float | None = None
    d_final = diss_final = cot = None
    if process.is_crawler:
        assert final.x is not None and final.slips is not None and process.friction is not None
        d_final = float(np.mean(final.x[-1] - final.x[0]))
        v0 = d_final / T
        diss_final = period_dissipation(process, final)
        roundoff = float(np.sum(np.abs(final.slips))) / process.blocks
        if solution is not None:
            # the verified period is periodic to its residual |P(w) - w|: a shape mismatch of
            # |F| / k_min (a length) bounds the displacement's
            F = float(np.max(np.abs(final.w[-1] - final.w[0])))
            assert process.stiffness is not None
            err = float((G * np.finfo(float).eps * roundoff
                         + F / float(np.min(process.stiffness))) / T)
        else:
            err = period_iteration_error(displacement, convergence, rate, G, roundoff, T)
    err_step: float | None = None
    diss_step: float | None = None
    err_reason: str | None = None
    if v0 is not None:
        if integrator == "exact":
            err_step = diss_step = 0.0
        elif time_step_error:
            reference = time_step_reference(process, max_periods=max_periods, tolerance=tolerance)
            if reference is not None and reference.v0 is not None:
                err_step = abs(v0 - reference.v0) + (reference.v0_error_estimate or 0.0)
                assert diss_final is not None and reference.dissipation_per_period is not None
                diss_step = abs(diss_final - reference.dissipation_per_period) + (
                    reference.dissipation_error_estimate or 0.0)
            else:  # the period iteration's part alone bounds nothing: catch-up is O(h)
                reason = ("the exact integrator needs a closed form of c(t), which this gait "
                          "has not" if process.offset_pieces is None
                          else "the exact integrator's reference run failed")
                err_reason = ("no error estimate: the catch-up time-step error could not be "
                              f"measured; {reason}")
    err_pi = err
    diss_err: float | None = None
    if diss_final is not None and err_pi is not None and diss_step is not None and v0:
        diss_err = abs(diss_final) * err_pi / abs(v0) + diss_step
    if err is not None and err_step is not None:
        err = err + err_step
    if process.is_crawler and d_final is not None and diss_final is not None and err is not None:
        # with loads the cost of transport counts the work against them (docs/model.md §6)
        paid = diss_final
        if process.load is not None:
            paid += period_energy(process, final).load_work  # type: ignore[union-attr]
        cot = cost_of_transport(paid, d_final, err, T)
    ledger = energy_ledger(process, final, d_final, cot) if d_final is not None else None
    energy_fields = {} if ledger is None else {
        "actuator_work_per_period": ledger.actuator_work_per_period,
        "jump_loss_per_period": ledger.jump_loss_per_period,
        "load_work_per_period": ledger.load_work_per_period,
        "energy_balance_residual": ledger.energy_balance_residual,
        "cost_of_transport_bound": ledger.cost_of_transport_bound,
        "efficiency": ledger.efficiency}
    simulated = len(log) + solver_cost[0]
    return RunResult(
        name=process.name, period=T, steps_per_period=G, convergence=convergence,
        periods=Q + 1, periodic_from=periodic_from, contraction_rate=rate, v0=v0,
        v0_error_estimate=None if err_reason else err, displacement_per_period=d_final,
        dissipation_per_period=diss_final, cost_of_transport=cot, history=hist,
        limit=limit_period(process, final, v0),
        clarabel_calls=stepper.projector.clarabel_calls + solver_cost[1],
        wall_time=_time.perf_counter() - began, steps=simulated * G, integrator=integrator,
        limit_method="newton" if solution is not None else "iterate",
        limit_newton_steps=solution.newton_steps if solution is not None else 0,
        limit_periods=solution.periods if solution is not None else 0,
        limit_residuals=solution.residuals if solution is not None else None,
        limit_kinds=solution.kinds if solution is not None else None,
        jacobian_rate=solution.jacobian_rate if solution is not None else None,
        v0_error_period_iteration=err_pi, v0_error_time_step=err_step, v0_error_reason=err_reason,
        dissipation_error_estimate=diss_err, limit_record=final, **energy_fields)


def time_step_reference(process: SweepingProcess, *, max_periods: int,
                        tolerance: float) -> RunResult | None:
    """The exact integrator's v0 for ``process`` (periodic-limit solver, no history): the
    reference a catch-up v0's time-step error is measured against; None where the exact
    integrator cannot run (no closed form of c(t), or it stops with an error)."""
    from crawlsim.errors import CrawlsimError

    if process.offset_pieces is None:
        return None
    try:
        return simulate(process, max_periods=max_periods, tolerance=tolerance,
                        integrator="exact", limit="newton", history=False,
                        time_step_error=False)
    except CrawlsimError:
        return None


class _History:
    """The true iterates of a run: per-period measurements, and each period's w and multipliers
    (spilled to disk) for their distances to the limit period, measured at the end against the
    limit the run settles on (the solver's, or the iterates' own if they become periodic on
    another member of a family of periodic solutions)."""

    def __init__(self, process: SweepingProcess):
        self.process = process
        self.h = np.diff(process.times)
        self.steps: list[float] = []
        self.rel_steps: list[float] = []
        self.displacements: list[float] = []
        self.dissipations: list[float] = []
        self.last: PeriodRecord | None = None
        self._spill: _PeriodSpill | None = _PeriodSpill()
        self._limit: PeriodRecord | None = None
        self._last_gap = np.inf

    def __len__(self) -> int:
        return len(self.steps)

    def add(self, record: PeriodRecord, sink, progress) -> PeriodRecord:
        p = self.process
        if sink is not None:
            sink.add_period(record)
        step, rel = poincare_step(p, record.w[0], record.w[-1])
        self.steps.append(step)
        self.rel_steps.append(rel)
        if p.is_crawler:
            assert record.x is not None and p.friction is not None
            self.displacements.append(float(np.mean(record.x[-1] - record.x[0])))
            self.dissipations.append(period_dissipation(p, record))
        assert self._spill is not None
        self._spill.add(record)
        self.last = record
        self._gap()
        if progress is not None:
            progress(len(self.steps) - 1, rel)
        return record

    def set_limit(self, limit: PeriodRecord) -> None:
        """The limit period the distances are measured against (`distances`)."""
        self._limit = limit
        self._gap()

    def _gap(self) -> None:
        if self._limit is None or self.last is None:
            return
        scale = max(float(np.linalg.norm(self._limit.w[0])), self.process.scale)
        self._last_gap = float(np.linalg.norm(self.last.w[-1] - self._limit.w[0])) / scale

    def reached(self, tol: float) -> bool:
        """Whether the last iterate's end state is within ``tol`` of the limit's start."""
        return bool(self.steps) and self._last_gap <= tol

    @property
    def gap(self) -> float:
        """The last iterate's relative distance to the limit's start (inf before a limit)."""
        return self._last_gap

    def distances(self) -> dict:
        """The distances of every period to the limit period (W^{1,2}, sup, slip rates)."""
        out: dict[str, list[float]] = {"w12_distance": [], "sup_distance": [],
                                       "slip_l2_distance": []}
        assert self._limit is not None and self._spill is not None
        for w, lam in self._spill.periods():
            for key, value in _period_distances(w, lam, self._limit, self.h).items():
                out[key].append(value)
        return {k: np.array(v) for k, v in out.items()}

    def close(self) -> None:
        if self._spill is not None:
            self._spill.close()
            self._spill = None


def _settled_elsewhere(log: _History, tol: float) -> bool:
    """Whether the iterates are periodic to ``tol`` yet cannot reach the solver's limit: the
    way they still have to go, at most the geometric tail ``step r / (1 - r)`` of their Poincare
    steps (none after a step of 0, a finite-time convergence), is shorter than their distance
    to it. An iterate that merely approaches the solver's limit slowly (``r`` near 1) has its
    tail at least as long as that distance, and goes on."""
    step = log.rel_steps[-1]
    if step > tol or log.reached(tol):
        return False
    if step == 0.0:
        travel = 0.0
    else:
        rate = contraction_rate(np.array(log.rel_steps))
        if rate is None or not rate < 1.0:
            return False
        travel = step * rate / (1.0 - rate)
    return log.gap > tol + 2.0 * travel


def period_iteration_error(displacements, convergence: Convergence, rate: float | None,
                           steps_per_period: int, mean_abs_slip: float, period: float) -> float:
    """Error bound of v0 from the period iteration: the roundoff of summing the period's slips
    (``mean_abs_slip``: sum of |dx| over the period, averaged over the blocks), plus, when the
    convergence is not finite-time, the geometric tail still to come."""
    err = steps_per_period * np.finfo(float).eps * mean_abs_slip / period
    if convergence != Convergence.FINITE_TIME and len(displacements) >= 2:
        dv = abs(displacements[-1] - displacements[-2]) / period
        r = rate if rate is not None and rate < 1 else None
        err += dv * r / (1 - r) if r is not None else dv
    return float(err)


def cost_of_transport(dissipation: float, displacement: float, v0_error: float,
                      period: float) -> float | None:
    """Dissipation per distance travelled, or None when the net motion is not distinguishable
    from zero (within ten times its error)."""
    if abs(displacement) > 10 * v0_error * period + 1e-300:
        return dissipation / abs(displacement)
    return None


def effective_tolerance(tolerance: float) -> float:
    """The Poincare-step tolerance actually used: relative steps below roundoff are clamped."""
    return max(float(tolerance), ROUNDOFF_FLOOR)


def poincare_step(process: SweepingProcess, w_start, w_end) -> tuple[float, float]:
    """The Poincare step ``|w(t0+(q+1)T) - w(t0+qT)|``, and relative to ``max(|w|, scale)``."""
    step = float(np.linalg.norm(w_end - w_start))
    size = max(float(np.linalg.norm(w_end)), process.scale)
    return step, step / size


def classify_convergence(rel_steps, tol: float) -> tuple[Convergence, int | None]:
    """(convergence, periodic_from) from the relative Poincare steps of periods 0..Q.

    Finite-time when the last step reached ``tol`` in one jump by more than `FINITE_JUMP`,
    asymptotic when it reached it gradually, not-converged when it did not reach it.
    """
    Q = len(rel_steps) - 1
    if rel_steps[Q] > tol:
        return Convergence.NOT_CONVERGED, None
    if Q == 0 or rel_steps[Q] < FINITE_JUMP * rel_steps[Q - 1]:
        return Convergence.FINITE_TIME, Q
    return Convergence.ASYMPTOTIC, None


def _period_distances(w: np.ndarray, lam: np.ndarray, final: PeriodRecord,
                      h: np.ndarray) -> dict[str, float]:
    """W^{1,2} and sup distances of one period's w, and the L^2 distance of its multiplier
    rates, to the limit period ``final``.

    On the grid, with e = w_q - w_final: ||e||_{L2}^2 by the trapezoidal rule, ||e'||_{L2}^2 as
    sum |e_{j+1} - e_j|^2 / h_j (e' is piecewise constant for the catch-up interpolant), and the
    slip rates lambda_j / h_j are piecewise constant too.
    """
    e = w - final.w
    e2 = np.sum(e * e, axis=1)
    l2 = float(np.sum(h * (e2[1:] + e2[:-1]) / 2))
    de = np.diff(e, axis=0)
    h1 = float(np.sum(np.sum(de * de, axis=1) / h))
    dl = lam - final.multipliers
    return {"w12_distance": math.sqrt(l2 + h1), "sup_distance": float(np.sqrt(np.max(e2))),
            "slip_l2_distance": math.sqrt(float(np.sum(np.sum(dl * dl, axis=1) / h)))}


def contraction_rate(rel_steps: np.ndarray) -> float | None:
    """Geometric rate of the Poincare steps: a least-squares fit of log(step) on the last periods.

    A relative step s carries a roundoff of about eps / s relative to itself, so the fit uses
    the last `RATE_WINDOW` steps above `RATE_RELIABLE` (each good to 1e-6 or better) when there
    are at least three; otherwise every step above the roundoff floor.
    """
    steps = np.asarray(rel_steps, dtype=float)
    q = np.arange(len(steps))
    reliable = np.flatnonzero(steps > RATE_RELIABLE)[-RATE_WINDOW:]
    if reliable.size >= 3 and reliable[-1] - reliable[0] == reliable.size - 1:
        chosen = reliable
    else:
        tail = q[-RATE_WINDOW:]
        chosen = tail[steps[tail] > ROUNDOFF_FLOOR / 10]
    if chosen.size < 2:
        return None
    slope = np.polyfit(q[chosen], np.log(steps[chosen]), 1)[0]
    return float(math.exp(slope))


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


def limit_period(process: SweepingProcess, final: PeriodRecord, v0: float | None) -> LimitPeriod:
    """The final period in the running frame: ``xbar(t) = xbar_0 + v0 (t - t0) + p(t)``."""
    t = process.times
    if not process.is_crawler:
        return LimitPeriod(final.start, t.copy(), final.w, final.multipliers)
    assert final.x is not None and final.slips is not None and v0 is not None
    assert process.stiffness is not None
    shape = -final.w / process.stiffness
    stress = final.w + process.stress_offset
    y0 = float(np.mean(final.x[0]))
    x_run = final.x - y0 - v0 * t[:, None]
    dx = final.slips
    eps = 1e-12 * max(float(np.max(np.abs(dx))), 1e-300)
    slip = np.where(dx > eps, 1, np.where(dx < -eps, -1, 0)).astype(np.int8)
    return LimitPeriod(final.start, t.copy(), final.w, final.multipliers, x=x_run, shape=shape,
                       stress=stress, slip=slip, slip_rate=dx / np.diff(t)[:, None])


def _error_parts(result: RunResult) -> str:
    """Where v0's error estimate comes from, after ``v0 ± estimate``."""
    if result.v0_error_estimate is None:
        return f" ({result.v0_error_reason or 'no error estimate'})"
    if result.integrator == "exact":
        return " (period iteration; the exact integrator has no time-step error)"
    step = result.v0_error_time_step
    if step is None:
        return " (period iteration only)"
    return (f" (time step {step:.1g}, measured against the exact integrator; period iteration "
            f"{result.v0_error_period_iteration:.1g})")


def not_converged_message(result: RunResult, max_periods: int, tolerance: float,
                          limit: str) -> str:
    """The one line on stderr of a run that ended without a verified limit (exit code 3): why,
    and what to change."""
    step = float(result.history.poincare_step[-1]) if len(result.history.poincare_step) else math.nan
    advice = "raise max_periods (--max-periods)"
    if limit == "iterate":
        advice += " or let the periodic-limit solver find the limit (--limit newton)"
    return (f"Not converged: max_periods = {max_periods} periods ran out before the limit was "
            f"found (final Poincare step {step:.3g}, tolerance {tolerance:.3g} relative); "
            f"{advice}. The numbers printed are those of the last period.")


def summary_text(result: RunResult, output: str | None = None) -> str:
    """The short human summary printed by ``crawlsim run``: each number with only the digits
    its error estimate supports (`crawlsim.analysis.digits`); ``--json`` keeps full precision."""
    from crawlsim.analysis.digits import with_error

    what = "gait" if result.v0 is not None else "process"  # a generic process has no v0
    units = getattr(result, "units", None)  # the gait file's units (crawlsim.api results)

    def unit(quantity: str) -> str:
        return "" if units is None else units.suffix(quantity)
    lines = [f"{what} {result.name}: {result.periods} periods of {result.steps_per_period} steps"]
    if result.v0 is not None:
        lines.append(f"  v0                       "
                     f"{with_error(result.v0, result.v0_error_estimate, unit('velocity'))}"
                     f"{_error_parts(result)}")
    if result.convergence == "finite-time":
        lines.append(f"  convergence              finite-time: periodic from period "
                     f"{result.periodic_from}")
    elif result.convergence == "asymptotic":
        rate = "n/a" if result.contraction_rate is None else f"{result.contraction_rate:.4g}"
        lines.append(f"  convergence              asymptotic, contraction rate {rate} per period")
    else:
        lines.append(f"  convergence              NOT converged: final Poincare step "
                     f"{result.history.poincare_step[-1]:.3g}. Try increasing max_periods.")
    from crawlsim.analysis.digits import how_found

    found = how_found(result.limit_method, result.limit_newton_steps, result.limit_periods,
                      result.jacobian_rate)
    lines.append(f"  limit found by           {found}")
    if result.displacement_per_period is not None:
        assert result.dissipation_per_period is not None
        lines.append("  displacement per period  "
                     + with_error(result.displacement_per_period,
                                  result.displacement_error_estimate, unit('length')))
        lines.append("  dissipation per period   "
                     + with_error(result.dissipation_per_period,
                                  result.dissipation_error_estimate, unit('dissipation')))
        cot = "n/a (no net motion)" if result.cost_of_transport is None else with_error(
            result.cost_of_transport, result.cost_of_transport_error_estimate, unit('force'))
        lines.append(f"  cost of transport        {cot}")
        lines.extend(energy_lines(result, unit))
    if output:
        lines.append(f"  written                  {output}")
    return "\n".join(lines)



def energy_lines(result: RunResult, unit) -> list[str]:
    """The energy ledger's lines of the summary (`crawlsim.analysis.energy`)."""
    if result.actuator_work_per_period is None:
        return []
    from crawlsim.analysis.digits import with_error

    work = result.actuator_work_per_period
    loss = result.jump_loss_per_period or 0.0
    residual = result.energy_balance_residual or 0.0
    relative = abs(residual) / max(abs(work), 1e-300)
    # W = D + J: the work is as accurate as the dissipation, and for catch-up its jump losses
    # J_h hold the scheme's own numerical loss (first order in the step) besides the true one
    err = result.dissipation_error_estimate
    if err is not None and result.integrator != "exact":
        err += abs(loss)
    lines = [f"  actuator work per period {with_error(work, err, unit('dissipation'))}",
             f"  jump losses per period   {loss:.3g}{unit('dissipation')}",
             f"  energy balance residual  {residual:.3g}{unit('dissipation')} (work - dissipation"
             f" - jump losses{' - load work' if result.load_work_per_period is not None else ''};"
             f" {relative:.1g} relative)"]
    if result.load_work_per_period is not None:
        # W_load carries the error of the work it is part of (W = D + J + W_load, §6)
        load = result.load_work_per_period
        lines.insert(2, f"  load work per period     {with_error(load, err, unit('dissipation'))}"
                        " (against the loads, docs/model.md §6)")
        if result.efficiency is not None:
            eff_err = None if err is None or load == 0 else result.efficiency * 1.01 * (
                err / abs(load) + err / abs(work))
            lines.append(f"  efficiency               {with_error(result.efficiency, eff_err)} "
                         "(load work / actuator work)")
    if result.cost_of_transport_bound is not None:
        cot_err = result.cost_of_transport_error_estimate
        eff = "n/a" if result.efficiency is None or result.cost_of_transport is None else (
            with_error(result.efficiency, None if cot_err is None else
                       1.01 * result.efficiency * cot_err / result.cost_of_transport))
        lines.append(f"  cost of transport bound  {result.cost_of_transport_bound:.12g}"
                     f"{unit('force')} (efficiency {eff})")
    return lines
