"""The certified projection step on a polyhedron, for every integrator (`crawlsim.projection.kkt`).

`Polyhedron` holds what every structure shares: the tolerance policy, the solve on an active
set with iterative refinement, the certificate, the primal-dual active-set updates and the
telescoped run of steps on a fixed active set. Its subclasses give the structure: the crawler
chain (`crawlsim.projection.chain_polyhedron`) and a dense generic process
(`crawlsim.projection.dense_polyhedron`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from crawlsim.kernel.policy import REFINE_FRACTION, UPDATE_ITERATIONS, tolerances
from crawlsim.projection.certificate import (
    CACHE_NUMBERS,
    GENERIC_RCOND,
    Certificate,
    Dependent,
    Run,
    Step,
    Tolerance,
)


class ActiveSet:
    """One factored active set A (sorted row indices ``index``) of a `Polyhedron`."""

    index: np.ndarray
    inverse_norm: float  # ||G_A^{-1}||_inf (a bound), for the dual tolerance
    gram_norm: float  # ||G_A||_inf

    @property
    def size(self) -> int:
        return len(self.index)

    def solve(self, R: np.ndarray) -> np.ndarray:
        """G_A^{-1} R for right-hand sides R (..., a)."""
        raise NotImplementedError


class _EmptySet(ActiveSet):
    def __init__(self) -> None:
        self.index = np.zeros(0, dtype=int)
        self.inverse_norm = 0.0
        self.gram_norm = 0.0

    def solve(self, R: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(R))


class Polyhedron:
    """The constant part of K(t) = {w : B w <= c(t)} and the metric M of its projections.

    Subclasses give B w (`apply`), M^{-1} B^T lambda (`respond`), factored active sets
    (`_factor`) and the LICQ test (`licq`); everything else, the tolerance policy, the solve
    with refinement, the certificate, the telescoped run and the primal-dual updates, is here
    once for every integrator.
    """

    m: int
    n: int
    row_norm: float  # ||B||_inf
    response_norm: float  # ||M^{-1} B^T||_inf
    c_scale: float  # a natural size of c, the floor of every tolerance

    def __init__(self) -> None:
        self._cache: dict[tuple[int, ...], ActiveSet] = {}
        self._cached_numbers = 0
        self._licq_ok: set[tuple[int, ...]] = set()
        self.empty: ActiveSet = _EmptySet()
        self._cache[()] = self.empty

    # -- structure (subclasses) ----------------------------------------------------------------
    def apply(self, W: np.ndarray) -> np.ndarray:
        """B w for states W (..., n) -> (..., m)."""
        raise NotImplementedError

    def respond(self, LAM: np.ndarray) -> np.ndarray:
        """M^{-1} B^T lambda for multipliers (..., m) -> (..., n)."""
        raise NotImplementedError

    def licq(self, index: npt.ArrayLike) -> bool:
        """Whether the normals of the rows ``index`` are linearly independent."""
        raise NotImplementedError

    def _factor(self, index: np.ndarray) -> ActiveSet:
        raise NotImplementedError

    def _numbers(self, size: int) -> int:
        """Numbers a factored active set of ``size`` rows keeps (chains: O(size))."""
        return 6 * size + 8

    def metric_times(self, w: np.ndarray) -> np.ndarray:
        """M w."""
        raise NotImplementedError

    def metric_solve(self, v: np.ndarray) -> np.ndarray:
        """M^{-1} v."""
        raise NotImplementedError

    def metric_root(self, v: np.ndarray) -> np.ndarray:
        """L^T v with M = L L^T (|v|_M = |L^T v|), for states (..., n)."""
        raise NotImplementedError

    def metric_root_transpose(self, v: np.ndarray) -> np.ndarray:
        """L v (the adjoint of `metric_root`)."""
        raise NotImplementedError

    def dense_normals(self) -> np.ndarray:
        raise NotImplementedError

    def dense_metric(self) -> np.ndarray:
        raise NotImplementedError

    def clarabel_matrices(self) -> tuple[Any, Any]:
        """(P, A) as scipy CSC matrices for Clarabel: P the upper triangle of M, A = B."""
        raise NotImplementedError

    def degenerate_slips(self, step: Step, tight: np.ndarray, tol: Tolerance) -> bool:
        """Whether the multipliers of a certified step are not unique (LICQ fails on the tight
        rows ``tight`` in a way that changes them); generic processes: whether LICQ fails."""
        return not self.licq(tight)

    # -- active sets ---------------------------------------------------------------------------
    def factor(self, index: npt.ArrayLike) -> ActiveSet:
        """The factored active set of the rows ``index`` (cached); `Dependent` if LICQ fails."""
        key = tuple(np.sort(np.asarray(index, dtype=int)).tolist())
        cached = self._cache.get(key)
        if cached is None:
            idx = np.array(key, dtype=int)
            if not self.licq(idx):
                raise Dependent(idx)
            cached = self._factor(idx)
            # long runs visit many sets: keep the cache's memory bounded
            self._cached_numbers += self._numbers(len(idx))
            if self._cached_numbers > CACHE_NUMBERS:
                self._cache.clear()
                self._cache[()] = self.empty
                self._cached_numbers = self._numbers(len(idx))
            self._cache[key] = cached
        return cached

    # -- the one tolerance policy (`crawlsim.kernel.policy`) -----------------------------------
    def tolerance(
        self, active: ActiveSet, c_size: npt.ArrayLike, w_size: npt.ArrayLike, lam_size: npt.ArrayLike
    ) -> Tolerance:
        """Certificate tolerances for a step (or arrays of steps) whose offsets, states and
        cumulative multipliers have these sup norms."""
        lam = np.asarray(lam_size)
        w_part, lam_part = self.row_norm * np.asarray(w_size), self.row_norm * self.response_norm * lam
        return Tolerance(
            *tolerances(self.c_scale, c_size, w_part, lam_part, active.inverse_norm, active.gram_norm, lam)
        )

    # -- one step on an active set --------------------------------------------------------------
    def solve_on(
        self,
        active: ActiveSet,
        w_trial: np.ndarray,
        c: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Tolerance]:
        """(w, lambda (m,), B w - c, tolerance) of the equality KKT system on ``active``."""
        Bw = self.apply(w_trial)
        lam = np.zeros(self.m)
        if active.size == 0:
            slack = Bw - c
            return np.array(w_trial, dtype=float), lam, slack, self.step_tolerance(active, c, w_trial, lam)
        idx = active.index
        lam[idx] = active.solve(Bw[idx] - c[idx])
        w = w_trial - self.respond(lam)
        slack = self.apply(w) - c
        tol = self.step_tolerance(active, c, w_trial, lam)
        if np.abs(slack[idx]).max() > REFINE_FRACTION * tol.primal:
            # one step of iterative refinement on the certified residual: B_A w - c_A
            delta = np.zeros(self.m)
            delta[idx] = active.solve(slack[idx])
            lam += delta
            w = w - self.respond(delta)
            slack = self.apply(w) - c
        return w, lam, slack, self.row_tolerance(active, w_trial, c, lam, tol)

    def row_tolerance(
        self, active: ActiveSet, w_trial: np.ndarray, c: np.ndarray, lam: np.ndarray, tol: Tolerance
    ) -> Tolerance:
        """``tol`` with each row's own dual tolerance where the structure gives one (chains:
        `ChainPolyhedron.row_tolerance`); generic processes keep the scalar bound."""
        return tol

    def step_tolerance(self, active: ActiveSet, c: np.ndarray, w: np.ndarray, lam: np.ndarray) -> Tolerance:
        """`tolerance` of one step from its offsets, state and multipliers (rows with an
        infinite offset, the exact integrator's velocity problems, are left out)."""
        c_size = float(np.max(np.abs(c), initial=0.0, where=np.isfinite(c)))
        return self.tolerance(active, c_size, float(np.abs(w).max(initial=0.0)), float(np.abs(lam).max(initial=0.0)))

    def certify(
        self, slack: np.ndarray, lam: np.ndarray, active: ActiveSet, tol: Tolerance, fixed: np.ndarray | None = None
    ) -> Certificate:
        """The certificate of one step from its slack B w - c and multipliers. Rows ``fixed``
        are equalities: their multipliers may have either sign."""
        comp = float(np.abs(slack[active.index]).max(initial=0.0))
        if fixed is not None and len(fixed):
            lam = lam.copy()
            lam[fixed] = 0.0
        primal = float(slack.max(initial=-np.inf))
        if np.ndim(tol.dual) == 0:
            return Certificate(primal, float(-lam.min(initial=0.0)), comp, tol)
        # per-row dual tolerances: the multiplier most negative relative to its own row's
        told = np.asarray(tol.dual, dtype=float)
        neg = np.maximum(-lam, 0.0)
        ratio = np.divide(neg, told, out=np.where(neg > 0, np.inf, 0.0), where=told > 0)
        r = int(np.argmax(ratio)) if len(ratio) else 0
        value = float(neg[r]) if len(neg) else 0.0
        return Certificate(primal, value, comp, tol, float(told[r]) if len(told) else 0.0)

    def tight_rows(self, slack: np.ndarray, active: ActiveSet, tol: Tolerance) -> np.ndarray:
        """Rows tight to roundoff at a certified point: the active ones and any inactive row
        whose slack is within the primal tolerance."""
        tight = slack >= -tol.primal
        tight[active.index] = True
        return np.flatnonzero(tight)

    # -- primal-dual active-set updates ------------------------------------------------------
    def refine(
        self,
        w_trial: np.ndarray,
        c: np.ndarray,
        start: ActiveSet | tuple[int, ...] | np.ndarray,
        *,
        iterations: int = UPDATE_ITERATIONS,
        single: bool = False,
        fixed: np.ndarray | None = None,
    ) -> Step | None:
        """A certified step from the active set ``start``, by primal-dual active-set updates,
        or None when they do not settle (then Clarabel proposes a set).

        Each update drops the rows whose multiplier is negative beyond tolerance and adds the
        rows violated beyond tolerance (all at once; ``single=True`` moves only the worst row,
        the slower but more cautious variant). A certified KKT point of this strictly convex
        problem *is* the projection, so how the set was found does not matter. Rows ``fixed``
        are equality constraints (always active, multipliers of either sign).
        """
        seen: set[tuple[int, ...]] = set()
        if fixed is not None and len(fixed):
            base = start.index if isinstance(start, ActiveSet) else np.asarray(start, dtype=int)
            start = np.union1d(base, fixed)
        try:
            active = start if isinstance(start, ActiveSet) else self.factor(start)
        except Dependent:
            return None
        for _ in range(iterations):
            key = tuple(active.index.tolist())
            if key in seen:
                return None
            seen.add(key)
            w, lam, slack, tol = self.solve_on(active, w_trial, c)
            cert = self.certify(slack, lam, active, tol, fixed)
            if cert.ok:
                return Step(w, lam, active, cert)
            index = self.update_set(active, lam, slack, tol, single=single, fixed=fixed)
            if index is None:
                return None  # complementarity failed even after refinement
            if not single and not self.licq(index):
                # adding every violated row at once made the set dependent: the worst only
                index = self.update_set(active, lam, slack, tol, single=True, fixed=fixed)
                if index is None:
                    return None
            if not self.licq(index):
                index = self.exchange(active, lam, slack, fixed)
                if index is None:
                    return None
            try:
                active = self.factor(index)
            except Dependent:
                return None
        return None

    def exchange(
        self, active: ActiveSet, lam: np.ndarray, slack: np.ndarray, fixed: np.ndarray | None = None
    ) -> np.ndarray | None:
        """The most violated row r enters although its normal depends on the active ones: the
        dual step of Goldfarb and Idnani. With z the dependency (B_{A+r}^T z = 0, z_r > 0),
        the multipliers lambda + t z stay non-negative until the active row j with z_j < 0 and
        the smallest lambda_j / |z_j| reaches zero; j leaves, r enters (None if no row can)."""
        idx = active.index
        inactive = np.ones(self.m, dtype=bool)
        inactive[idx] = False
        r = int(np.argmax(np.where(inactive, slack, -np.inf)))
        z = self.dependency(np.append(idx, r))
        if z is None:
            return None
        z = z if z[-1] > 0 else -z
        zA = z[:-1]
        leaving = zA < 0
        if fixed is not None and len(fixed):
            leaving &= ~np.isin(idx, fixed)
        if not leaving.any():
            return None
        ratio = np.where(leaving, np.maximum(lam[idx], 0.0) / np.where(leaving, -zA, 1.0), np.inf)
        j = int(np.argmin(ratio))
        return np.sort(np.append(np.delete(idx, j), r))

    def dependency(self, index: np.ndarray) -> np.ndarray | None:
        """A nonzero z with B_index^T z = 0, in the order of ``index`` (None if independent)."""
        B = self.dense_normals()[index] if self.m * self.n <= 4_000_000 else None
        if B is None:
            return None
        _, s, vt = np.linalg.svd(B.T)
        if len(index) > len(s) or s[-1] <= GENERIC_RCOND * s[0]:
            z: np.ndarray = vt[-1]
            return z
        return None

    def update_set(
        self,
        active: ActiveSet,
        lam: np.ndarray,
        slack: np.ndarray,
        tol: Tolerance,
        *,
        single: bool = False,
        fixed: np.ndarray | None = None,
    ) -> np.ndarray | None:
        """The next active set of a primal-dual update: drop the rows whose multiplier is
        negative beyond tolerance (never a ``fixed`` row), add the rows violated beyond
        tolerance (``single``: only the worst one); None when nothing is to change."""
        member = np.zeros(self.m, dtype=bool)
        member[active.index] = True
        drop = member & (lam < -tol.dual)
        if fixed is not None and len(fixed):
            drop[fixed] = False
        violated = ~member & (slack > tol.primal)
        if single:
            if drop.any():
                worst = int(np.argmin(np.where(drop, lam, np.inf)))
                drop[:] = False
                drop[worst] = True
                violated[:] = False
            elif violated.any():
                worst = int(np.argmax(np.where(violated, slack, -np.inf)))
                violated[:] = False
                violated[worst] = True
        if not drop.any() and not violated.any():
            return None
        return np.flatnonzero((member & ~drop) | violated)

    # -- a telescoped run of steps on one active set -----------------------------------------
    def run(self, active: ActiveSet, w: np.ndarray, C: np.ndarray) -> Run:
        """Steps from ``w`` to the offsets C (k, m) on the fixed active set A (module
        docstring), certified step by step; the run is accepted up to its first uncertified
        step. An inactive row tight to roundoff also stops the run where the tight set may fail
        LICQ (`tight_stop`): the full step decides that case."""
        k = len(C)
        if active.size == 0:
            slack = self.apply(w)[None, :] - C
            tol = self.tolerance(active, np.abs(C).max(axis=1), np.abs(w).max(), 0.0)
            primal = slack.max(axis=1)
            ok = primal <= tol.primal
            tight = slack >= -tol.primal[:, None]
            stop = self.tight_stop(tight, tight.any(axis=1))
            good = ok & ~stop
            acc = _prefix(good)
            W = np.broadcast_to(w, (k, self.n)).copy()
            failed = None
            next_set = None
            if acc < k and not ok[acc]:
                t = Tolerance(float(tol.primal[acc]), float(tol.dual[acc]))
                failed = Certificate(float(primal[acc]), 0.0, 0.0, t)
                next_set = np.flatnonzero(slack[acc] > t.primal)
            return Run(acc, W, np.zeros((k, self.m)), failed, bool(acc < k and ok[acc]), next_set)
        idx = active.index
        Bw = self.apply(w)
        R = Bw[idx][None, :] - C[:, idx]
        LAMC = np.zeros((k, self.m))
        LAMC[:, idx] = active.solve(R)
        W = w - self.respond(LAMC)
        slack = self.apply(W) - C
        tol = self.tolerance(active, np.abs(C).max(axis=1), np.abs(W).max(axis=1), np.abs(LAMC).max(axis=1))
        comp = np.abs(slack[:, idx]).max(axis=1)
        if np.any(comp > REFINE_FRACTION * tol.primal):
            delta = np.zeros((k, self.m))
            delta[:, idx] = active.solve(slack[:, idx])
            LAMC += delta
            W -= self.respond(delta)
            slack = self.apply(W) - C
            comp = np.abs(slack[:, idx]).max(axis=1)
        LAM = LAMC.copy()
        LAM[1:] -= LAMC[:-1]
        primal = slack.max(axis=1)
        dual = -LAM[:, idx].min(axis=1)
        ok = (primal <= tol.primal) & (dual <= tol.dual) & (comp <= tol.primal)
        tight = slack >= -tol.primal[:, None]
        tight[:, idx] = False
        stop = self.tight_stop(tight | _mask(idx, self.m)[None, :], tight.any(axis=1))
        acc = _prefix(ok & ~stop)
        failed = None
        degenerate = False
        next_set = None
        if acc < k:
            if ok[acc]:
                degenerate = True
            else:
                t = Tolerance(float(tol.primal[acc]), float(tol.dual[acc]))
                failed = Certificate(float(primal[acc]), float(dual[acc]), float(comp[acc]), t)
                next_set = self.update_set(active, LAM[acc], slack[acc], t)
        return Run(acc, W, LAM, failed, degenerate, next_set)

    def tight_stop(self, tight: np.ndarray, any_inactive: np.ndarray) -> np.ndarray:
        """Steps (rows of the tight masks (k, m)) whose tight set, with an inactive row tight to
        roundoff, is not known to satisfy LICQ: the run stops there and the full step decides.
        A tight set once verified by `licq_verified` is known from then on."""
        out = np.array(any_inactive, dtype=bool, copy=True)
        for i in np.flatnonzero(out):
            out[i] = tuple(np.flatnonzero(tight[i]).tolist()) not in self._licq_ok
        return out

    def licq_verified(self, index: np.ndarray) -> bool:
        """`licq`, remembering the sets that pass so that runs through them need not stop."""
        key = tuple(sorted(int(i) for i in index))
        if key in self._licq_ok:
            return True
        ok = self.licq(np.array(key, dtype=int))
        if ok and len(self._licq_ok) < 65536:
            self._licq_ok.add(key)
        return ok


def _mask(index: np.ndarray, m: int) -> np.ndarray:
    out = np.zeros(m, dtype=bool)
    out[index] = True
    return out


def _prefix(ok: np.ndarray) -> int:
    """Length of the leading run of True."""
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if bad.size else len(ok)
