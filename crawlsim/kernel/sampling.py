"""The zeros of the exact integrator that have no closed form, compiled: used by both its event
loops (`crawlsim.kernel.eventloop`, and the Python one of `crawlsim.integrate.exact`).

On a piece every gap of an inactive row and every slip rate of an active one is a combination
f(u) = phi(u) @ z of the offsets' basis, phi(u) = [1, (u,) cos 2 pi u, sin 2 pi u, ...,
cos 2 pi H u, sin 2 pi H u] (`crawlsim.model.offsets.Basis`). Its event is the first u in
(u0, u1) where f crosses zero upwards and goes on to exceed its tolerance
(`crawlsim.kernel.events`). With several harmonics, or one harmonic and a linear part, that zero
has no closed form; it is found by certified sampling:

* samples s_k every 1/(C H) cycle (C = ``cells_per_cycle``, at least 4 cells per piece);
* on a cell of width h, f exceeds the larger of its end values by at most h^2/8 max|f''|
  (the error bound of the linear interpolant), max|f''| <= sum_h (2 pi h)^2 (|a_h| + |b_h|)
  (`curvature`), so a cell where the larger sample plus that bound stays at or below tol
  holds no crossing, and only the other cells are searched, in order;
* in such a cell f reaches its tolerance at the right end, or at the maximum of f in the
  cell (Brent's bounded minimisation of -f, `maximum`), else not at all; the time ``over``
  where it does is a bracketed root of f - tol (`brentq`), and the zero crossing the bracketed
  root of f between the last sample below zero and ``over`` (a crossing at or before u0,
  roundoff of a row tight there, gives ``over``, strictly after u0).

`maximum` and `brentq` are scipy's algorithms (`scipy.optimize.minimize_scalar(method=
"bounded")` and the C code of `scipy.optimize.brentq`) with the tolerances the Python loop
used to give them, step for step, on the same evaluation of f (`scalar`, which is
`Basis.scalar`): the same roots and maxima, bit for bit, without scipy or Python calls.

`reach` bounds f and f' on a piece without trigonometry; `crawlsim.kernel.events.crossing`
uses it to rule out rows that cannot reach their tolerance, or not before the earliest event
found so far.

Plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same source runs as Python.
"""

from __future__ import annotations

import math

import numpy as np

from crawlsim.kernel.jit import jit
from crawlsim.kernel.piece import basis_values

TWO_PI = 2.0 * math.pi
#: scipy.optimize.brentq's defaults: relative tolerance 4 eps and 100 iterations, and the
#: absolute tolerance the Python loop gives it.
BRENT_RTOL = 4.0 * np.finfo(np.float64).eps
BRENT_ITERATIONS = 100
XTOL = 1e-15
#: scipy's bounded scalar minimisation: its sqrt(eps), golden ratio and default iterations.
SQRT_EPS = math.sqrt(2.2e-16)
GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))
BOUNDED_ITERATIONS = 500


@jit
def scalar(x: float, z: np.ndarray, linear: bool, H: int) -> float:
    """f(x) = phi(x) @ z for one cycle x, term by term (`crawlsim.model.offsets.Basis.scalar`
    is this function)."""
    total = float(z[0])
    if linear:
        total += z[1] * x
    h0 = 2 if linear else 1
    for h in range(1, H + 1):
        angle = TWO_PI * h * x
        total += z[h0 + 2 * h - 2] * math.cos(angle) + z[h0 + 2 * h - 1] * math.sin(angle)
    return total


@jit
def curvature(z: np.ndarray, linear: bool, H: int) -> float:
    """max_u |f''(u)| <= sum_h (2 pi h)^2 (|a_h| + |b_h|) (`Basis.curvature_bound`)."""
    h0 = 2 if linear else 1
    bound = 0.0
    for h in range(1, H + 1):
        w = TWO_PI * h
        bound = bound + w * w * (abs(z[h0 + 2 * (h - 1)]) + abs(z[h0 + 2 * (h - 1) + 1]))
    return bound


