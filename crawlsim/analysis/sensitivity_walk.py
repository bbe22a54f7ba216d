"""Forward-mode differentiation of one limit period (`crawlsim.analysis.sensitivity`,
docs/sensitivity.md): one matrix of tangents, n columns for the start w and p for the
parameters, carried along the period with the visited active sets and the order of the events
held fixed.

* The exact integrator: each piece on the active set A (eq. (piece)):
  Lambda_A(u) = G_A^{-1} (B_A w_s - c_A(u)), w(u) = w_s - K B_A^T Lambda_A(u), differentiated in
  w_s, in c_A (explicit in theta) and in K = M^{-1}; each hit, whose time moves with
  (w, theta) (eq. (saltation)): du = -dg_i / (b_i . w' - c_i'), then the state and the slips take
  w' du and Lambda' du; each jump of a ``steps`` signal: the projection on its active set; the
  dissipation, the integral of mu_A . lambda_A over each piece (Gauss-Legendre, plus the moving
  ends) and mu . Lambda at the jumps.
* Catch-up: the scheme's own discrete map w_{j+1} = proj_{K(t_{j+1})}(w_j) (eq. (catch-up)).
  On a run of steps with one active set A the projections telescope, B_A w_j = c_A(u_j) after
  the run's first step, so the run is the piece formula above at its last grid time, and each
  step's slips are Lambda_j = G_A^{-1} (c_A(u_j) - c_A(u_{j+1})); the dissipation is the grid
  sum of mu(u_{j+1}) . Lambda_j, as the run's ledger counts it. The grid times are fixed: no
  saltation.

Both walks run compiled (`crawlsim.kernel.tangent`), so that a walk costs its arithmetic. The
kernel screens every flow for touches (a gap or a slip rate reaching zero inside it) with
tolerances twice the walk's; the few flows (and catch-up runs) it flags are examined here, on
the closed form, from the state and tangent the kernel had at their start.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from crawlsim.analysis.sensitivity_terms import Coefficients, Limit
from crawlsim.errors import CrawlsimError
from crawlsim.kernel import tangent
from crawlsim.kernel.jit import kernel

if TYPE_CHECKING:
    from crawlsim.integrate.stepping import Transition

#: Two events closer than this (in cycles) count as simultaneous: a kink of the period map.
COINCIDENT = 1e-9
#: A gap or slip rate within this fraction of the size of c (or of c') counts as zero: a few
#: hundred times the roundoff of computing them (the size of c is set by the stiffest link's
#: K L, which can exceed the friction by 1e4, so a looser bound takes open gaps for touches).
TOUCH = 1e-11


@functools.lru_cache(maxsize=16)
def _gauss(nq: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [-1, 1]."""
    return np.polynomial.legendre.leggauss(nq)


@dataclass
class Walk:
    """Tangents of one period with respect to (w0, theta): n + p columns."""

    W: np.ndarray  # (n, q) d w(1)
    L: np.ndarray  # (m, q) d Lambda over the period
    D: np.ndarray  # (q,) d dissipation
    lam: np.ndarray  # (m,) Lambda over the period
    dissipation: float
    w_end: np.ndarray
    pieces: int
    kinks: list[str] = field(default_factory=list)
    column_kinks: np.ndarray | None = None  # (q,) bool: columns that split events reached together
    # touches (message, tangent (s, q) of the touching gaps or slip rates where they are 0):
    # a kink for the parameters that move them off zero at the limit
    touches: list[tuple[str, np.ndarray]] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class Prepared:
    """What a walk reads that depends on the compiled gait and the parameters' columns alone,
    not on the limit period: the normals B, K = M^{-1}, the Gauss-Legendre rule of the exact
    walk's dissipation integrals and, for catch-up,
    each grid time's cycle, piece and basis values (eq. (catch-up)). Built once per gait and
    set of parameters (`crawlsim.analysis.sensitivity` keeps it), so that a walk costs the
    period's own arithmetic."""

    B: np.ndarray  # (m, n) dense normals
    k: np.ndarray  # (n,)
    gauss: tuple[np.ndarray, np.ndarray] | None = None  # the exact walk's Gauss-Legendre rule
    # catch-up: u_j, the piece of each u_j, phi(u_j), c, mu, dc and dmu at u_j
    # (`crawlsim.kernel.tangent_catchup.grid_values`) and whether c's closed form reproduces the
    # grid's offsets (`_agrees`)
    grid: tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] | None = None
    agrees: bool = True
    offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # catch-up: the grid's c


