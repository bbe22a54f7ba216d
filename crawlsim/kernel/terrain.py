"""The ground under a crawler's blocks, compiled (docs/model.md §8): where each block stands, its
friction factors there, the event of a block reaching a boundary, and what follows it.

The ground is cells between boundaries (`crawlsim.gait.terrain.Terrain`). A block is inside a
cell, or at a boundary, where its factors are the larger of both sides (the closure). Each
block's rows of c(t) are its offsets on uniform ground plus (a - 1) times their friction part,
a the factor of the row (`effective`): with a = 1 the offsets themselves, bit for bit.

* **Reaching a boundary** is an event of the exact integrator: on a piece, block i's position
  x_i(u) = x_i + dx0_i - phi(u) @ Ydx_i is a combination of the basis like every gap, and its
  crossing of the next boundary ahead is found by the same closed forms (`next_crossing`). Onto
  rougher ground (a larger factor in the direction of motion) the block is held at the boundary
  (its row is no longer tight); onto ground as rough it goes on; onto smoother ground its force
  exceeds the new threshold and it slides on at once (`arrive`, then `settle`).
* **A block held at a boundary** leaves it when its force reaches the closure's threshold: the
  velocity problems decide it as any other row, and it then enters the cell on that side
  (`depart`), sliding on at once where that side is smoother.
* **The slide** is the limit of a viscous slide (docs/model.md §8): the least stable state
  beyond the start, found stage by stage (`settle`). A stage projects the state onto the set
  of the current factors (`crawlsim.kernel.eventloop.jump`, certified), with every block that
  would pass a boundary held at it (pinned at its displacement: its rows ignored, its force
  certified to reach its cell's threshold, pins added and dropped as the primal-dual active
  set of that box); blocks that moved are relocated, and the next stage starts where the
  factors have dropped under a block's force. Each stage is a jump of the energy ledger, with
  its factors (``fac``).

The catch-up integrator takes the factors of the ground at the positions each step starts from
(`catch_up`). Plain arrays and scalars in one record, `Ground`; with ``NUMBA_DISABLE_JIT=1`` the
same source runs as Python.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from crawlsim.kernel import chain, sampling
from crawlsim.kernel.events import crossing
from crawlsim.kernel.jit import jit
from crawlsim.kernel.piece import apply, combine, max_abs
from crawlsim.kernel.policy import RTOL

#: A position within this much (relative, at least absolute) of a boundary is at it.
SNAP = 1e-12
#: Stages of one slide before the loop hands the period over.
MAX_STAGES = 64
#: Kinds of ground events (``log[:, 3]``): held at a boundary, passed it, left a boundary.
HOLD, CROSS, LEAVE = range(3)
#: Columns of ``log``: the cycle, the block, the boundary, the kind, the direction (+1, -1), and
#: the block's factors (a^+, a^-) after the event.
L_U, L_BLOCK, L_BOUNDARY, L_KIND, L_DIRECTION, L_PLUS, L_MINUS = range(7)
#: What `settle` and `arrive` return.
SETTLED, HANDOFF, OVERFLOW = range(3)


class Ground(NamedTuple):
    """The ground and where the blocks stand on it: one record for the event loop and the
    catch-up steps. No terrain: ``plus`` empty (nothing here is then read)."""

    bounds: np.ndarray  # (K,) boundaries, sorted; in [0, repeat) when periodic
    plus: np.ndarray  # (C,) factor on mu^+ of each cell
    minus: np.ndarray  # (C,) factor on mu^-
    repeat: float  # the period of the ground, 0 on a line
    cell: np.ndarray  # (N,) int64: the cell of each block (state, in place)
    at: np.ndarray  # (N,) bool: at the right boundary of its cell
    log: np.ndarray  # (capacity, 7) the period's ground events (``L_U`` ...)
    logged: np.ndarray  # (1,) int64: entries of log
    fac: np.ndarray  # (jumps, 2N) the factors of each row during each jump of the period
    pinned: np.ndarray  # (jumps,) bool: whether the jump held a block at a boundary it would pass


@jit
def active(ground: Ground) -> bool:
    return bool(ground.plus.shape[0] > 0)


@jit
def bound(ground: Ground, g: int) -> float:
    """The position of boundary g (+-inf beyond the ends of a line)."""
    K = ground.bounds.shape[0]
    if ground.repeat > 0.0:
        q = g // K
        return float(ground.bounds[g - q * K] + ground.repeat * q)
    if g < 0:
        return -math.inf
    if g >= K:
        return math.inf
    return float(ground.bounds[g])


@jit
def cell_factors(ground: Ground, g: int) -> tuple[float, float]:
    C = ground.plus.shape[0]
    c = g % C if ground.repeat > 0.0 else min(max(g, 0), C - 1)
    return ground.plus[c], ground.minus[c]


@jit
def block_factors(ground: Ground, i: int) -> tuple[float, float]:
    """(a^+, a^-) under block i: its cell's, or the larger of both sides at a boundary."""
    a, b = cell_factors(ground, ground.cell[i])
    if ground.at[i]:
        a2, b2 = cell_factors(ground, ground.cell[i] + 1)
        a, b = max(a, a2), max(b, b2)
    return a, b


