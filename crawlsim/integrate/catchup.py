"""The driver of the compiled catch-up step (`crawlsim.kernel.chain`): it owns the kernel's
arrays between periods, calls it, and turns what it reports into crawlsim's terms: the active
sets as `crawlsim.projection.polyhedron.ActiveSet` (for the periodic-limit solver), a failed certificate as a
`CertificateError` naming the time and the rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import overload

import numpy as np

from crawlsim.kernel import chain
from crawlsim.kernel.jit import kernel
from crawlsim.projection.certificate import Dependent
from crawlsim.projection.chain_polyhedron import ChainPolyhedron
from crawlsim.projection.polyhedron import ActiveSet, Polyhedron


def signs_of(active: ActiveSet, blocks: int) -> np.ndarray:
    """The kernel's form of an active set of a chain: +1 forward limit, -1 backward, 0 free."""
    signs = np.zeros(blocks, dtype=np.int8)
    idx = active.index
    signs[idx[idx < blocks]] = 1
    signs[idx[idx >= blocks] - blocks] = -1
    return signs


def rows_of(signs: np.ndarray) -> np.ndarray:
    """The sorted row indices of the set ``signs``."""
    N = len(signs)
    return np.concatenate([np.flatnonzero(signs > 0), N + np.flatnonzero(signs < 0)])


class ChainKernel:
    """The compiled catch-up stepping of one crawler: the current active set and its factor
    carry over from step to step and period to period."""

    def __init__(self, polyhedron: Polyhedron):
        if not isinstance(polyhedron, ChainPolyhedron):
            raise TypeError("the compiled kernel steps crawler chains only")
        self.polyhedron = polyhedron
        N = polyhedron.blocks
        self.k = np.ascontiguousarray(polyhedron.stiffness, dtype=float)
        self.c_scale = float(polyhedron.c_scale)
        self.signs = np.zeros(N, dtype=np.int8)
        self.factored = np.full(N, 2, dtype=np.int8)  # no set: the first call factors
        self.D = np.empty(N)
        self.l = np.empty(max(N - 1, 0))
        self.norms = np.zeros(2)
        self.report = np.zeros(6)
        # the set `active` last returned and the signs it was made from: a period that starts
        # from the set the previous one ended on converts nothing (a few us a period, which at
        # N = 4 is several percent of the period's steps)
        self._active: ActiveSet | None = None
        self._key = b""

    def load(self, active: ActiveSet) -> None:
        if active is self._active and self.signs.tobytes() == self._key:
            return
        self.signs[:] = signs_of(active, len(self.signs))

    def active(self, fallback: ActiveSet) -> ActiveSet:
        """The current set, factored by `crawlsim.projection.kkt` (cached there), or ``fallback``."""
        key = self.signs.tobytes()
        if self._active is not None and key == self._key:
            return self._active
        try:
            A = self.polyhedron.factor(rows_of(self.signs))
        except Dependent:
            return fallback
        self._active, self._key = A, key
        return A

    def run(self, C: np.ndarray, W: np.ndarray, LAM: np.ndarray, S: np.ndarray, j0: int) -> tuple[int, int]:
        """Steps j0, j0+1, ... until the period ends or a step needs the projector
        (`chain.catch_up`)."""
        status, j = kernel().chain.catch_up(
            self.k, self.c_scale, C, W, LAM, S, self.signs, self.factored, self.D, self.l, self.norms, j0, self.report
        )
        return int(status), int(j)

    def failure(self, name: str, when: float, describe: Callable[[np.ndarray], str]) -> str:
        """The message of a step whose certificate failed with no update left (FAILED)."""
        r = self.report
        row = int(r[chain.REPORT_ROW])
        return (
            f"{name}: the catch-up step failed its certificate at t = {when:.12g}: primal "
            f"violation {r[chain.REPORT_PRIMAL]:.3g}, negative multiplier "
            f"{r[chain.REPORT_DUAL]:.3g}, complementarity {r[chain.REPORT_COMP]:.3g} "
            f"(tolerances {r[chain.REPORT_TOLP]:.3g} / {r[chain.REPORT_TOLD]:.3g}); worst "
            f"row {row} ({describe(np.array([row]))}), active set "
            f"{describe(rows_of(self.signs))}"
        )


class VisitedSets(Sequence[ActiveSet]):
    """The non-empty active sets of a period's steps, in order, consecutive repeats left out
    (`crawlsim.integrate.stepping.PeriodRecord.visited`), factored by `crawlsim.projection.kkt` only when the
    periodic-limit solver asks for them: most periods never need them."""

    def __init__(self, polyhedron: Polyhedron, S: np.ndarray):
        self._polyhedron = polyhedron
        self._sets = S[kernel().chain.set_starts(S)] if len(S) else S
        self._factored: list[ActiveSet] | None = None

    def _list(self) -> list[ActiveSet]:
        if self._factored is None:
            out: list[ActiveSet] = []
            for signs in self._sets:
                if not signs.any():
                    continue
                try:
                    A = self._polyhedron.factor(rows_of(signs))
                except Dependent:  # pragma: no cover - the kernel's sets are independent
                    continue
                if not out or out[-1] is not A:
                    out.append(A)
            self._factored = out
        return self._factored

    def __len__(self) -> int:
        return len(self._list())

    @overload
    def __getitem__(self, i: int) -> ActiveSet: ...

    @overload
    def __getitem__(self, i: slice) -> list[ActiveSet]: ...

    def __getitem__(self, i: int | slice) -> ActiveSet | list[ActiveSet]:
        return self._list()[i]


def velocity(
    polyhedron: Polyhedron, c: np.ndarray, warm: np.ndarray, fixed: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray] | None:
    """The exact integrator's velocity problem argmin 1/2 |v|_M^2 over {B_fixed v = c_fixed,
    B_i v <= c_i (finite c_i)} of a crawler, certified in the compiled kernel from the rows
    ``warm`` (`chain.project_rows`): (v, lambda, tol_p, tol_d), tol_d each row's own dual
    tolerance (m,), the threshold above which its multiplier is positive beyond roundoff; or
    None when the kernel does not settle it (the caller's Python path decides, as before)."""
    if not isinstance(polyhedron, ChainPolyhedron):
        return None
    N = polyhedron.blocks
    rows = np.zeros(2 * N, dtype=np.bool_)
    rows[warm] = True
    rows[fixed] = True
    world = kernel()
    if not world.chain.independent(rows, N):
        return None
    signs = np.zeros(N, dtype=np.int8)
    signs[rows[:N]] = 1
    signs[rows[N:]] = -1
    mask = np.zeros(2 * N, dtype=np.bool_)
    mask[fixed] = True
    w = np.empty(N - 1)
    lam = np.empty(2 * N)
    report = np.zeros(6)
    told = np.empty(2 * N)
    status = world.chain.project_rows(
        np.ascontiguousarray(polyhedron.stiffness, dtype=float),
        float(polyhedron.c_scale),
        np.zeros(N - 1),
        np.ascontiguousarray(c, dtype=float),
        signs,
        mask,
        w,
        lam,
        report,
        told,
    )
    if status != chain.DONE:
        return None
    return w, lam, float(report[chain.REPORT_TOLP]), told
