"""The compiled closed forms of the exact integrator's next event (`crawlsim.integrate.exact`).

On a piece, every gap of an inactive row and every slip rate of an active one is a combination
f(u) = phi(u) @ z of the offsets' basis. An event is the first u in (u0, u1) where some f
crosses zero upwards and goes on to exceed its tolerance; where roundoff puts the crossing at
u0 or before (a row tight at the start), the time it exceeds its tolerance, strictly after u0.

* linear, f(u) = a + s u: the zero -a / s, and (tol - a) / s above the tolerance;
* one harmonic, f(u) = a + alpha cos 2 pi u + beta sin 2 pi u = a + rho cos(theta - phi): the
  arc where f > tol is [phi - b, phi + b] + 2 pi k with cos b = (tol - a) / rho, the first one
  that ends at or after theta0 = 2 pi u0 (the next one if theta0 is inside it already), and its
  zero crossing phi - b0 + 2 pi k with cos b0 = -a / rho.

Element-wise loops over plain arrays; with ``NUMBA_DISABLE_JIT=1`` they run as Python. The
functions are those that give the same bits compiled and as Python: math.acos and math.atan2
(the C library's in both; numpy's own arccos and arctan2 differ from it in the last ulp) and
np.hypot (numba's math.hypot differs from the C library's).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def linear_crossing(a: float, s: float, tol: float, u0: float, u1: float) -> float:
    """Event time of f = a + s u (inf where there is none before u1)."""
    if not s > 0:
        return np.inf
    over = (tol - a) / s
    if over < u1 and over > u0:
        zero = -a / s
        return zero if zero > u0 else over
    return np.inf


@njit(cache=True)
def harmonic_crossing(a: float, alpha: float, beta: float, tol: float, u0: float,
                      u1: float) -> float:
    """Event time of f = a + alpha cos 2 pi u + beta sin 2 pi u (inf where there is none)."""
    rho = np.hypot(alpha, beta)
    if not rho > 0:
        return np.inf
    x_over = (tol - a) / rho
    if not x_over < 1.0:
        return np.inf
    x_zero = -a / rho
    b_over = math.acos(min(max(x_over, -1.0), 1.0))
    b_zero = math.acos(min(max(x_zero, -1.0), 1.0))
    ph = math.atan2(beta, alpha)
    th0 = TWO_PI * u0
    k = math.ceil((th0 - (ph + b_over)) / TWO_PI)
    start = ph - b_over + TWO_PI * k
    if start <= th0:  # inside the arc already: the next one
        k = k + 1
        start = ph - b_over + TWO_PI * k
    zero = ph - b_zero + TWO_PI * k
    t = zero / TWO_PI if zero / TWO_PI > u0 else start / TWO_PI
    return t if t < u1 else np.inf


@njit(cache=True)
def linear_crossings(a: np.ndarray, s: np.ndarray, tol: np.ndarray, u0: float, u1: float,
                     out: np.ndarray) -> None:
    """`linear_crossing` of every row into ``out``."""
    for r in range(a.shape[0]):
        out[r] = linear_crossing(a[r], s[r], tol[r], u0, u1)


@njit(cache=True)
def harmonic_crossings(a: np.ndarray, alpha: np.ndarray, beta: np.ndarray, tol: np.ndarray,
                       u0: float, u1: float, out: np.ndarray) -> None:
    """`harmonic_crossing` of every row into ``out``."""
    for r in range(a.shape[0]):
        out[r] = harmonic_crossing(a[r], alpha[r], beta[r], tol[r], u0, u1)