@jit
def locate(ground: Ground, i: int, x: float) -> None:
    """Block i at position x: its cell, or the boundary within `SNAP` of x."""
    K = ground.bounds.shape[0]
    ground.at[i] = False
    if K == 0:
        ground.cell[i] = 0
        return
    q = math.floor(x / ground.repeat) if ground.repeat > 0.0 else 0
    g = int(np.searchsorted(ground.bounds, x - q * ground.repeat)) + q * K
    ground.cell[i] = g
    for h in (g - 1, g):
        if abs(x - bound(ground, h)) <= SNAP * max(1.0, abs(x)):
            ground.cell[i], ground.at[i] = h, True


@jit
def effective(coef: np.ndarray, mu: np.ndarray, ground: Ground, out: np.ndarray, mu_out: np.ndarray) -> None:
    """Each row's offsets coef + (a - 1) mu and friction a mu with the factor a under its block
    (coef, mu: (nb, 2N) coefficients, or (1, 2N) values); a = 1 copies them."""
    N = ground.cell.shape[0]
    for i in range(N):
        a, b = block_factors(ground, i)
        scale_row(coef, mu, i, a, out, mu_out)
        scale_row(coef, mu, N + i, b, out, mu_out)


@jit
def scale_row(coef: np.ndarray, mu: np.ndarray, r: int, f: float, out: np.ndarray, mu_out: np.ndarray) -> None:
    for q in range(coef.shape[0]):
        out[q, r] = coef[q, r] if f == 1.0 else coef[q, r] + (f - 1.0) * mu[q, r]
        mu_out[q, r] = mu[q, r] if f == 1.0 else f * mu[q, r]


@jit
def factors(ground: Ground, out: np.ndarray) -> None:
    """The factor of every row (2N) under the blocks now."""
    N = ground.cell.shape[0]
    for i in range(N):
        out[i], out[N + i] = block_factors(ground, i)


@jit
def record(ground: Ground, u: float, i: int, g: int, kind: int, direction: int) -> bool:
    """A ground event into the log, with block i's factors where it now stands; False when the
    log is full."""
    e = ground.logged[0]
    if e >= ground.log.shape[0]:
        return False
    ground.log[e, L_U], ground.log[e, L_BLOCK], ground.log[e, L_BOUNDARY] = u, i, g
    ground.log[e, L_KIND], ground.log[e, L_DIRECTION] = kind, direction
    ground.log[e, L_PLUS], ground.log[e, L_MINUS] = block_factors(ground, i)
    ground.logged[0] = e + 1
    return True


@jit
def ahead(ground: Ground, i: int, s: int) -> int:
    """The boundary block i meets next moving in direction s: the end of its cell (of the cell
    on that side, for a block at a boundary)."""
    g = int(ground.cell[i])
    if ground.at[i]:
        return g + 1 if s > 0 else g - 1
    return g if s > 0 else g - 1


