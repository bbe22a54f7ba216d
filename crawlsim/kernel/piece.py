"""A piece of the exact flow, compiled (`crawlsim.kernel.eventloop`): the offsets' basis phi(u)
and products with it, the piece's coefficients from one factorisation of the chain's
tridiagonal KKT system (`crawlsim.kernel.chain`), with the dual tolerance's scale on it, or
from the runs an event changed (`rebuild`), and at an event the next active set from Moreau's
velocity problems (`decide`; `decide_local` solves them only on the runs that can change).

Between two events the active set (signs) is fixed, and w(u) = base + phi(u) @ Wc, the block
slips dx(u) = dx0 - phi(u) @ Ydx (docs/model.md §2-3; the formulas are those of
`crawlsim.integrate.exact`). Plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same
source runs as Python.
"""

from __future__ import annotations

import math

import numpy as np

from crawlsim.kernel import chain
from crawlsim.kernel.jit import jit
from crawlsim.kernel.policy import RTOL, UPDATE_ITERATIONS, tolerances

TWO_PI = 2.0 * math.pi


# -- the basis phi(u) and products with it ------------------------------------------------------
@jit
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
        scale = w**order
        angle = u * w
        out[h0 + 2 * (h - 1)] = scale * math.cos(angle + shift)
        out[h0 + 2 * (h - 1) + 1] = scale * math.sin(angle + shift)


@jit
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


@jit
def combine(phi: np.ndarray, coef: np.ndarray, out: np.ndarray) -> None:
    """out = phi @ coef for coef (nb, k), row by row of coef (contiguous; the sums add the same
    terms in the same order as the dot product of each column)."""
    for r in range(out.shape[0]):
        out[r] = 0.0
    for b in range(phi.shape[0]):
        p = phi[b]
        for r in range(out.shape[0]):
            out[r] += p * coef[b, r]


@jit
def apply(w: np.ndarray, out: np.ndarray) -> None:
    """B w = [D^T w; -D^T w] of a chain (`crawlsim.projection.kkt.ChainPolyhedron.apply`)."""
    N = out.shape[0] // 2
    for i in range(N):
        f = (w[i - 1] if i > 0 else 0.0) - (w[i] if i < N - 1 else 0.0)
        out[i] = f
        out[N + i] = -f


@jit
def max_abs(x: np.ndarray) -> float:
    out = 0.0
    for i in range(x.shape[0]):
        if abs(x[i]) > out:
            out = abs(x[i])
    return out


# -- a piece: the factor and the closed form of w(u) and the slips --------------------------------
@jit
def solve_rows(D: np.ndarray, l: np.ndarray, Y: np.ndarray) -> None:
    """Y[b] <- L~^{-1} Y[b] for every row b (`crawlsim.kernel.chain.solve`, the same operations
    on each row), the rows side by side: their recurrences overlap instead of waiting on one
    another."""
    solve_rows_on(D, l, Y, 0, Y.shape[1] - 1)


@jit
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


@jit
def piece(
    k: np.ndarray,
    signs: np.ndarray,
    w0: np.ndarray,
    coef: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    f: np.ndarray,
) -> tuple[float, float]:
    """w(u) = base + phi(u) @ Wc and dx(u) = dx0 - phi(u) @ Ydx on the set ``signs`` from w0:
    Lambda_A = G_A^{-1} (B_A w0 - c_A(u)) in the chain's block form L_JJ dx_J = f_J - f*_J.
    Returns (||L_JJ^{-1}||, ||L_JJ||) (zeros for the empty set)."""
    norms = np.zeros(2)
    for i in range(signs.shape[0]):
        if signs[i] != 0:
            norms[0], norms[1] = chain.factor(k, signs, D, l)
            break
    return piece_on(k, signs, w0, coef, D, l, norms, dx0, Ydx, base, Wc, f)


@jit
def factored_set(
    k: np.ndarray, signs: np.ndarray, factored: np.ndarray, D: np.ndarray, l: np.ndarray, norms: np.ndarray
) -> None:
    """The LDL^T of the set ``signs`` (`crawlsim.kernel.chain.factor`) in (D, l) and its norms
    in ``norms``, factored only when ``factored`` (the set they hold, shared with the velocity
    problems' `crawlsim.kernel.chain.settle`) is another set: an event's last velocity problem
    is most often on the set of the piece that follows it."""
    if not chain.same(factored, signs):
        norms[0], norms[1] = chain.factor(k, signs, D, l)
        factored[:] = signs


@jit
def piece_on(
    k: np.ndarray,
    signs: np.ndarray,
    w0: np.ndarray,
    coef: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    f: np.ndarray,
) -> tuple[float, float]:
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


