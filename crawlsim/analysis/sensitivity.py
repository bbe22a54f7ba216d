"""Exact sensitivities of v0, the displacement per period, the dissipation and the cost of
transport with respect to the numbers of a gait file (docs/sensitivity.md).

At the periodic limit w* = P(w*, theta) the implicit function theorem gives

    dv0/dtheta = (1/T) [dY/dtheta + dY/dw (I - dP/dw)^+ dP/dtheta],

Y the displacement over one period. The exact integrator (`crawlsim.integrate.exact`) is event-driven with
closed forms between events, so the period map is piecewise smooth in (w, theta), and every
partial derivative above is computed by forward-mode differentiation along the verified limit
period: the visited active sets and the order of the events are held fixed, and one matrix of
tangents, n columns for the start w and p for the parameters, is carried through

* each piece on the active set A (docs/sensitivity.md eq. (piece)):
  Lambda_A(u) = G_A^{-1} (B_A w_s - c_A(u)), w(u) = w_s - K B_A^T Lambda_A(u), differentiated in
  w_s, in c_A (the offsets are explicit in theta) and in K = M^{-1} (the stiffness);
* each hit, whose time moves with (w, theta) (eq. (saltation)): du = -dg_i / (b_i . w' - c_i'),
  then the state and the slips take w' du and Lambda' du;
* each jump of a ``steps`` signal: the certified projection on the same active set;
* the dissipation, the integral of mu_A . lambda_A over each piece (Gauss-Legendre on the piece,
  plus the moving ends) and mu . Lambda at the jumps, the terms of the exact ledger.

The work is shared between parameters: one walk along the period with an (n + p)-column
tangent, one least-squares solve with p right-hand sides.

The offsets' derivative dC_p/dtheta of a parameter comes from the gait with that number moved
(`Gait.replace`, validated like a file): every number of a gait file enters the coefficients of
c(t) affinely (means, amplitudes, Fourier coefficients, knot values, friction, stiffness), so one
difference quotient is exact to roundoff; a phase rotates each harmonic pair, and the rotation is
inverted exactly. A number whose change moves the breakpoints of c (knot times, the phase of a
piecewise-linear or steps signal) or the structure (``blocks``) is reported with the reason.
The period enters through rate independence alone: Y does not depend on T, so dv0/dT = -v0/T.

Where the limit period sits on a kink of the period map (a hit at the same time as another event,
a hit with zero rate, a constraint touching zero gap without entering, a slip rate touching
zero without leaving, rows hit together whose times move differently, or friction on the
boundary of the uniqueness condition), ``smooth`` is False, and the left and right derivatives
are measured by one-sided perturbations of theta with the exact integrator (Richardson
extrapolated), or the reason why they could not be.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from crawlsim.errors import CrawlsimError, GaitError
from crawlsim.gait.docpaths import resolve_path

if TYPE_CHECKING:
    from crawlsim.gait.document import Gait
    from crawlsim.integrate.stepping import PeriodRecord
    from crawlsim.model.process import SweepingProcess

EPS = float(np.finfo(float).eps)
#: Two events closer than this (in cycles) count as simultaneous: a kink of the period map.
COINCIDENT = 1e-9
#: A gap or slip rate within this fraction of the size of c (or of c') counts as zero: a few
#: hundred times the roundoff of computing them (the size of c is set by the stiffest link's
#: K L, which can exceed the friction by 1e4, so a looser bound takes open gaps for touches).
TOUCH = 1e-11
#: Relative step of the one-sided differences at a kink (h and 2 h, Richardson extrapolated).
ONE_SIDED_STEP = 1e-5
#: Relative step of the difference quotient of the offsets' coefficients (exact for affine
#: dependence, so only roundoff / h matters).
COEFFICIENT_STEP = 2.0 ** -10
#: Most blocks for which the uniqueness boundary is checked over every subset.
UNIQUENESS_BLOCKS = 12

Method = Literal["exact", "rate-independence", "one-sided", "unsupported"]


@dataclass(frozen=True)
class Derivative:
    """One derivative with its error estimate; None where it has no value (a kink)."""

    value: float | None
    error_estimate: float | None


@dataclass(frozen=True)
class ParameterSensitivity:
    """The derivatives of the run's outputs with respect to one number of the gait file."""

    path: str  # concrete dotted path (``*`` expanded)
    value: float  # the number in the gait
    v0: Derivative  # dv0/dtheta
    displacement_per_period: Derivative  # dY/dtheta
    dissipation_per_period: Derivative  # dD/dtheta
    cost_of_transport: Derivative  # d(D/|Y|)/dtheta
    smooth: bool
    method: Method
    reason: str | None = None  # why not smooth, or why not computed
    left: Derivative | None = None  # one-sided dv0/dtheta from below (smooth False)
    right: Derivative | None = None  # ... from above
    left_reason: str | None = None
    right_reason: str | None = None
    # dv0/dtheta on the limit period's own pieces (its visited active sets and event order
    # held): the derivative itself where smooth, one element of the generalized gradient at
    # a kink (which side is not known); what a gradient method can follow
    v0_on_pieces: float | None = None

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "value": self.v0.value, "error_estimate": self.v0.error_estimate,
            "smooth": self.smooth, "method": self.method, "parameter_value": self.value}
        for key in ("displacement_per_period", "dissipation_per_period", "cost_of_transport"):
            d: Derivative = getattr(self, key)
            out[f"d_{key}"] = d.value
            out[f"d_{key}_error_estimate"] = d.error_estimate
        if self.reason is not None:
            out["reason"] = self.reason
        if not self.smooth:
            for side in ("left", "right"):
                d_side: Derivative | None = getattr(self, side)
                out[side] = None if d_side is None else d_side.value
                out[f"{side}_error_estimate"] = None if d_side is None else d_side.error_estimate
                why = getattr(self, f"{side}_reason")
                if why is not None:
                    out[f"{side}_reason"] = why
        return out


