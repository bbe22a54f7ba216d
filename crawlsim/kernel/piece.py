"""A piece of the exact flow, compiled (`crawlsim.kernel.eventloop`): the offsets' basis phi(u)
and products with it, and the piece's coefficients from one factorisation of the chain's
tridiagonal KKT system (`crawlsim.kernel.chain`), with the dual tolerance's scale on it.

Between two events the active set (signs) is fixed, and w(u) = base + phi(u) @ Wc, the block
slips dx(u) = dx0 - phi(u) @ Ydx (docs/model.md §2-3; the formulas are those of
`crawlsim.integrate.exact`). Plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same
source runs as Python.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from crawlsim.kernel import chain

TWO_PI = 2.0 * math.pi
RTOL = chain.RTOL


# -- the basis phi(u) and products with it ------------------------------------------------------
@njit(cache=True)
def basis_values(u: float, order: int, linear: bool, H: int, out: np.ndarray) -> None:
    """The order-th derivative of phi at u into ``out`` (`crawlsim.model.offsets.Basis.values`)."""
    for b in range(out.shape[0]):
        out[b] = 0.0
    if order == 0:
        out[0] = 1.0
    h0 = 1
    if linear:
        h0 = 2
        if order == 0:
            out[1] = u
        elif order == 1:
            out[1] = 1.0
    shift = order * (math.pi / 2)
    for h in range(1, H + 1):
        w = TWO_PI * h
        scale = w ** order
        angle = u * w
        out[h0 + 2 * (h - 1)] = scale * math.cos(angle + shift)
        out[h0 + 2 * (h - 1) + 1] = scale * math.sin(angle + shift)


@njit(cache=True)
def derivative(coef: np.ndarray, linear: bool, H: int, out: np.ndarray) -> None:
    """Coefficients (nb, k) of f' for f = phi @ coef (`crawlsim.model.offsets.Basis.derivative`)."""
    out[:] = 0.0
    h0 = 1
    if linear:
        h0 = 2
        out[0] = coef[1]
    for h in range(1, H + 1):
        w = TWO_PI * h
        ci = h0 + 2 * (h - 1)
        out[ci] = w * coef[ci + 1]
        out[ci + 1] = -w * coef[ci]


@njit(cache=True)
def combine(phi: np.ndarray, coef: np.ndarray, out: np.ndarray) -> None:
    """out = phi @ coef for coef (nb, k), row by row of coef (contiguous; the sums add the same
    terms in the same order as the dot product of each column)."""
    for r in range(out.shape[0]):
        out[r] = 0.0
    for b in range(phi.shape[0]):
        p = phi[b]
        for r in range(out.shape[0]):
            out[r] += p * coef[b, r]


@njit(cache=True)
def apply(w: np.ndarray, out: np.ndarray) -> None:
    """B w = [D^T w; -D^T w] of a chain (`crawlsim.kernel.kkt.ChainPolyhedron.apply`)."""
    N = out.shape[0] // 2
    for i in range(N):
        f = (w[i - 1] if i > 0 else 0.0) - (w[i] if i < N - 1 else 0.0)
        out[i] = f
        out[N + i] = -f


@njit(cache=True)
def max_abs(x: np.ndarray) -> float:
    out = 0.0
    for i in range(x.shape[0]):
        if abs(x[i]) > out:
            out = abs(x[i])
    return out


# -- a piece: the factor and the closed form of w(u) and the slips --------------------------------
@njit(cache=True)
def solve_rows(D: np.ndarray, l: np.ndarray, Y: np.ndarray) -> None:
    """Y[b] <- L~^{-1} Y[b] for every row b (`crawlsim.kernel.chain.solve`, the same operations
    on each row), the rows side by side: their recurrences overlap instead of waiting on one
    another."""
    solve_rows_on(D, l, Y, 0, Y.shape[1] - 1)


@njit(cache=True)
def solve_rows_on(D: np.ndarray, l: np.ndarray, Y: np.ndarray, lo: int, hi: int) -> None:
    """`solve_rows` on the blocks lo..hi, a union of runs of the set (blocks lo - 1 and hi + 1
    free or absent: the padded system decouples there, so the other blocks are not read).
    The terms with l = 0, between runs, are skipped, as in `crawlsim.kernel.chain.solve`."""
    nb = Y.shape[0]
    for i in range(lo + 1, hi + 1):
        li = l[i - 1]
        if li != 0.0:
            for b in range(nb):
                Y[b, i] -= li * Y[b, i - 1]
    for i in range(lo, hi + 1):
        for b in range(nb):
            Y[b, i] /= D[i]
    for i in range(hi - 1, lo - 1, -1):
        li = l[i]
        if li != 0.0:
            for b in range(nb):
                Y[b, i] -= li * Y[b, i + 1]


