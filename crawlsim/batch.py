"""Batched catch-up stepping: many gaits of one block count, vectorised over the batch.

Each gait b of the batch follows the catch-up scheme of `crawlsim.stepping` (MODEL.md §3),

    w_{j+1} = argmin { 1/2 |w - w_j|_M^2 : B w <= c(t_{j+1}) },

on its own tabulated offsets, each gait at its own step j of its own period. On the active set A
of a gait the step is the equality KKT solution

    lambda = G_A^{-1} (B_A w_j - c_A(t_{j+1})),   w_{j+1} = w_j - M^{-1} B_A^T lambda,

and since then ``B_A w_{j+1} = c_A(t_{j+1})``, the next k steps on A telescope (as
`_reuse_block` of `crawlsim.stepping`):

    w_{j+k} = w_j - R_A (B_A w_j - c_A(t_{j+k})),   R_A = M^{-1} B_A^T G_A^{-1}.

With ``G_A^{-1}`` and ``R_A`` padded with zeros outside A to (m, m) and (n, m), a block of up to
`BLOCK` steps of every gait is one batched product over (gait, step of the block). Every step of
every gait is certified as `crawlsim.projection.ExactProjector.is_certified`
certifies, with that gait's own tolerances: primal feasibility ``B w <= c``, the sign of the
multipliers, and complementarity on A. A gait whose certificate fails gets a new active set,
first by primal-dual active-set updates from the previous set (drop the most negative
multiplier, else add the most violated row, exactly the refinement of
`ExactProjector.project`), each candidate solved with the projector's own `ActiveSet` algebra
and certified like any step; when that does not settle, by the gait's own
`ExactProjector.project` (Clarabel proposes the set, the KKT system is certified). A certified
KKT point of this strictly convex problem *is* the projection, so a gait in a batch takes the
same steps as in a single run, up to roundoff. A gait keeps the steps of a block before its
first uncertified one (or before an inactive row tight to roundoff whose union with A has not
been shown to satisfy LICQ) and takes that step alone, as above.

A gait that has converged leaves at its period boundary and the next one in the queue enters at
its own period 0 (continuous batching keeps the vectorised products full).

The period loop, the Poincare step and the classification of convergence are those of
`crawlsim.analysis.simulate` (`poincare_step`, `classify_convergence`, `effective_tolerance`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .analysis import (
    classify_convergence,
    contraction_rate,
    cost_of_transport,
    effective_tolerance,
    period_iteration_error,
    poincare_step,
)
from .errors import CrawlsimError
from .model import SweepingProcess
from .projection import ExactProjector
from .status import Convergence, PointStatus

#: Primal-dual active-set updates tried before a step goes to Clarabel.
REFINE_ITERATIONS = 4
#: Relative singular-value floor of the Gram matrix G_A: the LICQ test of `ExactProjector`.
LICQ_FLOOR = 1e-10
#: Steps telescoped per block on a fixed active set (`_Lockstep._block`).
BLOCK = 32
#: Largest m for which the active-set unions known to satisfy LICQ are tabulated densely
#: (2^m flags per structure), so a block certifies a row tight to roundoff without a lookup.
UNION_TABLE_ROWS = 16
#: Gaits stepped together at most.
DEFAULT_CAPACITY = 256


@dataclass(frozen=True)
class BatchRun:
    """What a batched run measured for one gait: the v0 part of `crawlsim.analysis.RunResult`."""

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
        groups.setdefault((p.steps, p.normals.shape), []).append(i)
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


def _slip_map(process: SweepingProcess) -> np.ndarray:
    assert process.slip_map is not None, "batched stepping needs crawlers"
    return process.slip_map


class _ActiveSets:
    """Padded ``G_A^{-1}`` and ``R_A`` of every active set met so far, per structure (B, M).

    Entries come from `ExactProjector.active_set` of a projector of that structure, so a batched
    step uses the very matrices of a single run. Entry 0 is the empty set; an active set whose
    normals are dependent (LICQ fails) maps to -1 and is left to the full projection, which
    reports it.
    """

    def __init__(self, m: int, n: int):
        self.m, self.n = m, n
        self.P = np.zeros((32, m, m))
        self.R = np.zeros((32, n, m))
        self.size = 1
        self._index: dict[tuple, int] = {}
        self.weights = 1 << np.arange(m, dtype=np.int64) if m < 63 else None

    def code(self, mask: np.ndarray):
        if self.weights is not None:
            return mask @ self.weights
        return [bytes(np.packbits(row)) for row in mask]

    def lookup(self, struct: int, code, mask_row: np.ndarray, projector: ExactProjector) -> int:
        key = (struct, code if isinstance(code, bytes) else int(code))
        entry = self._index.get(key)
        if entry is None:
            entry = self._add(mask_row, projector)
            self._index[key] = entry
        return entry

    def _add(self, mask_row, projector) -> int:
        index = np.flatnonzero(mask_row)
        if index.size == 0:
            return 0
        if index.size > self.n:
            return -1
        gram = projector.B[index] @ (projector.M_inv @ projector.B.T)[:, index]
        s = np.linalg.svd(gram, compute_uv=False)
        if s[-1] <= LICQ_FLOOR * s[0]:
            return -1
        active = projector.active_set(index)
        if self.size == len(self.P):
            self.P = np.concatenate([self.P, np.zeros_like(self.P)])
            self.R = np.concatenate([self.R, np.zeros_like(self.R)])
        k = self.size
        self.P[k][np.ix_(active.index, active.index)] = active.gram_inv
        self.R[k][:, active.index] = active.response
        self.size += 1
        return k


class _Lockstep:
    """One group: gaits with the same steps per period and the same m x n, batched together."""

    def __init__(self, processes: list[SweepingProcess], max_periods, tolerance, capacity,
                 progress):
        self.processes = processes
        self.max_periods = np.asarray(max_periods)
        self.tol = [effective_tolerance(t) for t in tolerance]
        self.capacity = max(1, int(capacity))
        self.progress = progress
        self.G = processes[0].steps
        m, n = processes[0].normals.shape
        self.m, self.n = m, n
        self.normals = processes[0].normals
        self.shared = all(np.array_equal(p.normals, self.normals) for p in processes)
        self.projectors: dict[int, ExactProjector] = {}
        self.structures: dict[bytes, tuple[int, ExactProjector]] = {}
        self.struct_of = np.zeros(len(processes), dtype=int)
        self.table = _ActiveSets(m, n)
        self.licq_ok = np.zeros((0, 1 << m), dtype=bool) if m <= UNION_TABLE_ROWS else None
        self.rel_steps: list[list[float]] = [[] for _ in processes]
        self.displacements: list[list[float]] = [[] for _ in processes]
        self.results: list[BatchRun | None] = [None] * len(processes)
        self.s: dict[str, np.ndarray] = {}

    # -- admission of gaits ------------------------------------------------------------------
    def _admit(self, ids: list[int]):
        """State arrays of the gaits ``ids``, appended to the batch at their period 0."""
        rows = []
        for k in ids:
            p = self.processes[k]
            projector = ExactProjector(p.normals, p.metric, p.scale,
                                       describe_active=p.describe_active)
            self.projectors[k] = projector
            key = p.normals.tobytes() + p.metric.tobytes()
            if key not in self.structures:
                self.structures[key] = (len(self.structures), projector)
            self.struct_of[k] = self.structures[key][0]
            rows.append((projector, p))
        if self.licq_ok is not None and len(self.licq_ok) < len(self.structures):
            grow = len(self.structures) - len(self.licq_ok)
            self.licq_ok = np.concatenate([self.licq_ok,
                                           np.zeros((grow, self.licq_ok.shape[1]), dtype=bool)])
        new = dict(
            id=np.array(ids, dtype=int),
            period=np.zeros(len(ids), dtype=int),
            j=np.zeros(len(ids), dtype=int),
            normals=np.stack([p.normals for _, p in rows]),
            minv_bt=np.stack([pr.M_inv @ p.normals.T for pr, p in rows]),
            offsets=np.stack([p.offsets for _, p in rows]),
            slip=np.stack([_slip_map(p) for _, p in rows]),
            tolp=np.array([pr.tol.primal for pr, _ in rows])[:, None],
            told=np.array([pr.tol.dual for pr, _ in rows])[:, None],
            w=np.stack([np.asarray(p.initial, dtype=float) for _, p in rows]),
            w_start=np.stack([np.asarray(p.initial, dtype=float) for _, p in rows]),
            lam_sum=np.zeros((len(ids), self.m)),
            diss=np.zeros(len(ids)),
            abs_slip=np.zeros(len(ids)),
            friction=np.stack([_friction(p) for _, p in rows]),
            mask=np.zeros((len(ids), self.m), dtype=bool),
            P=np.zeros((len(ids), self.m, self.m)),
            R=np.zeros((len(ids), self.n, self.m)),
        )
        if not self.s:
            self.s = new
        else:
            self.s = {key: np.concatenate([self.s[key], new[key]]) for key in self.s}

    def _keep(self, keep):
        self.s = {key: value[keep] for key, value in self.s.items()}

    # -- batched linear algebra ------------------------------------------------------------
    def _B(self, w, rows=None):
        """B w for every gait (rows of w)."""
        if self.shared:
            return w @ self.normals.T
        normals = self.s["normals"] if rows is None else self.s["normals"][rows]
        return np.einsum("bmn,bn->bm", normals, w)

    @staticmethod
    def _uncertified(lam, slack, mask, tolp, told):
        """Rows failing the projector's certificate: primal, dual sign or complementarity."""
        bad = slack > tolp
        bad |= lam < -told
        bad |= mask & (slack < -tolp)
        return bad.any(axis=1)

    # -- the run ------------------------------------------------------------------------------
    def run(self) -> list[BatchRun]:
        """Telescoped blocks of steps, each gait at its own step of its own period.

        On a fixed active set A, ``B_A w_{j+1} = c_A(t_{j+1})`` after every step, so the next
        ``k`` steps are ``w_{j+k} = w_j - R_A (B_A w_j - c_A(t_{j+k}))`` (as `_reuse_block` of
        `crawlsim.stepping`): one batched product over (gait, step of the block). Every step of
        the block is certified; each gait keeps the steps before its first uncertified one (or
        before an inactive row tight to roundoff) and takes that step exactly (`_exact_step`).
        """
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
        nb, K = len(s["id"]), min(BLOCK, self.G)
        rows = np.arange(nb)
        j = s["j"].copy()
        steps = j[:, None] + 1 + np.arange(K)
        valid = steps <= self.G
        C = s["offsets"][rows[:, None], np.minimum(steps, self.G)]
        w = s["w"]
        r0 = self._B(w)[:, None, :] - C
        W = w[:, None, :] - np.matmul(r0, s["R"].transpose(0, 2, 1))
        if self.shared:
            BW = W @ self.normals.T
        else:
            BW = np.matmul(W, s["normals"].transpose(0, 2, 1))
        slack = BW - C
        r = np.concatenate([r0[:, :1], BW[:, :-1] - C[:, 1:]], axis=1)
        lam = np.matmul(r, s["P"].transpose(0, 2, 1))
        tolp, told, mask = s["tolp"][:, :, None], s["told"][:, :, None], s["mask"][:, None, :]
        bad = (slack > tolp) | (lam < -told) | (mask & (slack < -tolp))
        near = ~mask & (slack >= -tolp)
        tight = near.any(axis=2)
        if self.licq_ok is not None and tight.any():
            codes = (mask | near) @ self.table.weights
            tight &= ~self.licq_ok[self.struct_of[s["id"]][:, None], codes]
        bad = bad.any(axis=2) | tight | ~valid
        accepted = np.where(bad.any(axis=1), bad.argmax(axis=1), K)
        taken = np.arange(K)[None, :] < accepted[:, None]
        s["lam_sum"] += np.einsum("bk,bkm->bm", taken, lam)
        F = s["friction"][rows[:, None], np.minimum(steps, self.G)]
        s["diss"] += np.einsum("bk,bkm,bkm->b", taken, lam, F)
        s["abs_slip"] += np.einsum("bk,bkm->b", taken, np.abs(lam))
        moved = accepted > 0
        s["w"][moved] = W[rows[moved], accepted[moved] - 1]
        s["j"] += accepted
        return np.flatnonzero(s["j"] < np.minimum(j + K, self.G))

    def _exact_step(self, positions):
        """One step of the gaits at ``positions``, each at its own step j: the batched step on
        the current active set, certified, with the repairs of `_repair` where it fails."""
        s = self.s
        nb = len(s["id"])
        w = s["w"]
        c = np.zeros((nb, self.m))
        c[positions] = s["offsets"][positions, s["j"][positions] + 1]
        lam = np.zeros((nb, self.m))
        w_new = w.copy()
        slack = np.zeros((nb, self.m))
        P, R = s["P"][positions], s["R"][positions]
        r = self._B(w[positions], positions) - c[positions]
        lam[positions] = np.einsum("bkm,bm->bk", P, r)
        w_new[positions] = w[positions] - np.einsum("bnm,bm->bn", R, r)
        slack[positions] = self._B(w_new[positions], positions) - c[positions]
        uncertified = self._uncertified(lam[positions], slack[positions], s["mask"][positions],
                                        s["tolp"][positions], s["told"][positions])
        bad = positions[uncertified]
        degenerate = self._degenerate(positions[~uncertified], slack)
        failed = self._repair(bad, s["j"], w, c, lam, w_new, slack, degenerate)
        s["lam_sum"][positions] += lam[positions]
        F = s["friction"][positions, s["j"][positions] + 1]
        s["diss"][positions] += np.einsum("bm,bm->b", lam[positions], F)
        s["abs_slip"][positions] += np.abs(lam[positions]).sum(axis=1)
        s["w"][positions] = w_new[positions]
        s["j"][positions] += 1
        if failed:
            keep = np.ones(nb, dtype=bool)
            keep[failed] = False
            self._keep(keep)

    def _degenerate(self, positions, slack) -> np.ndarray:
        """Certified gaits at a point where LICQ fails: an inactive row on its boundary whose
        normal depends on the active ones (for crawlers: every block at a friction limit, the
        instant the uniqueness condition fails). Their multipliers are not unique, so the step
        goes to the full projection, which decides and reports it as a single run does.
        """
        s = self.s
        near = (slack[positions] >= -s["tolp"][positions]) & ~s["mask"][positions]
        hit = near.any(axis=1)
        candidates = positions[hit]
        if not candidates.size:
            return candidates
        union = s["mask"][candidates] | near[hit]
        codes = self.table.code(union)
        entry = np.array([self.table.lookup(self.struct_of[k], code, row, self.projectors[k])
                          for k, code, row in zip(s["id"][candidates], codes, union)])
        if self.licq_ok is not None:
            known = entry >= 0
            self.licq_ok[self.struct_of[s["id"][candidates[known]]], codes[known]] = True
        return candidates[entry < 0]

    def _repair(self, todo, j, w, c, lam, w_new, slack, degenerate) -> list[int]:
        """New active sets for the gaits at positions ``todo``; fills ``lam`` and ``w_new``.

        Returns the positions of gaits whose projection could not be certified at all (for
        instance LICQ fails): they are recorded as failed and leave the batch.
        """
        s, table = self.s, self.table
        mask = s["mask"][todo]
        lam_t, slack_t = lam[todo], slack[todo]
        to_project = []
        for _ in range(REFINE_ITERATIONS if todo.size else 0):
            rows = np.arange(len(todo))
            worst_dual = np.argmin(lam_t, axis=1)
            worst_primal = np.argmax(slack_t, axis=1)
            drop = lam_t[rows, worst_dual] < -s["told"][todo, 0]
            add = ~drop & (slack_t[rows, worst_primal] > s["tolp"][todo, 0])
            mask[rows[drop], worst_dual[drop]] = False
            mask[rows[add], worst_primal[add]] = True
            codes = table.code(mask)
            entry = np.array([
                table.lookup(self.struct_of[k], code, row, self.projectors[k])
                if moved else -1
                for k, code, row, moved in zip(s["id"][todo], codes, mask, drop | add)])
            usable = entry >= 0
            to_project.append(todo[~usable])
            todo, mask, entry = todo[usable], mask[usable], entry[usable]
            if not todo.size:
                break
            P, R = table.P[entry], table.R[entry]
            r = self._B(w[todo], todo) - c[todo]
            lam_t = np.einsum("bkm,bm->bk", P, r)
            w_t = w[todo] - np.einsum("bnm,bm->bn", R, r)
            slack_t = self._B(w_t, todo) - c[todo]
            ok = ~self._uncertified(lam_t, slack_t, mask, s["tolp"][todo], s["told"][todo])
            done = todo[ok]
            s["mask"][done], s["P"][done], s["R"][done] = mask[ok], P[ok], R[ok]
            lam[done], w_new[done] = lam_t[ok], w_t[ok]
            todo, mask, lam_t, slack_t = todo[~ok], mask[~ok], lam_t[~ok], slack_t[~ok]
            if not todo.size:
                break
        to_project.extend([todo, degenerate])
        return self._project(np.concatenate(to_project), j, w, c, lam, w_new)

    def _project(self, todo, j, w, c, lam, w_new) -> list[int]:
        """The gait's own exact projection (Clarabel + certified KKT) for the steps left over."""
        s, failed = self.s, []
        for pos in np.unique(todo):
            k = int(s["id"][pos])
            p, q = self.processes[k], int(s["period"][pos])
            try:
                proj = self.projectors[k].project(w[pos], c[pos],
                                                  time=q * p.period + p.times[j[pos] + 1])
            except CrawlsimError as exc:
                self.results[k] = BatchRun(p.name, PointStatus.FAILED, None, None, None, q, None,
                                           q * self.G + int(j[pos]),
                                           self.projectors[k].clarabel_calls,
                                           str(exc))
                failed.append(int(pos))
                if self.progress is not None:
                    self.progress(1)
                continue
            A = proj.active
            s["mask"][pos] = False
            s["mask"][pos, A.index] = True
            s["P"][pos] = 0.0
            s["P"][pos][np.ix_(A.index, A.index)] = A.gram_inv
            s["R"][pos] = 0.0
            s["R"][pos][:, A.index] = A.response
            lam[pos], w_new[pos] = proj.multipliers, proj.point
        return failed

    def _end_period(self, positions):
        """Poincare step and displacement of the period just stepped by the gaits at
        ``positions``; finish the converged ones, start the next period of the others.

        The displacement is ``mean(S sum_j lambda_j)``: the multipliers are the slips (MODEL.md
        §3), so this is ``y(t0+(q+1)T) - y(t0+qT)``.
        """
        s = self.s
        dx = np.einsum("bNm,bm->bN", s["slip"][positions], s["lam_sum"][positions]).mean(axis=1)
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
                self.results[k] = BatchRun(
                    p.name, status, float(d) / p.period, float(d), convergence, q + 1,
                    periodic_from, (q + 1) * self.G, self.projectors[k].clarabel_calls,
                    dissipation_per_period=diss, v0_error_estimate=err, contraction_rate=rate,
                    cost_of_transport=cost_of_transport(diss, float(d), err, p.period))
        s["period"][positions] += 1
        s["j"][positions] = 0
        s["w_start"][positions] = s["w"][positions]
        s["lam_sum"][positions] = 0.0
        s["diss"][positions] = 0.0
        s["abs_slip"][positions] = 0.0
        if not keep.all():
            self._keep(keep)
            if self.progress is not None:
                self.progress(int(np.count_nonzero(~keep)))
