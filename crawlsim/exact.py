"""Exact, event-driven integration of a polyhedral sweeping process (MODEL.md §2-3).

The sweeping process ``w' in -N_{K(t)}(w)`` in the metric M, with K(t) = {w : B w <= c(t)}, reads

    M w'(t) + B^T lambda(t) = 0,   lambda >= 0,   lambda_i (B w - c)_i = 0,

the continuous-time limit of the catch-up KKT system M (w_{j+1} - w_j) + B^T lambda_j = 0, so
lambda(t) is the *rate* of the catch-up multipliers: the slip rates (dx/dt = S lambda).

**Between events** the active set A is fixed and B_A w(t) = c_A(t). Differentiating,
B_A w' = -G_A lambda_A = c'_A, with G_A = B_A M^{-1} B_A^T, so

    lambda_A(t) = -G_A^{-1} c'_A(t),
    int_{ta}^{t} lambda_A = G_A^{-1} (c_A(ta) - c_A(t))            (telescoping: exact),
    w(t) = w(ta) - R_A (B_A w(ta) - c_A(t)) = P_A^perp w(ta) + R_A c_A(t),

with R_A = M^{-1} B_A^T G_A^{-1} (the same ``ActiveSet.response`` catch-up uses). The block
displacements over any interval are therefore exact, whatever c is.

**Events** end a piece:

* a *gap closes*: an inactive row's (B w(t) - c(t))_i reaches 0;
* a *release*: an active multiplier lambda_i(t) reaches 0 (it would turn negative);
* a *breakpoint* of c (``process.breakpoints``, and the period end T): at a kink only the rates
  change; at a jump (a ``steps`` signal) the state is projected exactly onto K(t+), and that
  projection's multipliers are real, instantaneous slips (they belong to the grid interval
  ending at the jump, as in catch-up, because signals are right-continuous).

At every event the new active set comes from the **velocity problem** (Moreau): the right
derivative u = w'(t+) is the M-minimal-norm element of {u : B_A0 u <= c'_A0(t+)}, A0 the rows tight
at w. Its multipliers are lambda(t+); the rows with a positive multiplier form the next A. It is
solved by a certified `ExactProjector` on the rows A0 (Clarabel proposes, the equality KKT system
decides). Rows where the velocity problem is degenerate (tight with a zero multiplier: a
tangential contact, or a release) are decided to second order by a probe a short time ahead:
a row that the probe finds violated is added (a gap) or dropped (a negative multiplier).

**Locating events.** Every gap and multiplier is a closed form in t. They are sampled on a fixed
grid (`BRACKET_CELLS` cells per period plus the breakpoints), and the first sign change is
refined by `scipy.optimize.brentq` on the closed form to ~1e-15 T. For piecewise-linear c the
functions are linear between breakpoints, so brentq's secant step is exact: events are exact to
roundoff. For smooth c a gap can touch zero between two samples and come back; every discrete
local extremum that comes within its curvature bound of zero is refined with a bounded scalar
minimisation, so tangential contacts are not missed.

**Robustness.** More than ``max_events`` events in one period, or `ZENO_EVENTS` events within
`ZENO_WINDOW` T of each other (Zeno-like accumulation, or an active set that cannot be decided),
stops the run with an `EventError` that names the time and the constraints involved.

The stepper reports each period on the process grid ``process.times``, like catch-up: w at the
grid times, and in ``multipliers[j]`` the exact integral of lambda over [t_j, t_{j+1}] (plus any
jump), so every analysis of `crawlsim.analysis` applies unchanged and v0 is exact. The grid only
samples the solution; its accuracy does not depend on it. The exact trajectory at the event
times is in ``PeriodRecord.events``.
"""

from __future__ import annotations

import warnings
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .errors import CertificateError, EventError, LicqWarning
from .model import GRID_MERGE, SweepingProcess
from .projection import ActiveSet, ExactProjector, _Dependent
from .stepping import PeriodRecord

