"""The tangent walk of the exact integrator's limit period, compiled
(`crawlsim.analysis.sensitivity_walk`, docs/sensitivity.md).

One call carries the (n + p)-column tangent of (w0, theta) along the period's recorded
transitions, with the visited active sets and the order of the events held:

* a flow on A (eq. (piece)): Lambda_A(u) = G_A^{-1} (B_A w_s - c_A(u)),
  w(u) = w_s - K B_A^T Lambda_A(u), differentiated in w_s, in c_A and in K;
* a hit at the end of a flow (eq. (saltation)): du = -dg_i / (b_i . w' - c_i'), the state and
  the slips take w' du and Lambda' du; the kinks of the hit (zero rate, rows hit together whose
  du differ, a hit at the time of another event) as bits of ``kink``;
* a jump of a ``steps`` signal: the projection on its active set;
* the dissipation, int mu_A . lambda_A over each flow (Gauss-Legendre) with its tangent and the
  moving ends' terms, and mu . Lambda at the jumps.

The touches inside a flow (an inactive gap reaching zero without crossing, a slip rate reaching
zero without leaving) are screened here with tolerances twice the walk's: a flow that may hold
one is flagged, and the caller examines it on the closed form with the state and tangent the
walk had at its start (``w_start``, ``W_start``), so that the rare flagged flows cost Python and
the others their arithmetic.

Plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same source runs as Python.
"""

from __future__ import annotations

import math

import numpy as np

# the transition causes, coded as the compiled event loop codes them
from crawlsim.kernel.eventloop import CAUSES, HIT, JUMP  # noqa: F401 - CAUSES for the callers
from crawlsim.kernel.jit import jit
from crawlsim.kernel.piece import basis_values, derivative

TWO_PI = 2.0 * math.pi
EPS = float(np.finfo(np.float64).eps)
#: Bits of ``kink`` at a hit: reached with zero rate, rows reached together move apart, reached
#: at the time of another event.
ZERO_RATE, APART, COINCIDENT = 1, 2, 4


