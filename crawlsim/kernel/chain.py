"""The compiled, certified catch-up step of a crawler chain (docs/model.md §3).

One step projects the trial state w_j onto K(t_{j+1}) = {w : B w <= c} in the metric M = K^{-1},
with B = [D^T; -D^T] (`crawlsim.projection.chain_polyhedron.ChainPolyhedron`). On the saturated blocks J, with signs
s_i = +1 (forward limit, row i) or -1 (backward limit, row N + i), the KKT system is

    L_JJ dx_J = f_J - f*_J,   f = D^T w_j,   f*_i = c_i (s_i = +1) or -c_{N+i} (s_i = -1),

L = D^T K D the chain's tridiagonal stiffness Laplacian, and the step is
w_{j+1} = w_j - K D dx, multipliers lambda_i = dx_i (s_i = +1), lambda_{N+i} = -dx_i (s_i = -1).
The system is padded to all N blocks (identity rows on free blocks, no coupling across them) and
factored by LDL^T in O(N) (the Thomas recurrence), refactored only when J changes.

Every step is certified with the tolerance policy of `crawlsim.projection.polyhedron.Polyhedron.solve_on` and
`certify` (one policy for every integrator): primal feasibility max(B w - c) <= tol_p, the sign
of the multipliers -min(lambda) <= tol_d and complementarity max |(B w - c)_J| <= tol_p, where

    size  = max(c_scale, |c|, ||B|| |w_j|, ||B|| ||K D|| |lambda|),   ||B|| = 2, ||K D|| = 2 max k,
    tol_p = RTOL size,   tol_d = 2 RTOL ||L_JJ^{-1}|| (size + ||L_JJ|| |lambda|),

with ||L_JJ^{-1}||_inf = max(L_JJ^{-1} 1) exactly (an M-matrix). A complementarity residual above
a quarter of tol_p gets one step of iterative refinement. An uncertified step moves its active
set by the primal-dual updates of `crawlsim.projection.polyhedron.Polyhedron.refine` (drop the rows with negative
multipliers, add the violated rows; the worst one alone, or the exchange of Goldfarb and Idnani,
where all at once would saturate every block). A certified KKT point of this strictly convex
problem is the projection, so the steps agree with `crawlsim.projection.kkt` to roundoff.

A step at N = 4 costs a few hundred machine instructions, so its shape is its cost: after the
solve, one pass over the blocks forms the point, the multipliers, the slack and the three
numbers of the certificate (`state`); the sign of each multiplier is held to its own row's
tolerance (`row_duals`, at most tol_d, one more solve), which is formed only where it can
decide (a negative multiplier, or a step failing on its other numbers): a step whose
multipliers are all >= 0 passes the sign check under any tolerance in [0, tol_d], so every
step's certificate is the one above. The small functions of the step are inlined into the loop
(``inline='always'``: a call with twenty array arguments costs as much as a pass), and the
loop's scratch is allocated once per call of `catch_up`, not per step.

Everything here is a function of plain arrays and scalars, compiled by numba; with
``NUMBA_DISABLE_JIT=1`` the same source runs as Python.
"""

from __future__ import annotations

import numpy as np

from crawlsim.kernel.jit import jit
from crawlsim.kernel.policy import REFINE_FRACTION, RTOL, UPDATE_ITERATIONS, tolerances

#: What `catch_up` returns: every step done; step j handed to the Python projector (the
#: updates did not settle, or the step is certified with every block tight, where LICQ and the
#: uniqueness of the slips are decided there); step j failed its certificate with no update
#: left to try (the report array says how).
DONE, HANDOFF, FAILED = 0, 1, 2
#: Entries of the report array of a FAILED step.
REPORT_PRIMAL, REPORT_DUAL, REPORT_COMP, REPORT_TOLP, REPORT_TOLD, REPORT_ROW = range(6)
#: Restarts of the projection at a jump from the set where its primal-dual updates stopped: a
#: jump may change more rows than `UPDATE_ITERATIONS` updates do when the tight set, nearly
#: every block, only admits them one at a time.
JUMP_RESTARTS = 8