@jit
def rebuild(
    k: np.ndarray,
    signs: np.ndarray,
    w0: np.ndarray,
    coef: np.ndarray,
    lo: int,
    hi: int,
    D: np.ndarray,
    l: np.ndarray,
    inv: np.ndarray,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
) -> None:
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
    chain.eliminate(k, signs, D, l, lo, hi)
    solve_rows_on(D, l, inv.reshape((1, N)), lo, hi)
    solve_rows_on(D, l, dx0.reshape((1, N)), lo, hi)
    solve_rows_on(D, l, Ydx, lo, hi)
    for i in range(max(lo - 1, 0), min(hi + 1, N - 1)):
        base[i] = w0[i] - (dx0[i + 1] - dx0[i]) * k[i]
        for b in range(nb):
            Wc[b, i] = (Ydx[b, i + 1] - Ydx[b, i]) * k[i]


@jit
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


@jit
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


@jit
def dual_scale(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    signs: np.ndarray,
    c_size: float,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    inverse: float,
    gram: float,
) -> float:
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
    return float(tolerances(c_scale, c_size, 2.0 * w_size, 4.0 * kmax * lam_size, inverse, gram, lam_size)[1])


# -- an event: the next active set --------------------------------------------------------------
#: Orders of the velocity problem used to decide degenerate rows at an event (the exact
#: integrator's DECISION_ORDERS).
DECISION_ORDERS = 4


@jit
def tight_rows(
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    u: float,
    w: np.ndarray,
    forced: np.ndarray,
    phi: np.ndarray,
    cvec: np.ndarray,
    Bw: np.ndarray,
    candidates: np.ndarray,
    held: np.ndarray,
) -> None:
    """The rows tight at w to the primal tolerance of a step with no multipliers, those of the
    set ``held`` (the last piece's) and ``forced`` (the rows an event hit), into
    ``candidates``: the candidates of `decide` (`EventStepper._decide`). The tolerance follows the size of the terms of
    c(u) = phi(u) @ coef, not of their sum: on a steep piece late in the cycle they cancel,
    and a row within their roundoff of its limit that is left out would cross it at once,
    with no event to find."""
    m = Bw.shape[0]
    basis_values(u, 0, linear, H, phi)
    combine(phi, coef, cvec)
    apply(w, Bw)
    c_size = 0.0
    for r in range(m):
        if abs(cvec[r]) < np.inf:
            total = 0.0
            for b in range(phi.shape[0]):
                total += abs(phi[b] * coef[b, r])
            c_size = max(c_size, total)
    tol = RTOL * max(max(c_scale, c_size), 2.0 * max_abs(w))
    N = held.shape[0]
    for r in range(m):
        member = held[r] > 0 if r < N else held[r - N] < 0
        candidates[r] = Bw[r] - cvec[r] >= -tol or forced[r] or member


@jit
def settle_rows(
    candidates: np.ndarray,
    fixed: np.ndarray,
    lam: np.ndarray,
    Bv: np.ndarray,
    ck: np.ndarray,
    tol_p: float,
    told: np.ndarray,
) -> bool:
    """One order of `decide`: candidates with a multiplier above their own row's dual
    tolerance ``told[r]`` (`chain.project_rows`) become fixed, those whose velocity opens their
    gap leave. Returns whether candidates are left."""
    left = False
    for r in range(candidates.shape[0]):
        if candidates[r]:
            if lam[r] > told[r]:
                fixed[r] = True
                candidates[r] = False
            elif Bv[r] - ck[r] < -tol_p:
                candidates[r] = False
            else:
                left = True
    return left


@jit
def decide(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    u: float,
    w: np.ndarray,
    forced: np.ndarray,
    warm: np.ndarray,
    out: np.ndarray,
    phi: np.ndarray,
    cvec: np.ndarray,
    Bw: np.ndarray,
    masks: np.ndarray,
    rows_m: np.ndarray,
    rows_n: np.ndarray,
    sets: np.ndarray,
    factored: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    report: np.ndarray,
    held: np.ndarray,
) -> bool:
    """The active set on (u, u + eps) into ``out`` (`EventStepper._decide`): the rows tight at
    w (with ``forced`` and ``held``, `tight_rows`), decided by the velocity problems of orders
    1, 2, ...; False when one of them is not settled by the kernel's updates or the result is
    dependent (HANDOFF).

    Each velocity problem is `crawlsim.kernel.chain.project_rows` (w_trial = 0) on the period's
    scratch: ``masks`` (3, 2N), ``rows_m`` (4, 2N), ``rows_n`` (5, N; its last row stays 0),
    ``sets`` (2 + UPDATE_ITERATIONS, N) and the factor of the last set (``factored``, D, l,
    ``norms``, `crawlsim.kernel.piece.factored_set`), refactored only when the set changes."""
    tight_rows(c_scale, linear, H, coef, u, w, forced, phi, cvec, Bw, masks[0], held)
    return decide_from(
        k,
        kmax,
        c_scale,
        linear,
        H,
        coef,
        u,
        forced,
        warm,
        out,
        phi,
        cvec,
        Bw,
        masks,
        rows_m,
        rows_n,
        sets,
        factored,
        D,
        l,
        norms,
        report,
    )


