"""The certified KKT kernel: every projection step of every integrator is solved and certified here.

A step projects a trial point onto K = {w : B w <= c} in the metric M (docs/model.md §3):

    w* = argmin { 1/2 |w - w_trial|_M^2 : B w <= c }.

Its KKT conditions are necessary and sufficient (a strictly convex QP):

    M (w* - w_trial) + B^T lambda = 0,   B w* <= c,   lambda >= 0,   lambda_i (B w* - c)_i = 0.

On an active set A (rows with equality) they reduce to one linear system in lambda_A,

    G_A lambda_A = B_A w_trial - c_A,   G_A = B_A M^{-1} B_A^T,   w* = w_trial - M^{-1} B_A^T lambda_A,

which this module solves by a factorisation of G_A (LDL^T or Cholesky, never an explicit
inverse) and then *certifies*: primal feasibility, the sign of the multipliers and
complementarity, each to roundoff under one tolerance policy (`Polyhedron.tolerance`). A step
whose complementarity residual is above a quarter of its tolerance gets one step of iterative
refinement on that residual. Clarabel (`crawlsim.kernel.projection`) only proposes active sets; the
numbers of a step always come from here.

Two structures share the interface `Polyhedron`:

* `ChainPolyhedron`, the crawler (docs/model.md §2): B = [D^T; -D^T] with D the (N-1) x N
  forward difference, M = K^{-1}. Row j < N is block j at its forward friction limit, row N + j
  the same block at its backward limit; a block is never at both (mu^+ + mu^- > 0). Writing the
  slips dx = lambda^+ - lambda^-, the system on A becomes

      L_JJ dx_J = f_J - f*_J,   L = D^T K D (the chain's stiffness Laplacian, tridiagonal),

  with J the saturated blocks, f = D^T w their elastic forces and f* their friction limits
  (+mu^+ or -mu^-). L_JJ is a principal submatrix of a tridiagonal M-matrix: it is tridiagonal
  in block order, positive definite unless J is every block (L 1 = 0), and its inverse is
  entrywise non-negative, so ||L_JJ^{-1}||_inf = max(L_JJ^{-1} 1). Every operation is O(N): the
  system is padded to all N blocks (identity rows for free blocks) and factored by LDL^T, in
  numpy for small chains and with LAPACK's ``dpttrf``/``dpttrs`` for long ones. LICQ holds
  exactly when J is not every block, which is also when the multipliers (the slips) are unique
  (docs/model.md §3; paper Lemma lem:licqstar).
* `DensePolyhedron`, a generic polyhedral process (docs/model.md §5): dense B and M, Cholesky of
  G_A, and LICQ decided by the conditioning of G_A.

The telescoped run of steps on a fixed active set (`Polyhedron.run`, and `run_chains` for a
batch of crawlers) uses that after a step on A, B_A w = c_A, so the next k steps are

    w_{j+i} = w_j - M^{-1} B_A^T Lambda_i,   G_A Lambda_i = B_A w_j - c_A(t_{j+i}),

Lambda_i the cumulative multipliers: one factorisation and one multi-right-hand-side solve for a
whole run of steps, certified step by step in one vectorised pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Relative tolerance of every certificate: about 45 ulps of the size of the step's numbers.
RTOL = 1e-14
#: Active sets of up to this many blocks are factored in numpy, larger ones with LAPACK.
SMALL_CHAIN = 6
#: LICQ floor of generic processes: the reciprocal condition number of G_A.
GENERIC_RCOND = 1e-10
#: A complementarity residual above this fraction of its tolerance triggers refinement.
REFINE_FRACTION = 0.25
#: Primal-dual active-set updates tried before a step is handed to Clarabel.
UPDATE_ITERATIONS = 12
#: Numbers the cache of factored active sets may hold (about 32 MB); it is emptied when full.
CACHE_NUMBERS = 1 << 22


class Dependent(Exception):
    """The rows ``index`` have linearly dependent normals (LICQ fails)."""

    def __init__(self, index):
        super().__init__(index)
        self.index = np.asarray(index, dtype=int)


@dataclass(frozen=True)
class Tolerance:
    """Absolute certificate tolerances: on B w - c (units of c) and on lambda."""

    primal: Any  # a float, or an array of them for a run of steps
    dual: Any


@dataclass(frozen=True)
class Certificate:
    """The largest violations of one step, and the tolerances they are held to. With per-row
    dual tolerances (an array ``tolerance.dual``), ``dual`` is the negative multiplier largest
    relative to its own row's tolerance, ``dual_tolerance`` that tolerance."""

    primal: float  # max (B w - c)
    dual: float  # max (-lambda)
    complementarity: float  # max |(B w - c)_A|
    tolerance: Tolerance
    dual_tolerance: float | None = None

    @property
    def _dual_tol(self) -> float:
        return float(self.tolerance.dual) if self.dual_tolerance is None else self.dual_tolerance

    @property
    def ok(self) -> bool:
        t = self.tolerance
        return (self.primal <= t.primal and self.dual <= self._dual_tol
                and self.complementarity <= t.primal)

    def __str__(self) -> str:
        t = self.tolerance
        return (f"primal violation {self.primal:.3g} (tolerance {t.primal:.3g}), negative "
                f"multiplier {self.dual:.3g} (tolerance {self._dual_tol:.3g}), complementarity "
                f"{self.complementarity:.3g} (tolerance {t.primal:.3g})")


