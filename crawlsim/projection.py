"""Exact, certified projection onto a polyhedron: the one module that talks to Clarabel.

Catch-up stepping (MODEL.md §3) needs, at every step,

    z* = argmin { 1/2 |z - z_trial|_M^2 : B z <= c }.

An interior-point solution stops at a tolerance, and over thousands of steps its small dual errors
add up to visible errors in v0. So Clarabel is used only to *identify* the active set A; the step
itself solves the equality KKT system on A,

    lambda_A = G_A^{-1} (B_A z_trial - c_A),   G_A = B_A M^{-1} B_A^T,
    z*       = z_trial - M^{-1} B_A^T lambda_A,

and is then certified: primal feasibility ``B z* <= c``, dual sign ``lambda_A >= 0``, and
complementarity ``B_A z* = c_A``, all to roundoff. A certificate that fails is a
`CertificateError`, never a silently accepted step.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import clarabel
import numpy as np
import scipy.sparse as sp

from .errors import CertificateError, LicqWarning

#: Relative tolerance of every certificate: a few thousand ulps of the problem's scale.
CERTIFICATE_RTOL = 1e-14


@dataclass(frozen=True)
class ActiveSet:
    """Cached linear algebra of one active set A (rows of B with equality)."""

    index: np.ndarray  # (a,) sorted row indices of B
    normals: np.ndarray  # B_A (a, n)
    gram_inv: np.ndarray  # G_A^{-1} (a, a)
    response: np.ndarray  # R_A = M^{-1} B_A^T G_A^{-1} (n, a): z* = z_trial - R_A (B_A z_trial - c_A)

    @property
    def size(self) -> int:
        return len(self.index)


@dataclass(frozen=True)
class Projection:
    """A certified projection: the point, the multipliers of all m constraints, the active set."""

    point: np.ndarray
    multipliers: np.ndarray
    active: ActiveSet
    used_clarabel: bool


@dataclass(frozen=True)
class Tolerances:
    """Absolute certificate tolerances derived from the problem's scale."""

    primal: float  # on B z - c (units of c)
    dual: float  # on lambda (units of lambda)

    @classmethod
    def for_scale(cls, c_scale: float, gram_scale: float, rtol: float = CERTIFICATE_RTOL):
        c_scale = c_scale if c_scale > 0 else 1.0
        return cls(primal=rtol * c_scale, dual=rtol * c_scale / gram_scale)


def _label(index) -> str:
    return "{" + ", ".join(str(int(i)) for i in index) + "}"