@jit
def decide_from(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    u: float,
    forced: np.ndarray,
    warm: np.ndarray,
    out: np.ndarray,
    phi: np.ndarray,
    cvec: np.ndarray,
    Bw: np.ndarray,
    masks: np.ndarray,
    rows_m: np.ndarray,
    rows_n: np.ndarray,
    sets: np.ndarray,
    factored: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    report: np.ndarray,
) -> bool:
    """`decide` from its candidates, in masks[0] (`tight_rows`)."""
    candidates = masks[0]
    out[:] = 0
    if not candidates.any():
        return True
    N = out.shape[0]
    m = 2 * N
    fixed, rows = masks[1], masks[2]
    fixed[:] = False
    signs = sets[0]
    lam, c, told, slack = rows_m[0], rows_m[1], rows_m[2], rows_m[3]
    dx, f, res, v, zero = rows_n[0], rows_n[1], rows_n[2], rows_n[3, : N - 1], rows_n[4, : N - 1]
    for order in range(1, DECISION_ORDERS + 1):
        basis_values(u, order, linear, H, phi)
        combine(phi, coef, cvec)
        for r in range(m):
            c[r] = cvec[r] if (fixed[r] or candidates[r]) else np.inf
            block_warm = warm[r] > 0 if r < N else warm[r - N] < 0
            rows[r] = fixed[r] or (candidates[r] and block_warm)
        if not chain.independent(rows, N):
            return False
        if order == 1:  # the rows an event hit start in the set, where LICQ allows
            for r in range(m):
                if forced[r] and candidates[r] and not rows[r] and not rows[(r + N) % m]:
                    rows[r] = True
                    if not chain.independent(rows, N):
                        rows[r] = False
        for i in range(N):
            signs[i] = 1 if rows[i] else (-1 if rows[N + i] else 0)
        status, _ = chain.settle(
            k,
            kmax,
            c_scale,
            zero,
            c,
            signs,
            factored,
            D,
            l,
            norms,
            fixed,
            dx,
            v,
            lam,
            slack,
            f,
            res,
            sets[1],
            sets[2:],
            report,
            told,
        )
        if status != chain.DONE:
            return False
        apply(v, Bw)
        if not settle_rows(candidates, fixed, lam, Bw, cvec, report[chain.REPORT_TOLP], told):
            break
    if not chain.independent(fixed, N):
        return False
    for i in range(N):
        out[i] = 1 if fixed[i] else (-1 if fixed[N + i] else 0)
    return True


#: Chains of fewer blocks decide an event over the whole chain (`decide`): a velocity problem
#: of a few blocks costs less than the scratch of one on a run of its own (`decide_run`).
LOCAL_BLOCKS = 16
#: `decide_local` leaves a run of the set to its piece when each of its slip rates exceeds this
#: many times the largest dual tolerance a velocity problem at the event could give it.
CLEAR_MARGIN = 1e3