@dataclass(frozen=True, eq=False)
class Step:
    """A certified step: the point, all m multipliers, the active set and its certificate."""

    point: np.ndarray
    multipliers: np.ndarray
    active: ActiveSet
    certificate: Certificate


@dataclass(frozen=True, eq=False)
class Run:
    """A telescoped run on one active set: ``accepted`` leading steps are certified."""

    accepted: int
    w: np.ndarray  # (k, n) states after each step of the run (only the first `accepted` hold)
    multipliers: np.ndarray  # (k, m) multipliers of each step
    failed: Certificate | None  # the certificate of the first step not accepted, if any
    degenerate: bool  # the first step not accepted stopped on a tight row (LICQ to check)
    next_set: np.ndarray | None = None  # the primal-dual update suggested by the failed step


# ------------------------------------------------------------------------------------------------
# Tridiagonal LDL^T, vectorised over leading axes (chains, single and batched)

def ldl_tridiagonal(d: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LDL^T of symmetric tridiagonal matrices: diagonal ``d`` (..., N), off-diagonal ``e``
    (..., N-1). Returns (D, l): the pivots and the subdiagonal of the unit factor."""
    D = np.array(d, dtype=float, copy=True)
    e = np.asarray(e, dtype=float)
    l = np.empty_like(e)
    for i in range(1, D.shape[-1]):
        l[..., i - 1] = e[..., i - 1] / D[..., i - 1]
        D[..., i] -= l[..., i - 1] * e[..., i - 1]
    return D, l


def ldl_solve(D: np.ndarray, l: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve with an LDL^T factor for right-hand sides ``b`` (..., K, N) (K vectors per
    system; D and l broadcast as (..., 1, N))."""
    y = np.array(b, dtype=float, copy=True)
    N = y.shape[-1]
    lb = l[..., None, :]
    for i in range(1, N):
        y[..., i] -= lb[..., i - 1] * y[..., i - 1]
    y /= D[..., None, :]
    for i in range(N - 2, -1, -1):
        y[..., i] -= lb[..., i] * y[..., i + 1]
    return y


def _lapack():
    # Imported only for long chains: scipy.linalg costs start-up time the short runs don't need.
    from scipy.linalg.lapack import dpttrf, dpttrs

    return dpttrf, dpttrs


# ------------------------------------------------------------------------------------------------
# Active sets

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
    def __init__(self):
        self.index = np.zeros(0, dtype=int)
        self.inverse_norm = 0.0
        self.gram_norm = 0.0

    def solve(self, R):
        return np.zeros(np.shape(R))


class _ChainSet(ActiveSet):
    """G_A = S L_JJ S in block order (module docstring): L_JJ is tridiagonal, its free-block
    gaps splitting it into independent segments, factored once by LDL^T."""

    def __init__(self, poly: ChainPolyhedron, index: np.ndarray):
        N = poly.blocks
        self.index = index
        blocks = index % N
        order = np.argsort(blocks)
        self._order = order  # rows of A in block order
        self._signs = np.where(index < N, 1.0, -1.0)[order]
        J = blocks[order]
        d = poly.laplacian_diagonal[J]
        e = np.where(np.diff(J) == 1, -poly.stiffness[J[:-1]], 0.0)
        self._lapack = len(J) > SMALL_CHAIN
        if self._lapack:
            dpttrf, _ = _lapack()
            D, l, info = dpttrf(d, e)
            if info != 0:  # not positive definite: only when J is every block, refused earlier
                raise Dependent(index)
            self._D, self._l = D, l
        else:
            self._D, self._l = ldl_tridiagonal(d, e)
        # L_JJ is an M-matrix: its inverse is non-negative, so ||L_JJ^{-1}||_inf = max(L_JJ^{-1} 1)
        self.inverse_norm = float(np.max(self._solve_block(np.ones((1, len(J))))))
        self.gram_norm = float(np.max(2.0 * d))

    def _solve_block(self, rhs: np.ndarray) -> np.ndarray:
        """L_JJ^{-1} rhs for rhs (k, a) in block order (rows are right-hand sides)."""
        if not self._lapack:
            return ldl_solve(self._D, self._l, rhs)
        _, dpttrs = _lapack()
        x, info = dpttrs(self._D, self._l, rhs.T)
        return np.asarray(x).T

    def solve(self, R):
        R = np.asarray(R, dtype=float)
        flat = R.reshape(-1, self.size)
        y = self._solve_block(flat[:, self._order] * self._signs) * self._signs
        out = np.empty_like(flat)
        out[:, self._order] = y
        return out.reshape(R.shape)


class _DenseSet(ActiveSet):
    def __init__(self, poly: DensePolyhedron, index: np.ndarray):
        self.index = index
        if len(index) > poly.n:
            raise Dependent(index)
        G = poly.normals[index] @ poly.minv_bt[:, index]
        s = np.linalg.svd(G, compute_uv=False)
        if not s[-1] > GENERIC_RCOND * s[0]:
            raise Dependent(index)
        self._chol = np.linalg.cholesky(G)
        self.inverse_norm = float(math.sqrt(len(index)) / s[-1])
        self.gram_norm = float(np.max(np.sum(np.abs(G), axis=1)))

    def solve(self, R):
        from scipy.linalg import cho_solve

        R = np.asarray(R, dtype=float)
        flat = R.reshape(-1, self.size).T
        return cho_solve((self._chol, True), flat).T.reshape(R.shape)


# ------------------------------------------------------------------------------------------------
# Polyhedra

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

    def licq(self, index) -> bool:
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
    def factor(self, index) -> ActiveSet:
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

    # -- the one tolerance policy --------------------------------------------------------------
    def tolerance(self, active: ActiveSet, c_size, w_size, lam_size) -> Tolerance:
        """Certificate tolerances for a step (or arrays of steps) whose offsets, states and
        cumulative multipliers have these sup norms.

        Roundoff of B w - c is relative to the numbers summed: |c|, ||B|| |w| and, through
        w = w_trial - M^{-1} B^T lambda, ||B|| ||M^{-1} B^T|| |lambda|. The multipliers are
        G_A^{-1} times such a residual, so their roundoff is ||G_A^{-1}|| times it, plus the
        solve's own, ||G_A^{-1}|| ||G_A|| |lambda| eps.
        """
        size = np.maximum(np.maximum(np.maximum(self.c_scale, c_size),
                                     self.row_norm * np.asarray(w_size)),
                          self.row_norm * self.response_norm * np.asarray(lam_size))
        primal = RTOL * size
        dual = RTOL * active.inverse_norm * (size + active.gram_norm * np.asarray(lam_size))
        return Tolerance(primal, 2.0 * dual)

    # -- one step on an active set --------------------------------------------------------------
    def solve_on(self, active: ActiveSet, w_trial: np.ndarray, c: np.ndarray,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Tolerance]:
        """(w, lambda (m,), B w - c, tolerance) of the equality KKT system on ``active``."""
        Bw = self.apply(w_trial)
        lam = np.zeros(self.m)
        if active.size == 0:
            slack = Bw - c
            return np.array(w_trial, dtype=float), lam, slack, self._tolerance1(active, c, w_trial, lam)
        idx = active.index
        lam[idx] = active.solve(Bw[idx] - c[idx])
        w = w_trial - self.respond(lam)
        slack = self.apply(w) - c
        tol = self._tolerance1(active, c, w_trial, lam)
        if np.abs(slack[idx]).max() > REFINE_FRACTION * tol.primal:
            # one step of iterative refinement on the certified residual: B_A w - c_A
            delta = np.zeros(self.m)
            delta[idx] = active.solve(slack[idx])
            lam += delta
            w = w - self.respond(delta)
            slack = self.apply(w) - c
        return w, lam, slack, self.row_tolerance(active, w_trial, c, lam, tol)

    def row_tolerance(self, active: ActiveSet, w_trial: np.ndarray, c: np.ndarray,
                      lam: np.ndarray, tol: Tolerance) -> Tolerance:
        """``tol`` with each row's own dual tolerance where the structure gives one (chains:
        `ChainPolyhedron.row_tolerance`); generic processes keep the scalar bound."""
        return tol

    def _tolerance1(self, active, c, w, lam) -> Tolerance:
        """`tolerance` for one step, in Python floats."""
        # rows with an infinite offset are ignored (velocity problems of the exact integrator)
        c_size = float(np.max(np.abs(c), initial=0.0, where=np.isfinite(c)))
        lam_size = float(np.abs(lam).max(initial=0.0))
        size = max(self.c_scale, c_size, self.row_norm * float(np.abs(w).max(initial=0.0)),
                   self.row_norm * self.response_norm * lam_size)
        dual = RTOL * active.inverse_norm * (size + active.gram_norm * lam_size)
        return Tolerance(RTOL * size, 2.0 * dual)

    def certify(self, slack: np.ndarray, lam: np.ndarray, active: ActiveSet,
                tol: Tolerance, fixed: np.ndarray | None = None) -> Certificate:
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
        return Certificate(primal, value, comp, tol,
                           float(told[r]) if len(told) else 0.0)

    def tight_rows(self, slack: np.ndarray, active: ActiveSet, tol: Tolerance) -> np.ndarray:
        """Rows tight to roundoff at a certified point: the active ones and any inactive row
        whose slack is within the primal tolerance."""
        tight = slack >= -tol.primal
        tight[active.index] = True
        return np.flatnonzero(tight)

    # -- primal-dual active-set updates ------------------------------------------------------
    def refine(self, w_trial: np.ndarray, c: np.ndarray, start: ActiveSet | tuple | np.ndarray,
               *, iterations: int = UPDATE_ITERATIONS, single: bool = False,
               fixed: np.ndarray | None = None) -> Step | None:
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

    def exchange(self, active: ActiveSet, lam: np.ndarray, slack: np.ndarray,
                 fixed: np.ndarray | None = None) -> np.ndarray | None:
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
        ratio = np.where(leaving, np.maximum(lam[idx], 0.0) / np.where(leaving, -zA, 1.0),
                         np.inf)
        j = int(np.argmin(ratio))
        return np.sort(np.append(np.delete(idx, j), r))

    def dependency(self, index: np.ndarray) -> np.ndarray | None:
        """A nonzero z with B_index^T z = 0, in the order of ``index`` (None if independent)."""
        B = self.dense_normals()[index] if self.m * self.n <= 4_000_000 else None
        if B is None:
            return None
        _, s, vt = np.linalg.svd(B.T)
        if len(index) > len(s) or s[-1] <= GENERIC_RCOND * s[0]:
            return vt[-1]
        return None

    def update_set(self, active: ActiveSet, lam: np.ndarray, slack: np.ndarray, tol: Tolerance,
                   *, single: bool = False, fixed: np.ndarray | None = None) -> np.ndarray | None:
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
            return Run(acc, W, np.zeros((k, self.m)), failed, bool(acc < k and ok[acc]),
                       next_set)
        idx = active.index
        Bw = self.apply(w)
        R = Bw[idx][None, :] - C[:, idx]
        LAMC = np.zeros((k, self.m))
        LAMC[:, idx] = active.solve(R)
        W = w - self.respond(LAMC)
        slack = self.apply(W) - C
        tol = self.tolerance(active, np.abs(C).max(axis=1), np.abs(W).max(axis=1),
                             np.abs(LAMC).max(axis=1))
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

    def licq_verified(self, index) -> bool:
        """`licq`, remembering the sets that pass so that runs through them need not stop."""
        key = tuple(sorted(int(i) for i in index))
        if key in self._licq_ok:
            return True
        ok = self.licq(np.array(key, dtype=int))
        if ok and len(self._licq_ok) < 65536:
            self._licq_ok.add(key)
        return ok


class ChainPolyhedron(Polyhedron):
    """A crawler of N blocks with link stiffnesses k (module docstring): B = [D^T; -D^T],
    M = K^{-1}. Nothing of size N^2 is ever formed."""

    def __init__(self, stiffness, c_scale: float):
        super().__init__()
        k = np.asarray(stiffness, dtype=float)
        self.stiffness = k
        self.blocks = len(k) + 1
        self.n = len(k)
        self.m = 2 * self.blocks
        diag = np.zeros(self.blocks)
        diag[:-1] += k
        diag[1:] += k
        self.laplacian_diagonal = diag  # L_jj = k_{j-1} + k_j
        self.row_norm = 2.0
        self.response_norm = 2.0 * float(np.max(k))
        self.c_scale = c_scale if c_scale > 0 else 1.0

    def forces(self, W: np.ndarray) -> np.ndarray:
        """f = D^T w (..., N): f_j = w_{j-1} - w_j with w_{-1} = w_{N-1} = 0."""
        W = np.asarray(W, dtype=float)
        f = np.empty(W.shape[:-1] + (self.blocks,))
        f[..., 0] = -W[..., 0]
        f[..., 1:-1] = W[..., :-1] - W[..., 1:]
        f[..., -1] = W[..., -1]
        return f

    def apply(self, W):
        W = np.asarray(W, dtype=float)
        N = self.blocks
        out = np.empty(W.shape[:-1] + (2 * N,))
        f = out[..., :N]
        f[..., 0] = W[..., 0]
        f[..., 1:N - 1] = W[..., 1:]
        f[..., 1:N - 1] -= W[..., :-1]
        f[..., N - 1] = -W[..., -1]
        out[..., N:] = f  # rows N.. are -f; rows ..N are f = D^T w
        np.negative(f, out=f)
        return out

    def respond(self, LAM):
        LAM = np.asarray(LAM, dtype=float)
        N = self.blocks
        dx = LAM[..., :N] - LAM[..., N:]
        return (dx[..., 1:] - dx[..., :-1]) * self.stiffness

    def licq(self, index) -> bool:
        blocks = np.asarray(index, dtype=int) % self.blocks
        return len(np.unique(blocks)) == len(blocks) and len(blocks) < self.blocks

    def _factor(self, index):
        return _ChainSet(self, index)

    def dependency(self, index):
        """Every block saturated: B^T lambda = D (lambda^+ - lambda^-) vanishes for slips
        dx = 1, that is lambda = S 1 (the signs of the rows)."""
        index = np.asarray(index, dtype=int)
        if self.licq(index):
            return None
        blocks = index % self.blocks
        if len(np.unique(blocks)) < len(blocks):  # a block at both limits: opposite normals
            z = np.zeros(len(index))
            dup = blocks == blocks[-1]
            z[dup] = 1.0
            return z
        return np.where(index < self.blocks, 1.0, -1.0)

    def tight_stop(self, tight, any_inactive):
        """LICQ of a chain's tight rows fails only with every block tight (module docstring)."""
        N = self.blocks
        return np.asarray(any_inactive) & (tight[:, :N] | tight[:, N:]).all(axis=1)

    def degenerate_slips(self, step: Step, tight: np.ndarray, tol: Tolerance) -> bool:
        """Every block tight: the slips are unique only up to a rigid translation s 1, with s
        in the interval keeping every tight multiplier non-negative (lambda + s S 1 >= 0);
        they are determined exactly when that interval is a point (to roundoff)."""
        blocks = tight % self.blocks
        if len(np.unique(blocks)) < self.blocks:
            return False
        signs = np.where(tight < self.blocks, 1.0, -1.0)
        lam = step.multipliers[tight]
        upper = np.min(lam[signs < 0], initial=np.inf)  # s <= lam_j for s_j = -1
        lower = -np.min(lam[signs > 0], initial=np.inf)  # s >= -lam_j for s_j = +1
        return bool(upper - lower > float(np.max(tol.dual)))

    def row_tolerance(self, active, w_trial, c, lam, tol):
        """Each active row's own dual tolerance, the componentwise bound of
        `crawlsim.kernel.chain.row_duals` (same formula, numpy): with L_JJ^{-1} >= 0,

            |dx - dx*|_i <= 2 RTOL (L_JJ^{-1} s)_i,   s = |f| + |f*| + |w_{i-1}| + |w_i| + |L_JJ| |dx|,

        capped by the scalar bound; inactive rows keep the scalar one."""
        if not active.size:
            return tol
        N = self.blocks
        idx = active.index
        blocks = idx % N
        sign = np.where(idx < N, 1.0, -1.0)
        absdx = np.zeros(N + 2)
        absdx[blocks + 1] = np.abs(lam[idx])
        kpad = np.concatenate([[0.0], self.stiffness, [0.0]])
        wpad = np.abs(np.concatenate([[0.0], np.asarray(w_trial, dtype=float), [0.0]]))
        left, right = kpad[blocks], kpad[blocks + 1]
        s = (2.0 * (wpad[blocks] + wpad[blocks + 1]) + np.abs(c[idx])
             + (left + right) * absdx[blocks + 1] + left * absdx[blocks]
             + right * absdx[blocks + 2])
        y = sign * active.solve(sign * s)
        told = np.full(self.m, float(tol.dual))
        told[idx] = np.minimum(2.0 * RTOL * y, float(tol.dual))
        return Tolerance(tol.primal, told)

    def metric_times(self, w):
        return np.asarray(w, dtype=float) / self.stiffness

    def metric_solve(self, v):
        return np.asarray(v, dtype=float) * self.stiffness

    def metric_root(self, v):
        return np.asarray(v, dtype=float) / np.sqrt(self.stiffness)

    def metric_root_transpose(self, v):
        return np.asarray(v, dtype=float) / np.sqrt(self.stiffness)

    def dense_normals(self):
        N = self.blocks
        D = np.diff(np.eye(N), axis=0)
        return np.vstack([D.T, -D.T])

    def dense_metric(self):
        return np.diag(1.0 / self.stiffness)

    def sparse_normals(self):
        import scipy.sparse as sp

        N, n = self.blocks, self.n
        i = np.arange(n)
        # D^T: row j has +1 at column j-1 and -1 at column j
        rows = np.concatenate([i + 1, i])
        cols = np.concatenate([i, i])
        vals = np.concatenate([np.ones(n), -np.ones(n)])
        Dt = sp.csr_matrix((vals, (rows, cols)), shape=(N, n))
        return sp.vstack([Dt, -Dt]).tocsc()

    def clarabel_matrices(self):
        import scipy.sparse as sp

        return sp.diags(1.0 / self.stiffness, format="csc"), self.sparse_normals()


class DensePolyhedron(Polyhedron):
    """A generic polyhedral sweeping process: dense normals B (m, n) and metric M (n, n)."""

    def __init__(self, normals, metric, c_scale: float):
        super().__init__()
        self.normals = np.ascontiguousarray(normals, dtype=float)
        self.metric = np.ascontiguousarray(metric, dtype=float)
        self.m, self.n = self.normals.shape
        self.metric_inv = np.linalg.inv(self.metric)  # n x n, once: a constant of the problem
        self.minv_bt = self.metric_inv @ self.normals.T
        self.row_norm = float(np.max(np.sum(np.abs(self.normals), axis=1), initial=1.0))
        self.response_norm = float(np.max(np.sum(np.abs(self.minv_bt), axis=1), initial=1.0))
        self.c_scale = c_scale if c_scale > 0 else 1.0

    def apply(self, W):
        return np.asarray(W, dtype=float) @ self.normals.T

    def respond(self, LAM):
        return np.asarray(LAM, dtype=float) @ self.minv_bt.T

    def licq(self, index) -> bool:
        index = np.asarray(index, dtype=int)
        if len(index) == 0:
            return True
        if len(index) > self.n:
            return False
        G = self.normals[index] @ self.minv_bt[:, index]
        s = np.linalg.svd(G, compute_uv=False)
        return bool(s[-1] > GENERIC_RCOND * s[0])

    def _factor(self, index):
        return _DenseSet(self, index)

    def _numbers(self, size: int) -> int:
        return size * size + 8

    def metric_times(self, w):
        return np.asarray(w, dtype=float) @ self.metric.T

    def metric_solve(self, v):
        return np.asarray(v, dtype=float) @ self.metric_inv.T

    def metric_root(self, v):
        return np.asarray(v, dtype=float) @ self._root  # rows v -> (L^T v)^T = v^T L

    def metric_root_transpose(self, v):
        return np.asarray(v, dtype=float) @ self._root.T

    @property
    def _root(self) -> np.ndarray:
        """L with M = L L^T (Cholesky)."""
        cached = getattr(self, "_root_cache", None)
        if cached is None:
            cached = np.linalg.cholesky(self.metric)
            self._root_cache = cached
        return cached

    def dense_normals(self):
        return self.normals

    def dense_metric(self):
        return self.metric

    def clarabel_matrices(self):
        import scipy.sparse as sp

        return sp.csc_matrix(np.triu(self.metric)), sp.csc_matrix(self.normals)


# ------------------------------------------------------------------------------------------------
# Batched telescoped runs for crawlers of one block count (crawlsim.integrate.batch)

@dataclass(frozen=True, eq=False)
class ChainFactors:
    """Padded LDL^T factors of the active sets of a batch of crawlers (each row one gait):
    ``signs`` (b, N) +1 forward limit, -1 backward limit, 0 free."""

    signs: np.ndarray
    D: np.ndarray
    l: np.ndarray
    inverse_norm: np.ndarray  # (b,) ||G_A^{-1}||_inf
    gram_norm: np.ndarray  # (b,)


def chain_factors(stiffness: np.ndarray, signs: np.ndarray) -> ChainFactors:
    """Factor the padded systems L~ of gaits with stiffnesses (b, N-1) and active signs
    (b, N). No gait may have every block active (LICQ; the caller checks)."""
    k = np.asarray(stiffness, dtype=float)
    signs = np.asarray(signs, dtype=float)
    diag = np.zeros(signs.shape)
    diag[:, :-1] += k
    diag[:, 1:] += k
    active = signs != 0
    d = np.where(active, diag, 1.0)
    e = np.where(active[:, :-1] & active[:, 1:], -k, 0.0)
    D, l = ldl_tridiagonal(d, e)
    y = ldl_solve(D, l, active[:, None, :].astype(float))[:, 0, :]
    inverse_norm = np.max(np.where(active, y, 0.0), axis=1)
    gram_norm = np.max(np.where(active, 2.0 * diag, 0.0), axis=1)
    return ChainFactors(signs, D, l, inverse_norm, gram_norm)


@dataclass(frozen=True, eq=False)
class ChainRuns:
    """Telescoped runs of a batch of crawlers (`run_chains`): per gait b and step i."""

    w: np.ndarray  # (b, K, n)
    multipliers: np.ndarray  # (b, K, 2N), each step's
    slack: np.ndarray  # (b, K, 2N), B w - c
    primal_tolerance: np.ndarray  # (b, K)
    dual_tolerance: np.ndarray  # (b, K)
    ok: np.ndarray  # (b, K) the step's certificate holds
    stop: np.ndarray  # (b, K) every block tight to roundoff: LICQ fails, the full step decides


def chain_apply(W: np.ndarray) -> np.ndarray:
    """B w = [D^T w; -D^T w] for states (..., N-1) of crawlers."""
    padded = np.zeros(W.shape[:-1] + (W.shape[-1] + 2,))
    padded[..., 1:-1] = W
    f = padded[..., :-1] - padded[..., 1:]
    return np.concatenate([f, -f], axis=-1)


def chain_respond(stiffness: np.ndarray, LAM: np.ndarray) -> np.ndarray:
    """M^{-1} B^T lambda = K D (lambda^+ - lambda^-) for multipliers (b, ..., 2N) and
    stiffnesses (b, N-1)."""
    N = LAM.shape[-1] // 2
    dx = LAM[..., :N] - LAM[..., N:]
    k = stiffness.reshape(stiffness.shape[:1] + (1,) * (LAM.ndim - 2) + stiffness.shape[1:])
    return (dx[..., 1:] - dx[..., :-1]) * k


def run_chains(stiffness: np.ndarray, factors: ChainFactors, w: np.ndarray, C: np.ndarray,
               c_scale: np.ndarray) -> ChainRuns:
    """Telescoped runs of a batch: gait b steps from w[b] to the offsets C[b] (b, K, 2N) on its
    own fixed active set, certified with the tolerance policy of `Polyhedron.tolerance`
    (||B|| = 2, ||M^{-1} B^T|| = 2 max k for a chain)."""
    N = factors.signs.shape[1]
    s = factors.signs[:, None, :]
    active = s != 0
    F = chain_apply(w)[:, None, :N]
    target = np.where(s > 0, C[..., :N], -C[..., N:])  # the friction limit force f*
    rhs = np.where(active, F - target, 0.0)  # S r = f - f* on the saturated blocks
    dx = ldl_solve(factors.D, factors.l, rhs)  # cumulative slips (0 on free blocks)
    mask = np.concatenate([s > 0, s < 0], axis=-1)

    def state(dx):
        LAMC = np.concatenate([np.where(s > 0, dx, 0.0), np.where(s < 0, -dx, 0.0)], axis=-1)
        W = w[:, None, :] - chain_respond(stiffness, LAMC)
        return LAMC, W, chain_apply(W) - C

    LAMC, W, slack = state(dx)
    c_size = np.max(np.abs(C), axis=-1)
    lam_size = np.max(np.abs(LAMC), axis=-1)
    kmax = np.max(stiffness, axis=-1)[:, None]
    size = np.maximum(np.maximum(np.maximum(c_scale[:, None], c_size),
                                 2.0 * np.max(np.abs(W), axis=-1)), 4.0 * kmax * lam_size)
    tolp = RTOL * size
    told = 2.0 * RTOL * factors.inverse_norm[:, None] * (size + factors.gram_norm[:, None] * lam_size)
    comp = np.max(np.where(mask, np.abs(slack), 0.0), axis=-1)
    redo = comp > REFINE_FRACTION * tolp
    if redo.any():  # one step of iterative refinement on B_A w - c_A, where needed
        res = np.where(s > 0, slack[..., :N], np.where(s < 0, -slack[..., N:], 0.0))
        dx = dx + ldl_solve(factors.D, factors.l, res) * redo[..., None]
        LAMC, W, slack = state(dx)
        comp = np.max(np.where(mask, np.abs(slack), 0.0), axis=-1)
    LAM = np.diff(LAMC, axis=1, prepend=np.zeros_like(LAMC[:, :1]))
    primal = np.max(slack, axis=-1)
    dual = -np.min(np.where(mask, LAM, np.inf), axis=-1)
    dual = np.where(np.isfinite(dual), dual, 0.0)
    ok = (primal <= tolp) & (dual <= told) & (comp <= tolp)
    tight = (slack >= -tolp[..., None]) | mask
    stop = (tight[..., :N] | tight[..., N:]).all(axis=-1)
    return ChainRuns(W, LAM, slack, tolp, told, ok, stop)


def refine_chains(stiffness: np.ndarray, signs: np.ndarray, w: np.ndarray, c: np.ndarray,
                  c_scale: np.ndarray, iterations: int = UPDATE_ITERATIONS):
    """One step of each gait of a batch (w (b, n) to c (b, 2N)) by the primal-dual active-set
    updates of `Polyhedron.refine`, vectorised, from the active signs (b, N).

    Returns (w, multipliers, signs, certified): the rows of gaits that did not settle (or
    reached a set with every block saturated, or a tight set failing LICQ) are not certified and
    go to their own projector."""
    b, N = signs.shape
    w_out = np.array(w, dtype=float, copy=True)
    lam_out = np.zeros((b, 2 * N))
    signs = np.array(signs, dtype=float, copy=True)
    done = np.zeros(b, dtype=bool)
    todo = np.arange(b)
    for _ in range(iterations):
        full = (signs[todo] != 0).all(axis=1)
        todo = todo[~full]
        if not todo.size:
            break
        f = chain_factors(stiffness[todo], signs[todo])
        runs = run_chains(stiffness[todo], f, w[todo], c[todo][:, None, :], c_scale[todo])
        ok = runs.ok[:, 0] & ~runs.stop[:, 0]
        good = todo[ok]
        w_out[good], lam_out[good], done[good] = runs.w[ok, 0], runs.multipliers[ok, 0], True
        bad = ~runs.ok[:, 0]  # certified with every block tight: the projector decides LICQ
        if not bad.any():
            break
        lam, slack = runs.multipliers[bad, 0], runs.slack[bad, 0]
        tolp, told = runs.primal_tolerance[bad, 0][:, None], runs.dual_tolerance[bad, 0][:, None]
        new = signs[todo[bad]]
        drop = ((lam[:, :N] < -told) & (new > 0)) | ((lam[:, N:] < -told) & (new < 0))
        new[drop] = 0.0
        kept = new.copy()
        new[slack[:, :N] > tolp] = 1.0
        new[slack[:, N:] > tolp] = -1.0
        # adding every violated row may saturate every block (LICQ fails): add the worst only
        full = (new != 0).all(axis=1)
        if full.any():
            worst = np.argmax(slack[full], axis=1)
            rows_full = np.flatnonzero(full)
            new[full] = kept[full]
            new[rows_full, worst % N] = np.where(worst < N, 1.0, -1.0)
        unchanged = (new == signs[todo[bad]]).all(axis=1)
        signs[todo[bad]] = new
        todo = todo[bad][~unchanged]
    return w_out, lam_out, signs, done


def _mask(index, m) -> np.ndarray:
    out = np.zeros(m, dtype=bool)
    out[index] = True
    return out


def _prefix(ok: np.ndarray) -> int:
    """Length of the leading run of True."""
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if bad.size else len(ok)
