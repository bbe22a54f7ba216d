"""Exact, certified projections: the one module that talks to Clarabel.

Catch-up stepping (docs/model.md §3) needs, at every step,

    w* = argmin { 1/2 |w - w_trial|_M^2 : B w <= c }.

The numbers of every step come from the certified KKT kernel (`crawlsim.projection.kkt`): an active set A is
factored, the equality system on A solved, and the result certified (primal feasibility, the
sign of the multipliers, complementarity, to roundoff). This module decides *which* active set:

1. the cheap, certified updates of the kernel from the previous step's set (add the violated
   rows, drop the negative multipliers), which settle most changes of contact;
2. when they do not settle, Clarabel, the authority: an interior-point solution (accurate to
   about 1e-10) proposes the rows whose multiplier dominates their slack, and the kernel's
   updates then make that proposal exact and certified.

Clarabel's own numbers never enter a step. A projection that cannot be certified is a
`CertificateError` naming the time and the constraints involved (on a valid gait, a bug).

After a certified step, the rows tight to roundoff are checked for LICQ (`kkt.Polyhedron.licq`).
For a crawler, a failure with slips that are truly not unique is the instant where the
uniqueness condition fails: `DegenerateModelError`, exit code 2, naming the time and the
blocks. For a generic process the projected point is still unique (only the reactions are not):
a `LicqWarning`, once per set of rows, and the step goes on.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, SupportsInt

import numpy as np
import numpy.typing as npt

from crawlsim.errors import CertificateError, DegenerateModelError, LicqWarning
from crawlsim.projection.certificate import Dependent, Step
from crawlsim.projection.dense_polyhedron import DensePolyhedron
from crawlsim.projection.polyhedron import ActiveSet, Polyhedron


@dataclass(frozen=True, eq=False)
class Projection:
    """A certified projection: the point, the multipliers of all m constraints, the active set."""

    point: np.ndarray
    multipliers: np.ndarray
    active: ActiveSet
    used_clarabel: bool


def _label(index: Iterable[SupportsInt]) -> str:
    return "{" + ", ".join(str(int(i)) for i in index) + "}"


class ExactProjector:
    """Certified projections onto ``{w : B w <= c}`` in the metric M, for changing c and w_trial.

    One persistent Clarabel solver is kept; between calls only its data ``q = -M w_trial`` and
    ``b = c`` change (``presolve_enable = False`` keeps the structure fixed, which
    ``solver.update`` requires). Rows with an infinite offset are ignored (the velocity problems
    of the exact integrator use that to restrict a projection to the rows tight at an event).

    ``describe_active`` turns row indices into words for messages (for crawlers: which blocks
    are at which friction limit). ``on_dependent`` is "raise" (crawlers: non-unique slips are a
    `DegenerateModelError`) or "warn" (generic processes: `LicqWarning`, recorded in
    ``licq_failures`` as {row indices: (first time, occurrences)}).
    """

    def __init__(
        self,
        polyhedron: Polyhedron,
        *,
        describe_active: Callable[[np.ndarray], str] | None = None,
        persistent: bool = True,
        on_dependent: str = "raise",
    ) -> None:
        if on_dependent not in ("raise", "warn"):
            raise ValueError(f"on_dependent must be 'raise' or 'warn', got {on_dependent!r}")
        self.polyhedron = polyhedron
        self.m, self.n = polyhedron.m, polyhedron.n
        self.on_dependent = on_dependent
        self._describe = describe_active or (lambda idx: f"active constraints {_label(idx)}")
        self._solver: Any = None  # a clarabel.DefaultSolver (untyped)
        self._persistent = persistent  # False rebuilds the solver every call (benchmark baseline)
        self.clarabel_calls = 0
        self.clarabel_status: Any = None  # the last call's clarabel.SolverStatus (its proposal is certified)
        self.licq_failures: dict[tuple[int, ...], tuple[float | None, int]] = {}

    @classmethod
    def dense(
        cls, normals: npt.ArrayLike, metric: npt.ArrayLike, c_scale: float = 1.0, **options: Any
    ) -> ExactProjector:
        """A projector for dense normals B and metric M (a generic polyhedron)."""
        return cls(DensePolyhedron(normals, metric, c_scale), **options)

    @property
    def empty(self) -> ActiveSet:
        return self.polyhedron.empty

    # -- Clarabel, the authority on the active set ------------------------------------------
    def _clarabel(self, w_trial: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clarabel's (z, s) for the projection with every finite row an inequality."""
        poly = self.polyhedron
        finite = np.isfinite(c)
        b = np.where(finite, c, 0.0)
        if not finite.all():
            # ignored rows get an offset no point near the data can reach
            reach = poly.row_norm * float(np.max(np.abs(w_trial), initial=0.0))
            b[~finite] = 1e6 * (reach + float(np.max(np.abs(b), initial=0.0)) + poly.c_scale)
        q = -poly.metric_times(w_trial)
        fresh = self._solver is None or not self._persistent
        if fresh:
            self._solver = self._setup(q, b)
        else:
            self._solver.update(q=q, b=b)
        solution = self._solver.solve()
        if not fresh and _refused(solution):
            # an updated solver keeps the scaling it equilibrated for its first data, which can
            # stall it on data far from those (a projection's set is not empty, and M > 0 bounds
            # the objective): solved again, set up on this data
            self._solver = self._setup(q, b)
            solution = self._solver.solve()
        lam, slack = self._proposal(solution, "the projection")
        lam[~finite] = 0.0
        return lam, slack

    def _setup(self, q: np.ndarray, b: np.ndarray) -> Any:
        """A Clarabel solver of the projection with every row an inequality."""
        import clarabel

        P, A = self.polyhedron.clarabel_matrices()
        return _solver(P, q, A, b, [clarabel.NonnegativeConeT(self.m)])

    def _proposal(self, solution: Any, problem: str) -> tuple[np.ndarray, np.ndarray]:
        """The one status rule on Clarabel's answers (`clarabel.SolverStatus`). Clarabel only
        proposes the active set, which the kernel then certifies: any finite iterate is a
        proposal worth trying, an iterate stopped early (MaxIterations on a badly scaled set)
        included; a problem Clarabel finds (almost) infeasible, or a non-finite iterate, is a
        `CertificateError`."""
        self.clarabel_calls += 1
        self.clarabel_status = solution.status
        lam, slack = np.asarray(solution.z, dtype=float), np.asarray(solution.s, dtype=float)
        if _refused(solution):
            raise CertificateError(
                f"Clarabel could not solve {problem} (status {solution.status}); the set may be empty at this time"
            )
        return lam, slack

    # -- the projection ----------------------------------------------------------------------
    def project(
        self,
        w_trial: npt.ArrayLike,
        c: npt.ArrayLike,
        *,
        time: float | None = None,
        warm: ActiveSet | np.ndarray | None = None,
        verify: bool = False,
        fixed: np.ndarray | None = None,
    ) -> Projection:
        """Certified projection of ``w_trial`` onto ``{B w <= c}`` (module docstring): an
        elastic step if the trial point is admissible, else the kernel's updates from ``warm``,
        else Clarabel's proposal. ``verify=True`` always asks Clarabel (no shortcut). Rows
        ``fixed`` are equality constraints (the exact integrator's higher-order velocity
        problems). ``time`` labels messages."""
        poly = self.polyhedron
        w_trial = np.asarray(w_trial, dtype=float)
        c = np.asarray(c, dtype=float)
        fixed = np.zeros(0, dtype=int) if fixed is None else np.asarray(fixed, dtype=int)
        if not verify and warm is None and not fixed.size:
            # an elastic step (the trial point is admissible) needs no active set at all
            elastic = poly.refine(w_trial, c, poly.empty, iterations=1)
            if elastic is not None:
                return self._finish(elastic, c, False, time)
        if warm is not None and not verify:
            step = poly.refine(w_trial, c, warm, fixed=fixed)
            if step is not None:
                return self._finish(step, c, False, time)
        if fixed.size:
            lam_ip, slack_ip = self._clarabel_mixed(w_trial, c, fixed)
        else:
            lam_ip, slack_ip = self._clarabel(w_trial, c)
        # interior-point identification: a row is proposed active when its multiplier dominates
        # its slack, each in its natural scale
        finite = np.isfinite(c)
        c_size = max(
            poly.c_scale,
            float(np.max(np.abs(c[finite]), initial=0.0)),
            poly.row_norm * float(np.max(np.abs(w_trial), initial=0.0)),
        )
        lam_ref = c_size / max(poly.row_norm * poly.response_norm, 1e-300)
        proposed = np.flatnonzero(finite & (lam_ip / lam_ref > np.maximum(slack_ip, 0.0) / c_size))
        proposed = self._independent(np.union1d(proposed, fixed), lam_ip, fixed)
        step = poly.refine(w_trial, c, proposed, fixed=fixed)
        if step is None:
            step = poly.refine(w_trial, c, proposed, single=True, iterations=4 * self.m + 4, fixed=fixed)
        if step is None:
            last = self._last_attempt(w_trial, c, proposed)
            raise CertificateError(
                f"exact projection failed its certificate{_at(time)}: {last}; active set "
                f"proposed by Clarabel (status {self.clarabel_status}): "
                f"{self._describe(proposed)}"
            )
        return self._finish(step, c, True, time)

    def _independent(self, proposed: np.ndarray, lam_ip: np.ndarray, fixed: np.ndarray) -> np.ndarray:
        """Clarabel's proposal reduced to independent rows: while LICQ fails, drop the row
        with the smallest interior-point multiplier (a dependent set has a representation
        with non-negative multipliers on an independent subset, Caratheodory); equality rows
        ``fixed`` stay."""
        rows = list(proposed)
        while rows and not self.polyhedron.licq(np.array(rows)):
            free = [i for i in rows if i not in set(fixed.tolist())]
            if not free:
                break
            rows.remove(min(free, key=lambda i: lam_ip[i]))
        return np.array(sorted(rows), dtype=int)

    def _clarabel_mixed(self, w_trial: np.ndarray, c: np.ndarray, fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clarabel on the finite rows with the rows ``fixed`` as equalities (a one-off solver:
        the cone structure changes with ``fixed``)."""
        import clarabel
        import scipy.sparse as sp

        poly = self.polyhedron
        finite = np.isfinite(c)
        finite[fixed] = True
        others = np.flatnonzero(finite & ~np.isin(np.arange(self.m), fixed))
        order = np.concatenate([fixed, others])
        P, A = poly.clarabel_matrices()
        A = sp.csr_matrix(A)[order].tocsc()
        cones = [clarabel.ZeroConeT(len(fixed)), clarabel.NonnegativeConeT(len(others))]
        solver = _solver(P, -poly.metric_times(w_trial), A, c[order], cones)
        z, s = self._proposal(solver.solve(), "a velocity problem")
        lam = np.zeros(self.m)
        slack = np.full(self.m, np.inf)
        lam[order] = z
        slack[order] = s
        lam[fixed] = np.abs(lam[fixed]) + 1.0  # equalities: always proposed
        return lam, slack

    def _last_attempt(self, w_trial: np.ndarray, c: np.ndarray, proposed: np.ndarray) -> str:
        try:
            active = self.polyhedron.factor(proposed)
        except Dependent:
            return f"the proposed rows {_label(proposed)} are linearly dependent"
        _, lam, slack, tol = self.polyhedron.solve_on(active, w_trial, c)
        return str(self.polyhedron.certify(slack, lam, active, tol))

    def _finish(self, step: Step, c: np.ndarray, used_clarabel: bool, time: float | None) -> Projection:
        """LICQ of the rows tight at the certified point (module docstring)."""
        poly = self.polyhedron
        active = step.active
        slack = poly.apply(step.point) - c
        tol = step.certificate.tolerance
        tight = poly.tight_rows(slack, active, tol)
        if len(tight) > active.size and not poly.licq_verified(tight):
            if self.on_dependent == "raise":
                if poly.degenerate_slips(step, tight, tol):
                    raise DegenerateModelError("", "", self.degenerate_message(tight, time))
            else:
                self.record_licq(tight, time)
        return Projection(step.point, step.multipliers, active, used_clarabel)

    # -- messages ----------------------------------------------------------------------------
    def record_licq(self, index: Iterable[SupportsInt], time: float | None) -> None:
        """Count a dependent set of tight rows of a generic process; warn the first time."""
        key = tuple(int(i) for i in index)
        first, count = self.licq_failures.get(key, (time, 0))
        self.licq_failures[key] = (first, count + 1)
        if count == 0:
            warnings.warn(
                f"LICQ fails{_at(time)}: the normals of the tight constraints "
                f"{_label(key)} are linearly dependent, so their multipliers (the reactions) are "
                "not unique there. The projected point is unique and was certified on an "
                "independent subset; the paper's theorem does not need LICQ. Later occurrences "
                "of this set are counted in `licq_failures`, not repeated.",
                LicqWarning,
                stacklevel=3,
            )

    def degenerate_message(self, index: np.ndarray, time: float | None) -> str:
        if not hasattr(self.polyhedron, "blocks"):
            return (
                f"the normals of the tight constraints {_label(index)} are linearly "
                f"dependent{_at(time)}: LICQ fails there, so the multipliers (the reactions) "
                "are not unique"
            )
        return (
            f"the model does not determine the motion{_at(time)}: "
            f"{self._describe(np.asarray(index))}, so every block is at a friction limit "
            "and the active normals are linearly dependent (LICQ fails): the slips are "
            "unique only up to a rigid translation of the crawler. This is the instant "
            "where the uniqueness condition of docs/model.md §3 fails (sum of mu+ over the "
            "forward blocks = sum of mu- over the others). Change steps_per_period so that "
            "no grid time falls on this instant, or change the friction coefficients."
        )


def _solver(P: Any, q: np.ndarray, A: Any, b: np.ndarray, cones: list[Any]) -> Any:
    """A Clarabel solver with crawlsim's settings: no presolve (``solver.update`` needs the
    structure fixed) and tight tolerances, which make the identification of the active set
    unambiguous; the step itself never uses Clarabel's numbers."""
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.presolve_enable = False
    settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    return clarabel.DefaultSolver(P, q, A, b, cones, settings)


@functools.cache
def _infeasible() -> frozenset[Any]:
    """The statuses that refuse a proposal (built on first use: clarabel is imported only when
    a projection needs it)."""
    import clarabel

    S = clarabel.SolverStatus
    return frozenset({S.PrimalInfeasible, S.DualInfeasible, S.AlmostPrimalInfeasible, S.AlmostDualInfeasible})


def _refused(solution: Any) -> bool:
    """Whether Clarabel's answer proposes nothing: (almost) infeasible, or not finite."""
    finite = np.isfinite(solution.z).all() and np.isfinite(solution.s).all()
    return solution.status in _infeasible() or not finite


def _at(time: float | None) -> str:
    return "" if time is None else f" at t = {time:.12g}"
