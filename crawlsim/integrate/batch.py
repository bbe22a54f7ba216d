"""Batched catch-up stepping: many crawlers of one block count, vectorised over the batch.

Each gait b of the batch follows the catch-up scheme of `crawlsim.integrate.stepping` (docs/model.md §3),

    w_{j+1} = argmin { 1/2 |w - w_j|_M^2 : B w <= c(t_{j+1}) },

on its own tabulated offsets, each gait at its own step j of its own period. The numbers of every
step come from the KKT kernel's batched routines (`crawlsim.kernel.batched.run_chains`,
`crawlsim.kernel.batched.refine_chains`): on the active set of each gait a block of up to `BLOCK` steps
telescopes, all gaits at once, certified step by step with each gait's own tolerances; a gait
keeps the steps before its first uncertified one. That step then gets a new active set by the
kernel's primal-dual updates, vectorised over the gaits that need one, and, when those do not
settle, by the gait's own `crawlsim.kernel.projection.ExactProjector` (Clarabel proposes, the kernel
certifies). A certified KKT point of this strictly convex problem *is* the projection, so a gait
in a batch takes the same steps as in a single run, up to roundoff, and fails (or is refused)
exactly when its single run does.

A gait that has converged leaves at its period boundary and the next one in the queue enters at
its own period 0 (continuous batching keeps the vectorised products full).

The period loop, the Poincare step and the classification of convergence are those of
`crawlsim.analysis.run.simulate` (`poincare_step`, `classify_convergence`, `effective_tolerance`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from crawlsim.analysis.run import (
    classify_convergence,
    contraction_rate,
    cost_of_transport,
    effective_tolerance,
    period_iteration_error,
    poincare_step,
)
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.kernel import batched
from crawlsim.kernel.projection import ExactProjector
from crawlsim.model.process import SweepingProcess
from crawlsim.status import Convergence, PointStatus

#: Steps telescoped per block on a fixed active set (`_Lockstep._block`).
BLOCK = 32
#: Gaits stepped together at most.
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


def simulate_batch(processes, *, max_periods, tolerance, capacity: int = DEFAULT_CAPACITY,
                   progress=None) -> list[BatchRun]:
    """Run every crawler process to its periodic regime; results in the order given.

    ``max_periods`` and ``tolerance`` are numbers or one per process. Processes are grouped by
    (steps per period, shape of B); each group steps in lockstep, at most ``capacity`` gaits at
    a time. ``progress(k)`` is called whenever k more gaits have finished.
    """
    processes = list(processes)
    count = len(processes)
    max_periods = np.broadcast_to(np.asarray(max_periods, dtype=int), (count,))
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=float), (count,))
    groups: dict[tuple, list[int]] = {}
    for i, p in enumerate(processes):
        if not p.is_crawler:
            raise ValueError(f"{p.name}: batched stepping measures v0 and needs a crawler")
        groups.setdefault((p.steps, p.blocks), []).append(i)
    out: list[BatchRun | None] = [None] * count
    for members in groups.values():
        group = _Lockstep([processes[i] for i in members], max_periods[members],
                          tolerance[members], capacity, progress)
        for i, run in zip(members, group.run()):
            out[i] = run
    return out  # type: ignore[return-value]


def _friction(process: SweepingProcess) -> np.ndarray:
    assert process.friction is not None, "batched stepping needs crawlers"
    return process.friction


def _stiffness(process: SweepingProcess) -> np.ndarray:
    assert process.stiffness is not None, "batched stepping needs crawlers"
    return process.stiffness


class _Lockstep:
    """One group: crawlers with the same steps per period and block count, batched together."""

    def __init__(self, processes: list[SweepingProcess], max_periods, tolerance, capacity,
                 progress):
        self.processes = processes
        self.max_periods = np.asarray(max_periods)
        self.tol = [effective_tolerance(t) for t in tolerance]
        self.capacity = max(1, int(capacity))
        self.progress = progress
        self.G = processes[0].steps
        self.N = processes[0].blocks
        self.m, self.n = 2 * self.N, self.N - 1
        self.projectors: dict[int, ExactProjector] = {}
        self.rel_steps: list[list[float]] = [[] for _ in processes]
        self.displacements: list[list[float]] = [[] for _ in processes]
        self.results: list[BatchRun | None] = [None] * len(processes)
        self.s: dict[str, np.ndarray] = {}
        self.factors: batched.ChainFactors | None = None

    # -- admission of gaits ------------------------------------------------------------------
    def _admit(self, ids: list[int]):
        """State arrays of the gaits ``ids``, appended to the batch at their period 0."""
        rows = [self.processes[k] for k in ids]
        for k, p in zip(ids, rows):
            self.projectors[k] = ExactProjector(p.polyhedron, describe_active=p.describe_active)
        nb = len(ids)
        new = {
            "id": np.array(ids, dtype=int),
            "period": np.zeros(nb, dtype=int),
            "j": np.zeros(nb, dtype=int),
            "stiffness": np.stack([_stiffness(p) for p in rows]),
            "c_scale": np.array([p.scale for p in rows]),
            "offsets": np.stack([p.offsets for p in rows]),
            "friction": np.stack([_friction(p) for p in rows]),
            # the loads' share of the thresholds (docs/model.md §6), zero without loads
            "load": np.stack([p.load if p.load is not None else np.zeros_like(_friction(p))
                              for p in rows]),
            "w": np.stack([np.asarray(p.initial, dtype=float) for p in rows]),
            "w_start": np.stack([np.asarray(p.initial, dtype=float) for p in rows]),
            "lam_sum": np.zeros((nb, self.m)),
            "diss": np.zeros(nb),
            "load_work": np.zeros(nb),
            "abs_slip": np.zeros(nb),
            "signs": np.zeros((nb, self.N)),
        }
        self.s = new if not self.s else {key: np.concatenate([self.s[key], new[key]])
                                         for key in self.s}
        self._refactor()

    def _keep(self, keep):
        self.s = {key: value[keep] for key, value in self.s.items()}
        self._refactor()

    def _refactor(self, rows=None):
        """Factors of the active sets (all gaits, or refresh the ``rows`` whose set changed)."""
        s = self.s
        if rows is None or self.factors is None:
            self.factors = batched.chain_factors(s["stiffness"], s["signs"])
            return
        if not len(rows):
            return
        f = batched.chain_factors(s["stiffness"][rows], s["signs"][rows])
        for name in ("signs", "D", "l", "inverse_norm", "gram_norm"):
            getattr(self.factors, name)[rows] = getattr(f, name)

    # -- the run ------------------------------------------------------------------------------
    def run(self) -> list[BatchRun]:
        """Telescoped blocks of steps, each gait at its own step of its own period."""
        queue = deque(range(len(self.processes)))
        self._admit([queue.popleft() for _ in range(min(self.capacity, len(queue)))])
        while len(self.s["id"]):
            stopped = self._block()
            if stopped.size:
                self._exact_step(stopped)
            ended = np.flatnonzero(self.s["j"] == self.G)
            if ended.size:
                self._end_period(ended)
            room = self.capacity - len(self.s["id"])
            if room > 0 and queue:
                self._admit([queue.popleft() for _ in range(min(room, len(queue)))])
        return self.results  # type: ignore[return-value]

    def _block(self) -> np.ndarray:
        """Telescope up to BLOCK steps of every gait; positions stopped by an uncertified step."""
        s = self.s
        assert self.factors is not None
        nb, K = len(s["id"]), min(BLOCK, self.G)
        rows = np.arange(nb)
        j = s["j"].copy()
        steps = j[:, None] + 1 + np.arange(K)
        valid = steps <= self.G
        at = np.minimum(steps, self.G)
        C = s["offsets"][rows[:, None], at]
        runs = batched.run_chains(s["stiffness"], self.factors, s["w"], C, s["c_scale"])
        good = runs.ok & ~runs.stop & valid
        accepted = np.where(good.all(axis=1), K, np.argmin(good, axis=1))
        taken = np.arange(K)[None, :] < accepted[:, None]
        self._account(rows, runs.multipliers, s["friction"][rows[:, None], at], taken,
                      s["load"][rows[:, None], at])
        moved = accepted > 0
        s["w"][moved] = runs.w[rows[moved], accepted[moved] - 1]
        s["j"] += accepted
        return np.flatnonzero(s["j"] < np.minimum(j + K, self.G))

    def _account(self, rows, LAM, F, taken, LOAD):
        """Add the taken steps' multipliers, dissipation, load work and |slips| to each gait's
        period."""
        s = self.s
        s["lam_sum"][rows] += np.einsum("bk,bkm->bm", taken, LAM)
        s["diss"][rows] += np.einsum("bk,bkm,bkm->b", taken, LAM, F)
        s["load_work"][rows] += np.einsum("bk,bkm,bkm->b", taken, LAM, LOAD)
        s["abs_slip"][rows] += np.einsum("bk,bkm->b", taken, np.abs(LAM))

    def _exact_step(self, positions):
        """One step of the gaits at ``positions``, each at its own step j: the kernel's
        vectorised updates from the current active set, then each remaining gait's projector."""
        s = self.s
        jn = s["j"][positions] + 1
        c = s["offsets"][positions, jn]
        w, lam, signs, done = batched.refine_chains(s["stiffness"][positions], s["signs"][positions],
                                                s["w"][positions], c, s["c_scale"][positions])
        failed = []
        for i in np.flatnonzero(~done):
            pos = positions[i]
            k = int(s["id"][pos])
            p, q = self.processes[k], int(s["period"][pos])
            projector = self.projectors[k]
            try:
                proj = projector.project(s["w"][pos], c[i], time=q * p.period + p.times[jn[i]])
            except CrawlsimError as exc:
                status = PointStatus.INVALID if isinstance(exc, InputError) else PointStatus.FAILED
                self.results[k] = BatchRun(p.name, status, None, None, None, q, None,
                                           q * self.G + int(jn[i]) - 1,
                                           projector.clarabel_calls, str(exc))
                failed.append(int(pos))
                if self.progress is not None:
                    self.progress(1)
                continue
            w[i], lam[i] = proj.point, proj.multipliers
            signs[i] = 0.0
            idx = proj.active.index
            signs[i, idx[idx < self.N]] = 1.0
            signs[i, idx[idx >= self.N] - self.N] = -1.0
        changed = positions[(signs != s["signs"][positions]).any(axis=1)]
        s["signs"][positions] = signs
        self._refactor(changed)
        one = np.ones((len(positions), 1), dtype=bool)
        self._account(positions, lam[:, None, :], s["friction"][positions, jn][:, None, :], one,
                      s["load"][positions, jn][:, None, :])
        s["w"][positions] = w
        s["j"][positions] += 1
        if failed:
            keep = np.ones(len(s["id"]), dtype=bool)
            keep[failed] = False
            self._keep(keep)

    def _end_period(self, positions):
        """Poincare step and displacement of the period just stepped by the gaits at
        ``positions``; finish the converged ones, start the next period of the others.

        The displacement is ``mean(lambda^+ - lambda^-)`` summed over the period: the
        multipliers are the slips (docs/model.md §3), so this is ``y(t0+(q+1)T) - y(t0+qT)``.
        """
        s = self.s
        N = self.N
        lam = s["lam_sum"][positions]
        dx = (lam[:, :N] - lam[:, N:]).mean(axis=1)
        keep = np.ones(len(s["id"]), dtype=bool)
        for pos, d in zip(positions, dx):
            k = s["id"][pos]
            p, q = self.processes[k], int(s["period"][pos])
            _, rel = poincare_step(p, s["w_start"][pos], s["w"][pos])
            self.rel_steps[k].append(rel)
            self.displacements[k].append(float(d))
            if rel <= self.tol[k] or q + 1 >= self.max_periods[k]:
                keep[pos] = False
                convergence, periodic_from = classify_convergence(self.rel_steps[k], self.tol[k])
                status = (PointStatus.NOT_CONVERGED if convergence == Convergence.NOT_CONVERGED
                          else PointStatus.OK)
                rate = (None if convergence == Convergence.FINITE_TIME
                        else contraction_rate(np.array(self.rel_steps[k])))
                err = period_iteration_error(self.displacements[k], convergence, rate, self.G,
                                             float(s["abs_slip"][pos]) / p.blocks, p.period)
                diss = float(s["diss"][pos])
                paid = diss + float(s["load_work"][pos])  # cost of transport with loads, §6
                self.results[k] = BatchRun(
                    p.name, status, float(d) / p.period, float(d), convergence, q + 1,
                    periodic_from, (q + 1) * self.G, self.projectors[k].clarabel_calls,
                    dissipation_per_period=diss, v0_error_estimate=err, contraction_rate=rate,
                    cost_of_transport=cost_of_transport(paid, float(d), err, p.period))
        s["period"][positions] += 1
        s["j"][positions] = 0
        s["w_start"][positions] = s["w"][positions]
        s["lam_sum"][positions] = 0.0
        s["diss"][positions] = 0.0
        s["load_work"][positions] = 0.0
        s["abs_slip"][positions] = 0.0
        if not keep.all():
            self._keep(keep)
            if self.progress is not None:
                self.progress(int(np.count_nonzero(~keep)))
