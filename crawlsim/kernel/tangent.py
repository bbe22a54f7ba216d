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
from numba import njit

# the transition causes, coded as the compiled event loop codes them
from crawlsim.kernel.eventloop import CAUSES, HIT, JUMP  # noqa: F401 - CAUSES for the callers
from crawlsim.kernel.piece import basis_values

TWO_PI = 2.0 * math.pi
EPS = float(np.finfo(np.float64).eps)
#: Bits of ``kink`` at a hit: reached with zero rate, rows reached together move apart, reached
#: at the time of another event.
ZERO_RATE, APART, COINCIDENT = 1, 2, 4


@njit(cache=True)
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


@njit(cache=True)
def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A @ x, in loops (the same sums compiled and as Python)."""
    out = np.zeros(A.shape[0])
    for r in range(A.shape[0]):
        t = 0.0
        for c in range(A.shape[1]):
            t += A[r, c] * x[c]
        out[r] = t
    return out


@njit(cache=True)
def _mm(A: np.ndarray, X: np.ndarray) -> np.ndarray:
    """A @ X, in loops."""
    out = np.zeros((A.shape[0], X.shape[1]))
    for r in range(A.shape[0]):
        for s in range(A.shape[1]):
            f = A[r, s]
            for c in range(X.shape[1]):
                out[r, c] += f * X[s, c]
    return out


@njit(cache=True)
def _at(phi: np.ndarray, coef: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """phi @ coef[:, idx] for coef (nb, m)."""
    out = np.zeros(idx.shape[0])
    for b in range(phi.shape[0]):
        for r in range(idx.shape[0]):
            out[r] += phi[b] * coef[b, idx[r]]
    return out


@njit(cache=True)
def _at_p(phi: np.ndarray, coef: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """phi . coef[:, idx, :] for coef (nb, m, p): (a, p)."""
    p = coef.shape[2]
    out = np.zeros((idx.shape[0], p))
    for b in range(phi.shape[0]):
        for r in range(idx.shape[0]):
            for j in range(p):
                out[r, j] += phi[b] * coef[b, idx[r], j]
    return out


@njit(cache=True)
def solve_on(BA: np.ndarray, Gi: np.ndarray, idx: np.ndarray, k: np.ndarray, dk: np.ndarray,
             w_s: np.ndarray, W_s: np.ndarray, phi: np.ndarray, C: np.ndarray,
             dC: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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


@njit(cache=True)
def _saltation(B: np.ndarray, rows: np.ndarray, phi_e: np.ndarray, dcoef: np.ndarray,
               dC: np.ndarray, W_e: np.ndarray, v_b: np.ndarray, u_e: float, times: np.ndarray,
               edges: np.ndarray, coincident: float, touch: float,
               column_kinks: np.ndarray) -> tuple[np.ndarray, int]:
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


@njit(cache=True)
def _rate(Gi: np.ndarray, phi: np.ndarray, dcoef: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The slip rates lambda_A = -G_A^{-1} c_A' at one time."""
    return -_mv(Gi, _at(phi, dcoef, idx))


@njit(cache=True)
def _dissipation(BA: np.ndarray, Gi: np.ndarray, idx: np.ndarray, k_moves: bool, mu_moves: bool,
                 dk: np.ndarray, weights: np.ndarray, Phi: np.ndarray, Mu: np.ndarray,
                 dMu: np.ndarray, dcoef: np.ndarray, dC1: np.ndarray, phi_s: np.ndarray,
                 phi_e: np.ndarray, du_s: np.ndarray, du_e: np.ndarray,
                 D: np.ndarray) -> tuple[float, np.ndarray]:
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


@njit(cache=True)
def gap_coefficients(B: np.ndarray, k: np.ndarray, BA: np.ndarray, Gi: np.ndarray,
                     idx: np.ndarray, w: np.ndarray, coef: np.ndarray) -> np.ndarray:
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


@njit(cache=True)
def _gap_screen(B: np.ndarray, k: np.ndarray, BA: np.ndarray, Gi: np.ndarray, idx: np.ndarray,
                ends: np.ndarray, w: np.ndarray, coef: np.ndarray, grid: np.ndarray,
                values_phi: np.ndarray, H: int, first: int, tol: float) -> bool:
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
            curv += (TWO_PI * hh) ** 2 * (abs(g[first + 2 * (hh - 1)])
                                          + abs(g[first + 2 * (hh - 1) + 1]))
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


