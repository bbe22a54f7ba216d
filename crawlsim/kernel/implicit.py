"""The implicit function theorem at a walked limit period, compiled (docs/sensitivity.md): the
derivatives of the periodic limit, of the displacement and of the dissipation per period from the
tangent of one period (`crawlsim.kernel.tangent`, `crawlsim.kernel.tangent_catchup`).

Plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same source runs as Python.
"""

from __future__ import annotations

import numpy as np

from crawlsim.kernel.jit import jit


@jit
def implicit(
    W: np.ndarray, L: np.ndarray, D: np.ndarray, blocks: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
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


@jit
def column_moves(C: np.ndarray, dC: np.ndarray, k: np.ndarray, dk: np.ndarray) -> np.ndarray:
    """Each parameter column's largest relative move of the offsets and the stiffness,
    max |dC[..., c]| / max(max |C|, 1e-300) + max |dk[:, c]| / min k, for C (P, nb, m), dC
    (P, nb, m, p), k (n,) and dk (n, p): the relative roundoff floor of that column's
    derivatives (the error terms of `crawlsim.analysis.sensitivity`)."""
    P, nb, m, p = dC.shape
    size_c = 1e-300
    for a in range(P):
        for b in range(nb):
            for r in range(m):
                size_c = max(size_c, abs(C[a, b, r]))
    k_min = np.inf
    for v in k:
        k_min = min(k_min, v)
    top_c = np.zeros(p)
    for a in range(P):
        for b in range(nb):
            for r in range(m):
                for c in range(p):
                    top_c[c] = max(top_c[c], abs(dC[a, b, r, c]))
    out = np.zeros(p)
    for c in range(p):
        top_k = 0.0
        for i in range(dk.shape[0]):
            top_k = max(top_k, abs(dk[i, c]))
        out[c] = top_c[c] / size_c + top_k / k_min
    return out