# -- the event: a block reaching a boundary -------------------------------------------------------
@jit
def next_crossing(
    ground: Ground,
    signs: np.ndarray,
    start: tuple[np.ndarray, ...],
    piece: tuple[Any, ...],
    u0: float,
    u1: float,
    scratch: tuple[np.ndarray, ...],
) -> tuple[float, int]:
    """(u, block) of the first slipping block to reach the boundary ahead of it in (u0, u1), u1
    the end of the piece of c (inf, -1: none). start = (x0, lam_cum): the positions at the
    period's start and the slips up to the start of each block's piece; piece = (dx0, Ydx,
    linear, H, phi0, cells_per_cycle, dirty): the slip dx0 - phi(u) @ Ydx on the piece, and the
    blocks whose piece changed; scratch = (z (nb), times (N)). A block's crossing, sought to
    u1, is kept in ``times`` while its piece is the same and it is still ahead (as
    `crawlsim.kernel.events.next_event_kept` keeps the rows'): an event seeks only the blocks it
    changed."""
    x0, lam_cum = start
    dx0, Ydx, linear, H, phi0, cells_per_cycle, dirty = piece
    z, times = scratch
    N = signs.shape[0]
    first, who = np.inf, -1
    for i in range(N):
        if dirty[i] or not times[i] > u0:
            times[i] = np.inf
            s = signs[i]
            b = bound(ground, ahead(ground, i, s)) if s != 0 else np.inf
            if math.isfinite(b):
                for q in range(z.shape[0]):
                    z[q] = -s * Ydx[q, i]
                z[0] += s * (x0[i] + lam_cum[i] - lam_cum[N + i] + dx0[i] - b)
                tol = SNAP * max(1.0, abs(b))
                t = crossing(z, tol, u0, u1, linear, H, phi0, u1)
                if np.isnan(t):  # no closed form: certified sampling (`crawlsim.kernel.sampling`)
                    count = sampling.cells(u0, u1, cells_per_cycle, H)
                    S, PHIS = np.empty(count + 1), np.empty((count + 1, z.shape[0]))
                    sampling.grid(u0, u1, count, S)
                    t = sampling.crossing(z, tol, u0, u1, linear, H, u1, S, PHIS, np.zeros(1, dtype=np.int64))
                times[i] = t
        if times[i] < first:
            first, who = times[i], i
    return first, who


@jit
def arrive(ground: Ground, i: int, s: int, u: float) -> bool:
    """Block i, moving in direction s, at the boundary ahead: held there where the ground beyond
    is rougher in that direction, else on the ground beyond. False when the log is full."""
    g = ahead(ground, i, s)
    now = cell_factors(ground, ground.cell[i])[0 if s > 0 else 1]
    beyond = cell_factors(ground, g + 1 if s > 0 else g)[0 if s > 0 else 1]
    if beyond > now:
        ground.cell[i], ground.at[i] = g, True
        return record(ground, u, i, g, HOLD, s)
    ground.cell[i], ground.at[i] = (g + 1 if s > 0 else g), False
    return record(ground, u, i, g, CROSS, s)


@jit
def depart(ground: Ground, chosen: np.ndarray, u: float) -> int:
    """Blocks at a boundary that the velocity problems set slipping enter the cell on that side.
    Returns how many did, -1 when the log is full."""
    moved = 0
    for i in range(chosen.shape[0]):
        s = chosen[i]
        if s == 0 or not ground.at[i]:
            continue
        g = ground.cell[i]
        ground.cell[i], ground.at[i] = (g + 1 if s > 0 else g), False
        if not record(ground, u, i, g, LEAVE, s):
            return -1
        moved += 1
    return moved


@jit
def violated(w: np.ndarray, target: np.ndarray, tol: float, slack: np.ndarray) -> bool:
    """Whether some row of B w <= target fails by more than tol."""
    apply(w, slack)
    for r in range(target.shape[0]):
        if slack[r] - target[r] > tol:
            return True
    return False