@njit(cache=True)
def _jump(B: np.ndarray, k: np.ndarray, dk: np.ndarray, C: np.ndarray, Mu: np.ndarray,
          dC: np.ndarray, dMu: np.ndarray, mu_moves: bool, idx: np.ndarray, phi: np.ndarray,
          w: np.ndarray, Wt: np.ndarray, lam: np.ndarray, L: np.ndarray,
          D: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
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


@njit(cache=True)
def _samples(u_s: float, u_e: float, gx: np.ndarray, gw: np.ndarray, linear: bool, H: int,
             grid: np.ndarray, weights: np.ndarray, stacked: np.ndarray) -> None:
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


@njit(cache=True)
def _velocity(BA: np.ndarray, k: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """w' = -K B_A^T lambda_A for the slip rates lambda_A."""
    v = np.zeros(BA.shape[1])
    for s in range(BA.shape[0]):
        for i in range(BA.shape[1]):
            v[i] -= k[i] * BA[s, i] * rate[s]
    return v


@njit(cache=True)
def _outer_add(X: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """X += outer(a, b)."""
    for i in range(a.shape[0]):
        for c in range(b.shape[0]):
            X[i, c] += a[i] * b[c]


@njit(cache=True)
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


@njit(cache=True)
def walk_exact(B: np.ndarray, k: np.ndarray, C: np.ndarray, Mu: np.ndarray, dC: np.ndarray,
               dMu: np.ndarray, dk: np.ndarray, dcoef: np.ndarray, dC1: np.ndarray,
               linear: bool, H: int, edges: np.ndarray, u: np.ndarray, piece: np.ndarray,
               cause: np.ndarray, act: np.ndarray, hit: np.ndarray, gx: np.ndarray,
               gw: np.ndarray, w0: np.ndarray, scale: float,
               coincident: float, touch: float, W: np.ndarray, L: np.ndarray, D: np.ndarray,
               lam: np.ndarray, w_end: np.ndarray, kink: np.ndarray, column_kinks: np.ndarray,
               gap_flag: np.ndarray, rate_flag: np.ndarray, w_start: np.ndarray,
               W_start: np.ndarray) -> float:
    """The exact integrator's limit period walked from w0 along its transitions (module
    docstring); C, Mu (P, nb, m), dC, dMu (P, nb, m, p), dk (n, p), dcoef and dC1 the
    derivatives in u of C and dC; per transition its cycle u, piece, cause, the active rows
    after it and the rows it hit (masks (K, m)). Fills the tangents W (n, q),
    L (m, q), D (q,), the slips lam, the end state, the kink bits and the flags of flows to
    examine for touches; returns the dissipation."""
    m, n = B.shape
    p = dk.shape[1]
    q = n + p
    K = u.shape[0]
    nb = C.shape[1]
    nq = gx.shape[0]
    first = 2 if linear else 1
    k_moves = bool(np.any(dk != 0.0))
    mu_moves = bool(np.any(dMu != 0.0))
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
                w, Wt, part = _jump(B, k, dk, C[pc], Mu[pc], dC[pc], dMu[pc], mu_moves, idx,
                                    phi, w, Wt, lam, L, D)
                diss += part
                du_start = np.zeros(q)
            continue
        has_next = j + 1 < K
        u_s = u[j]
        u_e = u[j + 1] if has_next else 1.0
        length = u_e - u_s
        _samples(u_s, u_e, gx, gw, linear, H, grid, weights, stacked)
        phi_s, phi_e = stacked[0], stacked[nq + 1]
        Phi = stacked[1:nq + 1]
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
            du, bits = _saltation(B, rows, phi_e, dcoef[pc], dC[pc], W_e, v_b, u_e, u,
                                  edges, coincident, touch, column_kinks)
            kink[j + 1] = bits
            _outer_add(W_e, v_b, du)
            _outer_add(dLam, rate_e, du)
        if a:
            for s in range(a):
                lam[idx[s]] += Lam[s]
                L[idx[s]] += dLam[s]
            if length > 0:
                part, lam_x = _dissipation(BA, Gi, idx, k_moves, mu_moves, dk, weights, Phi, Mu[pc],
                                           dMu[pc], dcoef[pc], dC1[pc], phi_s, phi_e,
                                           du_start, du, D)
                diss += part
                if length > 4 * coincident:
                    rate_flag[j] = _rate_screen(Phi, dcoef[pc], lam_x, touch)
        if length > 4 * coincident:
            gap_flag[j] = _gap_screen(B, k, BA, Gi, idx, rows, w, C[pc], grid, stacked, H,
                                      first, touch * scale)
        w, Wt = w_e, W_e
        du_start = du
    W[:] = Wt
    w_end[:] = w
    return diss


@njit(cache=True)
def grid_agrees(Phi: np.ndarray, pieces: np.ndarray, C: np.ndarray, offsets: np.ndarray,
                atol: float) -> bool:
    """Whether the closed form of c reproduces the catch-up grid's offsets to ``atol``."""
    agrees = True
    for g in range(Phi.shape[0]):
        pc = pieces[g]
        for i in range(offsets.shape[1]):
            t = 0.0
            for b in range(Phi.shape[1]):
                t += Phi[g, b] * C[pc, b, i]
            if not abs(t - offsets[g, i]) <= atol:
                agrees = False
    return agrees


@njit(cache=True)
def grid_values(Phi: np.ndarray, pieces: np.ndarray, C: np.ndarray, Mu: np.ndarray,
                dC: np.ndarray, dMu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                          np.ndarray]:
    """c, mu (G+1, m) and their parameter columns dc, dmu (G+1, m, p) at every grid time of
    the catch-up walk, phi(u_j) @ (C, Mu, dC, dMu) of u_j's piece, each a sum over the basis
    in its order: what the steps of every run read (`_steps`), independent of the limit
    period, so computed once per gait and parameters."""
    G1, nb = Phi.shape
    m = C.shape[2]
    p = dC.shape[3]
    c = np.empty((G1, m))
    mu = np.empty((G1, m))
    dc = np.empty((G1, m, p))
    dmu = np.empty((G1, m, p))
    for j in range(G1):
        pc = pieces[j]
        for r_ in range(m):
            t1 = 0.0
            t2 = 0.0
            for b in range(nb):
                t1 += Phi[j, b] * C[pc, b, r_]
                t2 += Phi[j, b] * Mu[pc, b, r_]
            c[j, r_] = t1
            mu[j, r_] = t2
            for col in range(p):
                t1 = 0.0
                t2 = 0.0
                for b in range(nb):
                    t1 += Phi[j, b] * dC[pc, b, r_, col]
                    t2 += Phi[j, b] * dMu[pc, b, r_, col]
                dc[j, r_, col] = t1
                dmu[j, r_, col] = t2
    return c, mu, dc, dmu


@njit(cache=True)
def catch_up_runs(multipliers: np.ndarray, w: np.ndarray, B: np.ndarray, offsets: np.ndarray,
                  tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """A catch-up limit period's runs (eq. (catch-up)): the active rows of each step (a
    positive multiplier, (G, m)), the rows tight at w_{j+1} to ``tol`` with a zero multiplier
    (``weak``, (G, m): a touch), the first step of each run on one active set (with G at the
    end), whether each run holds a weak row, and max |w| over the period (the scale of the
    walk's check of the end state); one pass over the record."""
    G, m = multipliers.shape
    n = B.shape[1]
    active = np.empty((G, m), dtype=np.bool_)
    weak = np.zeros((G, m), dtype=np.bool_)
    for j in range(G):
        for r in range(m):
            active[j, r] = multipliers[j, r] > 0.0
            if not active[j, r]:
                t = 0.0
                for i in range(n):
                    t += w[j + 1, i] * B[r, i]
                weak[j, r] = abs(t - offsets[j + 1, r]) <= tol
    starts = np.empty(G + 1, dtype=np.int64)
    starts[0] = 0
    R = 1
    for j in range(1, G):
        for r in range(m):
            if active[j, r] != active[j - 1, r]:
                starts[R] = j
                R += 1
                break
    starts[R] = G
    runs_weak = np.zeros(R, dtype=np.bool_)
    for r_ in range(R):
        for j in range(starts[r_], starts[r_ + 1]):
            for r in range(m):
                if weak[j, r]:
                    runs_weak[r_] = True
    scale_w = 0.0
    for j in range(w.shape[0]):
        for i in range(n):
            scale_w = max(scale_w, abs(w[j, i]))
    return active, weak, starts[:R + 1].copy(), runs_weak, scale_w


@njit(cache=True)
def _steps(BA: np.ndarray, Gi: np.ndarray, idx: np.ndarray, k_moves: bool, dk: np.ndarray,
           values: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], j0: int, j1: int,
           D: np.ndarray,
           buffers: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                          np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> float:
    """The steps j0 + 1 .. j1 of a run on A: each step's slips
    Lambda_j = G_A^{-1} (B_A w_j - c_A(u_{j+1})) with their tangents, their dissipation
    mu(u_{j+1}) . Lambda_j returned and its tangent into D; ``values``: c, mu, dc and dmu at the
    grid times (`grid_values`). ``buffers`` hold B_A w_j and its
    tangent at the run's first step (``prev``, ``dprev``) and the per-step scratch, so that
    a step allocates nothing."""
    prev, c_j, mu_j, lam_j, dprev, R, dc_j, dmu_j, Bl = buffers
    cg, mug, dcg, dmug = values
    a, n = BA.shape
    p = dk.shape[1]
    q = n + p
    diss = 0.0
    for j in range(j0 + 1, j1 + 1):
        # c_A, mu_A and their parameter columns at u_j (`grid_values`; in the buffers: no
        # allocation per step)
        for s in range(a):
            r_ = idx[s]
            c_j[s] = cg[j, r_]
            mu_j[s] = mug[j, r_]
            for c in range(p):
                dc_j[s, c] = dcg[j, r_, c]
                dmu_j[s, c] = dmug[j, r_, c]
        # Lambda_j = G_A^{-1} (B_A w_j - c_A(u_{j+1})) and its tangent, with
        # d(G_A Lambda) = B_A dK B_A^T Lambda
        for s in range(a):
            t1 = 0.0
            for r_ in range(a):
                t1 += Gi[s, r_] * (prev[r_] - c_j[r_])
            lam_j[s] = t1
        for s in range(a):
            for c in range(n):
                R[s, c] = dprev[s, c]
            for c in range(p):
                R[s, n + c] = dprev[s, n + c] - dc_j[s, c]
        if k_moves:
            for i in range(n):
                t1 = 0.0
                for s in range(a):
                    t1 += lam_j[s] * BA[s, i]
                Bl[i] = t1
            for s in range(a):
                for i in range(n):
                    f = BA[s, i] * Bl[i]
                    for c in range(p):
                        R[s, n + c] -= f * dk[i, c]
        for s in range(a):
            diss += mu_j[s] * lam_j[s]
            for c in range(q):
                t1 = 0.0
                for r_ in range(a):
                    t1 += Gi[s, r_] * R[r_, c]
                D[c] += mu_j[s] * t1
            for c in range(p):
                D[n + c] += lam_j[s] * dmu_j[s, c]
        # B_A w_{j+1} = c_A(u_{j+1}) inside the run
        for s in range(a):
            prev[s] = c_j[s]
            for c in range(n):
                dprev[s, c] = 0.0
            for c in range(p):
                dprev[s, n + c] = dc_j[s, c]
    return diss


@njit(cache=True)
def walk_catch_up(B: np.ndarray, k: np.ndarray, C: np.ndarray, dC: np.ndarray, dk: np.ndarray,
                  Phi: np.ndarray, pieces: np.ndarray,
                  values: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                  active: np.ndarray, starts: np.ndarray, w0: np.ndarray, W: np.ndarray,
                  L: np.ndarray, D: np.ndarray, lam: np.ndarray, w_end: np.ndarray,
                  w_start: np.ndarray, W_start: np.ndarray) -> float:
    """The catch-up scheme's discrete period map walked from w0 (eq. (catch-up)): the grid's
    basis values Phi (G+1, nb) and pieces, the active rows of each step (G, m), the first step
    of each run on one active set (``starts``, G at the end). A run on A telescopes to the
    piece formula at its last grid time; its steps' slips are
    Lambda_j = G_A^{-1} (B_A w_j - c_A(u_{j+1})), B_A w_j = c_A(u_j) after the first, with their
    tangents, and the dissipation is sum_j mu(u_{j+1}) . Lambda_j (``values``: c, mu and their
    columns on the grid, `grid_values`). Fills the tangents and the start of each run (for the
    caller's touches); returns the dissipation. The caller checks once that c's closed form
    reproduces the grid's offsets (`grid_agrees`)."""
    m, n = B.shape
    p = dk.shape[1]
    q = n + p
    w = w0.copy()
    Wt = np.zeros((n, q))
    for i in range(n):
        Wt[i, i] = 1.0
    L[:] = 0.0
    D[:] = 0.0
    lam[:] = 0.0
    diss = 0.0
    k_moves = bool(np.any(dk != 0.0))
    prev, c_j, mu_j, lam_j = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    dprev, R = np.empty((m, q)), np.empty((m, q))
    dc_j, dmu_j = np.empty((m, p)), np.empty((m, p))
    Bl = np.empty(n)
    for r in range(starts.shape[0] - 1):
        j0, j1 = starts[r], starts[r + 1]
        w_start[r] = w
        W_start[r] = Wt
        idx = np.flatnonzero(active[j0])
        a = idx.shape[0]
        if a == 0:
            continue
        BA, Gi = factor(B, k, idx)
        pe = pieces[j1]
        Lam, dLam, w_e, W_e = solve_on(BA, Gi, idx, k, dk, w, Wt, Phi[j1], C[pe], dC[pe])
        # B_A w_j and its tangent at the run's first step
        for s in range(a):
            t = 0.0
            for i in range(n):
                t += BA[s, i] * w[i]
            prev[s] = t
            for c in range(q):
                t = 0.0
                for i in range(n):
                    t += BA[s, i] * Wt[i, c]
                dprev[s, c] = t
        diss += _steps(BA, Gi, idx, k_moves, dk, values, j0, j1, D,
                       (prev, c_j, mu_j, lam_j, dprev, R, dc_j, dmu_j, Bl))
        for s in range(a):
            lam[idx[s]] += Lam[s]
            L[idx[s]] += dLam[s]
        w, Wt = w_e, W_e
    W[:] = Wt
    w_end[:] = w
    return diss


@njit(cache=True)
def implicit(W: np.ndarray, L: np.ndarray, D: np.ndarray,
             blocks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                   float]:
    """The implicit function theorem at the limit for every parameter column of a walk (W, L,
    D over n + p columns): dw* = (I - dP/dw)^+ dP/dtheta, the least-squares solution of minimal
    norm from one SVD, singular values below 1e-12 of the largest dropped (a family of periodic
    solutions); dY = S (dLambda_w dw* + dLambda_theta), S the blocks' mean slip, and
    dD = D_w dw* + D_theta. Returns dw*, dY, dD, the sizes of their terms
    (|Y_theta| + |Y_w| |dw*|, likewise for D: what the caller's relative error multiplies) and
    the condition number of the kept part of the solve."""
    n = W.shape[0]
    q = W.shape[1]
    p = q - n
    Y = np.zeros(q)
    for c in range(q):
        t = 0.0
        for i in range(blocks):
            t += L[i, c]
        for i in range(blocks, 2 * blocks):
            t -= L[i, c]
        Y[c] = t / blocks
    A = np.eye(n)
    for i in range(n):
        for j in range(n):
            A[i, j] -= W[i, j]
    U, sv, Vt = np.linalg.svd(A)
    top = max(sv[0] if sv.shape[0] else 1.0, 1e-300)
    kept = 0
    for k in range(sv.shape[0]):
        if sv[k] > 1e-12 * top:
            kept += 1  # sv is in decreasing order: the kept ones come first
    dw = np.zeros((n, p))
    for k in range(kept):
        for c in range(p):
            t = 0.0
            for j in range(n):
                t += U[j, k] * W[j, n + c]
            t /= sv[k]
            for i in range(n):
                dw[i, c] += Vt[k, i] * t
    cond = sv[0] / sv[kept - 1] if kept else 1.0
    dY = np.empty(p)
    dD = np.empty(p)
    magY = np.empty(p)
    magD = np.empty(p)
    for c in range(p):
        y = Y[n + c]
        d = D[n + c]
        my = abs(Y[n + c])
        md = abs(D[n + c])
        for i in range(n):
            y += Y[i] * dw[i, c]
            d += D[i] * dw[i, c]
            my += abs(Y[i]) * abs(dw[i, c])
            md += abs(D[i]) * abs(dw[i, c])
        dY[c] = y
        dD[c] = d
        magY[c] = my
        magD[c] = md
    return dw, dY, dD, magY, magD, cond