@jit
def factor(k: np.ndarray, signs: np.ndarray, D: np.ndarray, l: np.ndarray) -> tuple[float, float]:
    """LDL^T of the padded L~ (diagonal L_ii on saturated blocks, 1 on free ones; off-diagonal
    -k_i where blocks i and i+1 are both saturated) into the pivots D and unit subdiagonal l.
    Returns (||L_JJ^{-1}||_inf, ||L_JJ||_inf)."""
    return factor_into(k, signs, D, l, np.empty(signs.shape[0]))


@jit
def factor_into(k: np.ndarray, signs: np.ndarray, D: np.ndarray, l: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """`factor` with the caller's scratch ``y`` (N) for the solve that gives ||L_JJ^{-1}||:
    the catch-up loop refactors without allocating."""
    N = signs.shape[0]
    gram = 0.0
    for i in range(N):
        if signs[i] != 0:
            d = (k[i - 1] if i > 0 else 0.0) + (k[i] if i < N - 1 else 0.0)
            D[i] = d
            if 2.0 * d > gram:
                gram = 2.0 * d
        else:
            D[i] = 1.0
    eliminate(k, signs, D, l, 0, N - 1)
    # L_JJ is an M-matrix: its inverse is non-negative, ||L_JJ^{-1}||_inf = max(L_JJ^{-1} 1)
    for i in range(N):
        y[i] = 1.0 if signs[i] != 0 else 0.0
    solve(D, l, y)
    inverse = 0.0
    for i in range(N):
        if signs[i] != 0 and y[i] > inverse:
            inverse = y[i]
    return inverse, gram


@jit
def eliminate(k: np.ndarray, signs: np.ndarray, D: np.ndarray, l: np.ndarray, lo: int, hi: int) -> None:
    """The elimination of `factor` along blocks lo..hi, their pivots D on the diagonal: the
    subdiagonal l and the pivots after it. l = 0 between runs (D[i] - 0 * 0 = D[i]): no chain
    across them, so a run can be refactored alone (`crawlsim.kernel.piece.rebuild`)."""
    for i in range(lo + 1, hi + 1):
        if signs[i - 1] != 0 and signs[i] != 0:
            e = -k[i - 1]
            l[i - 1] = e / D[i - 1]
            D[i] -= l[i - 1] * e
        else:
            l[i - 1] = 0.0


@jit
def solve(D: np.ndarray, l: np.ndarray, y: np.ndarray) -> None:
    """y <- L~^{-1} y in place with the LDL^T factor (D, l). The terms with l = 0 (between
    two runs of saturated blocks) are skipped: y - 0 y = y for finite y, and the recurrences
    then chain only along a run, not along the whole chain."""
    N = y.shape[0]
    for i in range(1, N):
        if l[i - 1] != 0.0:
            y[i] -= l[i - 1] * y[i - 1]
    for i in range(N):
        y[i] /= D[i]
    for i in range(N - 2, -1, -1):
        if l[i] != 0.0:
            y[i] -= l[i] * y[i + 1]


@jit
def force(w: np.ndarray, i: int, N: int) -> float:
    """f_i = (D^T w)_i = w_{i-1} - w_i, with w_{-1} = w_{N-1} = 0: the net force on block i."""
    if i == 0:
        return float(-w[0])
    if i == N - 1:
        return float(w[N - 2])
    return float(w[i - 1] - w[i])


@jit
def forces(w: np.ndarray, f: np.ndarray) -> None:
    """f = D^T w (`force` of every block)."""
    N = f.shape[0]
    for i in range(N):
        f[i] = force(w, i, N)


@jit
def state(
    k: np.ndarray,
    w_trial: np.ndarray,
    dx: np.ndarray,
    signs: np.ndarray,
    w: np.ndarray,
    lam: np.ndarray,
    slack: np.ndarray,
    c: np.ndarray,
    fixed: np.ndarray,
) -> tuple[float, float, float, float]:
    """From the slips dx (0 on free blocks): the point w = w_trial - K D dx, the multipliers
    lambda (2N) and the slack B w - c, in one pass over the blocks (f_i = (D^T w)_i as in
    `forces`), with the step's certificate from the same numbers. Returns (max |lambda|,
    primal, dual, complementarity): max(B w - c), max(0, -min lambda) over the rows not
    ``fixed`` (equalities: multipliers of either sign), max |(B w - c)_A|."""
    N = signs.shape[0]
    lam_size = 0.0
    primal = -np.inf
    dual = 0.0
    comp = 0.0
    for i in range(N):
        if i < N - 1:
            w[i] = w_trial[i] - (dx[i + 1] - dx[i]) * k[i]
        fi = force(w, i, N)
        up = fi - c[i]
        down = -fi - c[N + i]
        slack[i] = up
        slack[N + i] = down
        if up > primal:
            primal = up
        if down > primal:
            primal = down
        s = signs[i]
        if s > 0:
            lam[i] = dx[i]
            lam[N + i] = 0.0
            r = abs(up)
            if -dx[i] > dual and not fixed[i]:
                dual = -dx[i]
        elif s < 0:
            lam[i] = 0.0
            lam[N + i] = -dx[i]
            r = abs(down)
            if dx[i] > dual and not fixed[N + i]:
                dual = dx[i]
        else:
            lam[i] = 0.0
            lam[N + i] = 0.0
            r = 0.0
        if r > comp:
            comp = r
        if s != 0 and abs(dx[i]) > lam_size:
            lam_size = abs(dx[i])
    return lam_size, primal, dual, comp


@jit
def on_set(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    w_trial: np.ndarray,
    c: np.ndarray,
    signs: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    inverse: float,
    gram: float,
    dx: np.ndarray,
    w: np.ndarray,
    lam: np.ndarray,
    slack: np.ndarray,
    res: np.ndarray,
    fixed: np.ndarray,
) -> tuple[float, float, float, float, float]:
    """The equality KKT system on the factored set ``signs``, with one step of iterative
    refinement when its complementarity residual asks for it. Returns (tol_p, tol_d, primal,
    dual, complementarity): the scalar tolerances and the certificate of the final point
    (`state`); each row's own dual tolerance is `row_duals`, formed by `settle_from` where a
    sign is in doubt. The right-hand side r = f - f*, f = D^T w_trial (`forces`), and the
    sizes of c and w_trial are gathered in one pass."""
    N = signs.shape[0]
    active = False
    c_size = 0.0  # rows with an infinite offset are ignored (velocity problems)
    w_size = 0.0
    for i in range(N):
        fi = force(w_trial, i, N)
        if signs[i] > 0:
            dx[i] = fi - c[i]
            active = True
        elif signs[i] < 0:
            dx[i] = fi + c[N + i]
            active = True
        else:
            dx[i] = 0.0
        a = abs(c[i])
        if a > c_size and a < np.inf:
            c_size = a
        a = abs(c[N + i])
        if a > c_size and a < np.inf:
            c_size = a
        if i < N - 1 and abs(w_trial[i]) > w_size:
            w_size = abs(w_trial[i])
    if active:
        solve(D, l, dx)
    lam_size, primal, dual, comp = state(k, w_trial, dx, signs, w, lam, slack, c, fixed)
    tol_p, tol_d = tolerances(c_scale, c_size, 2.0 * w_size, 4.0 * kmax * lam_size, inverse, gram, lam_size)
    if active and comp > REFINE_FRACTION * tol_p:
        for i in range(N):
            if signs[i] > 0:
                res[i] = slack[i]
            elif signs[i] < 0:
                res[i] = -slack[N + i]
            else:
                res[i] = 0.0
        solve(D, l, res)
        for i in range(N):
            dx[i] += res[i]
        _, primal, dual, comp = state(k, w_trial, dx, signs, w, lam, slack, c, fixed)
    return tol_p, tol_d, primal, dual, comp


@jit
def row_duals(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    w_trial: np.ndarray,
    c: np.ndarray,
    signs: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    dx: np.ndarray,
    tol_d: float,
    s: np.ndarray,
    told: np.ndarray,
) -> None:
    """Each row's own dual tolerance into ``told`` (2N), from the magnitudes of the numbers its
    multiplier is computed from (a componentwise, Skeel-type bound).

    The slips solve L_JJ dx_J = r_J, r = f - f*, f = D^T w_trial. Rounding r costs
    eps (|f| + |f*| + |w_{i-1}| + |w_i|), and f* carries the roundoff of the terms it was
    summed from, at least the natural size of c scaled to the block's own links,
    c_scale max(k_{i-1}, k_i) / max k (the floor of the scalar policy, localised). The LDL^T
    of the M-matrix L_JJ is backward stable componentwise (its factors have no sign
    cancellation, |L~| |D| |L~^T| = |L_JJ|), so the solve adds eps |L_JJ| |dx|. With
    L_JJ^{-1} >= 0 entrywise, |L_JJ^{-1}| s = L_JJ^{-1} s and

        |dx - dx*|_i <= 2 RTOL (L_JJ^{-1} s)_i,
        s = |f| + |f*| + c_scale max(k_{i-1}, k_i) / max k + |w_{i-1}| + |w_i| + |L_JJ| |dx|,

    one extra O(N) solve. On a chain whose stiffness spans decades this is orders of magnitude
    below the scalar bound ||L_JJ^{-1}|| max s of `on_set`, which is set by the stiffest link:
    a slip of a soft segment is then decided by its own roundoff, not the stiff one's.
    Rows not in the set keep the scalar ``tol_d`` (their multiplier is exactly 0)."""
    N = signs.shape[0]
    for i in range(N):
        if signs[i] == 0:
            s[i] = 0.0
            continue
        left = k[i - 1] if i > 0 else 0.0
        right = k[i] if i < N - 1 else 0.0
        target = c[i] if signs[i] > 0 else -c[N + i]
        wl = abs(w_trial[i - 1]) if i > 0 else 0.0
        wr = abs(w_trial[i]) if i < N - 1 else 0.0
        coupled = 0.0
        if i > 0 and signs[i - 1] != 0:
            coupled += left * abs(dx[i - 1])
        if i < N - 1 and signs[i + 1] != 0:
            coupled += right * abs(dx[i + 1])
        floor = c_scale * max(left, right) / kmax if kmax > 0.0 else c_scale
        s[i] = 2.0 * (wl + wr) + abs(target) + floor + (left + right) * abs(dx[i]) + coupled
    solve(D, l, s)
    for r in range(2 * N):
        told[r] = tol_d
    for i in range(N):
        bound = 2.0 * RTOL * s[i]
        if signs[i] > 0 and bound < tol_d:
            told[i] = bound
        elif signs[i] < 0 and bound < tol_d:
            told[N + i] = bound


@jit
def dual_excess(lam: np.ndarray, told: np.ndarray, fixed: np.ndarray) -> tuple[float, float]:
    """(-lambda_r, tol_r) of the row whose multiplier is most negative relative to its own
    tolerance (rows ``fixed`` excluded); (0, tol) when every sign holds."""
    worst, value, tol = 0.0, 0.0, told[0] if told.shape[0] else 0.0
    for r in range(lam.shape[0]):
        if fixed[r] or lam[r] >= 0.0:
            continue
        ratio = -lam[r] / told[r] if told[r] > 0.0 else np.inf
        if ratio > worst:
            worst, value, tol = ratio, -lam[r], told[r]
    return value, tol


@jit
def independent(rows: np.ndarray, N: int) -> bool:
    """LICQ of the rows (a mask of 2N) of a chain: no block at both limits, not every block."""
    count = 0
    for i in range(N):
        if rows[i] and rows[N + i]:
            return False
        if rows[i] or rows[N + i]:
            count += 1
    return count < N


@jit
def update(
    signs: np.ndarray,
    lam: np.ndarray,
    slack: np.ndarray,
    tol_p: float,
    told: np.ndarray,
    new: np.ndarray,
    fixed: np.ndarray,
    rows: np.ndarray,
    member: np.ndarray,
    single: bool,
) -> int:
    """The next set of a primal-dual update into ``new`` (`crawlsim.projection.polyhedron.Polyhedron.update_set`,
    then `exchange` where the set would fail LICQ; the worst row alone where that, or
    ``single``, asks for it); rows ``fixed`` never leave. Returns 0 with a
    new set, 1 when nothing is to change (the certificate failed on its own numbers), 2 when
    no independent update exists (the Python projector decides). ``rows`` and ``member``
    (2N booleans) are scratch."""
    N = signs.shape[0]
    for i in range(N):
        member[i] = signs[i] > 0
        member[N + i] = signs[i] < 0
        rows[i] = False
        rows[N + i] = False
    change = False
    worst_drop, worst_lam = -1, np.inf
    worst_add, worst_slack = -1, -np.inf
    for r in range(2 * N):
        if member[r]:
            if lam[r] < -told[r] and not fixed[r]:
                change = True
                if lam[r] < worst_lam:
                    worst_lam, worst_drop = lam[r], r
            else:
                rows[r] = True
        elif slack[r] > tol_p:
            rows[r] = True
            change = True
            if slack[r] > worst_slack:
                worst_slack, worst_add = slack[r], r
    if not change:
        return 1
    if single or not independent(rows, N):
        # all at once would make the set dependent, or cycles: the worst row alone
        rows[:] = member
        if worst_drop >= 0:
            rows[worst_drop] = False
        else:
            rows[worst_add] = True
        if not independent(rows, N) and not exchange(member, lam, slack, fixed, rows):
            return 2
    for i in range(N):
        new[i] = 1 if rows[i] else (-1 if rows[N + i] else 0)
    return 0


@jit
def exchange(member: np.ndarray, lam: np.ndarray, slack: np.ndarray, fixed: np.ndarray, rows: np.ndarray) -> bool:
    """The exchange of Goldfarb and Idnani into ``rows`` (`crawlsim.projection.polyhedron.Polyhedron.exchange`):
    the most violated row r enters although it depends on the active ones, which happens only
    when every block would be saturated (a block at both limits has no leaving row); along the
    dependency z = S 1 (signs of the rows, z_r > 0) the active row of the opposite sign with
    the smallest multiplier leaves. False when no row can."""
    N = member.shape[0] // 2
    r = -1
    best = -np.inf
    for q in range(2 * N):
        if not member[q] and slack[q] > best:
            best, r = slack[q], q
    block = r % N
    if member[block] or member[N + block]:
        return False
    sign_r = 1 if r < N else -1
    leave, smallest = -1, np.inf
    for q in range(2 * N):
        if member[q] and not fixed[q] and (1 if q < N else -1) != sign_r:
            ratio = max(lam[q], 0.0)
            if ratio < smallest:
                smallest, leave = ratio, q
    if leave < 0:
        return False
    rows[:] = member
    rows[leave] = False
    rows[r] = True
    return True


@jit
def same(a: np.ndarray, b: np.ndarray) -> bool:
    """a == b for two sets of signs, without the temporary array of np.array_equal (a step at
    N = 4 costs about as much as that allocation)."""
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


@jit
def settle(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    w_trial: np.ndarray,
    c: np.ndarray,
    signs: np.ndarray,
    factored: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    fixed: np.ndarray,
    dx: np.ndarray,
    w: np.ndarray,
    lam: np.ndarray,
    slack: np.ndarray,
    f: np.ndarray,
    res: np.ndarray,
    new: np.ndarray,
    seen: np.ndarray,
    report: np.ndarray,
    told: np.ndarray,
) -> tuple[int, float]:
    """One certified projection of ``w_trial`` onto {B w <= c} (rows ``fixed`` as equalities)
    from the set ``signs``, by primal-dual updates (`crawlsim.projection.polyhedron.Polyhedron.refine`): DONE
    with w, lam, slack, the set and each row's own dual tolerance (``told``, `row_duals`) in
    place, HANDOFF when the updates cycle, run out or find no independent set, FAILED when the
    certificate fails with nothing to change (``report``). Returns (status, tol_p); the scalar
    tolerances are also left in report[REPORT_TOLP:REPORT_TOLD+1]. (``f`` is not used: the
    forces are formed in the passes of `on_set`.)"""
    return settle_from(
        k,
        kmax,
        c_scale,
        w_trial,
        c,
        signs,
        factored,
        D,
        l,
        norms,
        fixed,
        dx,
        w,
        lam,
        slack,
        res,
        new,
        seen,
        report,
        told,
        fixed[:0],
        fixed[:0],
        True,
    )


@jit
def settle_from(
    k: np.ndarray,
    kmax: float,
    c_scale: float,
    w_trial: np.ndarray,
    c: np.ndarray,
    signs: np.ndarray,
    factored: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    fixed: np.ndarray,
    dx: np.ndarray,
    w: np.ndarray,
    lam: np.ndarray,
    slack: np.ndarray,
    res: np.ndarray,
    new: np.ndarray,
    seen: np.ndarray,
    report: np.ndarray,
    told: np.ndarray,
    rows: np.ndarray,
    member: np.ndarray,
    duals: bool,
) -> tuple[int, float]:
    """`settle` with its scratch (``rows``, ``member``: 2N booleans, or empty to have them made
    when an update needs them) from the caller. The sign
    of each multiplier is held to its own row's tolerance (`row_duals`), which is at most the
    scalar tol_d; it is formed where it can decide the step: some multiplier is negative, or
    the step fails on its other numbers (the update and the report read it), or ``duals`` asks
    for it (the exact integrator's velocity problems return it). A step with every multiplier
    >= 0 (rows not ``fixed``) passes the sign check whatever the row tolerances are (each
    lies in [0, tol_d]), so the certificate is the same on every step."""
    N = signs.shape[0]
    single = False  # one row at a time, once the updates of every row at once cycle
    it = 0
    while it < UPDATE_ITERATIONS:
        for q in range(it):  # a set seen before: the updates cycle
            if same(seen[q], signs):
                if single:
                    return HANDOFF, 0.0
                single, it = True, 0
                break
        if not same(factored, signs):
            norms[0], norms[1] = factor_into(k, signs, D, l, res)
            for i in range(N):
                factored[i] = signs[i]
        tol_p, tol_d, primal, negative, comp = on_set(
            k, kmax, c_scale, w_trial, c, signs, D, l, norms[0], norms[1], dx, w, lam, slack, res, fixed
        )
        if duals or negative > 0.0 or not (primal <= tol_p and comp <= tol_p and 0.0 <= tol_d):
            row_duals(k, kmax, c_scale, w_trial, c, signs, D, l, dx, tol_d, res, told)
            dual, dual_tol = dual_excess(lam, told, fixed)
        else:
            dual, dual_tol = 0.0, tol_d
        report[REPORT_TOLP], report[REPORT_TOLD] = tol_p, tol_d
        if primal <= tol_p and dual <= dual_tol and comp <= tol_p:
            return DONE, tol_p
        for i in range(N):
            seen[it, i] = signs[i]
        if rows.shape[0] < 2 * N:
            rows = np.empty(2 * N, dtype=np.bool_)
            member = np.empty(2 * N, dtype=np.bool_)
        outcome = update(signs, lam, slack, tol_p, told, new, fixed, rows, member, single)
        if outcome == 1:
            report[REPORT_PRIMAL], report[REPORT_DUAL], report[REPORT_COMP] = primal, dual, comp
            report[REPORT_TOLD] = dual_tol
            report[REPORT_ROW] = worst_row(signs, lam, slack)
            return FAILED, tol_p
        if outcome == 2:
            return HANDOFF, tol_p
        for i in range(N):
            signs[i] = new[i]
        it += 1
    return HANDOFF, 0.0


@jit
def project(
    k: np.ndarray,
    c_scale: float,
    w_trial: np.ndarray,
    c: np.ndarray,
    signs: np.ndarray,
    fixed: np.ndarray,
    w: np.ndarray,
    lam: np.ndarray,
    report: np.ndarray,
) -> int:
    """One certified projection (`settle`) for the exact integrator's velocity problems:
    w_trial = 0, c infinite on the rows to ignore, ``fixed`` the rows held with equality.
    Returns the status; w, lam, signs and report[REPORT_TOLP], report[REPORT_TOLD] hold the
    step when it is DONE (`project_rows` also gives each row's own dual tolerance)."""
    return project_rows(k, c_scale, w_trial, c, signs, fixed, w, lam, report, np.empty(2 * signs.shape[0]))


@jit
def project_rows(
    k: np.ndarray,
    c_scale: float,
    w_trial: np.ndarray,
    c: np.ndarray,
    signs: np.ndarray,
    fixed: np.ndarray,
    w: np.ndarray,
    lam: np.ndarray,
    report: np.ndarray,
    told: np.ndarray,
) -> int:
    """`project`, leaving each row's own dual tolerance in ``told`` (2N, `row_duals`): the
    threshold above which a multiplier is positive beyond its roundoff."""
    N = signs.shape[0]
    kmax = 0.0
    for i in range(k.shape[0]):
        if k[i] > kmax:
            kmax = k[i]
    factored = np.full(N, 2, dtype=np.int8)
    D = np.empty(N)
    l = np.empty(max(N - 1, 0))
    norms = np.zeros(2)
    status, _ = settle(
        k,
        kmax,
        c_scale,
        w_trial,
        c,
        signs,
        factored,
        D,
        l,
        norms,
        fixed,
        np.empty(N),
        w,
        lam,
        np.empty(2 * N),
        np.empty(N),
        np.empty(N),
        np.empty(N, dtype=np.int8),
        np.empty((UPDATE_ITERATIONS, N), dtype=np.int8),
        report,
        told,
    )
    return status


@jit
def jump(
    k: np.ndarray,
    c_scale: float,
    w: np.ndarray,
    target: np.ndarray,
    signs: np.ndarray,
    w_out: np.ndarray,
    lam: np.ndarray,
    report: np.ndarray,
) -> int:
    """The projection of w onto {B v <= target} at a jump (of c, `crawlsim.kernel.eventloop`, or
    of the ground, `crawlsim.kernel.terrain`) from the set ``signs``, certified by `project`
    (DONE only with its certificate; restarted where its updates run out, `JUMP_RESTARTS`), and
    LICQ at its tight rows (`crawlsim.projection.adapter.ExactProjector`: a tight set that may be
    dependent goes to the projector, which decides whether the slips are unique). Returns DONE
    or HANDOFF."""
    N = signs.shape[0]
    m = 2 * N
    fixed = np.zeros(m, dtype=np.bool_)
    status = project(k, c_scale, w, target, signs, fixed, w_out, lam, report)
    for _ in range(JUMP_RESTARTS):  # the updates go on from the set where they stopped
        if status != HANDOFF:
            break
        status = project(k, c_scale, w, target, signs, fixed, w_out, lam, report)
    if status != DONE:
        return HANDOFF
    tol_p = report[REPORT_TOLP]
    tight = np.zeros(m, dtype=np.bool_)
    extra = False
    for r in range(m):
        s = signs[r % N]
        member = (r < N and s > 0) or (r >= N and s < 0)
        f = force(w_out, r % N, N)
        tight[r] = member or (f if r < N else -f) - target[r] >= -tol_p
        extra = extra or (tight[r] and not member)
    if extra and not independent(tight, N):
        return HANDOFF
    return DONE


@jit
def catch_up(
    k: np.ndarray,
    c_scale: float,
    C: np.ndarray,
    W: np.ndarray,
    LAM: np.ndarray,
    S: np.ndarray,
    signs: np.ndarray,
    factored: np.ndarray,
    D: np.ndarray,
    l: np.ndarray,
    norms: np.ndarray,
    j0: int,
    report: np.ndarray,
) -> tuple[int, int]:
    """Catch-up steps j = j0, j0+1, ... of a period: W[j+1] and LAM[j] from W[j] and C[j+1],
    each certified; S[j] the set it settled on. ``signs`` (the current set) and ``factored``,
    ``D``, ``l``, ``norms`` (its factor and (||L_JJ^{-1}||, ||L_JJ||)) carry over between calls.
    Returns (status, j): DONE with j = G, else the step to hand over or that failed."""
    N = signs.shape[0]
    G = LAM.shape[0]
    kmax = 0.0
    for i in range(k.shape[0]):
        if k[i] > kmax:
            kmax = k[i]
    dx = np.empty(N)
    res = np.empty(N)
    lam = np.empty(2 * N)
    slack = np.empty(2 * N)
    w = np.empty(N - 1)
    new = np.empty(N, dtype=np.int8)
    seen = np.empty((UPDATE_ITERATIONS, N), dtype=np.int8)
    fixed = np.zeros(2 * N, dtype=np.bool_)
    told = np.empty(2 * N)
    rows = np.empty(2 * N, dtype=np.bool_)
    member = np.empty(2 * N, dtype=np.bool_)
    for j in range(j0, G):
        c = C[j + 1]
        w_trial = W[j]
        status, tol_p = settle_from(
            k,
            kmax,
            c_scale,
            w_trial,
            c,
            signs,
            factored,
            D,
            l,
            norms,
            fixed,
            dx,
            w,
            lam,
            slack,
            res,
            new,
            seen,
            report,
            told,
            rows,
            member,
            False,
        )
        if status != DONE:
            return status, j
        # every block tight to roundoff with an inactive row among them: LICQ may fail and the
        # slips may not be unique; the Python projector decides (crawlsim.projection.adapter)
        all_tight = True
        inactive_tight = False
        for i in range(N):
            up = signs[i] > 0 or slack[i] >= -tol_p
            down = signs[i] < 0 or slack[N + i] >= -tol_p
            if not (up or down):
                all_tight = False
                break
            if (signs[i] <= 0 and slack[i] >= -tol_p) or (signs[i] >= 0 and slack[N + i] >= -tol_p):
                inactive_tight = True
        if all_tight and inactive_tight:
            return HANDOFF, j
        for i in range(N - 1):
            W[j + 1, i] = w[i]
        for i in range(N):
            LAM[j, i] = lam[i]
            LAM[j, N + i] = lam[N + i]
            S[j, i] = signs[i]
    return DONE, G


@jit
def set_starts(S: np.ndarray) -> np.ndarray:
    """The steps where the set S[j] differs from S[j-1] (step 0 included): the index of the
    first step of each run of one set (`crawlsim.integrate.catchup.VisitedSets`)."""
    G, N = S.shape
    starts = np.empty(G, dtype=np.int64)
    count = 0
    for j in range(G):
        if j == 0 or not same(S[j], S[j - 1]):
            starts[count] = j
            count += 1
    return starts[:count]


@jit
def positions(LAM: np.ndarray, x0: np.ndarray, X: np.ndarray) -> None:
    """Block positions of a period (docs/model.md §3): X[0] = x0 and X[j+1] = x0 + dx_0 + ...
    + dx_j, dx = lambda^+ - lambda^- of each step (`crawlsim.model.crawler.slips`). The running
    sum is the one of np.cumsum along the steps, then shifted by x0: the same numbers, without
    the period's temporary arrays."""
    N = x0.shape[0]
    G = LAM.shape[0]
    total = np.empty(N)
    for i in range(N):
        X[0, i] = x0[i]
    for j in range(G):
        for i in range(N):
            dx = LAM[j, i] - LAM[j, N + i]
            t = dx if j == 0 else total[i] + dx
            total[i] = t
            X[j + 1, i] = t + x0[i]


@jit
def worst_row(signs: np.ndarray, lam: np.ndarray, slack: np.ndarray) -> int:
    """The row that violates its certificate most, relative to nothing: the largest slack, or
    the most negative multiplier, or the active row with the largest residual."""
    N = signs.shape[0]
    row, worst = 0, -np.inf
    for r in range(2 * N):
        active = (r < N and signs[r] > 0) or (r >= N and signs[r - N] < 0)
        v = abs(slack[r]) if active else slack[r]
        if v > worst:
            worst, row = v, r
        if -lam[r] > worst:
            worst, row = -lam[r], r
    return row