# -- the slide onto smoother ground ---------------------------------------------------------------
@jit
def settle(
    k: np.ndarray,
    c_scale: float,
    u: float,
    ground: Ground,
    offsets: tuple[np.ndarray, ...],
    state: tuple[np.ndarray, ...],
    jumps: tuple[Any, ...],
    report: np.ndarray,
    always: bool,
) -> int:
    """Where the factors under the blocks have dropped below their forces, the slide that
    follows, stage by stage (module docstring). offsets = (coef, mu, phi, coefw, muw): the
    piece's offsets and friction coefficients on uniform ground and phi(u), coefw and muw
    refreshed with the factors (`effective`); state = (w, lam_cum, signs, x0), w and lam_cum
    advanced by every stage; jumps = (first, within, u_within, JUMP_PIECE, JUMP_U, JUMP_W,
    JUMP_LAM, count): each stage a jump record, the first of piece ``first`` at u, the others of
    piece ``within`` at ``u_within`` (-1 - p: within piece p, `crawlsim.integrate.ledger`),
    its factors in ``ground.fac``, count[0] the records so far. ``always``: the first stage is
    made and recorded even with nothing violated (a jump of c). Returns SETTLED, HANDOFF
    (``report`` as `crawlsim.kernel.chain.jump` leaves it) or OVERFLOW."""
    coef, mu, phi, coefw, muw = offsets
    w, lam_cum, signs, x0 = state
    first, within, u_within, JUMP_PIECE, JUMP_U, JUMP_W, JUMP_LAM, count = jumps
    N = signs.shape[0]
    m = 2 * N
    target, tgt, slack, lam = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    fac = np.empty(m)
    wt, w_out = np.empty(N - 1), np.empty(N - 1)
    pinned, dpin = np.zeros(N, dtype=np.bool_), np.zeros(N)
    for stage in range(MAX_STAGES):
        effective(coef, mu, ground, coefw, muw)
        combine(phi, coefw, target)
        tol = RTOL * max(c_scale, 2.0 * max_abs(w), max_abs(target))
        if not (always and stage == 0) and not violated(w, target, tol, slack):
            return SETTLED
        factors(ground, fac)
        pinned[:] = False
        for attempt in range(2 * N + 2):
            # the pinned blocks moved to their boundaries, their rows ignored
            wt[:] = w
            for j in range(N):
                tgt[j], tgt[N + j] = target[j], target[N + j]
                if pinned[j]:
                    tgt[j], tgt[N + j] = np.inf, np.inf
                    signs[j] = 0
                    if j > 0:
                        wt[j - 1] -= k[j - 1] * dpin[j]
                    if j < N - 1:
                        wt[j] += k[j] * dpin[j]
            if chain.jump(k, c_scale, wt, tgt, signs, w_out, lam, report) != chain.DONE:
                return HANDOFF
            change = False
            for j in range(N):
                xj = x0[j] + lam_cum[j] - lam_cum[N + j]
                if pinned[j]:  # its force must reach its cell's threshold: else it stops short
                    s = 1 if dpin[j] > 0 else -1
                    f = chain.force(w_out, j, N)
                    if s * f < (target[j] if s > 0 else target[N + j]) - tol:
                        pinned[j], change = False, True
                    continue
                dx = lam[j] - lam[N + j]
                if dx == 0.0:
                    continue
                s = 1 if dx > 0 else -1
                b = bound(ground, ahead(ground, j, s))
                if s * (xj + dx - b) > SNAP * max(1.0, abs(b)):
                    pinned[j], dpin[j], change = True, b - xj, True
            if not change:
                break
            if attempt == 2 * N + 1:
                return HANDOFF
        q = count[0]
        if q >= JUMP_U.shape[0]:
            return OVERFLOW
        for j in range(N):  # the pinned blocks' displacements are slips at their cell's threshold
            if pinned[j]:
                lam[j], lam[N + j] = max(dpin[j], 0.0), max(-dpin[j], 0.0)
        JUMP_PIECE[q], JUMP_U[q] = (first, u) if stage == 0 else (within, u_within)
        JUMP_W[q, 0], JUMP_W[q, 1], JUMP_LAM[q] = w, w_out, lam
        ground.fac[q] = fac
        ground.pinned[q] = pinned.any()
        count[0] = q + 1
        for j in range(N):
            dx = lam[j] - lam[N + j]
            if dx == 0.0:
                continue
            s = 1 if dx > 0 else -1
            if pinned[j] and ground.at[j]:  # it left one boundary for the next
                g = ground.cell[j]
                ground.cell[j], ground.at[j] = (g + 1 if s > 0 else g), False
                if not record(ground, u, j, g, LEAVE, s):
                    return OVERFLOW
            if pinned[j]:
                g = ahead(ground, j, s)
                ground.cell[j], ground.at[j] = g, True
                kind = HOLD
            elif ground.at[j]:
                g = ground.cell[j]
                ground.cell[j], ground.at[j] = (g + 1 if s > 0 else g), False
                kind = LEAVE
            else:
                continue
            if not record(ground, u, j, g, kind, s):
                return OVERFLOW
        w[:] = w_out
        for r in range(m):
            lam_cum[r] += lam[r]
    report[0] = u
    return HANDOFF