@dataclass(frozen=True)
class SensitivityResult:
    """`sensitivity`'s answer: the run's values and one `ParameterSensitivity` per number."""

    name: str
    period: float
    v0: float
    v0_error_estimate: float
    displacement_per_period: float
    dissipation_per_period: float
    cost_of_transport: float | None
    parameters: tuple[ParameterSensitivity, ...]
    kinks: tuple[str, ...] = field(default=())  # the kinks of the limit period found

    def __getitem__(self, path: str) -> ParameterSensitivity:
        for p in self.parameters:
            if p.path == path:
                return p
        raise KeyError(path)

    @property
    def smooth(self) -> bool:
        """True when v0 is differentiable in every parameter (no kink of the contact sequence)."""
        return all(p.smooth for p in self.parameters)

    def summary(self) -> dict[str, Any]:
        """The ``sensitivity`` mapping of ``crawlsim velocity --json``: path -> its derivatives."""
        return {p.path: p.summary() for p in self.parameters}


# -- the limit period ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Limit:
    process: SweepingProcess
    record: PeriodRecord
    v0: float
    v0_error: float
    displacement: float
    dissipation: float
    residual: float  # relative Poincare step of the verified period


def _limit(gait: Gait) -> _Limit:
    """The verified limit period of ``gait`` with the exact integrator (as `crawlsim velocity`
    finds it: plain periods, then the periodic-limit solver)."""
    from crawlsim.analysis.energy import period_dissipation
    from crawlsim.analysis.run import effective_tolerance
    from crawlsim.integrate.limit import PLAIN_PERIODS, relative_step, solve_limit
    from crawlsim.integrate.stepping import make_stepper
    from crawlsim.model.process import compile_gait

    process = compile_gait(gait)
    s = gait.simulation
    tol = effective_tolerance(s.tolerance)
    stepper = make_stepper(process, "exact")
    record = None
    final = None
    periods = 0
    while periods < min(PLAIN_PERIODS, s.max_periods):
        record = stepper.step_period()
        periods += 1
        if relative_step(process, record.w[0], record.w[-1]) <= tol:
            final = record
            break
    if final is None:
        solution = solve_limit(process, make_stepper(process, "exact"), tolerance=tol,
                               first=record, max_periods=max(s.max_periods - periods, 1),
                               plain=0)
        if not solution.converged:
            raise CrawlsimError(f"{gait.source}: the periodic limit was not found within "
                                f"max_periods = {s.max_periods}; sensitivities need it")
        final = solution.record
    slips = final.slips
    assert final.x is not None and slips is not None and process.stiffness is not None
    T = process.period
    d = float(np.mean(final.x[-1] - final.x[0]))
    F = float(np.max(np.abs(final.w[-1] - final.w[0])))
    roundoff = float(np.sum(np.abs(slips))) / process.blocks
    err = (process.steps * EPS * roundoff + F / float(np.min(process.stiffness))) / T
    return _Limit(process, final, d / T, err, d, period_dissipation(process, final),
                  relative_step(process, final.w[0], final.w[-1]))


# -- the offsets' coefficients and their derivatives -----------------------------------------
@dataclass(frozen=True, eq=False)
class _Coefficients:
    C: np.ndarray  # (P, nb, m) offsets c = phi @ C_p
    Mu: np.ndarray  # (P, nb, m) friction weights of the rows, mu = phi @ Mu_p
    k: np.ndarray  # (N-1,)
    edges: np.ndarray
    basis: Any


