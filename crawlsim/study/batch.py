"""Catch-up runs of many crawlers to their periodic regime, for sweeps.

Each gait follows the catch-up scheme of `crawlsim.integrate.stepping` (docs/model.md §3),

    w_{j+1} = argmin { 1/2 |w - w_j|_M^2 : B w <= c(t_{j+1}) },

through the same certified kernel step as its single run (`crawlsim.integrate.stepping.CatchUpStepper`
on the compiled `crawlsim.kernel.chain`, the projector where a step needs it), so a gait takes
the same steps here as in `crawlsim.analysis.run.simulate` and fails (or is refused) exactly
when its single run does. The compiled step costs what its arithmetic costs, so the gaits run
one after the other: there is no second, vectorised copy of the step to keep in agreement.

The period loop, the Poincare step and the classification of convergence are those of
`crawlsim.analysis.run.simulate` (`poincare_step`, `classify_convergence`, `effective_tolerance`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crawlsim import interrupts
from crawlsim.analysis.run import (
    classify_convergence,
    contraction_rate,
    cost_of_transport,
    displacement_roundoff,
    effective_tolerance,
    period_iteration_error,
    poincare_step,
)
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.integrate.stepping import CatchUpStepper, PeriodRecord
from crawlsim.model.process import SweepingProcess
from crawlsim.status import Convergence, PointStatus

#: The batch size callers ask for (`simulate_batch` ``capacity``; the gaits run one by one).
DEFAULT_CAPACITY = 256


@dataclass(frozen=True)
class BatchRun:
    """What a batched run measured for one gait: the v0 part of `crawlsim.analysis.run.RunResult`."""

    name: str
    status: PointStatus
    v0: float | None
    displacement_per_period: float | None
    convergence: Convergence | None  # as RunResult.convergence; None when the run failed
    periods: int
    periodic_from: int | None
    steps: int
    clarabel_calls: int
    message: str = ""
    dissipation_per_period: float | None = None
    v0_error_estimate: float | None = None
    contraction_rate: float | None = None
    cost_of_transport: float | None = None
    # with ``keep_limit``: the last period stepped and its process, walked by the sweep's
    # --sensitivity (`crawlsim.analysis.sensitivity`) instead of stepping the point again
    limit_record: PeriodRecord | None = field(default=None, repr=False, compare=False)
    limit_process: SweepingProcess | None = field(default=None, repr=False, compare=False)
    integrator: str = "catch-up"

    @property
    def converged(self) -> bool:
        return self.convergence not in (None, Convergence.NOT_CONVERGED)


def simulate_batch(
    processes, *, max_periods, tolerance, capacity: int = DEFAULT_CAPACITY, progress=None, keep_limit: bool = False
) -> list[BatchRun]:
    """Run every crawler process to its periodic regime; results in the order given.

    ``max_periods`` and ``tolerance`` are numbers or one per process. ``capacity`` is accepted
    for the callers that size batches; each gait runs on its own compiled kernel step.
    ``progress(k)`` is called whenever k more gaits have finished. ``keep_limit`` keeps each
    run's last period (`BatchRun.limit_record`).
    """
    processes = list(processes)
    count = len(processes)
    max_periods = np.broadcast_to(np.asarray(max_periods, dtype=int), (count,))
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=float), (count,))
    for p in processes:
        if p.crawler is None:
            raise ValueError(f"{p.name}: batched stepping measures v0 and needs a crawler")
    out = []
    for p, periods, tol in zip(processes, max_periods, tolerance):
        out.append(_run(p, int(periods), effective_tolerance(float(tol)), keep_limit))
        if progress is not None:
            progress(1)
    return out


def _run(p: SweepingProcess, max_periods: int, tol: float, keep_limit: bool = False) -> BatchRun:
    """One gait to its periodic regime: periods of catch-up until the Poincare step is below
    ``tol`` or ``max_periods`` have run.

    The displacement of a period is ``mean(lambda^+ - lambda^-)`` summed over its steps: the
    multipliers are the slips (docs/model.md §3), so this is ``y(t0+(q+1)T) - y(t0+qT)``. The
    dissipation is sum_j lambda_j . mu(t_{j+1}), the loads' work sum_j lambda_j . load(t_{j+1})
    (docs/model.md §6).
    """
    stepper = CatchUpStepper(p)
    N, G = p.blocks, p.steps
    friction = _friction(p)[1:]
    load = p.load[1:] if p.load is not None else None
    rel_steps: list[float] = []
    displacements: list[float] = []
    for q in range(max_periods):
        interrupts.check()  # a Ctrl-C noted elsewhere (the first compilation) stops the batch
        w_start = stepper.w.copy()
        try:
            record = stepper.step_period()
        except CrawlsimError as exc:
            status = PointStatus.INVALID if isinstance(exc, InputError) else PointStatus.FAILED
            return BatchRun(
                p.name, status, None, None, None, q, None, q * G, stepper.projector.clarabel_calls, str(exc)
            )
        LAM = record.multipliers
        total = LAM.sum(axis=0)
        d = float(np.mean(total[:N] - total[N:]))
        _, rel = poincare_step(p, w_start, stepper.w)
        rel_steps.append(rel)
        displacements.append(d)
        if rel <= tol or q + 1 >= max_periods:
            break
    convergence, periodic_from = classify_convergence(rel_steps, tol)
    status = PointStatus.NOT_CONVERGED if convergence == Convergence.NOT_CONVERGED else PointStatus.OK
    rate = None if convergence == Convergence.FINITE_TIME else contraction_rate(np.array(rel_steps))
    err = period_iteration_error(
        displacements, convergence, rate, displacement_roundoff(p, G, float(np.sum(np.abs(LAM))) / N, G), p.period
    )
    diss = float(np.einsum("km,km->", LAM, friction))
    paid = diss + (float(np.einsum("km,km->", LAM, load)) if load is not None else 0.0)
    return BatchRun(
        p.name,
        status,
        d / p.period,
        d,
        convergence,
        q + 1,
        periodic_from,
        (q + 1) * G,
        stepper.projector.clarabel_calls,
        dissipation_per_period=diss,
        v0_error_estimate=err,
        contraction_rate=rate,
        cost_of_transport=cost_of_transport(paid, d, err, p.period),
        limit_record=record if keep_limit else None,
        limit_process=p if keep_limit else None,
    )


def _friction(process: SweepingProcess) -> np.ndarray:
    assert process.friction is not None, "batched stepping needs crawlers"
    return process.friction