#: Sampling cells per period used to bracket events before brentq refines them.
BRACKET_CELLS = 1024
#: Default bound on the number of events in one period.
MAX_EVENTS = 10_000
#: Zeno-like accumulation: this many consecutive events ...
ZENO_EVENTS = 64
#: ... within this fraction of the period.
ZENO_WINDOW = 1e-9
#: Relative tolerance on gaps (units of c) and multiplier rates for "tight" and "violated".
EVENT_RTOL = 1e-14
#: How far ahead (fraction of T) the probe looks to decide degenerate rows at an event.
PROBE = 1e-6
#: Nodes of the Gauss-Legendre rule used for left limits of c at breakpoints.
_GAUSS = np.polynomial.legendre.leggauss(8)


class EventTrajectory(NamedTuple):
    """The exact trajectory at event times (absolute), after each event is processed.

    Between two consecutive entries the active set is fixed and w follows the closed form of the
    module docstring. Period starts and breakpoints are included.
    """

    t: np.ndarray  # (E,)
    w: np.ndarray  # (E, n)
    x: np.ndarray | None  # (E, N) block positions (crawlers)


@dataclass(frozen=True, eq=False)
class _Piece:
    """w(t) and int lambda on an interval with the active set A fixed (module docstring)."""

    t0: float
    w0: np.ndarray
    lam0: np.ndarray  # cumulative multipliers since the period start, at t0 (m,)
    active: ActiveSet
    tight: np.ndarray  # rows tight at t0 (A0), sorted

    def at(self, c):
        """(w, cumulative multipliers) where c (..., m) is c at the wanted times."""
        A = self.active
        if A.size == 0:
            shape = np.shape(c)[:-1]
            return (np.broadcast_to(self.w0, shape + self.w0.shape).copy(),
                    np.broadcast_to(self.lam0, shape + self.lam0.shape).copy())
        residual = A.normals @ self.w0 - np.asarray(c)[..., A.index]
        w = self.w0 - residual @ A.response.T
        lam = np.broadcast_to(self.lam0, np.shape(c)).copy()
        lam[..., A.index] += residual @ A.gram_inv.T
        return w, lam

    def rates(self, cdot):
        """lambda_A(t) = -G_A^{-1} c'_A(t) for c'(..., m)."""
        A = self.active
        return -np.asarray(cdot)[..., A.index] @ A.gram_inv.T


