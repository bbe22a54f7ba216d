"""How the true iterates of a run approach the periodic limit (docs/model.md §4).

The Poincare steps ``|w(t0+(q+1)T) - w(t0+qT)|`` of the periods q = 0, 1, ... classify the
convergence (`classify_convergence`: finite-time when the step falls to the tolerance in one jump
by more than `FINITE_JUMP`, asymptotic otherwise) and give the contraction rate, a least-squares
fit of their logarithm with its standard error (`fit_contraction_rate`). `History` keeps the
per-period measurements and spills each period's w and multipliers to disk, so that the distances
to the limit period, known only at the end, cost no memory during a long run.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim import interrupts
from crawlsim.analysis.energy import period_dissipation
from crawlsim.gait.settings import ROUNDOFF_FLOOR
from crawlsim.integrate.stepping import PeriodRecord
from crawlsim.model.process import SweepingProcess
from crawlsim.status import Convergence

#: One-period drop of the Poincare step that counts as finite-time convergence.
FINITE_JUMP = 1e-4
#: Periods used to fit the contraction rate.
RATE_WINDOW = 8
#: Relative Poincare steps above this carry at most ~1e-6 relative roundoff (eps / step).
RATE_RELIABLE = 1e-10


#: The distances of a period to the limit period (`History.distances`).
DISTANCES = ("w12_distance", "sup_distance", "slip_l2_distance")
#: Bytes of periods kept in memory before the spill moves to a temporary file: creating and
#: writing the file cost 0.5-1 ms per run, a quarter of a short run (a sweep point), while a long
#: run's memory stays bounded by this.
SPILL_BYTES = 1 << 25


class _PeriodSpill:
    """Each period's w and multipliers, in memory up to `SPILL_BYTES`, then spilled to an
    anonymous temporary file.

    The distances to the limit period need every period and the final one, which is known only at
    the end; keeping them on disk keeps a long run's memory bounded.
    """

    def __init__(self):
        self._file: Any = None
        self._memory: list[tuple[np.ndarray, np.ndarray]] = []
        self._bytes = 0
        self._shapes: tuple[tuple[int, ...], tuple[int, ...]] | None = None

    def add(self, rec: PeriodRecord):
        self._shapes = (rec.w.shape, rec.multipliers.shape)
        self._bytes += rec.w.nbytes + rec.multipliers.nbytes
        if self._file is None and self._bytes <= SPILL_BYTES:
            self._memory.append((rec.w.copy(), rec.multipliers.copy()))
            return
        if self._file is None:
            self._file = tempfile.TemporaryFile()
            for w, lam in self._memory:
                w.tofile(self._file)
                lam.tofile(self._file)
            self._memory = []
        rec.w.tofile(self._file)
        rec.multipliers.tofile(self._file)

    def periods(self):
        assert self._shapes is not None, "no period was added"
        if self._file is None:
            yield from self._memory
            return
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
        if self._file is not None:
            self._file.close()
        self._memory = []


class History:
    """The true iterates of a run: per-period measurements, and each period's w and multipliers
    (spilled to disk) for their distances to the limit period, measured at the end against the
    limit the run settles on (the solver's, or the iterates' own if they become periodic on
    another member of a family of periodic solutions). ``series=False`` keeps neither the periods
    nor the dissipation of each period (NaN): a sweep point's row holds only the limit period's,
    and `distances` is not asked for."""

    def __init__(self, process: SweepingProcess, series: bool = True):
        self.process = process
        self.series = series
        self.h = np.diff(process.times)
        self.steps: list[float] = []
        self.rel_steps: list[float] = []
        self.displacements: list[float] = []
        self.dissipations: list[float] = []
        self.last: PeriodRecord | None = None
        self._spill: _PeriodSpill | None = _PeriodSpill() if series else None
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
        if p.crawler is not None:
            assert record.x is not None
            self.displacements.append(float(np.mean(record.x[-1] - record.x[0])))
            # the exact integrator's ledger is made when first read: a sweep point reads the
            # limit period's alone
            self.dissipations.append(period_dissipation(p, record) if self.series else math.nan)
        if self.series:
            assert self._spill is not None
            self._spill.add(record)
        self.last = record
        self._gap()
        if progress is not None:
            progress(len(self.steps) - 1, rel)
        interrupts.check()  # a Ctrl-C noted in another library's code stops the run here
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
        out: dict[str, list[float]] = {key: [] for key in DISTANCES}
        assert self._limit is not None and self._spill is not None
        for w, lam in self._spill.periods():
            for key, value in _period_distances(w, lam, self._limit, self.h).items():
                out[key].append(value)
        return {k: np.array(v) for k, v in out.items()}

    def close(self) -> None:
        if self._spill is not None:
            self._spill.close()
            self._spill = None


def _travel(log: History) -> float | None:
    """The way the iterates still have to go: at most the geometric tail ``step r / (1 - r)`` of
    their Poincare steps (none after a step of 0, a finite-time convergence); None without a
    contraction rate below 1."""
    step, rate = log.rel_steps[-1], _rate(log)
    if step == 0.0:
        return 0.0
    return step * rate / (1.0 - rate) if rate is not None else None


def _rate(log: History) -> float | None:
    rate = contraction_rate(np.array(log.rel_steps))
    return rate if rate is not None and 0.0 < rate < 1.0 else None


def settled_elsewhere(log: History, tol: float) -> bool:
    """Whether the iterates are periodic to ``tol`` yet cannot reach the solver's limit: the
    way they still have to go is shorter than their distance to it. An iterate that merely
    approaches the solver's limit slowly (``r`` near 1) has its tail at least as long as that
    distance, and goes on."""
    if log.rel_steps[-1] > tol or log.reached(tol):
        return False
    travel = _travel(log)
    return travel is not None and log.gap > tol + 2.0 * travel


def approaching(log: History, tol: float, periods: int) -> bool:
    """Whether the iterates head for the solver's limit, the way they still have to go covering
    their distance to it (twice over, for a rate fitted on early periods), and would take more
    than ``periods`` periods more to reach ``tol`` at their rate."""
    travel, rate = _travel(log), _rate(log)
    if travel is None or rate is None or log.gap > 2.0 * travel:
        return False
    return log.gap > tol and math.log(tol / log.gap) / math.log(rate) > periods


def displacement_roundoff(
    process: SweepingProcess, steps_per_period: int, mean_abs_slip: float, restarts: int = 1
) -> float:
    """The roundoff of a crawler's displacement per period (a length): summing the period's
    slips (``mean_abs_slip``: the sum of |dx| over the period, averaged over the blocks),
    steps x eps x mean_abs_slip, and the slips each projection or piece reads off the state:
    w is exact to eps |c| (``process.scale``), and a piece's slips G_A^{-1} (B_A w - c_A(u))
    carry that through the softest link, z = -K^{-1} w (docs/model.md §2), so eps c_scale /
    k_min each. Those of the period's ``restarts`` (catch-up steps, the exact integrator's
    pieces) are independent roundoffs, and add as a random walk: sqrt(restarts) of it. The
    second term is what a stiff chain adds (c_scale ~ k_max L): on 40 random gaits with
    stiffness ratios up to 1e6, the v0 of the compiled and of the Python event loop (each
    exact, their roundoff apart) differ by up to 1.43 times it over T with one restart, and by
    at most 0.17 of it with sqrt(restarts); the Python loop's own v0 moves by 4.2 times the
    first when friction and stiffness are scaled together (which leaves the motion as it is)."""
    eps = float(np.finfo(float).eps)
    k_min = math.inf if process.crawler is None else float(np.min(process.crawler.stiffness))
    return steps_per_period * eps * mean_abs_slip + eps * process.scale / k_min * math.sqrt(max(restarts, 1))


def period_iteration_error(
    displacements, convergence: Convergence, rate: float | None, roundoff: float, period: float
) -> float:
    """Error bound of v0 from the period iteration: the displacement's roundoff
    (`displacement_roundoff`) over the period, plus, when the convergence is not finite-time,
    the geometric tail still to come."""
    err = roundoff / period
    if convergence != Convergence.FINITE_TIME and len(displacements) >= 2:
        dv = abs(displacements[-1] - displacements[-2]) / period
        r = rate if rate is not None and rate < 1 else None
        err += dv * r / (1 - r) if r is not None else dv
    return float(err)


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


def _period_distances(w: np.ndarray, lam: np.ndarray, final: PeriodRecord, h: np.ndarray) -> dict[str, float]:
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
    return {
        "w12_distance": math.sqrt(l2 + h1),
        "sup_distance": float(np.sqrt(np.max(e2))),
        "slip_l2_distance": math.sqrt(float(np.sum(np.sum(dl * dl, axis=1) / h))),
    }


@dataclass(frozen=True)
class RateFit:
    """The contraction rate r of the Poincare steps with its evidence: the standard error of
    the fitted r (the slope's, through r = exp(slope)) and the number of periods fitted."""

    rate: float
    error: float | None  # None with two periods: a line through two points has no residual
    periods: int


def fit_contraction_rate(rel_steps: np.ndarray) -> RateFit | None:
    """Geometric rate of the Poincare steps: a least-squares fit of log(step) on the last periods.

    A relative step s carries a roundoff of about eps / s relative to itself, so the fit uses
    the last `RATE_WINDOW` steps above `RATE_RELIABLE` (each good to 1e-6 or better) when there
    are at least three; otherwise every step above the roundoff floor.

    The error of the slope b = sum_q c_q log s_q (c_q = (q - mean q) / sum (q - mean q)^2) has two
    parts: the scatter of the points about the line, its standard error
    sqrt(sum e_q^2 / ((n - 2) sum (q - mean q)^2)) over the residuals e_q, and the roundoff of
    the logarithms, at most sum |c_q| eps / s_q. Their sum is carried to r = exp(b) to first
    order (dr = r db). The roundoff part keeps the estimate honest, and the same on every
    machine, where the steps contract exactly geometrically and the residuals are roundoff
    themselves.
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
    x, y = q[chosen].astype(float), np.log(steps[chosen])
    slope, intercept = np.polyfit(x, y, 1)
    rate = float(math.exp(slope))
    if chosen.size < 3:
        return RateFit(rate, None, int(chosen.size))
    residual = y - (slope * x + intercept)
    spread = float(np.sum((x - x.mean()) ** 2))
    scatter = math.sqrt(float(np.sum(residual**2)) / (chosen.size - 2) / spread)
    roundoff = float(np.sum(np.abs(x - x.mean()) / spread * np.finfo(float).eps / steps[chosen]))
    return RateFit(rate, rate * (scatter + roundoff), int(chosen.size))


def contraction_rate(rel_steps: np.ndarray) -> float | None:
    """The fitted geometric rate of the Poincare steps (`fit_contraction_rate`), or None."""
    fit = fit_contraction_rate(rel_steps)
    return None if fit is None else fit.rate