def _coefficients(gait: Gait) -> _Coefficients:
    """The offsets' coefficients as the integrator compiles them (every term of c(t), whatever
    the gait file adds to it), on a grid of the breakpoints only, and the friction weights."""
    from crawlsim.model.offsets import PiecewiseOffsets
    from crawlsim.model.process import compile_gait

    N = gait.blocks
    process = compile_gait(gait, steps_per_period=1)
    pieces = process.offset_pieces
    assert pieces is not None and process.stiffness is not None
    signals = list(gait.links) + list(gait.forward) + list(gait.backward)
    friction = PiecewiseOffsets(signals, lambda coef: coef[:, N - 1:], pieces.edges)
    P = pieces.pieces
    C = np.array([pieces.coefficients(p) for p in range(P)])
    Mu = np.array([friction.coefficients(p) for p in range(P)])
    if friction.basis != pieces.basis:  # pragma: no cover - the same signals span both
        raise CrawlsimError(f"{gait.source}: internal error, friction and offsets in two bases")
    return _Coefficients(C, Mu, np.array(process.stiffness, dtype=float), pieces.edges,
                         pieces.basis)


def _rotation_inverse(base: np.ndarray, moved: np.ndarray, basis: Any, shift: float) -> np.ndarray:
    """d/dphase of coefficients from those at phase and phase + shift: harmonic n of every
    column is rotated by 2 pi n shift (rotations commute with the linear combination of the
    signals), Delta_n = (R_n - I) Z_n, and dZ_n/dphase = 2 pi n J Z_n, J the quarter turn."""
    out = np.zeros_like(base)
    h0 = basis.first_harmonic
    delta = moved - base
    for n in range(1, basis.harmonics + 1):
        a = 2.0 * math.pi * n * shift
        R = np.array([[math.cos(a) - 1.0, -math.sin(a)], [math.sin(a), math.cos(a) - 1.0]])
        rows = slice(h0 + 2 * (n - 1), h0 + 2 * n)
        Z = np.linalg.solve(R, delta[..., rows, :].swapaxes(-1, -2)[..., None]).squeeze(-1)
        Z = Z.swapaxes(-1, -2)  # (..., 2, cols)
        out[..., rows.start, :] = -2.0 * math.pi * n * Z[..., 1, :]
        out[..., rows.start + 1, :] = 2.0 * math.pi * n * Z[..., 0, :]
    return out


@dataclass(frozen=True, eq=False)
class _Parameter:
    path: str
    keys: tuple[Any, ...]
    value: float
    dC: np.ndarray | None = None
    dMu: np.ndarray | None = None
    dk: np.ndarray | None = None
    reason: str | None = None  # not computed: why
    period: bool = False


def _parameter(gait: Gait, base: _Coefficients, keys: tuple[Any, ...]) -> _Parameter:
    path = ".".join(str(k) for k in keys)
    node: Any = gait.document
    for key in keys:
        node = node.get(key) if isinstance(node, dict) else node[key]
    if node is None and keys[-1] == "phase":
        node = 0.0
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise GaitError(gait.source, path, f"a sensitivity needs a number, found {node!r}")
    value = float(node)
    if keys == ("period",):
        return _Parameter(path, keys, value, period=True)
    if keys[0] in ("blocks", "simulation", "name", "description", "units", "kind"):
        return _Parameter(path, keys, value, reason=f"{path} is not a continuous parameter of "
                                                   "the gait")
    phase = keys[-1] == "phase"
    H = max(base.basis.harmonics, 1)
    h = 0.25 / (2 * H + 1) * 1e-2 if phase else COEFFICIENT_STEP * max(abs(value), 1.0)
    try:
        moved = _coefficients(gait.replace(path, value + h))
    except CrawlsimError as exc:
        try:
            h = -h
            moved = _coefficients(gait.replace(path, value + h))
        except CrawlsimError:
            return _Parameter(path, keys, value, reason=f"the gait with {path} moved is "
                                                       f"refused: {exc}")
    if (moved.C.shape != base.C.shape or not np.array_equal(moved.edges, base.edges)
            or moved.basis != base.basis):
        return _Parameter(path, keys, value, reason=f"moving {path} moves the breakpoints of "
                                                   "c(t) or changes its form: not differentiated")
    if phase:
        dC = _rotation_inverse(base.C, moved.C, base.basis, h)
        dMu = _rotation_inverse(base.Mu, moved.Mu, base.basis, h)
    else:
        dC, dMu = (moved.C - base.C) / h, (moved.Mu - base.Mu) / h
    return _Parameter(path, keys, value, dC, dMu, (moved.k - base.k) / h)