class EventStepper:
    """Exact event-driven stepping of a `SweepingProcess`, period by period (module docstring).

    Same interface as `crawlsim.stepping.CatchUpStepper`. ``check_every_step=True`` verifies the
    trajectory with Clarabel: every sampled state is projected onto K(t_j) and must be its own
    projection. ``bracket_cells`` sets the event-bracketing grid, ``max_events`` the bound on
    events per period, ``zeno_events`` and ``zeno_window`` (fraction of T) the accumulation test.
    """

    def __init__(self, process: SweepingProcess, *, check_every_step: bool = False,
                 bracket_cells: int = BRACKET_CELLS, max_events: int = MAX_EVENTS,
                 zeno_events: int = ZENO_EVENTS, zeno_window: float = ZENO_WINDOW):
        if process.offset_function is None or process.offset_rate is None:
            raise EventError(f"{process.name}: the exact integrator needs the closed form of "
                             "c(t) (offset_function and offset_rate); use --integrator catch-up")
        self.process = process
        self._offset = process.offset_function
        self._offset_rate = process.offset_rate
        self.check_every_step = check_every_step
        self.max_events = int(max_events)
        self.zeno_events, self.zeno_window = int(zeno_events), float(zeno_window)
        # Crawlers: dependent active normals make the slips undetermined, an error (MODEL.md
        # §3); generic processes keep their unique point with a LicqWarning, as in catch-up.
        self._on_dependent = "raise" if process.is_crawler else "warn"
        self.projector = ExactProjector(process.normals, process.metric, process.scale,
                                        describe_active=process.describe_active,
                                        on_dependent=self._on_dependent)
        self.B = self.projector.B
        self.w = np.array(process.initial, dtype=float)
        self.x = None if process.initial_positions is None else np.array(
            process.initial_positions, dtype=float)
        self.period_index = 0
        self._velocity_projectors: dict[tuple, ExactProjector] = {}
        T = process.period
        self._T = T
        self._prepare_stops()
        self._prepare_bracket_grid(int(bracket_cells))
        self.gap_tol = EVENT_RTOL * process.scale
        gram_scale = float(np.max(np.einsum("ij,jk,ik->i", self.B, self.projector.M_inv, self.B)))
        self.rate_tol = EVENT_RTOL * self._rate_scale / gram_scale

    # -- per-period constants ---------------------------------------------------------------
    def _prepare_stops(self):
        """Breakpoints in (0, T) and T itself, with left limits of c, c' and the jumps of c."""
        p, T = self.process, self._T
        bp = np.asarray(p.breakpoints if p.breakpoints is not None else [], dtype=float)
        bp = np.mod(bp, T)
        wraps = bool(np.any((bp <= GRID_MERGE * T) | (bp >= T * (1 - GRID_MERGE))))
        inner = np.unique(bp[(bp > GRID_MERGE * T) & (bp < T * (1 - GRID_MERGE))])
        # Snap to the grid times the model put them on, so that grid and stops agree exactly.
        for i, b in enumerate(inner):
            j = int(np.argmin(np.abs(p.times - b)))
            if abs(p.times[j] - b) <= 1e-12 * T:
                inner[i] = p.times[j]
        stops = np.append(inner, T)
        is_break = np.append(np.ones(len(inner), bool), wraps)
        previous = np.concatenate([[0.0], stops[:-1]])
        right = self._offset(stops)
        right[-1] = self._offset(np.array([0.0]))[0]
        left = right.copy()
        rate_left = self._offset_rate(stops)
        for i in np.flatnonzero(is_break):
            left[i], rate_left[i] = self._left_limit(stops[i], previous[i])
        jump = np.max(np.abs(left - right), axis=1) > EVENT_RTOL * p.scale
        self.stops, self._stop_is_break = stops, is_break
        self._c_left, self._cdot_left, self._c_right, self._jump = left, rate_left, right, jump

    def _left_limit(self, stop, previous):
        """c(stop-) and c'(stop-): c is continuous on (previous, stop), so
        c(stop-) = c(s) + int_s^stop c' (8-point Gauss-Legendre on a short interval, exact for the
        piecewise-linear parts), and c'(stop-) by Richardson extrapolation of one-sided samples."""
        delta = min(1e-3 * self._T, 0.5 * (stop - previous))
        s = stop - delta
        nodes, weights = _GAUSS
        t = s + (nodes + 1) * delta / 2
        c = self._offset(np.array([s]))[0] + (weights @ self._offset_rate(t)) * delta / 2
        h = min(1e-9 * self._T, delta / 4)
        r = self._offset_rate(np.array([stop - h, stop - 2 * h]))
        return c, 2 * r[0] - r[1]

    def _prepare_bracket_grid(self, cells):
        p, T = self.process, self._T
        u = np.linspace(0.0, T, cells + 1)[1:-1]
        near = np.min(np.abs(u[:, None] - self.stops[None, :]), axis=1) <= 1e-12 * T
        self._bt = u[~near]
        self._bc = self._offset(self._bt)
        self._bcdot = self._offset_rate(self._bt)
        both = np.vstack([np.abs(self._bcdot), np.abs(self._cdot_left)])
        self._rate_scale = max(float(np.max(both, initial=0.0)), p.scale / T)

    # -- closed forms ---------------------------------------------------------------------
    def _c(self, t, stop_index):
        """c(t) on the current piece, which ends at stops[stop_index] (left limit there)."""
        stop = self.stops[stop_index]
        if t >= stop - 1e-11 * self._T:
            return self._c_left[stop_index] - (stop - t) * self._cdot_left[stop_index]
        return self._offset(np.array([t]))[0]

    def _cdot(self, t, stop_index):
        stop = self.stops[stop_index]
        if t >= stop - 1e-11 * self._T:
            return self._cdot_left[stop_index]
        return self._offset_rate(np.array([t]))[0]

    # -- one period -------------------------------------------------------------------------
    def step_period(self) -> PeriodRecord:
        """Advance by one period and return its record, sampled on ``process.times``."""
        p, T = self.process, self._T
        G, n, m = p.steps, p.normals.shape[1], p.normals.shape[0]
        start = self.period_index * T
        calls0 = self.projector.clarabel_calls
        W = np.empty((G + 1, n))
        LAMC = np.zeros((G + 1, m))
        W[0] = self.w
        j = 1
        ev_t, ev_w, ev_lam = [], [], []
        recent: deque[float] = deque(maxlen=self.zeno_events)
        t, w, lam = 0.0, self.w.copy(), np.zeros(m)
        forced = np.zeros(0, dtype=int)
        stop_index = 0
        c_now, cdot_now = self._c_right[-1], self._offset_rate(np.array([0.0]))[0]
        while True:
            ev_t.append(t)
            ev_w.append(w)
            ev_lam.append(lam)
            self._guard(len(ev_t), recent, t, start, forced)
            stop = self.stops[stop_index]
            piece = self._start_piece(t, w, lam, c_now, cdot_now, forced, stop, stop_index,
                                      start)
            event = self._next_event(piece, stop_index)
            if event is None:
                t_e = stop
                c_e = self._c_left[stop_index]
            else:
                t_e, forced = event
                c_e = self._c(t_e, stop_index)
            while j <= G and p.times[j] < t_e:
                W[j], LAMC[j] = piece.at(p.offsets[j])
                j += 1
            w, lam = piece.at(c_e)
            t = t_e
            if event is not None:
                c_now, cdot_now = c_e, self._cdot(t_e, stop_index)
                continue
            forced = np.zeros(0, dtype=int)
            if self._jump[stop_index]:
                proj = self.projector.project(w, self._c_right[stop_index], time=start + stop)
                w, lam = proj.point, lam + proj.multipliers
            if j <= G and p.times[j] == stop:
                W[j], LAMC[j] = w, lam
                j += 1
            if stop_index == len(self.stops) - 1:
                break
            c_now = self._c_right[stop_index]
            cdot_now = self._offset_rate(np.array([stop]))[0]
            stop_index += 1
        if j != G + 1:  # pragma: no cover - the grid ends at T, which is the last stop
            raise EventError(f"{p.name}: internal error, sampled {j} of {G + 1} grid times")

        multipliers = np.diff(LAMC, axis=0)
        self._certify(W, multipliers, start)
        X = x_events = None
        if self.x is not None:
            assert p.slip_map is not None
            X = self.x + LAMC @ p.slip_map.T
            x_events = self.x + np.array(ev_lam) @ p.slip_map.T
            self.x = X[-1].copy()
        self.w = W[-1].copy()
        events = EventTrajectory(start + np.array(ev_t), np.array(ev_w), x_events)
        record = PeriodRecord(self.period_index, start, W, multipliers, X,
                              self.projector.clarabel_calls - calls0, events=events)
        self.period_index += 1
        return record

    def _guard(self, count, recent, t, start, rows):
        """Stop on too many events in a period or on Zeno-like accumulation."""
        p = self.process
        if count > self.max_events:
            raise EventError(
                f"{p.name}: more than {self.max_events} events in period {self.period_index} "
                f"(at t = {start + t:.12g}); the active set keeps changing. Raise max_events, or "
                "use --integrator catch-up")
        recent.append(t)
        if len(recent) == self.zeno_events and recent[-1] - recent[0] <= self.zeno_window * self._T:
            raise EventError(
                f"{p.name}: Zeno-like accumulation of events: {self.zeno_events} events within "
                f"{recent[-1] - recent[0]:.3g} time units near t = {start + t:.15g} "
                f"(last constraints involved: {p.describe_active(rows)}). The exact integrator "
                "cannot pass this point; use --integrator catch-up")

    # -- an event: velocity problem and the next active set ---------------------------------
    def _start_piece(self, t, w, lam, c, cdot, forced, stop, stop_index, start) -> _Piece:
        """The piece from an event: A0 = rows tight at w (and the rows that just hit), A from
        the velocity problem, then degenerate rows decided by the probe (module docstring)."""
        h = self.B @ w - c
        tight = np.union1d(np.flatnonzero(h >= -self.gap_tol), forced).astype(int)
        A = self._velocity_active(tight, cdot, start + t)
        probe = t + min(PROBE * self._T, 0.5 * (stop - t))
        c_p, cdot_p = self._c(probe, stop_index), self._cdot(probe, stop_index)
        for _ in range(2 * len(tight) + 2):
            piece = _Piece(t, w, lam, self._active_set(A, start + t), tight)
            w_p, _ = piece.at(c_p)
            gap = (self.B @ w_p - c_p)[tight]
            rate = piece.rates(cdot_p)
            add = tight[(gap > self.gap_tol) & ~np.isin(tight, A)]
            drop = A[rate < -self.rate_tol]
            if add.size == 0 and drop.size == 0:
                return piece
            A = np.union1d(np.setdiff1d(A, drop), add).astype(int)
        raise EventError(
            f"{self.process.name}: a tangential contact at t = {start + t:.15g} could not be "
            f"resolved ({self.process.describe_active(tight)} tight, no consistent active set); "
            "use --integrator catch-up")

    def _velocity_active(self, tight, cdot, time):
        """Rows with a positive multiplier in the velocity problem
        min 1/2 |u|_M^2 s.t. B_A0 u <= c'_A0 (A0 = ``tight``), certified."""
        if tight.size == 0:
            return tight
        key = tuple(tight.tolist())
        vp = self._velocity_projectors.get(key)
        if vp is None:
            describe = self.process.describe_active
            vp = ExactProjector(self.B[tight], self.process.metric, self._rate_scale,
                                describe_active=lambda idx: describe(tight[np.asarray(idx, int)]),
                                on_dependent=self._on_dependent)
            self._velocity_projectors[key] = vp
        calls, known = vp.clarabel_calls, set(vp.licq_failures)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LicqWarning)
            sol = vp.project(np.zeros(self.B.shape[1]), cdot[tight], time=time)
        self.projector.clarabel_calls += vp.clarabel_calls - calls  # one tally for `simulate`
        for local in set(vp.licq_failures) - known:  # warn once, in the process's row numbers
            self.projector._record_licq(tight[list(local)], time)
        return tight[sol.multipliers > self.rate_tol]

    def _active_set(self, A, time):
        try:
            return self.projector.active_set(A)
        except _Dependent as dep:
            raise CertificateError(self.projector._licq_message(dep.index, time)) from None

    # -- locating the next event ------------------------------------------------------------
    def _next_event(self, piece: _Piece, stop_index):
        """(time, rows newly tight) of the first event in (t0, stop), or None if there is none."""
        stop = self.stops[stop_index]
        t0 = piece.t0
        probe = t0 + min(PROBE * self._T, 0.5 * (stop - t0))
        lo, hi = np.searchsorted(self._bt, [probe, stop], side="right")
        S = np.concatenate([[probe], self._bt[lo:hi], [stop]])
        S = S[S <= stop]
        C = np.vstack([self._c(probe, stop_index)[None], self._bc[lo:hi],
                       self._c_left[stop_index][None]])[:len(S)]
        Cd = np.vstack([self._cdot(probe, stop_index)[None], self._bcdot[lo:hi],
                        self._cdot_left[stop_index][None]])[:len(S)]
        A = piece.active
        inactive = np.setdiff1d(np.arange(self.B.shape[0]), A.index)
        Wt, _ = piece.at(C)
        # Violation functions, scaled so that the tolerance is EVENT_RTOL: gaps, negative rates.
        V = np.hstack([(Wt @ self.B[inactive].T - C[:, inactive]) / self.gap_tol,
                       -piece.rates(Cd) / self.rate_tol])
        rows = np.concatenate([inactive, A.index])
        kinds = np.concatenate([np.zeros(len(inactive), int), np.ones(A.size, int)])

        def f(r):
            row, kind = rows[r], kinds[r]
            if kind == 0:
                def gap(t):
                    c = self._c(t, stop_index)
                    w, _ = piece.at(c)
                    return (self.B[row] @ w - c[row]) / self.gap_tol
                return gap
            k = int(np.searchsorted(A.index, row))

            def negative_rate(t):
                return -piece.rates(self._cdot(t, stop_index))[k] / self.rate_tol
            return negative_rate

        candidates = []
        bad = V > 1.0
        first = int(np.argmax(np.any(bad, axis=1))) if np.any(bad) else len(S)
        for r in np.flatnonzero(bad[first]) if first < len(S) else ():
            left = S[first - 1] if first > 0 else t0
            candidates.append((self._root(f(r), left, S[first]), r))
        # Touch-and-go: a discrete local maximum of a violation function that may cross the
        # tolerance between samples. Near a maximum the excess over the best sample is at most
        # about |f''| h^2 / 8, and the second difference estimates |f''| h^2: 8x margin.
        end = min(first, len(S) - 1)
        if end >= 2:
            Vs = V[:end + 1]
            mid = Vs[1:-1]
            second = np.abs(Vs[2:] - 2 * mid + Vs[:-2])
            peak = (mid >= Vs[:-2]) & (mid >= Vs[2:]) & (mid + second > 1.0)
            for i, r in zip(*np.nonzero(peak)):
                g = f(r)
                a, b = S[i], S[i + 2]
                from scipy.optimize import minimize_scalar  # ~0.4 s to import: only when used

                top = minimize_scalar(lambda t, g=g: -g(t), bounds=(a, b), method="bounded",
                                      options={"xatol": 1e-15 * self._T})
                if -top.fun > 1.0:
                    candidates.append((self._root(g, a, float(top.x)), r))
        if not candidates:
            return None
        t_e = min(tc for tc, _ in candidates)
        hit = [rows[r] for tc, r in candidates
               if kinds[r] == 0 and tc <= t_e + 1e-14 * self._T]
        return t_e, np.array(sorted(hit), dtype=int)

    def _root(self, g, a, b):
        """First zero of g in [a, b] with g(b) > 0: brentq, or a itself if g(a) >= 0."""
        ga = g(a)
        if ga >= 0:
            return a
        from scipy.optimize import brentq  # ~0.4 s to import: only when an event is refined

        return brentq(g, a, b, xtol=1e-15 * self._T, rtol=4 * np.finfo(float).eps)

    # -- certificate of the sampled period ---------------------------------------------------
    def _certify(self, W, multipliers, start):
        """Every sampled state is in K(t_j), every interval's slip integral is >= 0 (to
        roundoff); with ``check_every_step`` Clarabel confirms each state is its own projection."""
        p = self.process
        slack = W @ self.B.T - p.offsets
        worst = float(np.max(slack))
        dual = float(-np.min(multipliers, initial=0.0))
        tol_primal = 100 * self.projector.tol.primal
        tol_dual = 100 * self.projector.tol.dual
        if worst > tol_primal or dual > tol_dual:
            j = int(np.argmax(np.max(slack, axis=1)))
            raise CertificateError(
                f"{p.name}: the exact trajectory failed its certificate in period "
                f"{self.period_index}: constraint violation {worst:.3g} (tolerance "
                f"{tol_primal:.3g}) at t = {start + p.times[j]:.12g}, negative slip integral "
                f"{dual:.3g} (tolerance {tol_dual:.3g})")
        if self.check_every_step:
            for j in range(len(W)):
                proj = self.projector.project(W[j], p.offsets[j], time=start + p.times[j])
                if np.max(np.abs(proj.point - W[j])) > tol_primal:
                    raise CertificateError(
                        f"{p.name}: Clarabel moves the exact state at t = "
                        f"{start + p.times[j]:.12g} by {np.max(np.abs(proj.point - W[j])):.3g}")