def prepare(process: Any, co: Coefficients, dC: np.ndarray, dMu: np.ndarray, catch_up: bool) -> Prepared:
    """The `Prepared` data of a walk of ``process`` (compiled from the gait ``co`` is of) with
    the parameter columns dC, dMu (P, nb, m, p)."""
    B = np.ascontiguousarray(process.polyhedron.dense_normals(), dtype=float)
    k = np.ascontiguousarray(co.k, dtype=float)
    if not catch_up:
        return Prepared(B, k, _gauss(24 + 12 * co.basis.harmonics))
    u, pieces, Phi, c, mu, dc, dmu = kernel().tangent_catchup.grid_values(
        np.ascontiguousarray(process.times, dtype=float),
        float(process.period),
        np.ascontiguousarray(co.edges, dtype=float),
        co.basis.linear,
        co.basis.harmonics,
        co.C,
        co.Mu,
        dC,
        dMu,
    )
    # the limit's scale of a catch-up walk is its process's (`limit_of`)
    offsets = np.ascontiguousarray(process.offsets, dtype=float)
    return Prepared(
        B, k, grid=(u, pieces, Phi, (c, mu, dc, dmu)), agrees=_agrees(c, offsets, 1e-9 * process.scale), offsets=offsets
    )


def _agrees(c: np.ndarray, offsets: np.ndarray, atol: float) -> bool:
    """Whether the closed form of c (on the catch-up grid) reproduces the grid's offsets to
    ``atol``."""
    return bool(np.all(np.abs(c - offsets) <= atol))


