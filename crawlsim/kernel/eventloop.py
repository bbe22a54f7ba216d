"""The compiled event loop of the exact integrator for a crawler chain (`crawlsim.integrate.exact`).

One call runs one period of the exact, event-driven integration of docs/model.md §2-3 in machine
code: at every event the next active set from Moreau's velocity problems, order by order
(`decide`); on the piece that follows, w(u) = base + phi(u) @ Wc and the block slips
dx(u) = dx0 - phi(u) @ Ydx from one factorisation of the chain's tridiagonal KKT system
(`piece`, O(N), the factor and solve of `crawlsim.kernel.chain`); the next zero crossing of every
gap and slip rate (`next_event`: in closed form, `crawlsim.kernel.events`, or by certified
sampling, `crawlsim.kernel.sampling`); the grid samples and their certificate
(`sample_piece`); and at a jump of c(t) the certified projection onto K(t+) (`jump`). The
formulas, tolerances and decisions are those of the module docstring of
`crawlsim.integrate.exact`, which documents them; the rows of a chain are those of
`crawlsim.projection.kkt.ChainPolyhedron` (row i < N: block i at its forward limit, row N + i at its
backward one), and an active set is its signs (+1, -1, 0 per block).

An event touches what can change. The padded KKT system decouples at a free block, so the
piece is kept per run of active blocks: an event rebuilds only the ranges of blocks whose sign
it changed (`rebuild_changed`), the other runs go on with their closed form from an earlier
start (their slips so far in ``lam_cum``, the current ones in ``lam_now``). Where every row's
crossing has a closed form, each row keeps its crossing until its function or tolerance
changes (`crawlsim.kernel.events.next_event_kept`), and the velocity problems are solved only
on the runs of candidate blocks that can change (`crawlsim.kernel.piece.decide_local`); the
energy terms are summed by chunks, only the chunks an event rebuilt again (`energy_terms`).
Offsets whose zeros need sampling rebuild the whole piece, seek every row and decide over the
whole chain at every event, as the Python loop does.

The loop returns a status. DONE: the period is in the output arrays. HANDOFF: a step the
compiled code does not take (a velocity problem or projection whose updates do not settle, a
dependent set, a root search that does not converge; ``report[R_REASON]`` says which); the
caller runs the period on its Python path, which decides with Clarabel. FAILED_PIECE: the
certificate of a grid sample failed (``report``). TOO_MANY / ZENO: the event guards fired.
OVERFLOW: the event arrays are full (the caller enlarges them and runs the period again).

Every function takes plain arrays and scalars; with ``NUMBA_DISABLE_JIT=1`` the same source runs
as Python.
"""

from __future__ import annotations

import math

import numpy as np

from crawlsim.kernel import terrain
from crawlsim.kernel.chain import jump
from crawlsim.kernel.events import (  # noqa: F401 - eventloop.next_event etc. are entry points too
    SIMULTANEOUS,
    closed_forms,
    crossing,
    next_event,
    next_event_kept,
    rate_tolerance,
    row_functions,
)
from crawlsim.kernel.jit import jit
from crawlsim.kernel.piece import (  # noqa: F401 - eventloop.piece etc. are its entry points too
    CLEAR_MARGIN,
    DECISION_ORDERS,
    LOCAL_BLOCKS,
    apply,
    basis_values,
    combine,
    decide,
    decide_from,
    decide_local,
    derivative,
    dual_scale,
    factored_set,
    max_abs,
    offset_size,
    piece,
    piece_on,
    rebuild,
    set_norms,
    settle_rows,
    solve_rows,
    tight_rows,
)
from crawlsim.kernel.policy import RTOL, UPDATE_ITERATIONS, tolerances

TWO_PI = 2.0 * math.pi

DONE, HANDOFF, FAILED_PIECE, TOO_MANY, ZENO, OVERFLOW = range(6)
#: Transition causes (`crawlsim.integrate.stepping.TransitionCause`), in this order.
CAUSES = ("edge", "release", "hit", "jump", "ground")
EDGE, RELEASE, HIT, JUMP, GROUND = range(5)
#: Entries of ``report`` (R_REASON: why a period was handed over, one of HANDOFF_REASONS).
R_U, R_INDEX, R_PRIMAL, R_DUAL, R_TOLP, R_TOLD, R_COMP, R_REASON = range(8)
#: Why the loop hands a period over: an event's active set (a velocity problem not settled by
#: the kernel's updates, or a dependent set), a zero the loop cannot find, a jump projection.
HANDOFF_REASONS = ("decide", "zero", "jump")
H_DECIDE, H_ZERO, H_JUMP = range(3)
#: Entries of ``counts``.
C_EVENTS, C_TRANSITIONS, C_PIECES, C_JUMPS = range(4)