@jit
def factor(B: np.ndarray, k: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """B_A and G_A^{-1}, G_A = B_A K B_A^T (Gauss-Jordan with partial pivoting)."""
    a, n = idx.shape[0], B.shape[1]
    BA = np.empty((a, n))
    for r in range(a):
        for i in range(n):
            BA[r, i] = B[idx[r], i]
    G = np.zeros((a, a))
    for r in range(a):
        for s in range(a):
            t = 0.0
            for i in range(n):
                t += BA[r, i] * k[i] * BA[s, i]
            G[r, s] = t
    Gi = np.eye(a)
    for c in range(a):
        piv = c
        for r in range(c + 1, a):
            if abs(G[r, c]) > abs(G[piv, c]):
                piv = r
        if piv != c:
            for s in range(a):
                G[c, s], G[piv, s] = G[piv, s], G[c, s]
                Gi[c, s], Gi[piv, s] = Gi[piv, s], Gi[c, s]
        d = G[c, c]
        for s in range(a):
            G[c, s] /= d
            Gi[c, s] /= d
        for r in range(a):
            if r != c:
                f = G[r, c]
                if f != 0.0:
                    for s in range(a):
                        G[r, s] -= f * G[c, s]
                        Gi[r, s] -= f * Gi[c, s]
    return BA, Gi


@jit
def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A @ x, in loops (the same sums compiled and as Python)."""
    out = np.zeros(A.shape[0])
    for r in range(A.shape[0]):
        t = 0.0
        for c in range(A.shape[1]):
            t += A[r, c] * x[c]
        out[r] = t
    return out


@jit
def _mm(A: np.ndarray, X: np.ndarray) -> np.ndarray:
    """A @ X, in loops."""
    out = np.zeros((A.shape[0], X.shape[1]))
    for r in range(A.shape[0]):
        for s in range(A.shape[1]):
            f = A[r, s]
            for c in range(X.shape[1]):
                out[r, c] += f * X[s, c]
    return out


@jit
def _at(phi: np.ndarray, coef: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """phi @ coef[:, idx] for coef (nb, m)."""
    out = np.zeros(idx.shape[0])
    for b in range(phi.shape[0]):
        for r in range(idx.shape[0]):
            out[r] += phi[b] * coef[b, idx[r]]
    return out


@jit
def _at_p(phi: np.ndarray, coef: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """phi . coef[:, idx, :] for coef (nb, m, p): (a, p)."""
    p = coef.shape[2]
    out = np.zeros((idx.shape[0], p))
    for b in range(phi.shape[0]):
        for r in range(idx.shape[0]):
            for j in range(p):
                out[r, j] += phi[b] * coef[b, idx[r], j]
    return out


@jit
def solve_on(
    BA: np.ndarray,
    Gi: np.ndarray,
    idx: np.ndarray,
    k: np.ndarray,
    dk: np.ndarray,
    w_s: np.ndarray,
    W_s: np.ndarray,
    phi: np.ndarray,
    C: np.ndarray,
    dC: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Lambda_A(u), d Lambda_A, w(u) and its tangent for a flow (or projection) on A from w_s,
    phi the basis at u (eq. (piece)); C (nb, m), dC (nb, m, p) of the piece. With dK:
    d(G_A Lambda) carries B_A dK B_A^T Lambda, and dw carries -dK B_A^T Lambda."""
    a, n = BA.shape
    q = W_s.shape[1]
    p = q - n
    cA = _at(phi, C, idx)
    dcA = _at_p(phi, dC, idx)
    r = np.empty(a)
    for s in range(a):
        t = -cA[s]
        for i in range(n):
            t += BA[s, i] * w_s[i]
        r[s] = t
    Lam = _mv(Gi, r)
    BtL = np.zeros(n)
    for s in range(a):
        for i in range(n):
            BtL[i] += BA[s, i] * Lam[s]
    # W_s - dK B_A^T Lambda (parameter columns)
    V = W_s.copy()
    for i in range(n):
        for j in range(p):
            V[i, n + j] -= dk[i, j] * BtL[i]
    R = np.zeros((a, q))
    for s in range(a):
        for i in range(n):
            bi = BA[s, i]
            for c in range(q):
                R[s, c] += bi * V[i, c]
        for j in range(p):
            R[s, n + j] -= dcA[s, j]
    dLam = _mm(Gi, R)
    w_e = np.empty(n)
    for i in range(n):
        w_e[i] = w_s[i] - k[i] * BtL[i]
    dW = V
    for i in range(n):
        for s in range(a):
            f = k[i] * BA[s, i]
            for c in range(q):
                dW[i, c] -= f * dLam[s, c]
    return Lam, dLam, w_e, dW


@jit
def _saltation(
    B: np.ndarray,
    rows: np.ndarray,
    phi_e: np.ndarray,
    dcoef: np.ndarray,
    dC: np.ndarray,
    W_e: np.ndarray,
    v_b: np.ndarray,
    u_e: float,
    times: np.ndarray,
    edges: np.ndarray,
    coincident: float,
    touch: float,
    column_kinks: np.ndarray,
) -> tuple[np.ndarray, int]:
    """du of a hit of ``rows`` at u_e (eq. (saltation)) and its kink bits."""
    m, n = B.shape
    q = W_e.shape[1]
    nr = rows.shape[0]
    c1 = np.zeros(m)
    for b in range(phi_e.shape[0]):
        for i in range(m):
            c1[i] += phi_e[b] * dcoef[b, i]
    size = 1e-300
    for i in range(m):
        size = max(size, abs(c1[i]))
    rates = np.empty(nr)
    dg = np.zeros((nr, q))
    dcr = _at_p(phi_e, dC, rows)
    for s in range(nr):
        t = 0.0
        for i in range(n):
            t += B[rows[s], i] * v_b[i]
        rates[s] = t - c1[rows[s]]
        for i in range(n):
            bi = B[rows[s], i]
            for c in range(q):
                dg[s, c] += bi * W_e[i, c]
        for j in range(q - n):
            dg[s, n + j] -= dcr[s, j]
    best = 0
    for s in range(1, nr):
        if abs(rates[s]) > abs(rates[best]):
            best = s
    du = np.zeros(q)
    bits = 0
    if abs(rates[best]) <= touch * size:
        bits |= ZERO_RATE
    else:
        for c in range(q):
            du[c] = -dg[best, c] / rates[best]
        apart = False
        for c in range(q):
            spread = 0.0
            top = 0.0
            for s in range(nr):
                d = -dg[s, c] / rates[s]
                spread = max(spread, abs(d - du[c]))
                top = max(top, abs(d))
            if nr > 1 and spread > 1e-7 * (abs(du[c]) + 1e-300 + top) + 1e3 * EPS:
                column_kinks[c] = True
                apart = True
        if apart:
            bits |= APART
    close = 0
    for t in times:
        if abs(t - u_e) <= coincident:
            close += 1
    near_edge = False
    for e in edges:
        if abs(e - u_e) <= coincident:
            near_edge = True
    if close > 1 or near_edge:
        bits |= COINCIDENT
    return du, bits


@jit
def _rate(Gi: np.ndarray, phi: np.ndarray, dcoef: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The slip rates lambda_A = -G_A^{-1} c_A' at one time."""
    return -_mv(Gi, _at(phi, dcoef, idx))


@jit
def _dissipation(
    BA: np.ndarray,
    Gi: np.ndarray,
    idx: np.ndarray,
    k_moves: bool,
    mu_moves: bool,
    dk: np.ndarray,
    weights: np.ndarray,
    Phi: np.ndarray,
    Mu: np.ndarray,
    dMu: np.ndarray,
    dcoef: np.ndarray,
    dC1: np.ndarray,
    phi_s: np.ndarray,
    phi_e: np.ndarray,
    du_s: np.ndarray,
    du_e: np.ndarray,
    D: np.ndarray,
) -> tuple[float, np.ndarray]:
    """int mu_A . lambda_A over a flow, lambda_A = -G_A^{-1} c_A' (Gauss-Legendre ``weights``
    at the samples Phi), its tangent into D and the slip rates at the samples. With
    v = G_A^{-T} (weights mu_A) at each sample, int mu_A . dlambda_A = -sum v . (dc_A' +
    B_A dK B_A^T lambda_A); the terms linear in phi are summed over the samples first, so each
    parameter column costs O(nb a). dmu_A adds sum weights lambda_A . dmu_A; an end that moves
    (a hit) adds the power there times du."""
    a, n = BA.shape
    nq, nb = Phi.shape
    p = dk.shape[1]
    lam_x = np.zeros((nq, a))
    Vb = np.zeros((nb, a))  # sum_x phi(x) v(x)
    Lb = np.zeros((nb, a))  # sum_x weights phi(x) lambda_A(x)
    Q = np.zeros(n)  # sum_x (B_A^T v)_i (B_A^T lambda_A)_i
    c1 = np.empty(a)
    mu = np.empty(a)
    v = np.empty(a)
    total = 0.0
    for x in range(nq):
        for s in range(a):
            t1 = 0.0
            t2 = 0.0
            for b in range(nb):
                t1 += Phi[x, b] * dcoef[b, idx[s]]
                t2 += Phi[x, b] * Mu[b, idx[s]]
            c1[s] = t1
            mu[s] = weights[x] * t2
        for s in range(a):
            t1 = 0.0
            t2 = 0.0
            for r in range(a):
                t1 -= Gi[s, r] * c1[r]
                t2 += mu[r] * Gi[r, s]
            lam_x[x, s] = t1
            v[s] = t2
        for s in range(a):
            total += mu[s] * lam_x[x, s]
            for b in range(nb):
                Vb[b, s] += Phi[x, b] * v[s]
                Lb[b, s] += Phi[x, b] * weights[x] * lam_x[x, s]
        if k_moves:
            for i in range(n):
                bv = 0.0
                bl = 0.0
                for s in range(a):
                    bv += BA[s, i] * v[s]
                    bl += BA[s, i] * lam_x[x, s]
                Q[i] += bv * bl
    for j in range(p):
        t = 0.0
        for b in range(nb):
            for s in range(a):
                t += Vb[b, s] * dC1[b, idx[s], j]
        if k_moves:
            for i in range(n):
                t += Q[i] * dk[i, j]
        D[n + j] -= t
        if mu_moves:
            t = 0.0
            for b in range(nb):
                for s in range(a):
                    t += Lb[b, s] * dMu[b, idx[s], j]
            D[n + j] += t
    for end in range(2):
        phi = phi_e if end == 0 else phi_s
        du = du_e if end == 0 else du_s
        sign = 1.0 if end == 0 else -1.0
        moves = False
        for c in range(du.shape[0]):
            if du[c] != 0.0:
                moves = True
        if moves:
            power = 0.0
            rate = _rate(Gi, phi, dcoef, idx)
            muA = _at(phi, Mu, idx)
            for s in range(a):
                power += muA[s] * rate[s]
            for c in range(du.shape[0]):
                D[c] += sign * power * du[c]
    return total, lam_x


@jit
def gap_coefficients(
    B: np.ndarray, k: np.ndarray, BA: np.ndarray, Gi: np.ndarray, idx: np.ndarray, w: np.ndarray, coef: np.ndarray
) -> np.ndarray:
    """Every row's gap on a flow on A from w as coefficients of phi (nb, m): gap(u) =
    phi(u) @ out = B w(u) - c(u), w(u) = w - K B_A^T G_A^{-1} (B_A w - c_A(u)); coef = C_p."""
    m, n = B.shape
    nb = coef.shape[0]
    a = idx.shape[0]
    Wc = np.zeros((nb, n))
    for i in range(n):
        Wc[0, i] = w[i]
    if a:
        t = _mv(Gi, _mv(BA, w))
        M = np.zeros((nb, a))
        for b in range(nb):
            for s in range(a):
                for r in range(a):
                    M[b, s] += coef[b, idx[r]] * Gi[s, r]
        for i in range(n):
            back = 0.0
            for s in range(a):
                back += BA[s, i] * t[s]
            Wc[0, i] -= k[i] * back
            for b in range(nb):
                f = 0.0
                for s in range(a):
                    f += M[b, s] * BA[s, i]
                Wc[b, i] += f * k[i]
    out = np.empty((nb, m))
    for b in range(nb):
        for r in range(m):
            t2 = -coef[b, r]
            for i in range(n):
                t2 += Wc[b, i] * B[r, i]
            out[b, r] = t2
    return out


@jit
def _gap_screen(
    B: np.ndarray,
    k: np.ndarray,
    BA: np.ndarray,
    Gi: np.ndarray,
    idx: np.ndarray,
    ends: np.ndarray,
    w: np.ndarray,
    coef: np.ndarray,
    grid: np.ndarray,
    values_phi: np.ndarray,
    H: int,
    first: int,
    tol: float,
) -> bool:
    """Whether an inactive row's gap may touch zero inside the flow: it comes within 2 tol of
    zero (between the samples by the interpolant's bound h^2/8 max|gap''|) and is largest
    inside, or it stays within 2 tol of zero (the caller decides on the closed form)."""
    m = B.shape[0]
    nb = coef.shape[0]
    outside = np.ones(m, dtype=np.bool_)
    for r in idx:
        outside[r] = False
    for r in ends:
        outside[r] = False
    Gc = gap_coefficients(B, k, BA, Gi, idx, w, coef)
    h = 0.0
    for x in range(grid.shape[0] - 1):
        h = max(h, grid[x + 1] - grid[x])
    ns = values_phi.shape[0]
    for r in range(m):
        if not outside[r]:
            continue
        g = Gc[:, r]
        curv = 0.0
        for hh in range(1, H + 1):
            curv += (TWO_PI * hh) ** 2 * (abs(g[first + 2 * (hh - 1)]) + abs(g[first + 2 * (hh - 1) + 1]))
        # first the ends: below its chord, a gap exceeds neither end by more than
        # length^2/8 max|gap''|, so a row whose ends lie that far (plus the samples' own bound
        # and their roundoff) below -2 tol cannot be flagged by the samples either
        start, end, size = 0.0, 0.0, 0.0
        for b in range(nb):
            start += values_phi[0, b] * g[b]
            end += values_phi[ns - 1, b] * g[b]
            size += abs(g[b])
        length = grid[ns - 1] - grid[0]
        reach = (length * length + h * h) / 8.0 * curv + 8.0 * nb * EPS * size
        if max(start, end) + reach < -2.0 * tol:
            continue
        top = -np.inf
        inner_top = -np.inf
        inner_low = np.inf
        for x in range(ns):
            v = 0.0
            for b in range(nb):
                v += values_phi[x, b] * g[b]
            top = max(top, v)
            if 0 < x < ns - 1:
                inner_top = max(inner_top, v)
                inner_low = min(inner_low, v)
        if inner_low >= -2.0 * tol:
            return True  # flat at zero
        if top + h * h / 8.0 * curv >= -2.0 * tol and inner_top >= top - tol:
            return True
    return False


@jit
def _jump(
    B: np.ndarray,
    k: np.ndarray,
    dk: np.ndarray,
    C: np.ndarray,
    Mu: np.ndarray,
    dC: np.ndarray,
    dMu: np.ndarray,
    mu_moves: bool,
    idx: np.ndarray,
    phi: np.ndarray,
    w: np.ndarray,
    Wt: np.ndarray,
    lam: np.ndarray,
    L: np.ndarray,
    D: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float]:
    """A jump of c (a ``steps`` signal): the projection on its active set A with phi the basis
    at the jump; the slips and their tangents join lam and L, mu . Lambda and its tangent D.
    Returns the state, its tangent and mu . Lambda."""
    n = B.shape[1]
    p = dk.shape[1]
    a = idx.shape[0]
    BA, Gi = factor(B, k, idx)
    Lam, dLam, w, Wt = solve_on(BA, Gi, idx, k, dk, w, Wt, phi, C, dC)
    muA = _at(phi, Mu, idx)
    diss = 0.0
    for s in range(a):
        lam[idx[s]] += Lam[s]
        L[idx[s]] += dLam[s]
        diss += muA[s] * Lam[s]
        D += muA[s] * dLam[s]
    if mu_moves:
        dmuA = _at_p(phi, dMu, idx)
        for s in range(a):
            for c in range(p):
                D[n + c] += Lam[s] * dmuA[s, c]
    return w, Wt, diss


@jit
def _samples(
    u_s: float,
    u_e: float,
    gx: np.ndarray,
    gw: np.ndarray,
    linear: bool,
    H: int,
    grid: np.ndarray,
    weights: np.ndarray,
    stacked: np.ndarray,
) -> None:
    """A flow's samples: its ends and Gauss-Legendre nodes (``grid``), the weights of the
    nodes and the basis at all of them (``stacked``, ends first and last)."""
    nq = gx.shape[0]
    length = u_e - u_s
    grid[0] = u_s
    grid[nq + 1] = u_e
    for x in range(nq):
        grid[x + 1] = u_s + 0.5 * length * (gx[x] + 1.0)
        weights[x] = 0.5 * length * gw[x]
    for x in range(nq + 2):
        basis_values(grid[x], 0, linear, H, stacked[x])


@jit
def _velocity(BA: np.ndarray, k: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """w' = -K B_A^T lambda_A for the slip rates lambda_A."""
    v = np.zeros(BA.shape[1])
    for s in range(BA.shape[0]):
        for i in range(BA.shape[1]):
            v[i] -= k[i] * BA[s, i] * rate[s]
    return v


@jit
def _outer_add(X: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """X += outer(a, b)."""
    for i in range(a.shape[0]):
        for c in range(b.shape[0]):
            X[i, c] += a[i] * b[c]


@jit
def _rate_screen(Phi: np.ndarray, dcoef: np.ndarray, lam_x: np.ndarray, touch: float) -> bool:
    """Whether an active row's slip rate (``lam_x`` at the samples Phi) comes within twice the
    walk's tolerance of zero, relative to the size of c' on the samples (the caller decides
    on the closed form)."""
    size = 1e-300
    for x in range(Phi.shape[0]):
        for i in range(dcoef.shape[1]):
            t = 0.0
            for b in range(Phi.shape[1]):
                t += Phi[x, b] * dcoef[b, i]
            size = max(size, abs(t))
    low = np.inf
    for x in range(lam_x.shape[0]):
        for s in range(lam_x.shape[1]):
            low = min(low, lam_x[x, s])
    return bool(low <= 2.0 * touch * size)


@jit
def coefficient_derivatives(C: np.ndarray, dC: np.ndarray, linear: bool, H: int) -> tuple[np.ndarray, np.ndarray]:
    """The coefficients of c' and dc' on every piece, (P, nb, m) and (P, nb, m, p), from those
    of c and dc (`crawlsim.kernel.piece.derivative`: each entry a single product)."""
    dcoef = np.empty_like(C)
    dC1 = np.empty_like(dC)
    for a in range(C.shape[0]):
        derivative(C[a], linear, H, dcoef[a])
        derivative(dC[a], linear, H, dC1[a])
    return dcoef, dC1


@jit
def walk_exact(
    B: np.ndarray,
    k: np.ndarray,
    C: np.ndarray,
    Mu: np.ndarray,
    dC: np.ndarray,
    dMu: np.ndarray,
    dk: np.ndarray,
    linear: bool,
    H: int,
    edges: np.ndarray,
    u: np.ndarray,
    piece: np.ndarray,
    cause: np.ndarray,
    act: np.ndarray,
    hit: np.ndarray,
    gx: np.ndarray,
    gw: np.ndarray,
    w0: np.ndarray,
    scale: float,
    coincident: float,
    touch: float,
    W: np.ndarray,
    L: np.ndarray,
    D: np.ndarray,
    lam: np.ndarray,
    w_end: np.ndarray,
    kink: np.ndarray,
    column_kinks: np.ndarray,
    gap_flag: np.ndarray,
    rate_flag: np.ndarray,
    w_start: np.ndarray,
    W_start: np.ndarray,
) -> float:
    """The exact integrator's limit period walked from w0 along its transitions (module
    docstring); C, Mu (P, nb, m), dC, dMu (P, nb, m, p), dk (n, p); per transition its cycle
    u, piece, cause, the active rows after it and the rows it hit (masks (K, m)). Fills the
    tangents W (n, q), L (m, q), D (q,), the slips lam, the end state, the kink bits and the
    flags of flows to examine for touches; returns the dissipation."""
    m, n = B.shape
    p = dk.shape[1]
    q = n + p
    K = u.shape[0]
    nb = C.shape[1]
    nq = gx.shape[0]
    first = 2 if linear else 1
    k_moves = bool(np.any(dk != 0.0))
    mu_moves = bool(np.any(dMu != 0.0))
    dcoef, dC1 = coefficient_derivatives(C, dC, linear, H)
    w = w0.copy()
    Wt = np.zeros((n, q))
    for i in range(n):
        Wt[i, i] = 1.0
    L[:] = 0.0
    D[:] = 0.0
    lam[:] = 0.0
    column_kinks[:] = False
    diss = 0.0
    du_start = np.zeros(q)
    phi = np.empty(nb)
    stacked = np.empty((nq + 2, nb))
    grid = np.empty(nq + 2)
    weights = np.empty(nq)
    kink[:] = 0
    gap_flag[:] = False
    rate_flag[:] = False
    for j in range(K):
        w_start[j] = w
        W_start[j] = Wt
        idx = np.flatnonzero(act[j])
        a = idx.shape[0]
        pc = piece[j]
        if cause[j] == JUMP:
            if a:
                uj = u[j]
                if pc == 0 and uj >= 1.0 - 1e-15:
                    uj = 0.0
                basis_values(uj, 0, linear, H, phi)
                w, Wt, part = _jump(B, k, dk, C[pc], Mu[pc], dC[pc], dMu[pc], mu_moves, idx, phi, w, Wt, lam, L, D)
                diss += part
                du_start = np.zeros(q)
            continue
        has_next = j + 1 < K
        u_s = u[j]
        u_e = u[j + 1] if has_next else 1.0
        length = u_e - u_s
        _samples(u_s, u_e, gx, gw, linear, H, grid, weights, stacked)
        phi_s, phi_e = stacked[0], stacked[nq + 1]
        Phi = stacked[1 : nq + 1]
        if a:
            BA, Gi = factor(B, k, idx)
            Lam, dLam, w_e, W_e = solve_on(BA, Gi, idx, k, dk, w, Wt, phi_e, C[pc], dC[pc])
            # the slip rates and the velocity at the end: lambda = -G^{-1} c_A',
            # w' = K B_A^T G^{-1} c_A'
            rate_e = _rate(Gi, phi_e, dcoef[pc], idx)
            v_b = _velocity(BA, k, rate_e)
        else:
            BA, Gi = np.zeros((0, n)), np.zeros((0, 0))
            Lam, dLam = np.zeros(0), np.zeros((0, q))
            w_e, W_e = w.copy(), Wt.copy()
            rate_e, v_b = np.zeros(0), np.zeros(n)
        du = np.zeros(q)
        hits = has_next and cause[j + 1] == HIT
        rows = np.flatnonzero(hit[j + 1]) if hits else np.zeros(0, dtype=np.int64)
        if hits:
            du, bits = _saltation(
                B, rows, phi_e, dcoef[pc], dC[pc], W_e, v_b, u_e, u, edges, coincident, touch, column_kinks
            )
            kink[j + 1] = bits
            _outer_add(W_e, v_b, du)
            _outer_add(dLam, rate_e, du)
        if a:
            for s in range(a):
                lam[idx[s]] += Lam[s]
                L[idx[s]] += dLam[s]
            if length > 0:
                part, lam_x = _dissipation(
                    BA,
                    Gi,
                    idx,
                    k_moves,
                    mu_moves,
                    dk,
                    weights,
                    Phi,
                    Mu[pc],
                    dMu[pc],
                    dcoef[pc],
                    dC1[pc],
                    phi_s,
                    phi_e,
                    du_start,
                    du,
                    D,
                )
                diss += part
                if length > 4 * coincident:
                    rate_flag[j] = _rate_screen(Phi, dcoef[pc], lam_x, touch)
        if length > 4 * coincident:
            gap_flag[j] = _gap_screen(B, k, BA, Gi, idx, rows, w, C[pc], grid, stacked, H, first, touch * scale)
        w, Wt = w_e, W_e
        du_start = du
    W[:] = Wt
    w_end[:] = w
    return diss
