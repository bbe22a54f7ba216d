"""The offsets c(t) of a sweeping process in closed form, piece by piece (docs/model.md §2).

Every signal of a gait file is, between the breakpoints of all its signals, a linear combination
of the functions of one basis of the cycle u = t / T in [0, 1),

    phi(u) = [1, u, cos 2 pi u, sin 2 pi u, ..., cos 2 pi H u, sin 2 pi H u],

(the column u only when a piecewise-linear signal is present, H the largest number of harmonics
of a cosine or fourier signal): constants and steps use 1, piecewise-linear signals 1 and u,
cosine and fourier signals the harmonics (cos 2 pi h (u - phase) = cos 2 pi h phase cos 2 pi h u
+ sin 2 pi h phase sin 2 pi h u). The offsets are linear in the signals (for a crawler
c = [mu^+ - D^T K L; mu^- + D^T K L]), so on piece p

    c(u) = phi(u) @ C_p,   C_p of shape (nb, m).

The exact integrator (`crawlsim.integrate.exact`) builds every function it needs on a piece, the gaps of
the constraints and the slip rates, as such combinations, and finds their zeros in closed form
(one harmonic, or linear) or by certified sampling. Derivatives of any order are exact:
``derivative`` maps coefficients of f to those of df/du.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from crawlsim.gait.signals import Constant, Cosine, Fourier, PiecewiseLinear, Signal, Steps

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Basis:
    """phi(u) = [1, (u,) cos 2 pi u, sin 2 pi u, ..., cos 2 pi H u, sin 2 pi H u]."""

    linear: bool
    harmonics: int

    @property
    def size(self) -> int:
        return 1 + int(self.linear) + 2 * self.harmonics

    @property
    def first_harmonic(self) -> int:
        """Column of cos 2 pi u."""
        return 1 + int(self.linear)

    def values(self, u, order: int = 0) -> np.ndarray:
        """The order-th derivative of phi at cycles u: (len(u), nb). A grid of at least
        `_GRID_VALUES_MIN` cycles (a period's, tabulated once by every exact stepper) and of at
        most `_GRID_VALUES_SIZE` values is remembered (`_GRID_VALUES`): a sweep's points share
        it."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if not _GRID_VALUES_MIN <= u.size <= _GRID_VALUES_SIZE // self.size:
            return self._values(u, order)
        key = (self, order, u.tobytes())
        kept = _GRID_VALUES.get(key)
        if kept is None:
            if len(_GRID_VALUES) >= _GRID_VALUES_MAX:
                _GRID_VALUES.clear()
            kept = _GRID_VALUES[key] = self._values(u, order)
        return kept.copy()

    def _values(self, u: np.ndarray, order: int) -> np.ndarray:
        out = np.zeros((u.size, self.size))
        if order == 0:
            out[:, 0] = 1.0
        if self.linear:
            if order == 0:
                out[:, 1] = u
            elif order == 1:
                out[:, 1] = 1.0
        H = self.harmonics
        if H:
            w = _angular_rates(H)
            # d^k/du^k cos(w u) = w^k cos(w u + k pi/2), sin likewise
            angle = u[:, None] * w + order * (math.pi / 2)  # (k, H)
            h0 = self.first_harmonic
            if order:
                scale = w**order
                out[:, h0::2] = scale * np.cos(angle)
                out[:, h0 + 1 :: 2] = scale * np.sin(angle)
            else:  # w^0 = 1: the values themselves
                out[:, h0::2] = np.cos(angle)
                out[:, h0 + 1 :: 2] = np.sin(angle)
        return out

    def scalar(self, x: float, coef: np.ndarray) -> float:
        """f(x) = phi(x) @ coef for one cycle x and one coefficient vector (no arrays): the
        compiled `crawlsim.kernel.sampling.scalar` that the event loops' root searches use."""
        from crawlsim.kernel.jit import kernel

        return float(
            kernel().sampling.scalar(float(x), np.ascontiguousarray(coef, dtype=float), self.linear, self.harmonics)
        )

    def derivative(self, coef: np.ndarray) -> np.ndarray:
        """Coefficients (nb, ...) of f' for f = phi @ coef."""
        coef = np.asarray(coef, dtype=float)
        out = np.zeros_like(coef)
        if self.linear:
            out[0] = coef[1]
        h0 = self.first_harmonic
        for h in range(1, self.harmonics + 1):
            w = TWO_PI * h
            ci, si = h0 + 2 * (h - 1), h0 + 2 * (h - 1) + 1
            out[ci] = w * coef[si]
            out[si] = -w * coef[ci]
        return out

    def curvature_bound(self, coef: np.ndarray) -> np.ndarray:
        """max_u |f''(u)| bound for f = phi @ coef (columns of coef are functions)."""
        coef = np.abs(np.asarray(coef, dtype=float))
        bound = np.zeros(coef.shape[1:])
        h0 = self.first_harmonic
        for h in range(1, self.harmonics + 1):
            bound = bound + (TWO_PI * h) ** 2 * (coef[h0 + 2 * (h - 1)] + coef[h0 + 2 * (h - 1) + 1])
        return bound


@functools.lru_cache(maxsize=16)
def _angular_rates(harmonics: int) -> np.ndarray:
    """2 pi h for h = 1 .. harmonics (read-only)."""
    w = TWO_PI * np.arange(1, harmonics + 1)
    w.setflags(write=False)
    return w


#: `Basis.values` on grids (arrays of at least `_GRID_VALUES_MIN` cycles, 2 MB of values at
#: most), by basis, order and the cycles' bytes; a few grids at a time.
_GRID_VALUES: dict[tuple[Basis, int, bytes], np.ndarray] = {}
_GRID_VALUES_MIN = 64
_GRID_VALUES_SIZE = 1 << 18
_GRID_VALUES_MAX = 8


def _signal_basis(signals: Sequence[Signal]) -> Basis:
    linear = any(isinstance(s, PiecewiseLinear) for s in signals)
    harmonics = max((s.harmonics for s in signals if isinstance(s, (Cosine, Fourier))), default=0)
    return Basis(linear, int(harmonics))


def _smooth_coefficients(signal: Signal, basis: Basis) -> np.ndarray:
    """Coefficients (nb,) of a constant, cosine or fourier signal: the same on every piece."""
    out = np.zeros(basis.size)
    h0 = basis.first_harmonic
    if isinstance(signal, Constant):
        out[0] = signal.value
    elif isinstance(signal, Cosine):
        out[0] = signal.mean
        angle = TWO_PI * math.fmod(signal.phase, 1.0)
        out[h0] = signal.amplitude * math.cos(angle)
        out[h0 + 1] = signal.amplitude * math.sin(angle)
    elif isinstance(signal, Fourier):
        out[0] = signal.mean
        for n in range(1, signal.harmonics + 1):
            a = signal.cos[n - 1] if n <= len(signal.cos) else 0.0
            b = signal.sin[n - 1] if n <= len(signal.sin) else 0.0
            angle = TWO_PI * math.fmod(n * math.fmod(signal.phase, 1.0), 1.0)
            ca, sa = math.cos(angle), math.sin(angle)
            # a cos n(v - p) + b sin n(v - p), v = 2 pi u, expanded in cos n v, sin n v
            out[h0 + 2 * (n - 1)] = a * ca - b * sa
            out[h0 + 2 * (n - 1) + 1] = a * sa + b * ca
    else:  # pragma: no cover - every signal kind is handled
        raise TypeError(f"not a smooth signal: {signal!r}")
    return out


@dataclass(eq=False)
class PiecewiseOffsets:
    """c(u) = phi(u) @ C_p on the pieces [edges[p], edges[p+1]) of one cycle.

    ``signals`` are the signals c is built from, and ``combine`` maps their coefficients
    (nb, S) to those of c (nb, m) linearly. Piecewise signals are tabulated at the pieces'
    midpoints (value and slope), the others once; C_p is assembled on demand in O(nb m).
    """

    signals: Sequence[Signal]
    combine: Callable[[np.ndarray], np.ndarray]
    edges: np.ndarray  # (P+1,) cycles: 0 = edges[0] < ... < edges[P] = 1
    basis: Basis = field(init=False)
    _smooth: np.ndarray = field(init=False, repr=False)
    _piecewise: np.ndarray = field(init=False, repr=False)
    _values: np.ndarray = field(init=False, repr=False)
    _slopes: np.ndarray = field(init=False, repr=False)
    _cache: dict = field(init=False, repr=False, default_factory=dict)

    def __post_init__(self) -> None:
        self._tabulate()
        for table in (self._smooth, self._piecewise, self._values, self._slopes, self._mids):
            table.setflags(write=False)  # shared by `recombined`

    def recombined(self, combine: Callable[[np.ndarray], np.ndarray]) -> PiecewiseOffsets:
        """The same signals on the same pieces mapped by another ``combine`` (an exact
        stepper's energy ledger reads the signals themselves): the tables are shared, not
        formed again."""
        other = copy.copy(self)
        other.combine = combine
        other._cache = {}
        return other

    def _tabulate(self) -> None:
        self.basis = _signal_basis(self.signals)
        S = len(self.signals)
        smooth = np.zeros((self.basis.size, S))
        piecewise = []
        for i, s in enumerate(self.signals):
            if isinstance(s, (PiecewiseLinear, Steps)):
                piecewise.append(i)
            else:
                smooth[:, i] = _smooth_coefficients(s, self.basis)
        self._smooth = smooth
        self._piecewise = np.array(piecewise, dtype=int)
        mids = 0.5 * (self.edges[:-1] + self.edges[1:])
        self._values = (
            np.column_stack([self.signals[i](mids) for i in piecewise]) if piecewise else np.zeros((len(mids), 0))
        )
        self._slopes = (
            np.column_stack([self.signals[i].rate(mids) for i in piecewise]) if piecewise else np.zeros((len(mids), 0))
        )
        self._mids = mids

    @property
    def pieces(self) -> int:
        return len(self.edges) - 1

    def coefficients(self, p: int) -> np.ndarray:
        """C_p (nb, m)."""
        cached = self._cache.get(p)
        if cached is not None:
            return cached
        out = self.combine(self.signal_coefficients(p))
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[p] = out
        return out

    def signal_coefficients(self, p: int) -> np.ndarray:
        """The signals' own coefficients (nb, S) on piece p, which ``combine`` maps to C_p."""
        coef = self._smooth.copy()
        if self._piecewise.size:
            slope = self._slopes[p]
            coef[0, self._piecewise] = self._values[p] - slope * self._mids[p]
            if self.basis.linear:
                coef[1, self._piecewise] = slope
        return coef

    def piece_at(self, u: float) -> int:
        """The piece containing cycle u (right-continuous: an edge belongs to the next piece)."""
        return min(int(np.searchsorted(self.edges, u, side="right")) - 1, self.pieces - 1)

    def evaluate(self, u, order: int = 0, piece: int | None = None) -> np.ndarray:
        """c^(order)(u) (len(u), m), on ``piece`` if given (one-sided limits at its edges)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if piece is not None:
            return self.basis.values(u, order) @ self.coefficients(piece)
        out = np.empty((u.size, self.coefficients(0).shape[1]))
        idx = np.array([self.piece_at(x) for x in u])
        for p in np.unique(idx):
            sel = idx == p
            out[sel] = self.basis.values(u[sel], order) @ self.coefficients(int(p))
        return out