# -- catch-up ---------------------------------------------------------------------------------------
@jit
def catch_up(
    k: np.ndarray,
    c_scale: float,
    C: np.ndarray,
    MU: np.ndarray,
    ground: Ground,
    X: np.ndarray,
    W: np.ndarray,
    LAM: np.ndarray,
    S: np.ndarray,
    carry: tuple[np.ndarray, ...],
    j0: int,
    report: np.ndarray,
) -> tuple[int, int]:
    """Catch-up steps j = j0, ... of a period (`crawlsim.kernel.chain.catch_up`, one step at a
    time), each with the factors of the ground at the positions X[j] it starts from: C[j+1] +
    (a - 1) MU[j+1] into ``CW`` (the offsets the Python projector takes where a step is handed
    over). carry = (signs, factored, D, l, norms, CW, total, scratch): the kernel's set and
    factor, the running sum of the slips (X[j+1] = x0 + dx_0 + ... + dx_j,
    `crawlsim.kernel.chain.positions`) and a (1, 2N) scratch. A block whose cell changes is
    logged (CROSS, at the step's end). Returns (status, j)."""
    signs, factored, D, l, norms, CW, total, scratch = carry
    N = signs.shape[0]
    G = LAM.shape[0]
    cell = ground.cell.copy()
    for j in range(j0, G):
        for i in range(N):
            locate(ground, i, X[j, i])
        effective(C[j + 1 : j + 2], MU[j + 1 : j + 2], ground, CW[j + 1 : j + 2], scratch)
        status, _ = chain.catch_up(k, c_scale, CW, W, LAM[: j + 1], S, signs, factored, D, l, norms, j, report)
        if status != chain.DONE:
            return status, j
        advance(LAM, X, total, j)
        for i in range(N):
            if ground.cell[i] != cell[i]:  # logged while there is room (the run checks the last ground too)
                s = 1 if ground.cell[i] > cell[i] else -1
                record(ground, (j + 1) / G, i, min(cell[i], ground.cell[i]), CROSS, s)
            cell[i] = ground.cell[i]
    return chain.DONE, G


@jit
def advance(LAM: np.ndarray, X: np.ndarray, total: np.ndarray, j: int) -> None:
    """X[j+1] from the slips of step j, as `crawlsim.kernel.chain.positions` forms it."""
    N = X.shape[1]
    for i in range(N):
        dx = LAM[j, i] - LAM[j, N + i]
        t = dx if j == 0 else total[i] + dx
        total[i] = t
        X[j + 1, i] = t + X[0, i]
