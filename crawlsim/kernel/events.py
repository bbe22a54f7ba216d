"""The exact integrator's next event on a piece (`crawlsim.integrate.exact`), compiled: the
closed forms of a row's zero crossing, and `next_event`, which seeks them over the rows.

On a piece, every gap of an inactive row and every slip rate of an active one is a combination
f(u) = phi(u) @ z of the offsets' basis. An event is the first u in (u0, u1) where some f
crosses zero upwards and goes on to exceed its tolerance; where roundoff puts the crossing at
u0 or before (a row tight at the start), the time it exceeds its tolerance, strictly after u0.
A row already above its tolerance at u0 (by the roundoff of a state carried from steeper
pieces, or of a decision near its tolerance) has its event where f rises a tolerance above
f(u0): it is crossing now, and the event lets the next decision take it in, where skipping to
its next crossing would leave it violated on the whole piece.

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

from crawlsim.kernel import sampling
from crawlsim.kernel.jit import jit
from crawlsim.kernel.piece import basis_values, derivative
from crawlsim.kernel.policy import RTOL

TWO_PI = 2.0 * math.pi
#: Two rows hit within this many cycles of the first crossing are hit together, if the later
#: one's gap is at its limit there to roundoff (`hit_together`).
SIMULTANEOUS = 1e-13


@jit
def linear_crossing(a: float, s: float, tol: float, u0: float, u1: float) -> float:
    """Event time of f = a + s u (inf where there is none before u1)."""
    if not s > 0:
        return np.inf
    over = max((max(tol, a + s * u0 + tol) - a) / s, np.nextafter(u0, np.inf))
    if over < u1:
        zero = -a / s
        return zero if zero > u0 else over
    return np.inf


@jit
def harmonic_crossing(a: float, alpha: float, beta: float, tol: float, u0: float, u1: float) -> float:
    """Event time of f = a + alpha cos 2 pi u + beta sin 2 pi u (inf where there is none)."""
    rho = np.hypot(alpha, beta)
    if not rho > 0:
        return np.inf
    th0 = TWO_PI * u0
    tol = max(tol, a + alpha * math.cos(th0) + beta * math.sin(th0) + tol)
    x_over = (tol - a) / rho
    if not x_over < 1.0:
        return np.inf
    x_zero = -a / rho
    b_over = math.acos(min(max(x_over, -1.0), 1.0))
    b_zero = math.acos(min(max(x_zero, -1.0), 1.0))
    ph = math.atan2(beta, alpha)
    k = math.ceil((th0 - (ph + b_over)) / TWO_PI)
    start = ph - b_over + TWO_PI * k
    if start <= th0:  # inside the arc already: the next one
        k = k + 1
        start = ph - b_over + TWO_PI * k
    zero = ph - b_zero + TWO_PI * k
    t = zero / TWO_PI if zero / TWO_PI > u0 else max(start / TWO_PI, np.nextafter(u0, np.inf))
    return t if t < u1 else np.inf


@jit
def linear_crossings(a: np.ndarray, s: np.ndarray, tol: np.ndarray, u0: float, u1: float, out: np.ndarray) -> None:
    """`linear_crossing` of every row into ``out``."""
    for r in range(a.shape[0]):
        out[r] = linear_crossing(a[r], s[r], tol[r], u0, u1)


@jit
def harmonic_crossings(
    a: np.ndarray, alpha: np.ndarray, beta: np.ndarray, tol: np.ndarray, u0: float, u1: float, out: np.ndarray
) -> None:
    """`harmonic_crossing` of every row into ``out``."""
    for r in range(a.shape[0]):
        out[r] = harmonic_crossing(a[r], alpha[r], beta[r], tol[r], u0, u1)


@jit
def hit_together(z: np.ndarray, c_scale: float, phi: np.ndarray) -> bool:
    """Whether a row whose gap f = phi @ z crosses within `SIMULTANEOUS` after the first event
    (phi its basis values) is hit with it: f there is at least -RTOL of c_scale or of the size
    of its terms, the primal tolerance of a certificate. On a steep piece the gaps move by far
    more than a friction band in SIMULTANEOUS: a row still below its limit there, taken in,
    would hold that gap as its equality, a negative slip, and leave the row that did cross
    violated."""
    f, size = 0.0, 0.0
    for b in range(z.shape[0]):
        f += z[b] * phi[b]
        size += abs(z[b] * phi[b])
    return f >= -RTOL * max(c_scale, size)


# -- the next event on a piece ------------------------------------------------------------------
@jit
def crossing(
    z: np.ndarray, tol: float, u0: float, u1: float, linear: bool, H: int, phi0: np.ndarray, horizon: float
) -> float:
    """The first upward zero crossing of f = phi @ z in (u0, u1) that goes on to exceed tol
    (`crawlsim.kernel.events`); inf if none, NaN where the basis has no closed form for f
    (several harmonics, or one and a linear part: `crawlsim.kernel.sampling`). inf also for an
    f that stays below zero on [u0, horizon] (phi0 = phi(u0)): its crossing, where f = 0 or
    tol, is after horizon (the caller's earliest event so far)."""
    nb = z.shape[0]
    if nb == 1:
        return np.inf
    if H == 0:
        return linear_crossing(z[0], z[1], tol, u0, u1)
    # f <= top and |f'| <= slope on the piece (`sampling.reach`): a row that cannot reach its
    # tolerance has no event (the closed forms and the sampling agree), without their trig
    # (the bound's own roundoff is covered by 1e-12 of its terms' size)
    top, size, slope = sampling.reach(z, u0, u1, linear, H)
    if top + 1e-12 * size < tol:
        return np.inf
    # f(u) <= f(u0) + slope (u - u0) on [u0, horizon], without trig: below zero there (by
    # more than the roundoff of f(u0) and of the crossing's own closed form, 1e-12 of its
    # terms' size), f has neither its zero nor its tolerance before horizon
    f0 = 0.0
    for b in range(nb):
        f0 += z[b] * phi0[b]
    if f0 + slope * (horizon - u0) + 1e-12 * size < 0.0:
        return np.inf
    if H != 1 or (linear and z[1] != 0.0):
        return np.nan
    return harmonic_crossing(z[0], z[nb - 2], z[nb - 1], tol, u0, u1)


@jit
def rate_tolerance(c_size: float, signs: np.ndarray, Rdx: np.ndarray, inverse: float) -> float:
    """The tolerance of the active rows' slip rates on a piece: RTOL times the larger of the
    rates' own size (sum_b |Rdx[b, i]| over the active blocks) and what the offsets' rates
    carry through the inverse, ||L_JJ^{-1}|| 2 pi max_r sum_b |coef[b, r]| (``c_size``,
    `crawlsim.kernel.piece.offset_size`)."""
    nb = Rdx.shape[0]
    scale = 0.0
    for i in range(signs.shape[0]):
        if signs[i] != 0:
            total = 0.0
            for b in range(nb):
                total += abs(Rdx[b, i])
            scale = max(scale, total)
    return RTOL * max(scale, inverse * c_size * TWO_PI)


@jit
def block_functions(
    i: int, coef: np.ndarray, signs: np.ndarray, base: np.ndarray, Wc: np.ndarray, Rdx: np.ndarray, Z: np.ndarray
) -> None:
    """Z[i] and Z[N + i], the functions of block i's two rows (`row_functions`): the gap
    phi @ (B Wc - coef + B base e_0) of an inactive row, the slip rate s phi @ Rdx of an active
    one. Block i's force (B w)_i = w_{i-1} - w_i reads links i - 1 and i only."""
    N = signs.shape[0]
    s = signs[i]
    for b in range(coef.shape[0]):
        g = (Wc[b, i - 1] if i > 0 else 0.0) - (Wc[b, i] if i < N - 1 else 0.0)
        Z[i, b] = s * Rdx[b, i] if s > 0 else g - coef[b, i]
        Z[N + i, b] = s * Rdx[b, i] if s < 0 else -g - coef[b, N + i]
    g = (base[i - 1] if i > 0 else 0.0) - (base[i] if i < N - 1 else 0.0)
    if s <= 0:
        Z[i, 0] += g
    if s >= 0:
        Z[N + i, 0] += -g


@jit
def row_functions(
    linear: bool,
    H: int,
    coef: np.ndarray,
    signs: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    Rdx: np.ndarray,
    tol_gap: float,
    tol_rate: float,
    u0: float,
    u1: float,
    phi0: np.ndarray,
    Z: np.ndarray,
    reach: np.ndarray,
    slope_bound: np.ndarray,
) -> int:
    """Z[r] = the coefficients of the function of row r whose upward crossing is an event:
    the gap phi @ (B Wc - coef + B base e_0) of an inactive row (the entries of `apply`), the
    slip rate s phi @ Rdx of an active one; ``reach[r]``: 0 where it cannot reach its
    tolerance on (u0, u1) by the bound `crossing` applies first for one harmonic, 2 where
    `crossing` then applies its slope bound f(u) <= f(u0) + 2 pi (|alpha| + |beta|) (u - u0)
    (phi0 = phi(u0)), whose terms f(u0), 2 pi (|alpha| + |beta|) and its margin go to
    ``slope_bound[r]``, 1 otherwise; so that `next_event` calls `crossing` only for the rows
    that can cross before its horizon, with the same operations. One pass over the blocks
    (each block's force enters its two rows). Returns the row that the slope bound lets
    cross first (-1 if none): its crossing, sought first, bounds those of the others."""
    N = signs.shape[0]
    nb = coef.shape[0]
    bound = H == 1 and nb > 1
    for i in range(N):
        block_functions(i, coef, signs, base, Wc, Rdx, Z)
    best, soonest = -1, np.inf
    for r in range(2 * N):
        reach[r] = 1
        if bound:  # the bounds of `crossing`, the same operations
            z = Z[r]
            top = z[0] + abs(z[nb - 2]) + abs(z[nb - 1])
            size = abs(z[0]) + abs(z[nb - 2]) + abs(z[nb - 1])
            if linear:
                top += max(z[1] * u0, z[1] * u1)
                size += abs(z[1]) * max(abs(u0), abs(u1))
            s = signs[r % N]
            active = (r < N and s > 0) or (r >= N and s < 0)
            if top + 1e-12 * size < (tol_rate if active else tol_gap):
                reach[r] = 0
            elif not (linear and z[1] != 0.0):  # else no closed form: `crossing` hands over
                f0 = 0.0
                for b in range(nb):
                    f0 += z[b] * phi0[b]
                slope = TWO_PI * (abs(z[nb - 2]) + abs(z[nb - 1]))
                reach[r] = 2
                slope_bound[r, 0], slope_bound[r, 1], slope_bound[r, 2] = f0, slope, 1e-12 * size
                if f0 >= 0.0:  # at its zero already
                    if soonest > 0.0:
                        best, soonest = r, 0.0
                elif slope > 0.0 and -f0 < soonest * slope:
                    best, soonest = r, -f0 / slope
    return best


@jit
def next_event(
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    c_size: float,
    signs: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    Ydx: np.ndarray,
    inverse: float,
    u0: float,
    u1: float,
    hit: np.ndarray,
    Rdx: np.ndarray,
    Z: np.ndarray,
    times: np.ndarray,
    reach: np.ndarray,
    slope_bound: np.ndarray,
    phi0: np.ndarray,
    cells_per_cycle: int,
) -> tuple[float, bool]:
    """(u, handoff) of the first event in (u0, u1) (u = inf: none), the rows newly tight in
    ``hit`` (`EventStepper._next_event`): gaps phi @ (B Wc - coef + B base e_0) of the inactive
    rows, slip rates -dLambda/du = phi @ derivative(Y) of the active ones (`row_functions`;
    Z, times, reach, slope_bound and phi0 are scratch). Zeros without a closed form by
    `crawlsim.kernel.sampling.crossing`, on samples of (u0, u1) tabulated once, on first use."""
    N = signs.shape[0]
    m = 2 * N
    derivative(Ydx, linear, H, Rdx)
    tol_gap = 0.5 * RTOL * c_scale
    tol_rate = rate_tolerance(c_size, signs, Rdx, inverse)
    basis_values(u0, 0, linear, H, phi0)
    lead = row_functions(linear, H, coef, signs, base, Wc, Rdx, tol_gap, tol_rate, u0, u1, phi0, Z, reach, slope_bound)
    # the samples of (u0, u1) for `sampling.crossing`, made on first use (closed forms need none)
    count = 0
    first, t_lead = np.inf, np.inf
    if lead >= 0:  # sought first: the horizon of the others is then short from the start
        s = signs[lead % N]
        active = (lead < N and s > 0) or (lead >= N and s < 0)
        t_lead = crossing(Z[lead], tol_rate if active else tol_gap, u0, u1, linear, H, phi0, u1)
        if np.isnan(t_lead):
            return np.inf, True
        first = t_lead
    for r in range(m):
        times[r] = t_lead if r == lead else np.inf
        if reach[r] == 0 or r == lead:
            continue
        # a row whose crossing is after first + SIMULTANEOUS is neither the first nor hit
        horizon = min(u1, first + SIMULTANEOUS)
        if reach[r] == 2 and (slope_bound[r, 0] + slope_bound[r, 1] * (horizon - u0) + slope_bound[r, 2] < 0.0):
            continue  # the slope bound of `crossing`: no crossing before horizon
        s = signs[r % N]
        active = (r < N and s > 0) or (r >= N and s < 0)
        tol = tol_rate if active else tol_gap
        t = crossing(Z[r], tol, u0, u1, linear, H, phi0, horizon)
        if np.isnan(t):  # no closed form: certified sampling
            if count == 0:
                count = sampling.cells(u0, u1, cells_per_cycle, H)
                S, PHIS = np.empty(count + 1), np.empty((count + 1, coef.shape[0]))
                filled = np.zeros(1, dtype=np.int64)
                sampling.grid(u0, u1, count, S)
            t = sampling.crossing(Z[r], tol, u0, u1, linear, H, horizon, S, PHIS, filled)
        if np.isnan(t):
            return np.inf, True
        times[r] = t
        first = min(first, t)
    hit[:] = False
    if not first < u1:
        return np.inf, False
    basis_values(first, 0, linear, H, phi0)
    for r in range(m):
        s = signs[r % N]
        inactive = not ((r < N and s > 0) or (r >= N and s < 0))
        together = times[r] <= first + SIMULTANEOUS and hit_together(Z[r], c_scale, phi0)
        hit[r] = inactive and (times[r] == first or together)
    return first, False


@jit
def closed_forms(linear: bool, H: int) -> bool:
    """Whether every row's crossing has a closed form (`crossing` never hands a row to the
    sampling): a linear basis, or one harmonic without a linear part."""
    return H == 0 or (H == 1 and not linear)


@jit
def next_event_kept(
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    c_size: float,
    signs: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    Rdx: np.ndarray,
    inverse: float,
    u0: float,
    u1: float,
    dirty: np.ndarray,
    hit: np.ndarray,
    Z: np.ndarray,
    times: np.ndarray,
    tols: np.ndarray,
    phi0: np.ndarray,
) -> float:
    """`next_event` for a basis with `closed_forms`, from the crossings kept per row: row r's
    function Z[r] and its crossing ``times[r]`` (sought to the piece's end u1, with the
    tolerance ``tols[r]``) stay valid while its block is not ``dirty`` (its function has not
    changed: `crawlsim.kernel.piece.rebuild` left its links), its tolerance is the same and
    the crossing is still ahead (times[r] > u0). The first crossing after an earlier u0 that
    lies after u0 is the first after u0 (the closed forms of the module docstring pick the
    same zero or arc), so only the rows of the blocks an event changed, and those it reached,
    are sought again; the others cost a comparison. ``dirty`` is cleared. Returns the event
    time (inf: none before u1), the rows newly tight in ``hit``."""
    N = signs.shape[0]
    tol_gap = 0.5 * RTOL * c_scale
    tol_rate = rate_tolerance(c_size, signs, Rdx, inverse)
    basis_values(u0, 0, linear, H, phi0)
    first = np.inf
    for i in range(N):
        s = signs[i]
        tol_plus = tol_rate if s > 0 else tol_gap
        tol_minus = tol_rate if s < 0 else tol_gap
        if dirty[i]:
            block_functions(i, coef, signs, base, Wc, Rdx, Z)
            times[i] = crossing(Z[i], tol_plus, u0, u1, linear, H, phi0, u1)
            times[N + i] = crossing(Z[N + i], tol_minus, u0, u1, linear, H, phi0, u1)
            tols[i], tols[N + i] = tol_plus, tol_minus
            dirty[i] = False
        else:
            if tols[i] != tol_plus or not times[i] > u0:
                times[i] = crossing(Z[i], tol_plus, u0, u1, linear, H, phi0, u1)
                tols[i] = tol_plus
            if tols[N + i] != tol_minus or not times[N + i] > u0:
                times[N + i] = crossing(Z[N + i], tol_minus, u0, u1, linear, H, phi0, u1)
                tols[N + i] = tol_minus
        first = min(first, min(times[i], times[N + i]))
    hit[:] = False
    if not first < u1:
        return np.inf
    basis_values(first, 0, linear, H, phi0)
    for r in range(2 * N):
        s = signs[r % N]
        inactive = s <= 0 if r < N else s >= 0
        together = times[r] <= first + SIMULTANEOUS and hit_together(Z[r], c_scale, phi0)
        hit[r] = inactive and (times[r] == first or together)
    return first