@jit
def reach(z: np.ndarray, u0: float, u1: float, linear: bool, H: int) -> tuple[float, float, float]:
    """(top, size, slope) of f = phi @ z on [u0, u1]: f <= top, |f'| <= slope, and size the sum
    of the magnitudes of f's terms (the scale of its roundoff), without trigonometry."""
    h0 = 2 if linear else 1
    top = z[0]
    size = abs(z[0])
    slope = 0.0
    for h in range(1, H + 1):
        a, b = abs(z[h0 + 2 * (h - 1)]), abs(z[h0 + 2 * (h - 1) + 1])
        top = top + a + b
        size = size + a + b
        slope += TWO_PI * h * (a + b)
    if linear:
        top += max(z[1] * u0, z[1] * u1)
        size += abs(z[1]) * max(abs(u0), abs(u1))
        slope += abs(z[1])
    return top, size, slope


@jit
def _negative(x: float) -> bool:
    """signbit(x): True for negative numbers and -0."""
    return math.copysign(1.0, x) < 0.0


@jit
def brentq(z: np.ndarray, t: float, xa: float, xb: float, linear: bool, H: int) -> float:
    """The root of f - t in [xa, xb] (f = `scalar`), as scipy.optimize.brentq with xtol 1e-15
    finds it: its C code, step for step. NaN where f - t has the same sign at both ends or the
    iterations do not converge (scipy raises there)."""
    xpre, xcur = xa, xb
    xblk, fblk, spre, scur = 0.0, 0.0, 0.0, 0.0
    fpre = scalar(xpre, z, linear, H) - t
    fcur = scalar(xcur, z, linear, H) - t
    if fpre == 0.0:
        return xpre
    if fcur == 0.0:
        return xcur
    if _negative(fpre) == _negative(fcur):
        return np.nan
    for _ in range(BRENT_ITERATIONS):
        if fpre != 0.0 and fcur != 0.0 and _negative(fpre) != _negative(fcur):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (XTOL + BRENT_RTOL * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2 * abs(stry) < min(abs(spre), 3 * abs(sbis) - delta):  # a good short step
                spre, scur = scur, stry
            else:  # bisect
                spre, scur = sbis, sbis
        else:  # bisect
            spre, scur = sbis, sbis
        xpre, fpre = xcur, fcur
        if abs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = scalar(xcur, z, linear, H) - t
    return np.nan


@jit
def _sign1(x: float) -> float:
    """np.sign(x) + (x == 0): the direction of a step of scipy's bounded minimisation."""
    return 1.0 if x >= 0.0 else -1.0


@jit
def maximum(z: np.ndarray, x1: float, x2: float, linear: bool, H: int) -> tuple[float, float]:
    """(x, f(x)) at the maximum of f on [x1, x2], as scipy.optimize.minimize_scalar(-f,
    bounds=(x1, x2), method="bounded", options={"xatol": 1e-15}) finds it (Brent's golden
    section and parabolic steps, step for step)."""
    a, b = x1, x2
    fulc = a + GOLDEN * (b - a)
    nfc, xf = fulc, fulc
    rat = e = 0.0
    x = xf
    fx = -scalar(x, z, linear, H)
    num = 1
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = SQRT_EPS * abs(xf) + XTOL / 3.0
    tol2 = 2.0 * tol1
    while abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = True
        if abs(e) > tol1:  # a parabolic fit
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r = e
            e = rat
            if abs(p) < abs(0.5 * q * r) and p > q * (a - xf) and p < q * (b - xf):
                rat = (p + 0.0) / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 * _sign1(xm - xf)
            else:
                golden = True
        if golden:  # a golden-section step
            e = a - xf if xf >= xm else b - xf
            rat = GOLDEN * e
        x = xf + _sign1(rat) * max(abs(rat), tol1)
        fu = -scalar(x, z, linear, H)
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif fu <= ffulc or fulc == xf or fulc == nfc:
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = SQRT_EPS * abs(xf) + XTOL / 3.0
        tol2 = 2.0 * tol1
        if num >= BOUNDED_ITERATIONS:
            break
    return xf, -fx


@jit
def cells(u0: float, u1: float, cells_per_cycle: int, H: int) -> int:
    """The sampling cells of (u0, u1): one every 1/(C H) cycle, at least 4."""
    return max(4, int(math.ceil((u1 - u0) * cells_per_cycle * max(H, 1))))


@jit
def grid(u0: float, u1: float, count: int, S: np.ndarray) -> None:
    """The samples s_k = u0 + k (u1 - u0) / count, k = 0 ... count, into S (np.linspace)."""
    step = (u1 - u0) / count
    for k in range(count):
        S[k] = k * step + u0
    S[count] = u1


@jit
def _sample(z: np.ndarray, k: int, S: np.ndarray, PHIS: np.ndarray, filled: np.ndarray, linear: bool, H: int) -> float:
    """f(s_k), the basis at the samples tabulated on first use (PHIS[:filled[0]] hold it)."""
    while filled[0] <= k:
        basis_values(S[filled[0]], 0, linear, H, PHIS[filled[0]])
        filled[0] += 1
    total = 0.0
    for b in range(z.shape[0]):
        total += PHIS[k, b] * z[b]
    return total


@jit
def crossing(
    z: np.ndarray,
    tol: float,
    u0: float,
    u1: float,
    linear: bool,
    H: int,
    horizon: float,
    S: np.ndarray,
    PHIS: np.ndarray,
    filled: np.ndarray,
) -> float:
    """The first upward zero crossing of f = phi @ z in (u0, u1) that goes on to exceed tol, by
    certified sampling (module docstring) on the samples S of (u0, u1) (`grid`); inf if there
    is none, or if it is after ``horizon`` (the caller's earliest event so far, at most u1);
    NaN where `brentq` does not converge."""
    count = S.shape[0] - 1
    h = (u1 - u0) / count
    bound = h * h / 8.0 * curvature(z, linear, H)
    last_below = -1  # the last sample where f < 0
    f_k = _sample(z, 0, S, PHIS, filled, linear, H)
    tol = max(tol, f_k + tol)  # above it at u0: where it rises further (`crawlsim.kernel.events`)
    for k in range(count):
        if f_k < 0.0:
            last_below = k
            if S[k] > horizon:  # every later zero is after s_k
                return np.inf
        f_next = _sample(z, k + 1, S, PHIS, filled, linear, H)
        if max(f_k, f_next) + bound > tol and not f_k > tol:
            left, right = S[k], S[k + 1]
            top, f_max = right, f_next
            if not f_next > tol:  # f reaches tol inside the cell, if at all, at its maximum
                x_max, f_max = maximum(z, left, right, linear, H)
                top = x_max
            if f_next > tol or f_max > tol:
                # the samples and `scalar` may round differently at the bracket's ends: a
                # bracket without a sign change has its crossing at an end
                f_left = scalar(left, z, linear, H) - tol
                f_top = scalar(top, z, linear, H) - tol
                if f_left * f_top > 0.0 or (_negative(f_left) == _negative(f_top) and f_left != 0.0 and f_top != 0.0):
                    over = left if f_left > 0.0 else top
                else:
                    over = brentq(z, tol, left, top, linear, H)
                    if np.isnan(over):
                        return np.nan
                zero = u0
                if last_below >= 0:
                    # f(over) = tol to within brentq's xtol times the slope, which may be
                    # more than tol: a bracket without a sign change has its zero at an end
                    a = S[last_below]
                    f_a = scalar(a, z, linear, H)
                    zero = a if f_a >= 0.0 else over
                    if f_a < 0.0 < scalar(over, z, linear, H):
                        zero = brentq(z, 0.0, a, over, linear, H)
                        if np.isnan(zero):
                            return np.nan
                out = zero if zero > u0 else max(over, np.nextafter(u0, u1))
                return out if out < u1 else np.inf
        f_k = f_next
    return np.inf


@jit
def crossings(
    Z: np.ndarray, tol: np.ndarray, u0: float, u1: float, linear: bool, H: int, cells_per_cycle: int, out: np.ndarray
) -> None:
    """`crossing` of every column of Z (nb, k) into ``out``, on one set of samples (the Python
    loop of `crawlsim.integrate.exact`)."""
    count = cells(u0, u1, cells_per_cycle, H)
    S, PHIS = np.empty(count + 1), np.empty((count + 1, Z.shape[0]))
    filled = np.zeros(1, dtype=np.int64)
    grid(u0, u1, count, S)
    z = np.empty(Z.shape[0])
    for r in range(Z.shape[1]):
        z[:] = Z[:, r]
        out[r] = crossing(z, tol[r], u0, u1, linear, H, u1, S, PHIS, filled)