# -- the grid samples of a piece and their certificate ------------------------------------------
@jit
def sample_piece(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    coef: np.ndarray,
    signs: np.ndarray,
    PHI: np.ndarray,
    j0: int,
    j1: int,
    W: np.ndarray,
    LAMC: np.ndarray,
    lam_cum: np.ndarray,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    inverse: float,
    gram: float,
    carried: float,
    own: float,
    report: np.ndarray,
    MU: np.ndarray,
    x0: np.ndarray,
    X: np.ndarray,
) -> bool:
    """W[j0:j1] and LAMC[j0:j1] at the grid times in the piece, each certified
    (`EventStepper._certify_piece`): in K(t_j), slip integrals >= 0 and complementary, to the
    kernel's tolerances; the first one carries the roundoff of earlier pieces (``carried``).
    Returns False with ``report`` filled on a failure. The record's arrays are formed in the
    same pass where MU has rows (empty arrays: none):
    MU[j-1] = LAMC[j] - LAMC[j-1] (the slips of step j - 1, the differences the certificate
    checks) and, where x0 is not empty, X[j] = x0 + (lambda^+ - lambda^-)(t_j), the block
    positions (docs/model.md §3).

    One pass over the blocks per sample: block i's force (B w)_i = w_{i-1} - w_i needs only
    the link state w_i formed in the same pass, so the state, the slips, the offsets, the
    slacks and the sizes of the tolerance are each formed once, with the operations (and so
    the bits) of ``combine`` and ``apply``."""
    N = signs.shape[0]
    nb = coef.shape[0]
    slips, positions = MU.shape[0] > 0, x0.shape[0] > 0
    for j in range(j0, j1):
        phi = PHI[j]  # phi at the grid times, tabulated once
        # sizes of the numbers summed, not of the sums: phi @ coef and base + phi @ Wc cancel
        # on short pieces with steep offsets (`EventStepper._certify_piece`)
        c_size, w_size, lam_size = 0.0, 0.0, 0.0
        primal, dual, comp = -np.inf, 0.0, 0.0
        w_left = 0.0  # w_{i-1}, 0 beyond the first block
        for i in range(N):
            w_right = 0.0
            if i < N - 1:
                acc = 0.0
                total = abs(base[i])
                for b in range(nb):
                    acc += phi[b] * Wc[b, i]
                    total += abs(phi[b]) * abs(Wc[b, i])
                w_right = acc + base[i]
                W[j, i] = w_right
                w_size = max(w_size, total)
            lam_plus, lam_minus = lam_cum[i], lam_cum[N + i]
            s = signs[i]
            if s != 0:
                slip, terms = 0.0, abs(dx0[i])
                for b in range(nb):
                    slip += phi[b] * Ydx[b, i]
                    terms += abs(phi[b] * Ydx[b, i])
                lam_size = max(lam_size, terms)  # the slips' terms cancel as w's do
                if s > 0:
                    lam_plus = lam_plus + (dx0[i] - slip)
                else:
                    lam_minus = lam_minus + -(dx0[i] - slip)
            LAMC[j, i], LAMC[j, N + i] = lam_plus, lam_minus
            lam_size = max(lam_size, max(abs(lam_plus), abs(lam_minus)))
            mu_plus, mu_minus = lam_plus - LAMC[j - 1, i], lam_minus - LAMC[j - 1, N + i]
            dual = max(dual, max(-mu_plus, -mu_minus))
            if slips:
                MU[j - 1, i], MU[j - 1, N + i] = mu_plus, mu_minus
            if positions:
                X[j, i] = x0[i] + (lam_plus - lam_minus)
            c_plus, c_minus, size_plus, size_minus = 0.0, 0.0, 0.0, 0.0
            for b in range(nb):
                c_plus += phi[b] * coef[b, i]
                c_minus += phi[b] * coef[b, N + i]
                size_plus += abs(phi[b]) * abs(coef[b, i])
                size_minus += abs(phi[b]) * abs(coef[b, N + i])
            c_size = max(c_size, max(size_plus, size_minus))
            f = w_left - w_right
            slack_plus, slack_minus = f - c_plus, -f - c_minus
            primal = max(primal, max(slack_plus, slack_minus))
            if s > 0:
                comp = max(comp, abs(slack_plus))
            elif s < 0:
                comp = max(comp, abs(slack_minus))
            w_left = w_right
        tol_p, tol_d = tolerances(c_scale, c_size, 2.0 * w_size, 4.0 * kmax * lam_size, inverse, gram, lam_size)
        tol_d = max(max(tol_d, own), 4 * RTOL * lam_size)
        if j == j0:
            tol_d = max(tol_d, carried)
        if primal > tol_p or dual > tol_d or comp > tol_p:
            report[R_INDEX] = j
            report[R_PRIMAL], report[R_DUAL], report[R_COMP] = primal, dual, comp
            report[R_TOLP], report[R_TOLD] = tol_p, tol_d
            return False
    return True


