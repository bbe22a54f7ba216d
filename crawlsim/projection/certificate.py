"""The certificate of a step and the records of a certified step or run (`crawlsim.projection.kkt`).

Every certificate of every integrator holds a step to the tolerances of `crawlsim.kernel.policy`:
primal feasibility max(B w - c), the sign of the multipliers -min(lambda) and complementarity
max |(B w - c)_A|.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from crawlsim.projection.polyhedron import ActiveSet

#: Float arrays of any shape (the annotation that lets numpy's stubs type their arithmetic).
Floats = npt.NDArray[np.floating[Any]]

#: Active sets of up to this many blocks are factored in numpy, larger ones with LAPACK.
SMALL_CHAIN = 6
#: LICQ floor of generic processes: the reciprocal condition number of G_A.
GENERIC_RCOND = 1e-10
#: Numbers the cache of factored active sets may hold (about 32 MB); it is emptied when full.
CACHE_NUMBERS = 1 << 22


class Dependent(Exception):
    """The rows ``index`` have linearly dependent normals (LICQ fails)."""

    def __init__(self, index: npt.ArrayLike):
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
        return self.primal <= t.primal and self.dual <= self._dual_tol and self.complementarity <= t.primal

    def __str__(self) -> str:
        t = self.tolerance
        return (
            f"primal violation {self.primal:.3g} (tolerance {t.primal:.3g}), negative "
            f"multiplier {self.dual:.3g} (tolerance {self._dual_tol:.3g}), complementarity "
            f"{self.complementarity:.3g} (tolerance {t.primal:.3g})"
        )


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