class ExactProjector:
    """Certified projections onto ``{z : B z <= c}`` in the metric M, for changing c and z_trial.

    One persistent Clarabel solver is kept; between calls only its data ``q = -M z_trial`` and
    ``b = c`` change (``presolve_enable = False`` keeps the problem's structure fixed, which
    ``solver.update`` requires).

    ``describe_active`` turns a set of row indices into words for error messages (for crawlers:
    which blocks slip in which direction).
    """

    def __init__(self, normals, metric, c_scale: float, *, rtol: float = CERTIFICATE_RTOL,
                 describe_active=None, persistent: bool = True, on_dependent: str = "raise"):
        self.B = np.ascontiguousarray(normals, dtype=float)
        self.M = np.ascontiguousarray(metric, dtype=float)
        self.m, self.n = self.B.shape
        self.M_inv = np.linalg.inv(self.M)
        self._MinvBT = self.M_inv @ self.B.T
        gram_diag = np.einsum("ij,ji->i", self.B, self._MinvBT)
        self._gram_scale = float(np.max(gram_diag)) if self.m else 1.0
        self._row_norm = float(np.max(np.sum(np.abs(self.B), axis=1))) if self.m else 1.0
        self._c_scale = c_scale if c_scale > 0 else 1.0
        self.tol = Tolerances.for_scale(self._c_scale, self._gram_scale, rtol)
        self.rtol = rtol
        self._describe = describe_active or (lambda idx: f"active constraints {_label(idx)}")
        self._cache: dict[tuple, ActiveSet] = {}
        self._solver = None
        self._persistent = persistent  # False rebuilds the solver every call (benchmark baseline)
        self.clarabel_calls = 0
        # "raise": LICQ failure is an error (crawlers: the slips are the multipliers, MODEL.md §3).
        # "warn": a generic process keeps its unique point, certified on an independent subset of
        # the active rows; each dependent set is warned about once (LicqWarning) and recorded in
        # `licq_failures` as {row indices: (first time, occurrences)}.
        if on_dependent not in ("raise", "warn"):
            raise ValueError(f"on_dependent must be 'raise' or 'warn', got {on_dependent!r}")
        self.on_dependent = on_dependent
        self.licq_failures: dict[tuple, tuple] = {}
        self.empty = self.active_set(())

    # -- Clarabel, the authority on the active set ------------------------------------------
    def _clarabel(self, z_trial, c):
        q = -(self.M @ z_trial)
        if self._solver is None or not self._persistent:
            settings = clarabel.DefaultSettings()
            settings.verbose = False
            settings.presolve_enable = False
            # Tight tolerances make the identification of the active set unambiguous; the step
            # itself never uses Clarabel's numbers.
            settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
            settings.tol_feas = 1e-10
            P = sp.csc_matrix(np.triu(self.M))
            A = sp.csc_matrix(self.B)
            self._solver = clarabel.DefaultSolver(
                P, q, A, np.asarray(c, float), [clarabel.NonnegativeConeT(self.m)], settings)
        else:
            self._solver.update(q=q, b=np.asarray(c, float))
        solution = self._solver.solve()
        self.clarabel_calls += 1
        status = str(solution.status)
        if status not in ("Solved", "AlmostSolved"):
            raise CertificateError(
                f"Clarabel could not solve the projection (status {status}); the set may be "
                "empty at this time")
        return np.asarray(solution.x), np.asarray(solution.z), np.asarray(solution.s)

    # -- equality KKT on an active set --------------------------------------------------------
    def active_set(self, index) -> ActiveSet:
        key = tuple(sorted(int(i) for i in index))
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        idx = np.array(key, dtype=int)
        B_A = self.B[idx]
        if len(idx) == 0:
            entry = ActiveSet(idx, B_A, np.zeros((0, 0)), np.zeros((self.n, 0)))
        else:
            G = B_A @ self._MinvBT[:, idx]
            # LICQ: the active normals must be independent, else the multipliers (the slips)
            # are not unique (MODEL.md §3). rank-revealing test on the Gram matrix.
            s = np.linalg.svd(G, compute_uv=False)
            if len(idx) > self.n or s[-1] <= 1e-10 * s[0]:
                raise _Dependent(idx)
            G_inv = np.linalg.inv(G)
            entry = ActiveSet(idx, B_A, G_inv, self._MinvBT[:, idx] @ G_inv)
        self._cache[key] = entry
        return entry

    def solve_on(self, active: ActiveSet, z_trial, c):
        """Point and full multiplier vector of the equality KKT system on ``active``."""
        lam = np.zeros(self.m)
        if active.size == 0:
            return np.array(z_trial, dtype=float), lam
        lam_A = active.gram_inv @ (active.normals @ z_trial - c[active.index])
        lam[active.index] = lam_A
        return z_trial - self._MinvBT[:, active.index] @ lam_A, lam

    def certificate(self, z, lam, c, active: ActiveSet):
        """Largest violations: (primal, dual sign, complementarity)."""
        slack = self.B @ z - c
        primal = float(np.max(slack)) if self.m else 0.0
        dual = float(-np.min(lam)) if self.m else 0.0
        comp = float(np.max(np.abs(slack[active.index]))) if active.size else 0.0
        return primal, dual, comp

    def is_certified(self, z, lam, c, active, tol: Tolerances | None = None) -> bool:
        tol = tol or self.tol
        primal, dual, comp = self.certificate(z, lam, c, active)
        return primal <= tol.primal and dual <= tol.dual and comp <= tol.primal

    def tolerances_for(self, z_trial, c) -> Tolerances:
        """Certificate tolerances for one call: roundoff of ``B z - c`` is relative to the
        larger of |c| and |B| |z|, so a far-away trial point widens them proportionally."""
        size = max(self._c_scale, float(np.max(np.abs(c), initial=0.0)),
                   self._row_norm * float(np.max(np.abs(z_trial), initial=0.0)))
        return Tolerances.for_scale(size, self._gram_scale, self.rtol)

    # -- the full projection ------------------------------------------------------------------
    def project(self, z_trial, c, *, time: float | None = None) -> Projection:
        """Certified projection of ``z_trial`` onto ``{B z <= c}``; Clarabel picks the active set.

        Clarabel's solution (accurate to ~1e-10) proposes the active set: the rows whose
        multiplier dominates their slack (both in their natural scales), the usual
        interior-point identification. A short primal-dual refinement then fixes rows at the
        roundoff boundary (add the most violated row, drop the most negative multiplier, drop
        the weakest row of a dependent set), every candidate being solved exactly and
        certified. Finally a row left out but tight to roundoff whose normal depends on the
        active ones means the multipliers are not unique (LICQ fails): that is an error.
        ``time`` only labels messages.
        """
        z_trial = np.asarray(z_trial, dtype=float)
        c = np.asarray(c, dtype=float)
        _, lam_ip, slack_ip = self._clarabel(z_trial, c)
        tol = self.tolerances_for(z_trial, c)
        lam_ref, slack_ref = tol.dual / self.rtol, tol.primal / self.rtol
        candidate = set(np.flatnonzero(
            lam_ip / lam_ref > np.maximum(slack_ip, 0.0) / slack_ref).tolist())
        tried = set()
        active = z = lam = None
        for _ in range(4 * self.m + 4):
            key = tuple(sorted(candidate))
            if key in tried:
                break
            tried.add(key)
            try:
                active = self.active_set(key)
            except _Dependent:
                candidate.discard(min(candidate, key=lambda i: lam_ip[i]))
                continue
            z, lam = self.solve_on(active, z_trial, c)
            slack = self.B @ z - c
            worst_primal = int(np.argmax(slack))
            worst_dual = int(np.argmin(lam))
            if lam[worst_dual] < -tol.dual:
                candidate.discard(worst_dual)
            elif slack[worst_primal] > tol.primal:
                candidate.add(worst_primal)
            elif self.is_certified(z, lam, c, active, tol):
                self._check_licq(active, slack, tol, time)
                return Projection(z, lam, active, True)
            else:  # pragma: no cover - complementarity fails only with dependent normals
                break
        if active is None:
            raise CertificateError(f"no independent active set found{self._at(time)} among "
                                   f"{self._describe(sorted(tried)[-1])}")
        primal, dual, comp = self.certificate(z, lam, c, active)
        raise CertificateError(
            f"exact projection failed its certificate{self._at(time)}: primal violation "
            f"{primal:.3g} (tolerance {tol.primal:.3g}), negative multiplier {dual:.3g} "
            f"(tolerance {tol.dual:.3g}), complementarity {comp:.3g}; "
            f"last active set: {self._describe(active.index)}")

    def _check_licq(self, active, slack, tol, time):
        """Refuse a point where a tight row left out of A depends on A's normals."""
        for i in np.flatnonzero(np.abs(slack) <= tol.primal):
            if i in active.index:
                continue
            try:
                self.active_set(tuple(active.index) + (int(i),))
            except _Dependent as dep:
                if self.on_dependent == "raise":
                    raise CertificateError(self._licq_message(dep.index, time)) from None
                self._record_licq(dep.index, time)

    def _record_licq(self, index, time):
        key = tuple(int(i) for i in index)
        first, count = self.licq_failures.get(key, (time, 0))
        self.licq_failures[key] = (first, count + 1)
        if count == 0:
            warnings.warn(
                f"LICQ fails{self._at(time)}: the normals of the tight constraints "
                f"{_label(key)} are linearly dependent, so their multipliers (the reactions) are "
                "not unique there. The projected point is unique and was certified on an "
                "independent subset; the paper's theorem does not need LICQ. Later occurrences "
                "of this set are counted in `licq_failures`, not repeated.",
                LicqWarning, stacklevel=2)

    def _at(self, time):
        return "" if time is None else f" at t = {time:.12g}"

    def _licq_message(self, index, time):
        return (f"the active normals are linearly dependent{self._at(time)} "
                f"({self._describe(index)}): LICQ fails there, so the multipliers (the slips) are "
                "not unique and the model does not determine the motion (the uniqueness "
                "condition of the crawler model fails at this instant). Change the step count so that no "
                "grid time falls on this instant, or change the friction coefficients.")


class _Dependent(Exception):
    def __init__(self, index):
        super().__init__(index)
        self.index = index