@njit(cache=True)
def piece(k: np.ndarray, signs: np.ndarray, w0: np.ndarray, coef: np.ndarray, D: np.ndarray,
          l: np.ndarray, dx0: np.ndarray, Ydx: np.ndarray, base: np.ndarray, Wc: np.ndarray,
          f: np.ndarray) -> tuple[float, float]:
    """w(u) = base + phi(u) @ Wc and dx(u) = dx0 - phi(u) @ Ydx on the set ``signs`` from w0:
    Lambda_A = G_A^{-1} (B_A w0 - c_A(u)) in the chain's block form L_JJ dx_J = f_J - f*_J.
    Returns (||L_JJ^{-1}||, ||L_JJ||) (zeros for the empty set)."""
    norms = np.zeros(2)
    for i in range(signs.shape[0]):
        if signs[i] != 0:
            norms[0], norms[1] = chain.factor(k, signs, D, l)
            break
    return piece_on(k, signs, w0, coef, D, l, norms, dx0, Ydx, base, Wc, f)


@njit(cache=True)
def factored_set(k: np.ndarray, signs: np.ndarray, factored: np.ndarray, D: np.ndarray,
                 l: np.ndarray, norms: np.ndarray) -> None:
    """The LDL^T of the set ``signs`` (`crawlsim.kernel.chain.factor`) in (D, l) and its norms
    in ``norms``, factored only when ``factored`` (the set they hold, shared with the velocity
    problems' `crawlsim.kernel.chain.settle`) is another set: an event's last velocity problem
    is most often on the set of the piece that follows it."""
    if not chain.same(factored, signs):
        norms[0], norms[1] = chain.factor(k, signs, D, l)
        factored[:] = signs


@njit(cache=True)
def piece_on(k: np.ndarray, signs: np.ndarray, w0: np.ndarray, coef: np.ndarray, D: np.ndarray,
             l: np.ndarray, norms: np.ndarray, dx0: np.ndarray, Ydx: np.ndarray,
             base: np.ndarray, Wc: np.ndarray, f: np.ndarray) -> tuple[float, float]:
    """`piece` with the set already factored: (D, l) its LDL^T and ``norms`` its
    (||L_JJ^{-1}||, ||L_JJ||)."""
    N = signs.shape[0]
    nb = coef.shape[0]
    active = False
    for i in range(N):
        if signs[i] != 0:
            active = True
    base[:] = w0
    if not active:  # with a set, every entry below is written
        Wc[:] = 0.0
        dx0[:] = 0.0
        Ydx[:] = 0.0
        return 0.0, 0.0
    inverse, gram = norms[0], norms[1]
    chain.forces(w0, f)
    for i in range(N):
        dx0[i] = f[i] if signs[i] != 0 else 0.0
    chain.solve(D, l, dx0)
    for b in range(nb):
        for i in range(N):
            s = signs[i]
            Ydx[b, i] = coef[b, i] if s > 0 else (-coef[b, N + i] if s < 0 else 0.0)
    solve_rows(D, l, Ydx)
    for i in range(N - 1):
        base[i] = w0[i] - (dx0[i + 1] - dx0[i]) * k[i]
        for b in range(nb):
            Wc[b, i] = (Ydx[b, i + 1] - Ydx[b, i]) * k[i]
    return inverse, gram