class _Walker:
    """The start of a flow or run that the compiled walk flagged (``w``, ``Wt``), the touches
    found there, and the kernel's formulas (`crawlsim.kernel.tangent`) called from Python."""

    def __init__(self, lim: Limit, co: Coefficients, dC: np.ndarray, dk: np.ndarray):
        self.B = np.ascontiguousarray(lim.process.polyhedron.dense_normals(), dtype=float)
        self.k = np.ascontiguousarray(co.k, dtype=float)
        self.co, self.dC, self.dk = co, dC, dk
        self.m, self.n = self.B.shape
        self.q = self.n + dk.shape[1]
        self.basis = co.basis
        self.scale = lim.scale
        self.w = np.zeros(self.n)
        self.Wt = np.zeros((self.n, self.q))
        self.touches: list[tuple[str, np.ndarray]] = []

    def factor(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """B_A and G_A^{-1}, G_A = B_A K B_A^T."""
        return kernel().tangent.factor(self.B, self.k, np.asarray(index, dtype=np.int64))

    def pad(self, X: np.ndarray) -> np.ndarray:
        """Parameter columns X (..., p) as full tangent columns (..., n + p)."""
        out = np.zeros(X.shape[:-1] + (self.q,))
        out[..., self.n :] = X
        return out

    def solve_on(
        self, index: np.ndarray, w_s: np.ndarray, W_s: np.ndarray, piece: int, phi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Lambda_A(u), w(u) and their tangents for a flow (or projection) on A from w_s;
        phi = phi(u), the basis at u (eq. (piece), `crawlsim.kernel.tangent.solve_on`)."""
        BA, Gi = self.factor(index)
        return kernel().tangent.solve_on(
            BA,
            Gi,
            np.asarray(index, dtype=np.int64),
            self.k,
            self.dk,
            np.ascontiguousarray(w_s),
            np.ascontiguousarray(W_s),
            np.ascontiguousarray(phi),
            self.co.C[piece],
            self.dC[piece],
        )


# -- the exact integrator ----------------------------------------------------------------------
def walk_exact(
    lim: Limit, co: Coefficients, dC: np.ndarray, dMu: np.ndarray, dk: np.ndarray, prep: Prepared | None = None
) -> Walk:
    """Differentiate the exact integrator's limit period from its start (module docstring);
    dC (P, nb, m, p), dMu (P, nb, m, p), dk (n, p). The walk is the compiled
    `crawlsim.kernel.tangent.walk_exact`; the flows it flags as holding a possible touch are
    examined here on the closed form, from the state and tangent it had at their start.
    ``prep``: `prepare`'s data for these columns, built here when not given."""
    if prep is None:
        prep = prepare(lim.process, co, dC, dMu, False)
    B, k = prep.B, prep.k
    assert prep.gauss is not None
    m, n = B.shape
    q = n + dk.shape[1]
    u, piece, cause, act, hit = _transition_arrays(lim.record.transitions, m)
    K = len(u)
    basis = co.basis
    gx, gw = prep.gauss
    W, L, D = np.empty((n, q)), np.empty((m, q)), np.empty(q)
    lam, w_end = np.empty(m), np.empty(n)
    kink = np.zeros(K, dtype=np.int64)
    column_kinks = np.zeros(q, dtype=np.bool_)
    gap_flag, rate_flag = np.zeros(K, dtype=np.bool_), np.zeros(K, dtype=np.bool_)
    w_start, W_start = np.empty((K, n)), np.empty((K, n, q))
    diss = kernel().tangent.walk_exact(
        B,
        k,
        co.C,
        co.Mu,
        dC,
        dMu,
        dk,
        basis.linear,
        basis.harmonics,
        co.edges,
        u,
        piece,
        cause,
        act,
        hit,
        gx,
        gw,
        np.array(lim.record.w[0], dtype=float),
        float(lim.scale),
        COINCIDENT,
        TOUCH,
        W,
        L,
        D,
        lam,
        w_end,
        kink,
        column_kinks,
        gap_flag,
        rate_flag,
        w_start,
        W_start,
    )
    kinks: list[str] = []
    for at in np.flatnonzero(kink).tolist() if kink.any() else ():
        u_e, bits = u[at], int(kink[at])
        if bits & tangent.ZERO_RATE:
            kinks.append(f"a constraint is reached with zero rate at t/T = {u_e:.12g}")
        if bits & tangent.APART:
            kinks.append(f"{np.count_nonzero(hit[at])} constraints reached together at t/T = {u_e:.12g} move apart")
        if bits & tangent.COINCIDENT:
            kinks.append(f"a constraint is reached at t/T = {u_e:.12g}, at the time of another event")
    touches: list[tuple[str, np.ndarray]] = []
    flags = gap_flag | rate_flag
    if flags.any():
        flagged = np.flatnonzero(flags)
        s = _Walker(lim, co, dC, dk)
        # c' and dc', as the kernel formed them
        derivatives = kernel().tangent.coefficient_derivatives(co.C, dC, basis.linear, basis.harmonics)
        for at in flagged.tolist():
            s.w, s.Wt = w_start[at], W_start[at]
            _touches_of_flow(
                s, (u, piece, cause, act, hit), at, derivatives, (gx, gw), (bool(gap_flag[at]), bool(rate_flag[at]))
            )
        touches = s.touches
    return Walk(W, L, D, lam, float(diss), w_end, K, kinks, column_kinks, touches)


def _transition_arrays(transitions: Sequence[Transition], m: int) -> tuple[np.ndarray, ...]:
    """The transitions as arrays: u, piece, cause (`crawlsim.kernel.tangent.CAUSES`), the
    active rows after each (K, m) and the rows hit (K, m). A compiled period's are read off
    its loop's arrays, without factoring its sets."""
    arrays = getattr(transitions, "arrays", None)
    if arrays is not None:  # `crawlsim.integrate.compiled`: signs per block, rows_of's order
        u, piece, signs, cause, hit = arrays
        act = np.concatenate([signs > 0, signs < 0], axis=1)
        return (
            np.asarray(u, dtype=float),
            np.asarray(piece, dtype=np.int64),
            np.asarray(cause, dtype=np.int64),
            act,
            np.asarray(hit, dtype=np.bool_),
        )
    K = len(transitions)
    act, hit = np.zeros((K, m), dtype=np.bool_), np.zeros((K, m), dtype=np.bool_)
    for j, tr in enumerate(transitions):
        act[j, np.asarray(tr.active.index, dtype=np.int64)] = True
        hit[j, np.asarray(tr.hit, dtype=np.int64)] = True
    return (
        np.array([t.u for t in transitions], dtype=float),
        np.array([t.piece for t in transitions], dtype=np.int64),
        np.array([tangent.CAUSES.index(t.cause) for t in transitions], dtype=np.int64),
        act,
        hit,
    )


def _touches_of_flow(
    s: _Walker,
    arrays: tuple[np.ndarray, ...],
    j: int,
    derivative: tuple[np.ndarray, np.ndarray],
    gauss: tuple[np.ndarray, np.ndarray],
    flags: tuple[bool, bool],
) -> None:
    """The touches of the flow from transition j (``arrays``: `_transition_arrays`), flagged
    by the compiled walk: an inactive gap (``flags[0]``) or a slip rate (``flags[1]``)
    reaching zero inside it."""
    u, pieces, cause, act, hit = arrays
    last = j + 1 >= len(u)
    index = np.flatnonzero(act[j])
    piece = int(pieces[j])
    u_s, u_e = float(u[j]), (1.0 if last else float(u[j + 1]))
    gx, _ = gauss
    x = u_s + 0.5 * (u_e - u_s) * (gx + 1.0)
    stacked = s.basis.values(np.concatenate([[u_s], x, [u_e]]))
    if flags[0]:
        ends = np.flatnonzero(hit[j + 1]) if not last and cause[j + 1] == tangent.HIT else np.zeros(0, int)
        _gap_touches(s, index, piece, x, stacked, (u_s, u_e), ends)
    if flags[1] and index.size:
        dcoef, dC1 = derivative[0][piece], derivative[1][piece]
        _, Gi = s.factor(index)
        Phi = stacked[1:-1]
        rate = -(Phi @ dcoef[:, index]) @ Gi.T
        _rate_touches(s, index, rate, Phi, dcoef, dC1, (u_s, u_e))


def _gap_touches(
    s: _Walker,
    index: np.ndarray,
    piece: int,
    x: np.ndarray,
    stacked: np.ndarray,
    span: tuple[float, float],
    hit_at_end: np.ndarray,
) -> None:
    """Inactive constraints whose gap reaches zero inside the piece without crossing (or
    stays at zero), seen on the closed form of the gaps between the samples x, with the
    tangents of those gaps where they are zero. A touch is an interior maximum at zero (one at
    an end is an event there; a touch exactly at the start of the period is not looked for).
    ``stacked``: the basis at u_s, at the samples x and at u_e."""
    B, k, basis = s.B, s.k, s.basis
    u_s, u_e = span
    outside = np.ones(s.m, dtype=bool)
    outside[index] = False
    outside[hit_at_end] = False
    # every row's gap(u) = phi(u) @ Gcoef (nb, m)
    BA, Gi = s.factor(index)
    Gcoef = kernel().tangent.gap_coefficients(
        B, k, BA, Gi, np.asarray(index, dtype=np.int64), np.ascontiguousarray(s.w), s.co.C[piece]
    )
    tol = TOUCH * s.scale
    grid = np.concatenate([[u_s], x, [u_e]])
    values = stacked @ Gcoef  # (s + 2, m)
    # between two samples a gap exceeds the larger by at most h^2/8 max|gap''| (the linear
    # interpolant's error): only rows that can reach -tol are looked at closely
    h = float(np.max(np.diff(grid)))
    reach = np.max(values, axis=0) + h * h / 8.0 * basis.curvature_bound(Gcoef) >= -tol
    flat = np.min(values[1:-1], axis=0, initial=np.inf) >= -tol
    found: list[tuple[int, float]] = []
    for j in np.flatnonzero((reach | flat) & outside):
        u_best = float(x[len(x) // 2]) if flat[j] else _interior_maximum(basis, Gcoef[:, j], grid, values[:, j], tol)
        if u_best == u_best:  # not NaN: a touch
            found.append((int(j), u_best))
    if not found:
        return
    tangents = []
    for r, u_r in found:
        phi = basis.values(u_r)[0]
        dW = s.solve_on(index, s.w, s.Wt, piece, phi)[3] if index.size else s.Wt
        dc = s.pad(np.einsum("b,bp->p", phi, s.dC[piece][:, r, :]))
        tangents.append((B[r] @ dW - dc)[None, :])
    s.touches.append(
        (
            f"constraint(s) {[r for r, _ in found]} touch zero gap without entering in t/T in [{u_s:.9g}, {u_e:.9g}]",
            np.concatenate(tangents),
        )
    )


def _interior_maximum(basis: Any, z: np.ndarray, grid: np.ndarray, values: np.ndarray, tol: float) -> float:
    """Where the gap phi(u) @ z, largest at an interior sample, reaches 0 to ``tol`` between
    the samples next to it; NaN where it does not (or its maximum is at an end)."""
    from scipy.optimize import minimize_scalar

    i = int(np.argmax(values))
    if not 0 < i < len(grid) - 1:
        return float("nan")  # largest at an end: a release at the start, an event at the end
    res = minimize_scalar(
        lambda v: -basis.scalar(v, z),
        bounds=(float(grid[i - 1]), float(grid[i + 1])),
        method="bounded",
        options={"xatol": 1e-14},
    )
    u_best, v_best = float(res.x), max(float(-res.fun), float(values[i]))
    inside = min(u_best - grid[0], grid[-1] - u_best) > 1e-6 * (grid[-1] - grid[0])
    return u_best if v_best >= -tol and inside else float("nan")


def _rate_touches(
    s: _Walker,
    index: np.ndarray,
    rate: np.ndarray,
    Phi: np.ndarray,
    dcoef: np.ndarray,
    dC1: np.ndarray,
    span: tuple[float, float],
) -> None:
    """Active constraints whose slip rate (``rate`` at the samples Phi) touches zero inside
    the piece without leaving, with the tangents of those rates where they are zero."""
    size = max(float(np.max(np.abs(Phi @ dcoef))), 1e-300)
    if float(np.min(rate)) > TOUCH * size:
        return  # every slip rate stays positive on the samples
    BA, Gi = s.factor(index)
    low = _touching(-rate, TOUCH * size)
    if not low.any():
        return
    tangents = []
    for s_i in np.flatnonzero(np.min(rate[:, low], axis=1) <= TOUCH * size):
        dc1 = np.einsum("b,bap->ap", Phi[s_i], dC1[:, index, :])
        dG_rate = BA @ (s.dk * (BA.T @ rate[s_i])[:, None])
        tangents.append(s.pad((-Gi @ (dc1 + dG_rate))[low]))
    s.touches.append(
        (
            f"slip rate(s) of constraint(s) {index[low].tolist()} touch zero in t/T in ({span[0]:.9g}, {span[1]:.9g})",
            np.concatenate(tangents),
        )
    )


def _touching(f: np.ndarray, tol: float) -> np.ndarray:
    """Columns of samples f (s, r), all <= 0 to roundoff, that rise to 0 and fall again inside
    the piece (samples below -tol on both sides of the maximum), or stay at 0: a touch. A
    column at 0 near an end only is an event there (a row hit at the end, or released at the
    start, whose gap opens at second order), not a kink."""
    if not f.shape[1]:
        return np.zeros(0, dtype=bool)
    top = np.max(f, axis=0) >= -tol
    flat = np.min(f, axis=0) >= -tol
    i = np.argmax(f, axis=0)
    rows = np.arange(len(f))[:, None]
    below = f < -tol
    before = np.any(below & (rows < i[None, :]), axis=0)
    after = np.any(below & (rows > i[None, :]), axis=0)
    return top & ((before & after) | flat)


# -- catch-up ----------------------------------------------------------------------------------
def walk_catch_up(
    lim: Limit, co: Coefficients, dC: np.ndarray, dMu: np.ndarray, dk: np.ndarray, prep: Prepared | None = None
) -> Walk:
    """Differentiate the catch-up scheme's discrete period map at its limit period (module
    docstring, eq. (catch-up)): runs of steps on one active set (the rows with a positive
    multiplier) telescope to the piece formula at the run's last grid time. The walk is the
    compiled `crawlsim.kernel.tangent_catchup.walk_catch_up`; the runs with a row tight at a zero
    multiplier are examined here, from the state and tangent it had at their start.
    ``prep``: `prepare`'s data (with the grid) for these columns, built here when not given."""
    process, record = lim.process, lim.record
    if prep is None or prep.grid is None:
        prep = prepare(process, co, dC, dMu, True)
    assert prep.grid is not None
    agrees = prep.agrees if lim.scale == process.scale else _agrees(prep.grid[3][0], prep.offsets, 1e-9 * lim.scale)
    if not agrees:
        raise CrawlsimError(
            f"{process.name}: the offsets' closed form does not reproduce the "
            "catch-up grid's; the catch-up map is not differentiated"
        )
    B = prep.B
    m, n = B.shape
    q = n + dk.shape[1]
    u, pieces, Phi, values = prep.grid
    # the active rows, and the rows tight at w_{j+1} with a zero multiplier ("weak"): the map
    # has a kink there for the parameters that move that gap off zero (a touch, as in the
    # exact walk)
    active, weak, starts, runs_weak, scale_w = kernel().tangent_catchup.catch_up_runs(
        np.ascontiguousarray(record.multipliers, dtype=float),
        np.ascontiguousarray(record.w, dtype=float),
        B,
        prep.offsets,
        TOUCH * lim.scale,
    )
    G = len(active)
    R = len(starts) - 1
    W, L, D = np.empty((n, q)), np.empty((m, q)), np.empty(q)
    lam, w_end = np.empty(m), np.empty(n)
    w_start, W_start = np.empty((R, n)), np.empty((R, n, q))
    diss = kernel().tangent_catchup.walk_catch_up(
        B,
        prep.k,
        co.C,
        dC,
        dk,
        Phi,
        pieces,
        values,
        active,
        starts,
        np.array(record.w[0], dtype=float),
        W,
        L,
        D,
        lam,
        w_end,
        w_start,
        W_start,
    )
    touches: list[tuple[str, np.ndarray]] = []
    weak_runs = np.flatnonzero(runs_weak).tolist()
    if weak_runs:
        s = _Walker(lim, co, dC, dk)
        for r in weak_runs:
            j0, j1 = int(starts[r]), int(starts[r + 1])
            s.w, s.Wt = w_start[r], W_start[r]
            _weak_steps(s, (pieces, Phi), np.flatnonzero(active[j0]), j0, weak[j0:j1])
        touches = s.touches
    if float(np.max(np.abs(w_end - record.w[-1]))) > 1e-8 * max(scale_w, 1e-300):
        raise CrawlsimError(f"{process.name}: the catch-up walk does not reproduce the limit period (internal error)")
    return Walk(W, L, D, lam, float(diss), w_end, G, [], np.zeros(q, dtype=bool), touches)


def _weak_steps(s: _Walker, grid: tuple[np.ndarray, np.ndarray], index: np.ndarray, j0: int, weak: np.ndarray) -> None:
    """The tangents of the gaps of rows tight with a zero multiplier after steps j0 + r of a
    run on A (``weak`` (r, m)): w_{j+1} is the piece formula at u_{j+1} from the run's start;
    ``grid``: the piece and the basis values of each grid time."""
    pieces, Phi = grid
    tangents = []
    for r, i in np.argwhere(weak):
        j = j0 + int(r) + 1
        piece = int(pieces[j])
        dW = s.solve_on(index, s.w, s.Wt, piece, Phi[j])[3] if index.size else s.Wt
        dc = np.einsum("b,bp->p", Phi[j], s.dC[piece][:, i, :])
        tangents.append((s.B[i] @ dW - s.pad(dc))[None, :])
    first = int(np.argwhere(weak)[0][0]) + j0 + 1
    s.touches.append(
        (
            f"catch-up step(s) from {first}: constraint(s) "
            f"{sorted(set(np.argwhere(weak)[:, 1].tolist()))} tight with a zero "
            "multiplier",
            np.concatenate(tangents),
        )
    )
