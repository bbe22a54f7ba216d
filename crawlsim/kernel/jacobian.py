"""The compiled products J v and J^T v of a crawler's period-map Jacobian (docs/model.md §4).

The Jacobian of the period map from a start is the product of the factors visited in its
period (`crawlsim.integrate.limit.factors`): projectors P_A = I - R_A B_A of active sets and
saltations S = I - (v_b - v_a) b_i^T / rate. For a chain (`crawlsim.projection.chain_polyhedron`,
B = [D^T; -D^T], M = K^{-1}) a projector depends only on the saturated blocks J of A, not on
the signs of its rows: with f = D^T v,

    P_A v = v - K D dx,   L_JJ dx_J = f_J,   dx = 0 off J,
    P_A^T v = v - D dx',  L_JJ dx'_J = (D^T K v)_J,

L = D^T K D the tridiagonal stiffness Laplacian, so a product costs O(|J|) per projector. A
saltation on row i (block b, sign s: row i = b or N + b) has b_i^T v = s f_b, and its row
vector b_i = s D e_b (entries +s at link b - 1, -s at link b), so

    S v = v - jump (s f_b / rate),   S^T v = v - s D e_b <jump, v> / rate.

The factors are packed once per Newton step (`pack`: the blocks of each projector and the LDL^T
of its L_JJ, from `crawlsim.kernel.chain.factor` on the padded system, restricted to J), then
a product by J or J^T is one compiled call over all of them (`apply`, `apply_transpose`),
O(sum |J|) <= O(K N) for K factors, instead of K Python solves; a projector is two passes
over its blocks (`_project`). The products agree with the numpy ones factor by factor
(`crawlsim.integrate.limit.apply_jacobian`) to the roundoff of the tridiagonal solves.

Everything here is a function of plain arrays and scalars, compiled by numba; with
``NUMBA_DISABLE_JIT=1`` the same source runs as Python.
"""

from __future__ import annotations

import numpy as np

from crawlsim.kernel.chain import factor
from crawlsim.kernel.jit import jit

#: The kind of a packed factor: the projector of an active set, or a saltation.
PROJECTOR, SALTATION = 0, 1


@jit
def pack(
    k: np.ndarray, kinds: np.ndarray, starts: np.ndarray, blocks: np.ndarray, D: np.ndarray, l: np.ndarray
) -> None:
    """Fill D and l (like ``blocks``) with the LDL^T of L_JJ of every projector, D with the
    reciprocals of its pivots (the solves multiply by them): factor p's
    saturated blocks are ``blocks[starts[p]:starts[p + 1]]`` (sorted). L_JJ is the padded L~
    of `crawlsim.kernel.chain.factor` restricted to J (the padding decouples every free
    block), so its pivots are L~'s at J and its subdiagonal L~'s between consecutive blocks
    (zero across a free block, which separates independent runs)."""
    N = k.shape[0] + 1
    signs = np.zeros(N)
    Dp, lp = np.empty(N), np.empty(N - 1)
    for p in range(kinds.shape[0]):
        if kinds[p] != PROJECTOR:
            continue
        lo, hi = starts[p], starts[p + 1]
        for q in range(lo, hi):
            signs[blocks[q]] = 1.0
        factor(k, signs, Dp, lp)
        for q in range(lo, hi):
            b = blocks[q]
            D[q] = 1.0 / Dp[b]
            l[q] = lp[b] if b < N - 1 else 0.0
            signs[b] = 0.0


@jit
def _project(
    k: np.ndarray,
    blocks: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    lo: int,
    hi: int,
    x: np.ndarray,
    y: np.ndarray,
    transpose: bool,
) -> None:
    """x <- P_A x (or P_A^T x) for the projector of the blocks J = ``blocks[lo:hi]``, in two
    passes over J: forward, f_J = (D^T x)_J (D^T K x with ``transpose``) and the unit lower
    solve of the LDL^T of L_JJ (into ``y``); backward, the pivots and the unit upper solve
    give the slips dx_J, and each link next to a block moves as soon as the slips on both its
    sides are known: link j by (dx_{j+1} - dx_j) k_j, that is x - K D dx (or, divided by k_j,
    x - D dx). Link j moves once: with block j if it is saturated (its right link), else with
    block j + 1 (its left link). l is zero between blocks that are not neighbours, so the
    recurrences run over J as over one tridiagonal system."""
    n = x.shape[0]
    prev = 0.0
    for q in range(lo, hi):
        b = blocks[q]
        if transpose:
            f = ((x[b - 1] * k[b - 1]) if b > 0 else 0.0) - ((x[b] * k[b]) if b < n else 0.0)
        else:
            f = (x[b - 1] if b > 0 else 0.0) - (x[b] if b < n else 0.0)
        if q > lo:
            f -= l[q - 1] * prev
        y[q - lo] = f
        prev = f
    right = 0.0  # the slip of the next saturated block, and whether it is block b + 1
    for q in range(hi - 1, lo - 1, -1):
        b = blocks[q]
        dx = y[q - lo] * D[q]
        beside = q + 1 < hi and blocks[q + 1] == b + 1
        if beside:
            dx -= l[q] * right
        if b < n:  # link b: dx_{b+1} - dx_b
            step = (right if beside else 0.0) - dx
            x[b] -= step if transpose else step * k[b]
        if b > 0 and not (q > lo and blocks[q - 1] == b - 1):  # link b - 1, block b - 1 free
            x[b - 1] -= dx if transpose else dx * k[b - 1]
        right = dx


@jit
def apply(
    k: np.ndarray,
    kinds: np.ndarray,
    starts: np.ndarray,
    blocks: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    slot: np.ndarray,
    rows: np.ndarray,
    rates: np.ndarray,
    jumps: np.ndarray,
    x: np.ndarray,
) -> None:
    """x <- J x, the packed factors (module docstring) in turn. Saltation p is number
    ``slot[p]`` of ``rows``, ``rates`` and ``jumps`` (one jump v_b - v_a a row)."""
    N = k.shape[0] + 1
    n = x.shape[0]
    y = np.empty(N)
    for p in range(kinds.shape[0]):
        lo, hi = starts[p], starts[p + 1]
        if kinds[p] == SALTATION:
            t = slot[p]
            row = rows[t]
            b, sign = (row, 1.0) if row < N else (row - N, -1.0)
            f = sign * ((x[b - 1] if b > 0 else 0.0) - (x[b] if b < n else 0.0))  # (B x)_row
            s = f / rates[t]
            for j in range(n):
                x[j] -= s * jumps[t, j]
            continue
        _project(k, blocks, D, l, lo, hi, x, y, False)


@jit
def apply_transpose(
    k: np.ndarray,
    kinds: np.ndarray,
    starts: np.ndarray,
    blocks: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    slot: np.ndarray,
    rows: np.ndarray,
    rates: np.ndarray,
    jumps: np.ndarray,
    x: np.ndarray,
) -> None:
    """x <- J^T x: the transposed factors (module docstring) in reverse order."""
    N = k.shape[0] + 1
    n = x.shape[0]
    y = np.empty(N)
    for p in range(kinds.shape[0] - 1, -1, -1):
        lo, hi = starts[p], starts[p + 1]
        if kinds[p] == SALTATION:
            t = slot[p]
            row = rows[t]
            dot = 0.0
            for j in range(n):
                dot += x[j] * jumps[t, j]
            s = dot / rates[t]
            b, sign = (row, 1.0) if row < N else (row - N, -1.0)
            if b > 0:
                x[b - 1] -= s * sign
            if b < n:
                x[b] -= s * -sign
            continue
        _project(k, blocks, D, l, lo, hi, x, y, True)
