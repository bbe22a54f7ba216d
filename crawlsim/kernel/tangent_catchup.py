"""The tangent walk of the catch-up scheme's limit period, compiled
(`crawlsim.analysis.sensitivity_walk`, docs/sensitivity.md, eq. (catch-up)): the discrete period
map walked run by run on its active sets, with the offsets and friction on the grid
(`grid_values`) and the runs and touches of the record (`catch_up_runs`). The formulas it shares
with the exact walk (`factor`, `solve_on`) are those of `crawlsim.kernel.tangent`.

Plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same source runs as Python.
"""

from __future__ import annotations

import numpy as np

from crawlsim.kernel.jit import jit
from crawlsim.kernel.piece import basis_values
from crawlsim.kernel.tangent import factor, solve_on


@jit
def grid_values(
    times: np.ndarray,
    period: float,
    edges: np.ndarray,
    linear: bool,
    H: int,
    C: np.ndarray,
    Mu: np.ndarray,
    dC: np.ndarray,
    dMu: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What the steps of every run read at the catch-up grid's times (`_steps`), independent
    of the limit period, so computed once per gait and parameters, in one pass: each time's
    cycle u_j = t_j / T mod 1 (c(1) is c(0)), its piece (the last edge <= u_j), the basis
    phi(u_j), and c, mu (G+1, m) with their parameter columns dc, dmu (G+1, m, p),
    phi(u_j) @ (C, Mu, dC, dMu) of u_j's piece, each a sum over the basis in its order."""
    G1 = times.shape[0]
    P, nb, m = C.shape
    p = dC.shape[3]
    u = np.empty(G1)
    pieces = np.empty(G1, dtype=np.int64)
    Phi = np.empty((G1, nb))
    c = np.zeros((G1, m))
    mu = np.zeros((G1, m))
    dc = np.zeros((G1, m, p))
    dmu = np.zeros((G1, m, p))
    mu_moves = np.any(dMu != 0.0)  # (a link's number leaves the friction: its columns are 0)
    for j in range(G1):
        x = (times[j] / period) % 1.0
        u[j] = x
        lo, hi = 0, edges.shape[0]  # the number of edges <= x, by bisection
        while lo < hi:
            mid = (lo + hi) // 2
            if edges[mid] <= x:
                lo = mid + 1
            else:
                hi = mid
        pc = min(lo - 1, P - 1)
        pieces[j] = pc
        phi = Phi[j]
        basis_values(x, 0, linear, H, phi)
        # each entry summed over the basis in its order, the rows innermost (contiguous)
        cj, muj, dcj, dmuj = c[j], mu[j], dc[j], dmu[j]
        for b in range(nb):
            f = phi[b]
            for r_ in range(m):
                cj[r_] += f * C[pc, b, r_]
                muj[r_] += f * Mu[pc, b, r_]
                for col in range(p):
                    dcj[r_, col] += f * dC[pc, b, r_, col]
            if mu_moves:
                for r_ in range(m):
                    for col in range(p):
                        dmuj[r_, col] += f * dMu[pc, b, r_, col]
    return u, pieces, Phi, c, mu, dc, dmu


@jit
def catch_up_runs(
    multipliers: np.ndarray, w: np.ndarray, B: np.ndarray, offsets: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
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
    return active, weak, starts[: R + 1].copy(), runs_weak, scale_w


@jit
def _steps(
    BA: np.ndarray,
    Gi: np.ndarray,
    idx: np.ndarray,
    k_moves: bool,
    dk: np.ndarray,
    values: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    j0: int,
    j1: int,
    D: np.ndarray,
    buffers: tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
    ],
) -> float:
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


@jit
def walk_catch_up(
    B: np.ndarray,
    k: np.ndarray,
    C: np.ndarray,
    dC: np.ndarray,
    dk: np.ndarray,
    Phi: np.ndarray,
    pieces: np.ndarray,
    values: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    active: np.ndarray,
    starts: np.ndarray,
    w0: np.ndarray,
    W: np.ndarray,
    L: np.ndarray,
    D: np.ndarray,
    lam: np.ndarray,
    w_end: np.ndarray,
    w_start: np.ndarray,
    W_start: np.ndarray,
) -> float:
    """The catch-up scheme's discrete period map walked from w0 (eq. (catch-up)): the grid's
    basis values Phi (G+1, nb) and pieces, the active rows of each step (G, m), the first step
    of each run on one active set (``starts``, G at the end). A run on A telescopes to the
    piece formula at its last grid time; its steps' slips are
    Lambda_j = G_A^{-1} (B_A w_j - c_A(u_{j+1})), B_A w_j = c_A(u_j) after the first, with their
    tangents, and the dissipation is sum_j mu(u_{j+1}) . Lambda_j (``values``: c, mu and their
    columns on the grid, `grid_values`). Fills the tangents and the start of each run (for the
    caller's touches); returns the dissipation. The caller checks once that c's closed form
    reproduces the grid's offsets."""
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
        diss += _steps(BA, Gi, idx, k_moves, dk, values, j0, j1, D, (prev, c_j, mu_j, lam_j, dprev, R, dc_j, dmu_j, Bl))
        for s in range(a):
            lam[idx[s]] += Lam[s]
            L[idx[s]] += dLam[s]
        w, Wt = w_e, W_e
    W[:] = Wt
    w_end[:] = w
    return diss