@jit
def decide_local(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    c_size: float,
    u: float,
    w: np.ndarray,
    forced: np.ndarray,
    warm: np.ndarray,
    out: np.ndarray,
    phi: np.ndarray,
    cvec: np.ndarray,
    Bw: np.ndarray,
    masks: np.ndarray,
    rows_m: np.ndarray,
    rows_n: np.ndarray,
    sets: np.ndarray,
    factored: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    report: np.ndarray,
    Rdx: np.ndarray,
    inverse: float,
    rate: np.ndarray,
    held: np.ndarray,
) -> bool:
    """`decide` at an event of a piece of the set ``warm`` (its slip rates' coefficients Rdx,
    its ||L_JJ^{-1}|| ``inverse``), solving the velocity problems only where the set can change.

    The velocity problems decouple at a block with no candidate row (both its offsets are
    infinite there: a free block of every set they try), so each run of candidate blocks is a
    problem of its own. A run whose candidate rows are the rows of ``warm``, none of them hit,
    each with a slip rate -s phi(u) @ Rdx above `CLEAR_MARGIN` times the dual tolerance
    2 RTOL ||L_JJ^{-1}|| (size + ||L_JJ|| |lambda|) that a velocity problem could give it
    (with 4 ||L_JJ^{-1}|| of the piece, ||L_JJ|| <= 4 max k, |c'| <= 2 pi max(H, 1) |c|),
    has every multiplier of its order-1 problem positive beyond doubt: every row of it is
    fixed at order 1, and it keeps its set. The other runs are decided by `decide_from` on the
    chain of their blocks and the free block on either side (`decide_run`), with the same
    candidates; the whole chain by `decide` where every block is a candidate."""
    N = warm.shape[0]
    nb = coef.shape[0]
    candidates = masks[0]
    tight_rows(c_scale, linear, H, coef, u, w, forced, phi, cvec, Bw, candidates, held)
    # phi = phi(u): the slip rates of the piece's active blocks, and their size
    lam_size = 0.0
    count = 0
    for i in range(N):
        s = warm[i]
        if candidates[i] or candidates[N + i]:
            count += 1
        if s != 0:
            total = 0.0
            for b in range(nb):
                total += phi[b] * Rdx[b, i]
            rate[i] = -s * total
            lam_size = max(lam_size, abs(rate[i]))
    if count == N:
        return decide_from(
            k,
            kmax,
            c_scale,
            linear,
            H,
            coef,
            u,
            forced,
            warm,
            out,
            phi,
            cvec,
            Bw,
            masks,
            rows_m,
            rows_n,
            sets,
            factored,
            D,
            l,
            norms,
            report,
        )
    size = max(max(c_scale, TWO_PI * max(H, 1) * c_size), 4.0 * kmax * lam_size)
    clear = CLEAR_MARGIN * 2.0 * RTOL * 4.0 * inverse * (size + 4.0 * kmax * lam_size)
    hot = masks[1]
    for i in range(N):
        s = warm[i]
        h = forced[i] or forced[N + i] or candidates[i] != (s > 0) or candidates[N + i] != (s < 0)
        if not h and s != 0:
            h = not rate[i] > clear
        hot[i] = h
    out[:] = warm
    if not decide_hot_runs(k, kmax, c_scale, linear, H, coef, u, forced, warm, candidates, hot, out, report):
        return False
    count = 0
    for i in range(N):
        if out[i] != 0:
            count += 1
    return bool(count < N)  # LICQ of the whole set (`chain.independent`)


@jit
def decide_hot_runs(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    u: float,
    forced: np.ndarray,
    warm: np.ndarray,
    candidates: np.ndarray,
    hot: np.ndarray,
    out: np.ndarray,
    report: np.ndarray,
) -> bool:
    """The runs of candidate blocks that hold a ``hot`` block (`decide_local`), each decided on
    its own chain (`decide_run`) into ``out``; a hot block with no candidate row leaves the
    set. False where one of them is not settled (HANDOFF)."""
    N = warm.shape[0]
    i = 0
    while i < N:
        if not hot[i]:
            i += 1
            continue
        if not (candidates[i] or candidates[N + i]):
            out[i] = 0
            i += 1
            continue
        lo, hi = i, i
        while lo > 0 and (candidates[lo - 1] or candidates[N + lo - 1]):
            lo -= 1
        while hi < N - 1 and (candidates[hi + 1] or candidates[N + hi + 1]):
            hi += 1
        if not decide_run(
            k,
            kmax,
            c_scale,
            linear,
            H,
            coef,
            u,
            forced,
            warm,
            candidates,
            max(lo - 1, 0),
            min(hi + 1, N - 1),
            out,
            report,
        ):
            return False
        i = hi + 1
    return True


@jit
def decide_run(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    linear: bool,
    H: int,
    coef: np.ndarray,
    u: float,
    forced: np.ndarray,
    warm: np.ndarray,
    candidates: np.ndarray,
    a: int,
    b: int,
    out: np.ndarray,
    report: np.ndarray,
) -> bool:
    """`decide_from` on the chain of blocks a..b (links a..b-1), a run of candidate blocks
    and the free blocks beside it, its result into out[a:b+1]."""
    N = warm.shape[0]
    n = b - a + 1
    nb = coef.shape[0]
    sub = np.empty((nb, 2 * n))
    masks = np.zeros((3, 2 * n), dtype=np.bool_)
    hit = np.empty(2 * n, dtype=np.bool_)
    for j in range(n):
        for q in range(nb):
            sub[q, j], sub[q, n + j] = coef[q, a + j], coef[q, N + a + j]
        masks[0, j], masks[0, n + j] = candidates[a + j], candidates[N + a + j]
        hit[j], hit[n + j] = forced[a + j], forced[N + a + j]
    result = np.empty(n, dtype=np.int8)
    ok = decide_from(
        k[a:b],
        kmax,
        c_scale,
        linear,
        H,
        sub,
        u,
        hit,
        warm[a : b + 1],
        result,
        np.empty(nb),
        np.empty(2 * n),
        np.empty(2 * n),
        masks,
        np.empty((4, 2 * n)),
        np.zeros((5, n)),
        np.empty((2 + UPDATE_ITERATIONS, n), dtype=np.int8),
        np.full(n, 2, dtype=np.int8),
        np.empty(n),
        np.empty(max(n - 1, 0)),
        np.zeros(2),
        report,
    )
    out[a : b + 1] = result
    return ok