@njit(cache=True)
def rebuild(k: np.ndarray, signs: np.ndarray, w0: np.ndarray, coef: np.ndarray, lo: int, hi: int,
            D: np.ndarray, l: np.ndarray, inv: np.ndarray, dx0: np.ndarray, Ydx: np.ndarray,
            base: np.ndarray, Wc: np.ndarray) -> None:
    """`piece_on` on the blocks lo..hi alone, a union of runs of the set ``signs`` (blocks
    lo - 1 and hi + 1 free or absent), from the state w0: the padded L~ decouples at a free
    block, so the factor (D, l), L_JJ^{-1} 1 (``inv``, whose largest entry over the set is
    ||L_JJ^{-1}||, `set_norms`), dx0 and Ydx of these blocks and base, Wc of the links that
    touch them (lo - 1..hi) are those of the whole set, with the operations of
    `crawlsim.kernel.chain.factor` and `piece_on`; the other runs keep theirs. An event that
    changes the set on a few blocks so rebuilds only the runs that hold them."""
    N = signs.shape[0]
    nb = coef.shape[0]
    for i in range(lo, hi + 1):
        s = signs[i]
        if s != 0:
            D[i] = (k[i - 1] if i > 0 else 0.0) + (k[i] if i < N - 1 else 0.0)
            inv[i] = 1.0
            dx0[i] = (w0[i - 1] if i > 0 else 0.0) - (w0[i] if i < N - 1 else 0.0)
        else:
            D[i] = 1.0
            inv[i] = 0.0
            dx0[i] = 0.0
        for b in range(nb):
            Ydx[b, i] = coef[b, i] if s > 0 else (-coef[b, N + i] if s < 0 else 0.0)
    if lo > 0:
        l[lo - 1] = 0.0
    if hi < N - 1:
        l[hi] = 0.0
    for i in range(lo + 1, hi + 1):
        if signs[i - 1] != 0 and signs[i] != 0:
            e = -k[i - 1]
            l[i - 1] = e / D[i - 1]
            D[i] -= l[i - 1] * e
        else:
            l[i - 1] = 0.0
    solve_rows_on(D, l, inv.reshape((1, N)), lo, hi)
    solve_rows_on(D, l, dx0.reshape((1, N)), lo, hi)
    solve_rows_on(D, l, Ydx, lo, hi)
    for i in range(max(lo - 1, 0), min(hi + 1, N - 1)):
        base[i] = w0[i] - (dx0[i + 1] - dx0[i]) * k[i]
        for b in range(nb):
            Wc[b, i] = (Ydx[b, i + 1] - Ydx[b, i]) * k[i]


@njit(cache=True)
def set_norms(k: np.ndarray, signs: np.ndarray, inv: np.ndarray) -> tuple[float, float]:
    """(||L_JJ^{-1}||, ||L_JJ||) of the set (`crawlsim.kernel.chain.factor`) from
    inv = L_JJ^{-1} 1 (`rebuild`): its largest entry (an M-matrix) and the largest row sum
    2 L_ii."""
    N = signs.shape[0]
    inverse, gram = 0.0, 0.0
    for i in range(N):
        if signs[i] != 0:
            d = (k[i - 1] if i > 0 else 0.0) + (k[i] if i < N - 1 else 0.0)
            if 2.0 * d > gram:
                gram = 2.0 * d
            if inv[i] > inverse:
                inverse = inv[i]
    return inverse, gram


@njit(cache=True)
def offset_size(coef: np.ndarray) -> float:
    """max_r sum_b |coef[b, r]|: the size of a piece's offsets and of their rates (a bound on
    |c(u)| and |c'(u)| / 2 pi for one harmonic), once per piece of c."""
    c_size = 0.0
    for r in range(coef.shape[1]):
        total = 0.0
        for b in range(coef.shape[0]):
            total += abs(coef[b, r])
        c_size = max(c_size, total)
    return c_size


@njit(cache=True)
def dual_scale(k: np.ndarray, kmax: float, c_scale: float, signs: np.ndarray, c_size: float,
               dx0: np.ndarray, Ydx: np.ndarray, base: np.ndarray, Wc: np.ndarray, inverse: float,
               gram: float) -> float:
    """The roundoff of the slips a piece adds (`EventStepper._dual_scale`): the dual tolerance of
    its set at the size of its offsets (``c_size``, `offset_size`), state and slips."""
    if inverse == 0.0:
        return 0.0
    N = signs.shape[0]
    nb = Ydx.shape[0]
    w_size = max_abs(base)
    lam_size = 0.0
    for i in range(N):
        if signs[i] != 0:
            lam_size = max(lam_size, abs(dx0[i]))
    for b in range(nb):
        w_size += max_abs(Wc[b])
        top = 0.0
        for i in range(N):
            if signs[i] != 0:
                top = max(top, abs(Ydx[b, i]))
        lam_size += top
    size = max(max(c_scale, c_size), max(2.0 * w_size, 4.0 * kmax * lam_size))
    return 2.0 * RTOL * inverse * (size + gram * lam_size)


# -- an event: the next active set --------------------------------------------------------------