@jit
def state_at(
    u: float,
    linear: bool,
    H: int,
    signs: np.ndarray,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    lam_cum: np.ndarray,
    w: np.ndarray,
    phi: np.ndarray,
    dx: np.ndarray,
    lam_now: np.ndarray,
) -> None:
    """w(u) into ``w`` and the cumulative slips at u into ``lam_now``: ``lam_cum`` (the slips up
    to the start of each block's piece, `rebuild_changed`) plus those of the piece up to u."""
    N = signs.shape[0]
    basis_values(u, 0, linear, H, phi)
    combine(phi, Wc, w)
    for i in range(N - 1):
        w[i] += base[i]
    combine(phi, Ydx, dx)
    for i in range(N):
        lam_now[i], lam_now[N + i] = lam_cum[i], lam_cum[N + i]
        if signs[i] > 0:
            lam_now[i] = lam_cum[i] + (dx0[i] - dx[i])
        elif signs[i] < 0:
            lam_now[N + i] = lam_cum[N + i] + -(dx0[i] - dx[i])


@jit
def rebuild_changed(
    k: np.ndarray,
    old: np.ndarray,
    new: np.ndarray,
    w: np.ndarray,
    coef: np.ndarray,
    linear: bool,
    H: int,
    D: np.ndarray,
    l: np.ndarray,
    inv: np.ndarray,
    dx0: np.ndarray,
    Ydx: np.ndarray,
    Rdx: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    lam_cum: np.ndarray,
    lam_now: np.ndarray,
    dirty: np.ndarray,
    stale: np.ndarray,
    full: bool,
) -> None:
    """The piece of the set ``new`` at w (`crawlsim.kernel.piece.rebuild`) where it differs from
    the piece of ``old`` (every block when ``full``): each block whose sign changes lies in a
    range of blocks each saturated in one set or the other, ended by blocks free in both, and
    only those ranges are factored and solved again, their slips so far committed to
    ``lam_cum`` (the other runs go on with their own pieces, the same closed form from an
    earlier start), their rates Rdx formed, and their blocks and the next ones marked
    ``dirty`` (their rows' functions changed, `crawlsim.kernel.events.next_event_kept`), the
    chunks of their links ``stale`` (`energy_terms`)."""
    N = new.shape[0]
    i = 0
    while i < N:
        if not full and old[i] == new[i]:
            i += 1
            continue
        lo, hi = i, i
        if full:
            lo, hi = 0, N - 1
        while lo > 0 and (old[lo - 1] != 0 or new[lo - 1] != 0):
            lo -= 1
        while hi < N - 1 and (old[hi + 1] != 0 or new[hi + 1] != 0):
            hi += 1
        for b in range(lo, hi + 1):
            lam_cum[b], lam_cum[N + b] = lam_now[b], lam_now[N + b]
        rebuild(k, new, w, coef, lo, hi, D, l, inv, dx0, Ydx, base, Wc)
        derivative(Ydx[:, lo : hi + 1], linear, H, Rdx[:, lo : hi + 1])
        for b in range(max(lo - 1, 0), min(hi + 2, N)):
            dirty[b] = True
        for c in range(max(lo - 1, 0) // CHUNK, min(hi + 1, N - 1) // CHUNK + 1):
            stale[c] = True  # links lo - 1..hi, blocks lo..hi (`energy_terms`)
        i = hi + 1


#: Links (and blocks) per chunk of the energy terms' partial sums (`energy_terms`).
CHUNK = 32


@jit
def energy_terms(
    signs: np.ndarray,
    base: np.ndarray,
    Wc: np.ndarray,
    dY: np.ndarray,
    KLc: np.ndarray,
    dLc: np.ndarray,
    Mc: np.ndarray,
    lc: np.ndarray,
    loaded: bool,
    out: np.ndarray,
    stale: np.ndarray,
    partial: np.ndarray,
) -> None:
    """The piece's products for `crawlsim.analysis.energy.ExactLedger` (its ``piece``):
    (Wc + K Lc + base e_0) @ dLc^T, -Mc_A @ Y'^T and, with loads (``loaded``; out[2] stays 0
    without: the ledger reads two products then), -lc_A @ Y'^T, dY = Y' the slips' rates
    (`derivative` of Ydx). Each product is a sum over the links and the slipping blocks,
    summed by chunks of `CHUNK` links and blocks into ``partial`` (chunk, 3, nb, nb), and the
    chunks' sums in order into ``out``: only the chunks ``stale`` (whose links or blocks an
    event rebuilt, `rebuild_changed`; cleared here) are summed again, the others' pieces go
    on unchanged."""
    N = signs.shape[0]
    nb = Wc.shape[0]
    for c in range(stale.shape[0]):
        if not stale[c]:
            continue
        stale[c] = False
        sums = np.zeros((3, nb, nb))  # local, so that the sums stay in registers
        for i in range(c * CHUNK, min((c + 1) * CHUNK, N - 1)):
            for a in range(nb):
                # the stress coefficient a (adding base to a = 0 only: the other terms are
                # those of Wc + KLc + 0.0, the same numbers)
                stress = Wc[a, i] + KLc[a, i]
                if a == 0:
                    stress += base[i]
                for b in range(nb):
                    sums[0, a, b] += stress * dLc[b, i]
        for i in range(c * CHUNK, min((c + 1) * CHUNK, N)):  # the slipping blocks only
            s = signs[i]
            if s == 0:
                continue
            r = i if s > 0 else N + i
            for a in range(nb):
                for b in range(nb):
                    sums[1, a, b] -= Mc[a, r] * (s * dY[b, i])
            if loaded:
                for a in range(nb):
                    for b in range(nb):
                        sums[2, a, b] -= lc[a, r] * (s * dY[b, i])
        partial[c] = sums
    out[:] = 0.0
    for c in range(stale.shape[0]):
        out += partial[c]


# -- a jump of c at a breakpoint ----------------------------------------------------------------
@jit
def record_at(j: int, LAMC: np.ndarray, x0: np.ndarray, MU: np.ndarray, X: np.ndarray) -> None:
    """The record's slips of the step ending at grid point j, MU[j-1] = LAMC[j] - LAMC[j-1]
    (j > 0), and the positions X[j] = x0 + (lambda^+ - lambda^-)(t_j) (x0 not empty), as
    `sample_piece` forms them: for the first grid point and for one a jump has moved."""
    N = LAMC.shape[1] // 2
    for i in range(N):
        if j > 0:
            MU[j - 1, i] = LAMC[j, i] - LAMC[j - 1, i]
            MU[j - 1, N + i] = LAMC[j, N + i] - LAMC[j - 1, N + i]
        if x0.shape[0] > 0:
            X[j, i] = x0[i] + (LAMC[j, i] - LAMC[j, N + i])


@jit
def at_jump(
    k: np.ndarray,
    c_scale: float,
    u: float,
    p: int,
    piece_after: int,
    target: np.ndarray,
    w: np.ndarray,
    w_next: np.ndarray,
    lam_cum: np.ndarray,
    lam_jump: np.ndarray,
    lam_now: np.ndarray,
    signs: np.ndarray,
    forced: np.ndarray,
    grid: np.ndarray,
    W: np.ndarray,
    LAMC: np.ndarray,
    x0: np.ndarray,
    MU: np.ndarray,
    X: np.ndarray,
    TR_U: np.ndarray,
    TR_PIECE: np.ndarray,
    TR_SIGNS: np.ndarray,
    TR_CAUSE: np.ndarray,
    TR_HIT: np.ndarray,
    JUMP_PIECE: np.ndarray,
    JUMP_U: np.ndarray,
    JUMP_W: np.ndarray,
    JUMP_LAM: np.ndarray,
    counts: np.ndarray,
    inner: np.ndarray,
    report: np.ndarray,
) -> int:
    """The jump of c at the end u of piece p onto K(t+) = {B v <= target} (`jump`), recorded:
    the jump, the state after it (`after_jump`) and its grid point. Returns DONE, or HANDOFF
    with ``report`` saying why."""
    report[R_U] = u
    if jump(k, c_scale, w, target, signs, w_next, lam_jump, inner) != DONE:
        report[R_REASON] = H_JUMP
        return HANDOFF
    q = counts[C_JUMPS]
    JUMP_PIECE[q], JUMP_U[q] = p, u
    JUMP_W[q, 0], JUMP_W[q, 1], JUMP_LAM[q] = w, w_next, lam_jump
    counts[C_JUMPS] = q + 1
    je = after_jump(
        u,
        piece_after,
        w,
        w_next,
        lam_cum,
        lam_jump,
        signs,
        forced,
        grid,
        W,
        LAMC,
        TR_U,
        TR_PIECE,
        TR_SIGNS,
        TR_CAUSE,
        TR_HIT,
        counts,
    )
    lam_now[:] = lam_cum
    record_at(je, LAMC, x0, MU, X)
    return DONE


@jit
def slid(status: int, u: float, report: np.ndarray) -> int:
    """The loop's status after a slide on terrain (`crawlsim.kernel.terrain.settle`)."""
    if status == terrain.SETTLED:
        return DONE
    if status == terrain.OVERFLOW:
        return OVERFLOW
    report[R_U], report[R_REASON] = u, H_JUMP
    return HANDOFF


# -- one period -----------------------------------------------------------------------------------
@jit
def begin_event(
    u: float,
    w: np.ndarray,
    lam_cum: np.ndarray,
    forced: np.ndarray,
    max_events: int,
    zeno_events: int,
    zeno_window: float,
    EV_T: np.ndarray,
    EV_W: np.ndarray,
    EV_DX: np.ndarray,
    TR_HIT: np.ndarray,
    counts: np.ndarray,
    report: np.ndarray,
) -> int:
    """Record the state at an event and apply the guards (`EventStepper._guard`): DONE, or
    OVERFLOW (the arrays are full), TOO_MANY or ZENO (the rows hit in TR_HIT at the count of
    transitions)."""
    e = counts[C_EVENTS]
    t_count = counts[C_TRANSITIONS]
    if e >= EV_T.shape[0] or t_count + 2 > TR_HIT.shape[0]:
        return OVERFLOW
    N = EV_DX.shape[1]
    EV_T[e], EV_W[e] = u, w
    for i in range(N):  # the block slips so far (positions): lambda^+ - lambda^-
        EV_DX[e, i] = lam_cum[i] - lam_cum[N + i]
    counts[C_EVENTS] = e + 1
    report[R_U] = u
    if e + 1 > max_events:
        return TOO_MANY
    if e + 1 >= zeno_events and u - EV_T[e + 1 - zeno_events] <= zeno_window:
        TR_HIT[t_count] = forced
        return ZENO
    return DONE


@jit
def after_jump(
    u: float,
    piece_after: int,
    w: np.ndarray,
    w_next: np.ndarray,
    lam_cum: np.ndarray,
    lam_jump: np.ndarray,
    signs: np.ndarray,
    forced: np.ndarray,
    grid: np.ndarray,
    W: np.ndarray,
    LAMC: np.ndarray,
    TR_U: np.ndarray,
    TR_PIECE: np.ndarray,
    TR_SIGNS: np.ndarray,
    TR_CAUSE: np.ndarray,
    TR_HIT: np.ndarray,
    counts: np.ndarray,
) -> int:
    """The state after the projection at a jump: w and the cumulative slips, the transition,
    and the grid point at the jump (signals are right-continuous), whose index it returns."""
    w[:] = w_next
    for r in range(lam_cum.shape[0]):
        lam_cum[r] += lam_jump[r]
    t_count = counts[C_TRANSITIONS]
    TR_U[t_count], TR_PIECE[t_count], TR_SIGNS[t_count] = u, piece_after, signs
    TR_CAUSE[t_count], TR_HIT[t_count] = JUMP, forced
    counts[C_TRANSITIONS] = t_count + 1
    je = 0
    while grid[je] < u:
        je += 1
    W[je], LAMC[je] = w, lam_cum
    return je


@jit
def period(
    k: np.ndarray,
    c_scale: float,
    linear: bool,
    H: int,
    COEF: np.ndarray,
    edges: np.ndarray,
    jumps: np.ndarray,
    TARGET: np.ndarray,
    grid: np.ndarray,
    PHI: np.ndarray,
    w_start: np.ndarray,
    signs: np.ndarray,
    max_events: int,
    zeno_events: int,
    zeno_window: float,
    ledger: int,
    KLC: np.ndarray,
    DLC: np.ndarray,
    MC: np.ndarray,
    LC: np.ndarray,
    W: np.ndarray,
    LAMC: np.ndarray,
    MU: np.ndarray,
    x0: np.ndarray,
    X: np.ndarray,
    EV_T: np.ndarray,
    EV_W: np.ndarray,
    EV_DX: np.ndarray,
    TR_U: np.ndarray,
    TR_PIECE: np.ndarray,
    TR_SIGNS: np.ndarray,
    TR_CAUSE: np.ndarray,
    TR_HIT: np.ndarray,
    PIECE_BOUNDS: np.ndarray,
    PIECE_TERMS: np.ndarray,
    JUMP_PIECE: np.ndarray,
    JUMP_U: np.ndarray,
    JUMP_W: np.ndarray,
    JUMP_LAM: np.ndarray,
    counts: np.ndarray,
    report: np.ndarray,
    cells_per_cycle: int,
    ground: terrain.Ground,
) -> int:
    """One period from w_start (in K(0)) with the warm set ``signs`` (left at the final set), on
    the grid ``grid`` (PHI: phi at its times):
    W and LAMC (cumulative slips) on the grid, and the record's slips MU and positions X from
    x0 (x0 empty: none; `sample_piece`); the events, transitions, the pieces' energy
    terms (``ledger``: the number of products the ledger keeps, 0 without one) and the jumps
    into the other arrays, their numbers in ``counts``. On terrain (``ground``,
    `crawlsim.kernel.terrain`) each block's offsets and friction are those of the ground under
    it (COEF and MC on uniform ground, refreshed into coefw and muw), a block reaching a
    boundary is an event, and the slides that follow are jumps.
    Returns a status (module docstring)."""
    N = signs.shape[0]
    n, m = N - 1, 2 * N
    nb = COEF.shape[1]
    P = COEF.shape[0]
    G1 = grid.shape[0]
    kmax = 0.0
    for i in range(n):
        kmax = max(kmax, k[i])
    D, l, dx0, dx = np.empty(N), np.empty(max(N - 1, 0)), np.empty(N), np.empty(N)
    Ydx, Rdx = np.empty((nb, N)), np.empty((nb, N))
    base, Wc = np.empty(n), np.empty((nb, n))
    Z, times, phi0 = np.empty((m, nb)), np.empty(m), np.empty(nb)
    reach, slope_bound = np.empty(m, dtype=np.int8), np.empty((m, 3))
    C_SIZE = np.empty(P)  # the size of each piece's offsets (`offset_size`)
    for q in range(P):
        C_SIZE[q] = offset_size(COEF[q])
    phi, cvec, Bw = np.empty(nb), np.empty(m), np.empty(m)
    w, lam_cum = w_start.copy(), np.zeros(m)
    w_next, lam_jump = np.empty(n), np.empty(m)
    forced = np.zeros(m, dtype=np.bool_)
    chosen = np.empty(N, dtype=np.int8)
    # the set held at an event: the last piece's, not the warm start's (`piece.tight_rows`)
    unheld = np.zeros(N, dtype=np.int8)
    inner = np.zeros(8)
    # the velocity problems' scratch and the factor of the last set (`decide`)
    masks = np.zeros((3, m), dtype=np.bool_)
    rows_m, rows_n = np.empty((4, m)), np.zeros((5, N))
    sets = np.empty((2 + UPDATE_ITERATIONS, N), dtype=np.int8)
    factored, norms = np.full(N, 2, dtype=np.int8), np.zeros(2)
    # the piece's own factor, L_JJ^{-1} 1, the slips at the last event and the rows' kept
    # crossings (`rebuild_changed`, `next_event_kept`); built: the piece arrays hold the
    # pieces of ``signs`` on COEF[p] (not at the start, nor after an edge). Where a row's
    # zero has no closed form (``kept`` False), every event rebuilds the whole piece from the
    # state there and seeks every row again (`next_event`): the sampled zeros are then those
    # of the Python loop, which rebuilds at every event, to roundoff
    Dp, lp, inv = np.ones(N), np.zeros(max(N - 1, 0)), np.zeros(N)
    lam_now, dirty = np.zeros(m), np.ones(N, dtype=np.bool_)
    tols, rate = np.zeros(m), np.zeros(N)
    stale = np.ones((N + CHUNK - 1) // CHUNK, dtype=np.bool_)
    partial = np.zeros((stale.shape[0], 3, nb, nb))
    kept = closed_forms(linear, H)
    on_ground = terrain.active(ground)
    coefw, muw, ground_times, zg = np.empty((nb, m)), np.empty((nb, m)), np.full(N, np.inf), np.empty(nb)
    edge_mu, one = np.empty((1, m)), np.ones(1)
    jump_count = counts[C_JUMPS : C_JUMPS + 1]
    built = False
    inverse = 0.0
    W[0] = w_start
    LAMC[0] = 0.0
    record_at(0, LAMC, x0, MU, X)
    counts[:] = 0
    u, j, p, cause, reached = 0.0, 1, 0, EDGE, -1
    carried = 0.0
    while True:
        status = begin_event(
            u, w, lam_now, forced, max_events, zeno_events, zeno_window, EV_T, EV_W, EV_DX, TR_HIT, counts, report
        )
        if status != DONE:
            return status
        t_count = counts[C_TRANSITIONS]
        coef, c_size, mc = COEF[p], C_SIZE[p], MC[p]
        if on_ground:
            if not built:  # a new piece of c, or the ground under a block changed
                terrain.effective(COEF[p], MC[p], ground, coefw, muw)
            coef, c_size, mc = coefw, offset_size(coefw), muw
        held = signs if t_count > 0 else unheld
        if cause == GROUND and reached >= 0:  # its thresholds jumped: its rows are not held
            held = held.copy()
            held[reached] = 0
        if built and kept and N >= LOCAL_BLOCKS and cause != GROUND:  # the piece of ``signs`` is in place
            decided = decide_local(
                k,
                kmax,
                c_scale,
                linear,
                H,
                coef,
                c_size,
                u,
                w,
                forced,
                signs,
                chosen,
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
                inner,
                Rdx,
                inverse,
                rate,
                held,
            )
        else:
            decided = decide(
                k,
                kmax,
                c_scale,
                linear,
                H,
                coef,
                u,
                w,
                forced,
                signs,
                chosen,
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
                inner,
                held,
            )
        if not decided:
            report[R_U], report[R_REASON] = u, H_DECIDE
            return HANDOFF
        moved = terrain.depart(ground, chosen, u) if on_ground else 0
        if moved < 0:
            return OVERFLOW
        if moved > 0:  # onto the ground beside a boundary: a slide where it is smoother
            lam_cum[:] = lam_now
            built = False
            basis_values(u, 0, linear, H, phi)
            jumped = jump_count[0]
            status = slid(
                terrain.settle(
                    k,
                    c_scale,
                    u,
                    ground,
                    (COEF[p], MC[p], phi, coefw, muw),
                    (w, lam_cum, signs, x0),
                    (-1 - p, -1 - p, u, JUMP_PIECE, JUMP_U, JUMP_W, JUMP_LAM, jump_count),
                    inner,
                    False,
                ),
                u,
                report,
            )
            if status != DONE:
                return status
            lam_now[:] = lam_cum
            coef, c_size = coefw, offset_size(coefw)
            if jump_count[0] > jumped:  # it slid: the set is decided again where it stopped
                forced[:] = False
                cause = GROUND
                continue
        rebuild_changed(
            k,
            signs,
            chosen,
            w,
            coef,
            linear,
            H,
            Dp,
            lp,
            inv,
            dx0,
            Ydx,
            Rdx,
            base,
            Wc,
            lam_cum,
            lam_now,
            dirty,
            stale,
            not (built and kept),
        )
        built = True
        signs[:] = chosen
        TR_U[t_count], TR_PIECE[t_count], TR_SIGNS[t_count] = u, p, signs
        TR_CAUSE[t_count], TR_HIT[t_count] = cause, forced
        counts[C_TRANSITIONS] = t_count + 1
        inverse, gram = set_norms(k, signs, inv)
        u_end = edges[p + 1]
        reached, u_g = -1, np.inf
        if on_ground:  # a block reaching a boundary: sought before the rows clear ``dirty``
            basis_values(u, 0, linear, H, phi0)
            u_g, reached = terrain.next_crossing(
                ground,
                signs,
                (x0, lam_cum),
                (dx0, Ydx, linear, H, phi0, cells_per_cycle, dirty),
                u,
                u_end,
                (zg, ground_times),
            )
        if kept:
            u_e, handoff = (
                next_event_kept(
                    c_scale,
                    linear,
                    H,
                    coef,
                    c_size,
                    signs,
                    base,
                    Wc,
                    Rdx,
                    inverse,
                    u,
                    u_end,
                    dirty,
                    forced,
                    Z,
                    times,
                    tols,
                    phi0,
                ),
                False,
            )
        else:
            u_e, handoff = next_event(
                c_scale,
                linear,
                H,
                coef,
                c_size,
                signs,
                base,
                Wc,
                Ydx,
                inverse,
                u,
                u_end,
                forced,
                Rdx,
                Z,
                times,
                reach,
                slope_bound,
                phi0,
                cells_per_cycle,
            )
        if handoff:
            report[R_U], report[R_REASON] = u, H_ZERO
            return HANDOFF
        if u_g < min(u_e, u_end):  # the block reaches it before the rows' next event
            u_e = u_g
            forced[:] = False
        else:
            reached = -1
        event = u_e < u_end
        if not event:
            u_e = u_end
        if ledger > 0 and u_e > u:
            q = counts[C_PIECES]
            PIECE_BOUNDS[q, 0], PIECE_BOUNDS[q, 1] = u, u_e
            energy_terms(signs, base, Wc, Rdx, KLC[p], DLC[p], mc, LC[p], ledger == 3, PIECE_TERMS[q], stale, partial)
            counts[C_PIECES] = q + 1
        own = dual_scale(k, kmax, c_scale, signs, c_size, dx0, Ydx, base, Wc, inverse, gram)
        j_end = j
        while j_end < G1 and grid[j_end] <= u_e:
            j_end += 1
        if j_end > j:
            if not sample_piece(
                k,
                kmax,
                c_scale,
                coef,
                signs,
                PHI,
                j,
                j_end,
                W,
                LAMC,
                lam_cum,
                dx0,
                Ydx,
                base,
                Wc,
                inverse,
                gram,
                carried,
                own,
                inner,
                MU,
                x0,
                X,
            ):
                report[1:] = inner[1:]
                return FAILED_PIECE
            carried = own
            j = j_end
        else:  # the grid interval spans this piece: its roundoff enters the next sample
            carried = max(carried, own)
        state_at(u_e, linear, H, signs, dx0, Ydx, base, Wc, lam_cum, w, phi, dx, lam_now)
        u = u_e
        if event and reached >= 0:  # held at the boundary, on beyond it, or a slide onto it
            if not terrain.arrive(ground, reached, signs[reached], u):
                return OVERFLOW
            terrain.effective(COEF[p], MC[p], ground, coefw, muw)
            combine(phi, coefw, cvec)
            if not terrain.violated(w, cvec, RTOL * max(c_scale, 2.0 * max_abs(w), max_abs(cvec)), Bw):
                # held, or on ground as rough: only this block's rows changed; the piece goes on
                # (its sign, if it changes, is rebuilt at the next event with the rest of its run,
                # which the velocity problems of the whole chain decide)
                for b in range(max(reached - 1, 0), min(reached + 2, N)):
                    dirty[b] = True
                stale[reached // CHUNK] = True
                cause = GROUND
                continue
            lam_cum[:] = lam_now
            built = False
            status = slid(
                terrain.settle(
                    k,
                    c_scale,
                    u,
                    ground,
                    (COEF[p], MC[p], phi, coefw, muw),
                    (w, lam_cum, signs, x0),
                    (-1 - p, -1 - p, u, JUMP_PIECE, JUMP_U, JUMP_W, JUMP_LAM, jump_count),
                    inner,
                    False,
                ),
                u,
                report,
            )
            if status != DONE:
                return status
            lam_now[:] = lam_cum
            cause = GROUND
            continue
        if event:
            cause = HIT if forced.any() else RELEASE
            continue
        forced[:] = False
        cause = EDGE
        edge = p + 1
        lam_cum[:] = lam_now  # the next piece is built anew (another piece of c)
        built = False
        if jumps[edge] and on_ground:  # the jump's slide, stage by stage (`crawlsim.kernel.terrain`)
            u_after = u if edge < P else 0.0
            basis_values(u_after, 0, linear, H, phi)
            combine(phi, MC[edge % P], edge_mu[0])
            status = slid(
                terrain.settle(
                    k,
                    c_scale,
                    u,
                    ground,
                    (TARGET[edge : edge + 1], edge_mu, one, coefw[:1], muw[:1]),
                    (w, lam_cum, signs, x0),
                    (p, -1 - edge % P, u_after, JUMP_PIECE, JUMP_U, JUMP_W, JUMP_LAM, jump_count),
                    inner,
                    True,
                ),
                u,
                report,
            )
            if status != DONE:
                return status
            lam_jump[:] = 0.0
            je = after_jump(
                u,
                edge % P,
                w,
                w,
                lam_cum,
                lam_jump,
                signs,
                forced,
                grid,
                W,
                LAMC,
                TR_U,
                TR_PIECE,
                TR_SIGNS,
                TR_CAUSE,
                TR_HIT,
                counts,
            )
            lam_now[:] = lam_cum
            record_at(je, LAMC, x0, MU, X)
        elif (
            jumps[edge]
            and at_jump(
                k,
                c_scale,
                u,
                p,
                edge % P,
                TARGET[edge],
                w,
                w_next,
                lam_cum,
                lam_jump,
                lam_now,
                signs,
                forced,
                grid,
                W,
                LAMC,
                x0,
                MU,
                X,
                TR_U,
                TR_PIECE,
                TR_SIGNS,
                TR_CAUSE,
                TR_HIT,
                JUMP_PIECE,
                JUMP_U,
                JUMP_W,
                JUMP_LAM,
                counts,
                inner,
                report,
            )
            != DONE
        ):
            return HANDOFF
        if edge == P:
            break
        p = edge
    if j != G1:
        return HANDOFF  # pragma: no cover - the grid ends at 1, the last edge
    return DONE