# -- forward-mode differentiation along the limit period ------------------------------------
@functools.lru_cache(maxsize=16)
def _gauss(nq: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [-1, 1]."""
    return np.polynomial.legendre.leggauss(nq)


@dataclass
class _Walk:
    """Tangents of one period with respect to (w0, theta): n + p columns."""

    W: np.ndarray  # (n, q) d w(1)
    L: np.ndarray  # (m, q) d Lambda over the period
    D: np.ndarray  # (q,) d dissipation
    lam: np.ndarray  # (m,) Lambda over the period
    dissipation: float
    w_end: np.ndarray
    pieces: int
    kinks: list[str]
    column_kinks: np.ndarray  # (q,) bool
    # touches (message, tangent (s, q) of the touching gaps or slip rates where they are 0):
    # a kink for the parameters that move them off zero at the limit
    touches: list[tuple[str, np.ndarray]]


def _walk(lim: _Limit, co: _Coefficients, dC: np.ndarray, dMu: np.ndarray,
          dk: np.ndarray) -> _Walk:
    """Differentiate one period from the limit's start (module docstring); dC (P, nb, m, p),
    dMu (P, nb, m, p), dk (n, p)."""
    process, record = lim.process, lim.record
    poly = process.polyhedron
    B = poly.dense_normals()
    k = co.k
    n, m = B.shape[1], B.shape[0]
    p = dk.shape[1]
    q = n + p
    basis = co.basis
    scale = poly.c_scale
    w = np.array(record.w[0], dtype=float)
    Wt = np.zeros((n, q))
    Wt[:, :n] = np.eye(n)
    lam_total = np.zeros(m)
    Lt = np.zeros((m, q))
    diss = 0.0
    Dt = np.zeros(q)
    kinks: list[str] = []
    touches: list[tuple[str, np.ndarray]] = []
    column_kinks = np.zeros(q, dtype=bool)
    transitions = record.transitions
    cache: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    nq = 24 + 12 * basis.harmonics
    gx, gw = _gauss(nq)

    def factor(index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = tuple(int(i) for i in index)
        if key not in cache:
            BA = B[index]
            G = BA @ (k[:, None] * BA.T)
            cache[key] = (BA, G, np.linalg.inv(G))
        return cache[key]

    def pad(X: np.ndarray) -> np.ndarray:
        out = np.zeros(X.shape[:-1] + (q,))
        out[..., n:] = X
        return out

    def solve_on(index, w_s, W_s, piece, phi):
        """Lambda_A(u), w(u) and their tangents for a flow (or projection) on A from w_s;
        phi = phi(u), the basis at u."""
        BA, G, Gi = factor(index)
        cA = phi @ co.C[piece][:, index]
        dcA = pad(np.einsum("b,bap->ap", phi, dC[piece][:, index, :]))
        Lam = Gi @ (BA @ w_s - cA)
        BtL = BA.T @ Lam
        dGL = pad(BA @ (dk * BtL[:, None]))  # d G_A Lambda, parameter columns
        dLam = Gi @ (BA @ W_s - dcA - dGL)
        w_e = w_s - k * BtL
        dW = W_s - pad(dk * BtL[:, None]) - k[:, None] * (BA.T @ dLam)
        return Lam, dLam, w_e, dW

    count = len(transitions)
    times = np.array([t.u for t in transitions])
    derivatives: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    du_start = np.zeros(q)
    for j, tr in enumerate(transitions):
        index = np.asarray(tr.active.index, dtype=int)
        piece = int(tr.piece)
        if tr.cause == "jump":
            if not index.size:
                continue
            u_t = 0.0 if (piece == 0 and tr.u >= 1.0 - 1e-15) else tr.u
            phi = basis.values(u_t)[0]
            Lam, dLam, w, Wt = solve_on(index, w, Wt, piece, phi)
            lam_total[index] += Lam
            Lt[index] += dLam
            muA = phi @ co.Mu[piece][:, index]
            dmuA = np.einsum("b,bap->ap", phi, dMu[piece][:, index, :])
            diss += float(muA @ Lam)
            Dt += muA @ dLam + pad(Lam @ dmuA)
            du_start = np.zeros(q)
            continue
        u_s = tr.u
        nxt = transitions[j + 1] if j + 1 < count else None
        u_e = nxt.u if nxt is not None else 1.0
        hit = nxt is not None and nxt.cause == "hit"
        phi_e, phi_s = basis.values(u_e)[0], basis.values(u_s)[0]
        coef = co.C[piece]
        if piece not in derivatives:
            derivatives[piece] = (basis.derivative(coef), basis.derivative(dC[piece]))
        dcoef, dC1 = derivatives[piece]
        length = u_e - u_s
        sampled = length > 0
        if sampled:
            x = u_s + 0.5 * length * (gx + 1.0)
            weights = 0.5 * length * gw
            Phi = basis.values(x)
        if index.size:
            Lam, dLam, w_e, W_e = solve_on(index, w, Wt, piece, phi_e)
        else:
            Lam, dLam, w_e, W_e = np.zeros(0), np.zeros((0, q)), w.copy(), Wt.copy()
        BA, G, Gi = factor(index) if index.size else (np.zeros((0, n)),) * 3
        # the flow's velocity and slip rates at the end: w' = K B_A^T G^{-1} c_A', lambda = -G^{-1} c_A'
        if index.size:
            c1 = phi_e @ dcoef[:, index]
            rate_e = -Gi @ c1
            v_b = -k * (BA.T @ rate_e)
        else:
            rate_e, v_b = np.zeros(0), np.zeros(n)
        du = np.zeros(q)
        if hit:
            assert nxt is not None
            rows = np.asarray(nxt.hit, dtype=int)
            c1_all = phi_e @ dcoef
            rates = B[rows] @ v_b - c1_all[rows]
            dg = B[rows] @ W_e - pad(np.einsum("b,bip->ip", phi_e, dC[piece][:, rows, :]))
            size = max(float(np.max(np.abs(c1_all))), 1e-300)
            best = int(np.argmax(np.abs(rates)))
            if abs(rates[best]) <= TOUCH * size:
                kinks.append(f"a constraint is reached with zero rate at t/T = {u_e:.12g}")
            else:
                dus = -dg / rates[:, None]
                du = dus[best]
                spread = np.max(np.abs(dus - du), axis=0)
                bad = spread > 1e-7 * (np.abs(du) + 1e-300 + np.max(np.abs(dus), axis=0)) \
                    + 1e3 * EPS
                if rows.size > 1 and bad.any():
                    column_kinks |= bad
                    kinks.append(f"{rows.size} constraints reached together at t/T = "
                                 f"{u_e:.12g} move apart")
            # coincidences of the hit with a fixed-time event or another event
            near = np.count_nonzero(np.abs(times - u_e) <= COINCIDENT) > 1 or \
                np.any(np.abs(co.edges - u_e) <= COINCIDENT)
            if near:
                kinks.append(f"a constraint is reached at t/T = {u_e:.12g}, at the time of "
                             "another event")
            W_e = W_e + np.outer(v_b, du)
            if index.size:
                dLam = dLam + np.outer(rate_e, du)
        if index.size:
            lam_total[index] += Lam
            Lt[index] += dLam
            # dissipation: int mu_A . lambda_A over [u_s, u_e], lambda_A = -G^{-1} c_A'
            if sampled:
                lam_x = -(Phi @ dcoef[:, index]) @ Gi.T  # (nq, a)
                mu_x = Phi @ co.Mu[piece][:, index]
                dmu_x = np.einsum("xb,bap->xap", Phi, dMu[piece][:, index, :])
                dc1_x = np.einsum("xb,bap->xap", Phi, dC1[:, index, :])
                Btl = lam_x @ BA  # (nq, n): B_A^T lambda
                dGl = np.einsum("ai,ip,xi->xap", BA, dk, Btl)
                dlam_x = -np.einsum("ab,xbp->xap", Gi, dc1_x + dGl)
                diss += float(weights @ np.sum(mu_x * lam_x, axis=1))
                Dt[n:] += np.einsum("x,xap->p", weights,
                                    dmu_x * lam_x[:, :, None] + mu_x[:, :, None] * dlam_x)
                # the moving ends of the piece
                end_power = float(phi_e @ co.Mu[piece][:, index] @ rate_e)
                Dt += end_power * du
                rate_s = -Gi @ (phi_s @ dcoef[:, index])
                Dt -= float(phi_s @ co.Mu[piece][:, index] @ rate_s) * du_start
        if length > 4 * COINCIDENT:  # shorter: an event at the time of another, above
            ends = np.asarray(nxt.hit, dtype=int) if hit and nxt is not None else np.zeros(0, int)
            touches.extend(_touches(B, k, index, w, Wt, coef, dcoef, dC[piece], dC1, dk, x,
                                    Phi, u_s, u_e, scale, solve_on, pad, piece, ends, basis,
                                    phi_s, phi_e))
        w, Wt = w_e, W_e
        du_start = du
    return _Walk(Wt, Lt, Dt, lam_total, diss, w, count, kinks, column_kinks, touches)


def _touches(B, k, index, w_s, W_s, coef, dcoef, dC, dC1, dk, x, Phi, u_s, u_e, scale,
             solve_on, pad, piece, hit_at_end, basis, phi_s,
             phi_e) -> list[tuple[str, np.ndarray]]:
    """Touches inside a flow piece, seen at the interior samples x (basis values Phi): an
    inactive constraint whose gap reaches zero without crossing (or stays at zero), or an
    active one whose slip rate does so without leaving; with the tangents of those gaps and
    rates at the samples where they are zero."""
    out: list[tuple[str, np.ndarray]] = []
    rows_all = np.arange(B.shape[0])
    inactive = rows_all[np.isin(rows_all, index, invert=True)]
    if index.size:
        BA = B[index]
        Gi = np.linalg.inv(BA @ (k[:, None] * BA.T))
    tol = TOUCH * scale
    # the gaps in closed form, gap(u) = phi(u) @ Gcoef (w(u) = w_s - K B_A^T G^{-1}
    # (B_A w_s - c_A(u))), to find each one's largest value between the samples: a touch is an
    # interior maximum at zero (one at an end is an event there; a touch exactly at the start of
    # the period is not looked for)
    candidates = inactive[np.isin(inactive, hit_at_end, invert=True)]
    Gcoef = -np.array(coef[:, candidates], dtype=float)
    Gcoef[0] += B[candidates] @ w_s
    if index.size:
        Wc = (coef[:, index] @ Gi.T @ BA) * k[None, :]  # (nb, n): the response to c_A(u)
        Gcoef += Wc @ B[candidates].T
        Gcoef[0] -= B[candidates] @ (k * (BA.T @ (Gi @ (BA @ w_s))))
    grid = np.concatenate([[u_s], x, [u_e]])
    values = np.vstack([phi_s, Phi, phi_e]) @ Gcoef  # (s + 2, r)
    gap = values[1:-1]
    # between two samples a gap exceeds the larger by at most h^2/8 max|gap''| (the linear
    # interpolant's error): only rows that can reach -tol are looked at closely
    h = float(np.max(np.diff(grid)))
    reach = np.max(values, axis=0) + h * h / 8.0 * basis.curvature_bound(Gcoef) >= -tol
    flat = np.min(gap, axis=0, initial=np.inf) >= -tol
    found: list[tuple[int, float]] = []
    for j in np.flatnonzero(reach | flat):
        r = int(candidates[j])
        if flat[j]:
            found.append((r, float(x[len(x) // 2])))
            continue
        i = int(np.argmax(values[:, j]))
        if not 0 < i < len(grid) - 1:
            continue  # largest at an end: a release at the start, an event at the end
        from scipy.optimize import minimize_scalar

        res = minimize_scalar(lambda v, z=Gcoef[:, j]: -basis.scalar(v, z),
                              bounds=(float(grid[i - 1]), float(grid[i + 1])),
                              method="bounded", options={"xatol": 1e-14})
        u_best, v_best = float(res.x), max(float(-res.fun), float(values[i, j]))
        inside = min(u_best - u_s, u_e - u_best) > 1e-6 * (u_e - u_s)
        if v_best >= -tol and inside:
            found.append((r, u_best))
    if found:
        tangents = []
        for r, u_r in found:
            phi = basis.values(u_r)[0]
            if index.size:
                _, _, _, dW = solve_on(index, w_s, W_s, piece, phi)
            else:
                dW = W_s
            dc = pad(np.einsum("b,bp->p", phi, dC[:, r, :]))
            tangents.append((B[r] @ dW - dc)[None, :])
        rows = [r for r, _ in found]
        out.append((f"constraint(s) {rows} touch zero gap without entering in t/T in "
                    f"[{u_s:.9g}, {u_e:.9g}]", np.concatenate(tangents)))
    if index.size:
        rate = -(Phi @ dcoef[:, index]) @ Gi.T
        size = max(float(np.max(np.abs(Phi @ dcoef))), 1e-300)
        low = _touching(-rate, TOUCH * size)
        if low.any():
            tangents = []
            for s_i in np.flatnonzero(np.min(rate[:, low], axis=1) <= TOUCH * size):
                dc1 = np.einsum("b,bap->ap", Phi[s_i], dC1[:, index, :])
                dG_rate = BA @ (dk * (BA.T @ rate[s_i])[:, None])
                tangents.append(pad((-Gi @ (dc1 + dG_rate))[low]))
            out.append((f"slip rate(s) of constraint(s) {index[low].tolist()} touch zero in "
                        f"t/T in ({u_s:.9g}, {u_e:.9g})", np.concatenate(tangents)))
    return out


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


def _uniqueness_touch(gait: Gait, co: _Coefficients) -> str | None:
    """Friction on the boundary of the uniqueness condition: some g_J(t) (docs/model.md §3)
    reaches zero without changing sign (a tangency), so that moving the friction creates or
    removes instants where the slips are not unique."""
    N = gait.blocks
    if N > UNIQUENESS_BLOCKS or not np.any(co.Mu[:, 1:, :]):
        return None  # friction constant on each piece: g_J = 0 there is refused by validation
    total = np.zeros(N)
    J = ((np.arange(2 ** N)[:, None] >> np.arange(N)[None, :]) & 1).astype(float)  # (2^N, N)
    for p in range(co.Mu.shape[0]):
        Mu = co.Mu[p]
        if co.basis.size == 1:
            x = np.array([0.5 * (co.edges[p] + co.edges[p + 1])])
        else:
            x = np.linspace(co.edges[p], co.edges[p + 1], 513)
        vals = co.basis.values(x) @ Mu  # (s, 2N)
        plus, minus = vals[:, :N], vals[:, N:]
        total = np.maximum(total, np.max(plus + minus, axis=0))
        g = J @ (plus + minus).T - np.sum(minus, axis=1)[None, :]  # (2^N, s)
        tol = 1e-9 * float(np.max(np.sum(plus + minus, axis=1)))
        low = np.min(np.abs(g), axis=1)
        for r in np.flatnonzero(low <= 1e-3 * tol / 1e-9):
            gr = g[r]
            i = int(np.argmin(np.abs(gr)))
            if np.all(gr >= -tol) or np.all(gr <= tol):
                # refine the minimum of |g| near sample i on the closed form
                from scipy.optimize import minimize_scalar

                coefs = (J[r] @ (Mu[:, :N] + Mu[:, N:]).T) - np.sum(Mu[:, N:], axis=1)
                lo, hi = x[max(i - 1, 0)], x[min(i + 1, len(x) - 1)]
                if hi > lo:
                    res = minimize_scalar(lambda v, z=coefs: abs(co.basis.scalar(v, z)),
                                          bounds=(lo, hi), method="bounded",
                                          options={"xatol": 1e-12})
                    val = float(res.fun)
                else:
                    val = abs(float(gr[i]))
                if val <= tol:
                    blocks = [j + 1 for j in range(N) if J[r, j]]
                    return (f"the friction is on the boundary of the uniqueness condition: "
                            f"g_J touches zero at t/T = {x[i]:.6g} for J = {blocks}")
    return None


# -- the public function ---------------------------------------------------------------------
def sensitivity(gait: Gait, paths: Sequence[str] | str, *,
                one_sided: bool = True) -> SensitivityResult:
    """dv0/dtheta (and of the displacement, dissipation and cost of transport per period) for
    every number ``paths`` name in ``gait`` (dotted paths with ``*``, as ``--sweep``; each
    ``*`` expands to one parameter per element), at the exact integrator's verified limit.

    ``one_sided=False`` skips the one-sided differences at a kink (left and right are then
    None with the reason)."""
    from crawlsim.gait.document import Gait as _Gait

    if not isinstance(gait, _Gait):
        raise GaitError(getattr(gait, "source", "<gait>"), "",
                        "sensitivities are defined for crawler gaits (kind: crawler)")
    if isinstance(paths, str):
        paths = [paths]
    keys_list: list[tuple[Any, ...]] = []
    for path in paths:
        for keys in resolve_path(gait.document, path, gait.source):
            if keys not in keys_list:
                keys_list.append(keys)
    exact = gait if gait.simulation.integrator == "exact" else \
        gait.replace("simulation.integrator", "exact")
    lim = _limit(exact)
    co = _coefficients(exact)
    params = [_parameter(exact, co, keys) for keys in keys_list]
    active = [i for i, prm in enumerate(params) if prm.dC is not None]
    P, nb, m = co.C.shape
    n = len(co.k)
    p = len(active)
    dC = np.zeros((P, nb, m, p))
    dMu = np.zeros((P, nb, m, p))
    dk = np.zeros((n, p))
    for col, i in enumerate(active):
        prm = params[i]
        assert prm.dC is not None and prm.dMu is not None and prm.dk is not None
        dC[..., col], dMu[..., col], dk[:, col] = prm.dC, prm.dMu, prm.dk
    walk = _walk(lim, co, dC, dMu, dk)
    T = lim.process.period
    N = gait.blocks
    S = np.concatenate([np.ones(N), -np.ones(N)]) / N
    Y, D = lim.displacement, lim.dissipation
    J = walk.W[:, :n]
    Ptheta = walk.W[:, n:]
    Yw, Ytheta = S @ walk.L[:, :n], S @ walk.L[:, n:]
    Dw, Dtheta = walk.D[:n], walk.D[n:]
    A = np.eye(n) - J
    dw, *_ = np.linalg.lstsq(A, Ptheta, rcond=1e-12)
    dY = Ytheta + Yw @ dw
    dD = Dtheta + Dw @ dw
    # error: roundoff of every term (pieces x eps x their sizes, times the conditioning of the
    # least-squares solve) plus the verified limit's distance, relative, on the same sizes
    sv = np.linalg.svd(A, compute_uv=False)
    kept = sv[sv > 1e-12 * max(float(sv[0]) if sv.size else 1.0, 1e-300)]
    cond = float(kept[0] / kept[-1]) if kept.size else 1.0
    magY = np.abs(Ytheta) + np.abs(Yw) @ np.abs(dw)
    magD = np.abs(Dtheta) + np.abs(Dw) @ np.abs(dw)
    rel = 64 * EPS * (walk.pieces + n) * cond + lim.residual
    # a floor at the roundoff of the slips themselves: a derivative that cancels to ~0 (a
    # common phase shift) is zero to eps times the sizes the period's slips are made of
    size_c = max(float(np.max(np.abs(co.C))), 1e-300)
    moved = np.max(np.abs(dC), axis=(0, 1, 2)) / size_c + np.max(np.abs(dk), axis=0) / np.min(
        co.k) if p else np.zeros(0)
    floor = 64 * EPS * walk.pieces * moved
    errY = rel * magY + floor * (float(np.sum(np.abs(walk.lam))) / N)
    errD = rel * magD + floor * abs(D)
    kinks = list(walk.kinks)
    scale_c = lim.process.polyhedron.c_scale
    friction_kink = _uniqueness_touch(exact, co)
    out: list[ParameterSensitivity] = []
    cot = D / abs(Y) if abs(Y) > 10 * lim.v0_error * T + 1e-300 else None
    for i, prm in enumerate(params):
        if prm.period:
            dv = Derivative(-lim.v0 / T, lim.v0_error / T)
            zero = Derivative(0.0, 0.0)
            out.append(ParameterSensitivity(prm.path, prm.value, dv, zero, zero,
                                            zero if cot is not None else Derivative(None, None),
                                            True, "rate-independence",
                                            v0_on_pieces=dv.value))
            continue
        if prm.dC is None:
            none = Derivative(None, None)
            out.append(ParameterSensitivity(prm.path, prm.value, none, none, none, none, False,
                                            "unsupported", prm.reason))
            continue
        col = active.index(i)
        reasons = list(kinks)
        for message, tangent in walk.touches:
            total = tangent[:, :n] @ dw[:, col] + tangent[:, n + col]
            size = np.abs(tangent[:, :n]) @ np.abs(dw[:, col]) + np.abs(tangent[:, n + col])
            if np.any(np.abs(total) > 1e-7 * np.max(size) + 1e3 * EPS * scale_c):
                reasons.append(message)
        if walk.column_kinks[n + col] and not reasons:
            reasons.append("constraints reached together move apart")
        if friction_kink is not None and np.any(dMu[..., col] != 0.0):
            reasons.append(friction_kink)
        y, ey = float(dY[col]), float(errY[col])
        dd, ed = float(dD[col]), float(errD[col])
        if cot is not None:
            sgn = math.copysign(1.0, Y)
            dcot = dd / abs(Y) - D * sgn * y / (Y * Y)
            ecot = ed / abs(Y) + abs(D) * ey / (Y * Y) + abs(dcot) * lim.v0_error * T / abs(Y)
            dcot_d = Derivative(dcot, ecot)
        else:
            dcot_d = Derivative(None, None)
        if not reasons:
            out.append(ParameterSensitivity(
                prm.path, prm.value, Derivative(y / T, ey / T), Derivative(y, ey),
                Derivative(dd, ed), dcot_d, True, "exact", v0_on_pieces=y / T))
            continue
        reason = "; ".join(dict.fromkeys(reasons))
        left = right = None
        lr: str | None = "one-sided differences not requested"
        rr: str | None = lr
        if one_sided:
            left, lr = _one_sided(exact, prm, lim.v0, -1)
            right, rr = _one_sided(exact, prm, lim.v0, +1)
        none = Derivative(None, None)
        out.append(ParameterSensitivity(prm.path, prm.value, none, none, none, none, False,
                                        "one-sided", reason, left, right,
                                        None if left is not None else lr,
                                        None if right is not None else rr, y / T))
    return SensitivityResult(gait.name, T, lim.v0, lim.v0_error, Y, D, cot, tuple(out),
                             tuple(dict.fromkeys(kinks)))


def _one_sided(gait: Gait, prm: _Parameter, v0: float,
               side: int) -> tuple[Derivative | None, str | None]:
    """The one-sided derivative of v0 from the exact integrator's v0 at theta + side h and
    theta + 2 side h: D(h) = (v(theta + s h) - v0) / (s h), extrapolated 2 D(h) - D(2 h); its
    error: the extrapolation's change |D(h) - D(2h)| plus the runs' roundoff over h."""
    h = ONE_SIDED_STEP * max(abs(prm.value), 1.0)
    values = []
    try:
        for mult in (1, 2):
            lim = _limit(gait.replace(prm.path, prm.value + side * mult * h))
            values.append((lim.v0, lim.v0_error))
    except CrawlsimError as exc:
        return None, f"{prm.path} = {prm.value + side * h:g}: {exc}"
    d1 = (values[0][0] - v0) / (side * h)
    d2 = (values[1][0] - v0) / (side * 2 * h)
    err = abs(d1 - d2) + 3 * (values[0][1] + values[1][1]) / h
    return Derivative(2 * d1 - d2, err), None
