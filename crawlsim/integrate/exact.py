"""Exact, event-driven integration of a polyhedral sweeping process (docs/model.md §2-3).

The sweeping process ``w' in -N_{K(t)}(w)`` in the metric M, with K(t) = {w : B w <= c(t)}, reads

    M w'(t) + B^T lambda(t) = 0,   lambda >= 0,   lambda_i (B w - c)_i = 0,

the continuous-time limit of the catch-up KKT system, so lambda(t) is the *rate* of the catch-up
multipliers: the slip rates (dx/dt = lambda^+ - lambda^-). Times are in cycles u = t / T here.

**Between events** the active set A is fixed and B_A w(u) = c_A(u), so (telescoping, exact)

    Lambda_A(u) = G_A^{-1} (B_A w_0 - c_A(u)),   w(u) = w_0 - M^{-1} B_A^T Lambda_A(u),

Lambda_A the slips accumulated since the piece began, G_A = B_A M^{-1} B_A^T. On a piece of c
(`crawlsim.model.offsets`: c(u) = phi(u) @ C_p in a basis of 1, u and harmonics), every gap
(B w(u) - c(u))_i and every slip rate is itself such a combination, computed with one
multi-right-hand-side solve of the KKT kernel (`crawlsim.projection.kkt`), O(N) for a crawler.

**Events** end a piece: an inactive row's gap reaches 0 from below, or an active row's slip rate
reaches 0 from above; and the breakpoints of c, where at a jump (a ``steps`` signal) the state
is projected exactly onto K(t+) by the certified projector (its multipliers are instantaneous
slips, booked to the grid interval ending at the jump since signals are right-continuous).
Zeros are found in closed form where the basis allows it (1 and u: linear; 1 and one harmonic:
``a + rho cos(theta - phi) = 0``), else by sampling with a curvature bound that rules out a
crossing between samples, and brentq on the closed form. An event time is the zero crossing;
it is exact to roundoff.

**The next active set** at an event (or at a breakpoint) comes from Moreau's velocity problem:
the right derivative v = w'(u+) is the M-minimal element of {v : B_T v <= c'_T(u+)}, T the rows
tight at w; rows with a positive multiplier stay active, rows whose velocity opens a gap leave.
Rows where that problem is degenerate (tight, zero multiplier: a tangential contact, or a
release) are decided at the next order, by the same projection with c'' (the rows already
decided active as equalities), and so on: on a piece w^(k) = R_A c_A^(k) and
lambda^(k-1) = -G_A^{-1} c_A^(k), so the k-th order problem is exactly the velocity problem one
level up. Rows still degenerate after `DECISION_ORDERS` orders stay tight without slipping
(their gap and rate vanish identically, as for piecewise-linear offsets). Every such problem is
solved by the kernel (Clarabel proposes only when its updates do not settle).

**Where it runs.** For a crawler, the whole period, every step above and the certificate of
every sample, runs in the compiled event loop `crawlsim.kernel.eventloop` (numba; one source,
which runs as Python under ``NUMBA_DISABLE_JIT=1``), whatever the offsets' basis. A period it
cannot finish on its own (a velocity problem or a jump projection whose active-set updates do
not settle, a dependent tight set) is handed over whole to the Python loop below, which decides
with Clarabel; generic processes always take the Python loop. Zeros without a closed form are
found by the same compiled sampling (`crawlsim.kernel.sampling`) in both loops. A failed
certificate is a `CertificateError` in both.

**Robustness.** More than ``max_events`` events in one period, or `ZENO_EVENTS` events within
`ZENO_WINDOW` T of each other (a genuine Zeno accumulation), stops the run with an `EventError`
naming the time and the constraints involved.

The stepper reports each period on the process grid ``process.times``, like catch-up: w at the
grid times, and in ``multipliers[j]`` the exact integral of lambda over [t_j, t_{j+1}] (plus any
jump), so every analysis of `crawlsim.analysis.run` applies unchanged and v0 is exact. Every sampled
state and slip integral is certified with the kernel's tolerance policy. The trajectory at the
event times is in ``PeriodRecord.events``.
"""

from __future__ import annotations

import warnings
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.errors import CertificateError, DegenerateModelError, EventError, InputError, LicqWarning
from crawlsim.integrate.compiled import EventTrajectory, _CompiledLoop
from crawlsim.integrate.ground import GroundState
from crawlsim.integrate.ledger import ExactLedger
from crawlsim.integrate.stepping import PeriodRecord, PeriodStepper, Transition, TransitionCause
from crawlsim.kernel.events import SIMULTANEOUS
from crawlsim.kernel.jit import kernel
from crawlsim.kernel.policy import REFINE_LIMIT
from crawlsim.model.offsets import TWO_PI, PiecewiseOffsets
from crawlsim.model.process import SweepingProcess
from crawlsim.projection.adapter import Projection
from crawlsim.projection.kkt import RTOL, ActiveSet, Dependent, Tolerance

#: Default bound on the number of events in one period.
MAX_EVENTS = 100_000
#: Zeno-like accumulation: this many consecutive events ...
ZENO_EVENTS = 64
#: ... within this fraction of the period.
ZENO_WINDOW = 1e-9
#: Orders of the velocity problem used to decide degenerate rows at an event.
DECISION_ORDERS = 4
#: Sampling cells per cycle and harmonic where no closed form gives the zeros.
CELLS_PER_CYCLE = 64
#: Periods in a row the compiled event loop may hand over to the Python loop before a stepper
#: stops trying it (a gait whose velocity problems or jumps need Clarabel every period; one
#: that needs it now and then, at a jump from a Newton candidate of the limit search, keeps
#: the compiled loop for the other periods).
LOOP_HANDOFFS = 3


@dataclass(frozen=True, eq=False)
class _Piece:
    """w(u) and Lambda_A(u) on an interval with the active set A fixed (module docstring)."""

    u0: float
    active: ActiveSet
    base: np.ndarray  # (n,) w(u) = base + phi(u) @ Wc
    Wc: np.ndarray  # (nb, n)
    lam0: np.ndarray  # (a,) Lambda_A(u) = lam0 - phi(u) @ Y
    Y: np.ndarray  # (nb, a)

    def at(self, phi: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
        """(w, Lambda padded to m rows) at basis values phi (k, nb)."""
        w = self.base + phi @ self.Wc
        lam = np.zeros((len(phi), m))
        if self.active.size:
            lam[:, self.active.index] = self.lam0 - phi @ self.Y
        return w, lam


class EventStepper(PeriodStepper):
    """Exact event-driven stepping of a `SweepingProcess`, period by period (module docstring).

    Same interface as `crawlsim.integrate.stepping.CatchUpStepper`. ``check_every_step=True`` verifies the
    trajectory with Clarabel: every sampled state is projected onto K(t_j) and must be its own
    projection. ``max_events`` bounds the events per period, ``zeno_events`` and
    ``zeno_window`` (fraction of T) set the accumulation test, ``cells_per_cycle`` the sampling
    where zeros have no closed form. ``kernel=False`` keeps a crawler on the Python loop (the
    path of generic processes), for comparison.
    """

    #: A period must start in K(0) (`crawlsim.integrate.limit` projects a Newton candidate first).
    needs_admissible_start = True
    pieces: PiecewiseOffsets

    def __init__(
        self,
        process: SweepingProcess,
        *,
        check_every_step: bool = False,
        max_events: int = MAX_EVENTS,
        zeno_events: int = ZENO_EVENTS,
        zeno_window: float = ZENO_WINDOW,
        cells_per_cycle: int = CELLS_PER_CYCLE,
        kernel: bool = True,
    ):
        if process.offset_pieces is None:
            raise EventError(
                f"{process.name}: the exact integrator needs the closed form of "
                "c(t) that gait and process files provide; use --integrator "
                "catch-up"
            )
        super().__init__(process, check_every_step=check_every_step)
        self.poly = process.polyhedron
        self.pieces = process.offset_pieces
        self.basis = self.pieces.basis
        self.max_events = int(max_events)
        self.zeno_events, self.zeno_window = int(zeno_events), float(zeno_window)
        self.cells_per_cycle = int(cells_per_cycle)
        # the period's energy ledger, integrated exactly on the pieces (crawlers)
        self._ledger = ExactLedger(process) if process.crawler is not None else None
        self._grid = process.cycles
        edges = self.pieces.edges
        self._edge_index = np.searchsorted(self._grid, edges)
        if not np.array_equal(self._grid[self._edge_index], edges):  # pragma: no cover
            raise EventError(f"{process.name}: internal error, breakpoints off the grid")
        # c(edge-) and c(edge+) at every inner edge and at the end of the cycle (wrapping to 0)
        P = self.pieces.pieces
        self._jump = np.zeros(P + 1, dtype=bool)
        for p in range(1, P + 1):
            left = self.pieces.evaluate(edges[p], piece=p - 1)[0]
            right = self.pieces.evaluate(edges[p] if p < P else 0.0, piece=p % P)[0]
            self._jump[p] = np.max(np.abs(left - right)) > 100 * RTOL * self.poly.c_scale
        # the ground under the blocks (docs/model.md §8): only the compiled loop walks terrain
        self.ground = None if process.terrain is None else GroundState(process, np.asarray(self.x))
        if self.ground is not None and (check_every_step or not kernel):
            raise InputError(
                process.name,
                "terrain",
                "on terrain the exact integrator runs its compiled loop only, without --check-every-step "
                "(Clarabel's check projects onto the sets of uniform ground)",
            )
        self._loop = _CompiledLoop.of(self) if kernel else None

    # -- one period -------------------------------------------------------------------------
    def _step_impl(self) -> PeriodRecord:
        """One period, sampled on ``process.times``: in the compiled event loop
        (`crawlsim.kernel.eventloop`) for a crawler, else (or where that loop hands the period
        over) in Python."""
        if self._loop is not None:
            record = self._loop.period(self)
            if record is not None:
                self._loop.handoffs = 0
                return record
            self._loop.handoffs += 1
            if self._loop.handoffs >= LOOP_HANDOFFS:  # a gait the compiled loop cannot take
                self._loop = None
        return self._python_period()

    def reset(self, w: np.ndarray, x: np.ndarray | None = None) -> None:
        super().reset(w, x)
        if self.ground is not None and self.x is not None:
            self.ground.locate(self.x)

    def _python_period(self) -> PeriodRecord:
        """One period with the event loop in Python (generic processes, and the periods the
        compiled loop hands over)."""
        p, T = self.process, self.process.period
        poly, pieces = self.poly, self.pieces
        G, n, m = p.steps, poly.n, poly.m
        start = self.period_index * T
        calls0 = self.projector.clarabel_calls
        W = np.empty((G + 1, n))
        LAMC = np.zeros((G + 1, m))
        W[0] = self.w
        j = 1
        ev_t, ev_w, ev_lam = [], [], []
        recent: deque[float] = deque(maxlen=self.zeno_events)
        u, w, lam_cum = 0.0, self.w.copy(), np.zeros(m)
        forced = np.zeros(0, dtype=int)
        cause: TransitionCause = "edge"
        piece_index = 0
        edges = pieces.edges
        carried = 0.0  # the largest slip roundoff of the pieces since the last sampled point
        self._visited = []
        ledger = self._ledger
        if ledger is not None:
            ledger.start()
        transitions: list[Transition] = []
        while True:
            ev_t.append(u)
            ev_w.append(w)
            ev_lam.append(lam_cum)
            self._guard(len(ev_t), recent, u, start, forced)
            time = start + u * T
            self.active = self._decide(u, w, piece_index, forced, time, self.active if transitions else poly.empty)
            self._visit(self.active)
            transitions.append(Transition(u, piece_index, self.active, cause, forced))
            piece = self._piece(self.active, w, piece_index, u)
            u_end = edges[piece_index + 1]
            event = self._next_event(piece, piece_index, u, u_end)
            u_e = u_end if event is None else event[0]
            # sample the grid times in (u, u_e]
            j_end = int(np.searchsorted(self._grid, u_e, side="right"))
            if j_end > j:
                phi = self.basis.values(self._grid[j:j_end])
                Wg, Lg = piece.at(phi, m)
                W[j:j_end] = Wg
                LAMC[j:j_end] = lam_cum + Lg
                try:
                    carried = self._certify_piece(
                        Wg, LAMC[j - 1 : j_end], piece, phi, piece_index, start + self._grid[j:j_end] * T, carried
                    )
                except _Uncertified as failed:
                    if failed.excess > REFINE_LIMIT:
                        raise
                    j += failed.index  # refined: the piece ends at that sample, projected there
                    u = self._grid[j]
                    if ledger is not None:
                        ledger.piece(piece_index, piece.u0, u, piece.base, piece.Wc, piece.active.index, piece.Y)
                    w, lam_cum = self._refine(piece_index, u, W, LAMC, j, start + u * T, ledger)
                    j, carried = j + 1, 0.0
                    transitions.append(Transition(u, piece_index, self.active, "jump", forced))
                    forced, cause = np.zeros(0, dtype=int), "release"
                    continue
                j = j_end
            else:  # the grid interval spans this piece: its roundoff enters the next sample
                carried = max(carried, self._dual_scale(piece, piece_index))
            if ledger is not None:
                ledger.piece(piece_index, u, u_e, piece.base, piece.Wc, piece.active.index, piece.Y)
            w_e, lam_e = piece.at(self.basis.values(u_e), m)
            w, lam_cum = w_e[0], lam_cum + lam_e[0]
            u = u_e
            if event is not None:
                forced = event[1]
                cause = "hit" if forced.size else "release"
                continue
            forced = np.zeros(0, dtype=int)
            cause = "edge"
            edge = piece_index + 1
            if self._jump[edge]:
                target = pieces.evaluate(u if edge < pieces.pieces else 0.0, piece=edge % pieces.pieces)[0]
                proj = self.projector.project(w, target, time=start + u * T, warm=self.active)
                self._certify_jump(w, target, proj, start + u * T)
                if ledger is not None:
                    ledger.jump(piece_index, u, w, proj.point, proj.multipliers)
                w, lam_cum = proj.point, lam_cum + proj.multipliers
                self.active = proj.active
                self._visit(proj.active)
                transitions.append(Transition(u, edge % pieces.pieces, proj.active, "jump", forced))
                je = self._edge_index[edge]
                W[je], LAMC[je] = w, lam_cum
            if edge == pieces.pieces:
                break
            piece_index = edge
        if j != G + 1:  # pragma: no cover - the grid ends at 1, the last edge
            raise EventError(f"{p.name}: internal error, sampled {j} of {G + 1} grid times")

        multipliers = np.diff(LAMC, axis=0)
        if self.check_every_step:
            self._verify(W, start)
        X = x_events = None
        if self.x is not None:
            X = self.x + p.slips(LAMC)
            x_events = self.x + p.slips(np.array(ev_lam))
            self.x = X[-1].copy()
        self.w = W[-1].copy()
        events = EventTrajectory(start + np.array(ev_t) * T, np.array(ev_w), x_events)
        record = PeriodRecord(
            self.period_index,
            start,
            W,
            multipliers,
            X,
            self.projector.clarabel_calls - calls0,
            events=events,
            visited=tuple(self._visited),
            transitions=tuple(transitions),
            energy_of=None if ledger is None else ledger.finish(W[0], W[-1]),
        )
        return record

    def _guard(self, count: int, recent: deque[float], u: float, start: float, rows: np.ndarray) -> None:
        """Stop on too many events in a period or on Zeno-like accumulation."""
        if count > self.max_events:
            raise self._too_many(u, start)
        recent.append(u)
        if len(recent) == self.zeno_events and recent[-1] - recent[0] <= self.zeno_window:
            raise self._zeno(recent[-1] - recent[0], u, start, rows)

    def _too_many(self, u: float, start: float) -> EventError:
        p = self.process
        return EventError(
            f"{p.name}: more than {self.max_events} events in period {self.period_index} "
            f"(at t = {start + u * p.period:.12g}); the active set keeps changing. Raise "
            "max_events, or use --integrator catch-up"
        )

    def _zeno(self, width: float, u: float, start: float, rows: np.ndarray) -> EventError:
        p = self.process
        return EventError(
            f"{p.name}: Zeno-like accumulation of events: {self.zeno_events} events within "
            f"{width * p.period:.3g} time units near t = "
            f"{start + u * p.period:.15g} (last constraints involved: "
            f"{p.describe_active(rows)}). The exact integrator cannot pass this point; use "
            "--integrator catch-up"
        )

    # -- an event: the next active set, order by order ----------------------------------------
    def _decide(
        self, u: float, w: np.ndarray, piece_index: int, forced: np.ndarray, time: float, held: ActiveSet
    ) -> ActiveSet:
        """The active set on (u, u + eps) from the velocity problems (module docstring). The
        candidates are the rows tight at w, those an event hit and those of ``held``, the last
        piece's set (empty at a period's start, whose warm set may be another state's): a row
        of it is at its limit, to that piece's roundoff, which on a stiff chain may be far
        above what a slack alone can tell; left out, it would be released without its velocity
        problem, hit again at once, and chatter."""
        poly = self.poly
        coef = self.pieces.coefficients(piece_index)
        phi = self.basis.values(u)
        c0 = (phi @ coef)[0]
        slack = poly.apply(w) - c0
        # the size of c's terms, not of their sum (`crawlsim.kernel.piece.tight_rows`)
        tol = poly.step_tolerance(poly.empty, (np.abs(phi) @ np.abs(coef))[0], w, np.zeros(0))
        tight = slack >= -tol.primal
        tight[forced] = True
        tight[held.index] = True
        if not tight.any():
            return poly.empty
        if self.projector.on_dependent == "warn" and not poly.licq_verified(np.flatnonzero(tight)):
            self.projector.record_licq(np.flatnonzero(tight), time)  # generic: a warning, once
        fixed = np.zeros(poly.m, dtype=bool)
        candidates = tight.copy()
        warm = np.zeros(poly.m, dtype=bool)
        warm[self.active.index] = True
        for order in range(1, DECISION_ORDERS + 1):
            ck = (self.basis.values(u, order) @ coef)[0]
            c = np.where(fixed | candidates, ck, np.inf)
            step = self._velocity(c, np.flatnonzero(fixed | (candidates & warm)), np.flatnonzero(fixed), time)
            opening = poly.apply(step.point) - ck
            positive = candidates & (step.multipliers > step.tolerance.dual)
            leaving = candidates & (opening < -step.tolerance.primal)
            fixed |= positive
            candidates &= ~(positive | leaving)
            if not candidates.any():
                break
        try:
            return poly.factor(np.flatnonzero(fixed))
        except Dependent:
            raise DegenerateModelError("", "", self.projector.degenerate_message(np.flatnonzero(fixed), time)) from None

    def _velocity(self, c: np.ndarray, warm: np.ndarray, fixed: np.ndarray, time: float) -> _Velocity:
        """argmin 1/2 |v|_M^2 over {B_fixed v = c_fixed, B_i v <= c_i (finite c_i)}: the
        kernel's updates from ``warm``, Clarabel's proposal when they do not settle."""
        from crawlsim.integrate.catchup import velocity  # crawlers: the compiled, certified step

        found = velocity(self.poly, c, warm, fixed)
        if found is not None:
            return _Velocity(found[0], found[1], Tolerance(found[2], found[3]))
        poly = self.poly
        zero = np.zeros(poly.n)
        step = poly.refine(zero, c, warm, fixed=fixed)
        if step is None:  # one row at a time, as long as it takes, before Clarabel's proposal
            step = poly.refine(zero, c, warm, single=True, iterations=4 * poly.m + 4, fixed=fixed)
        if step is not None:
            return _Velocity(step.point, step.multipliers, step.certificate.tolerance)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LicqWarning)
            proj = self.projector.project(zero, c, time=time, warm=warm, fixed=fixed)
        _, _, _, tol = poly.solve_on(proj.active, zero, c)
        return _Velocity(proj.point, proj.multipliers, tol)

    # -- a piece: w(u), Lambda(u), and the functions whose zeros are events ---------------------
    def _piece(self, active: ActiveSet, w0: np.ndarray, piece_index: int, u0: float) -> _Piece:
        poly = self.poly
        coef = self.pieces.coefficients(piece_index)
        nb = self.basis.size
        if not active.size:
            return _Piece(u0, active, w0.copy(), np.zeros((nb, poly.n)), np.zeros(0), np.zeros((nb, 0)))
        idx = active.index
        lam0 = active.solve(poly.apply(w0)[idx])
        Y = active.solve(coef[:, idx])
        pad = np.zeros(poly.m)
        pad[idx] = lam0
        base = w0 - poly.respond(pad)
        padY = np.zeros((nb, poly.m))
        padY[:, idx] = Y
        return _Piece(u0, active, base, poly.respond(padY), lam0, Y)

    def _next_event(self, piece: _Piece, piece_index: int, u0: float, u1: float) -> tuple[float, np.ndarray] | None:
        """(u, rows newly tight) of the first event in (u0, u1), or None if there is none."""
        poly, basis = self.poly, self.basis
        coef = self.pieces.coefficients(piece_index)
        idx = piece.active.index
        inactive = np.ones(poly.m, dtype=bool)
        inactive[idx] = False
        # gap(u) = phi(u) @ Gc, with the constant part in column 0
        Gc = poly.apply(piece.Wc) - coef
        Gc[0] += poly.apply(piece.base)
        gaps = Gc[:, inactive]
        c_size = float(np.max(np.sum(np.abs(coef), axis=0)))
        # half the smallest primal tolerance the certificate of a sample can have: a gap that
        # would fail the certificate is always an event first
        tol_gap = 0.5 * RTOL * poly.c_scale
        rows = np.flatnonzero(inactive)
        Z = gaps
        tol = np.full(gaps.shape[1], tol_gap)
        kinds = np.zeros(gaps.shape[1], dtype=bool)  # True: a release
        if idx.size:
            R = basis.derivative(piece.Y)  # -dLambda/du = phi(u) @ R
            scale = float(np.max(np.sum(np.abs(R), axis=0)))
            tol_rate = RTOL * max(scale, piece.active.inverse_norm * c_size * TWO_PI)
            Z = np.hstack([gaps, R])
            tol = np.concatenate([tol, np.full(R.shape[1], tol_rate)])
            rows = np.concatenate([rows, idx])
            kinds = np.concatenate([kinds, np.ones(R.shape[1], dtype=bool)])
        if not Z.shape[1]:
            return None
        crossing = self._crossings(Z, tol, u0, u1)
        first = float(np.min(crossing))
        if not first < u1:
            return None
        # rows within SIMULTANEOUS of it are hit too if at their limit there (`events.hit_together`)
        phi = basis.values(first)
        gap, size = (phi @ Z)[0], (np.abs(phi) @ np.abs(Z))[0]
        together = (crossing <= first + SIMULTANEOUS) & (gap >= -RTOL * np.maximum(poly.c_scale, size))
        hit = rows[(~kinds) & ((crossing == first) | together)]
        return first, np.sort(hit)

    # -- zeros -------------------------------------------------------------------------------
    def _crossings(self, Z: np.ndarray, tol: np.ndarray, u0: float, u1: float) -> np.ndarray:
        """For each column f = phi @ Z[:, r]: the first u in (u0, u1) where f crosses zero
        upwards and goes on to exceed tol[r] (inf when it does not before u1)."""
        b = self.basis
        out = np.full(Z.shape[1], np.inf)
        if b.size == 1:
            return out  # constants: nothing happens inside a piece
        if b.harmonics == 0:
            return self._linear(Z, tol, u0, u1)
        if b.harmonics == 1 and not b.linear:
            lin = np.zeros_like(Z[0])
            return self._harmonic(Z[0], lin, Z[1], Z[2], tol, u0, u1)
        if b.harmonics == 1 and b.linear:
            pure = Z[1] == 0.0  # no linear part in this function: closed form
            out[pure] = self._harmonic(Z[0, pure], Z[1, pure], Z[2, pure], Z[3, pure], tol[pure], u0, u1)
            rest = np.flatnonzero(~pure)
            if rest.size:
                out[rest] = self._sampled(Z[:, rest], tol[rest], u0, u1)
            return out
        return self._sampled(Z, tol, u0, u1)

    def _linear(self, Z: np.ndarray, tol: np.ndarray, u0: float, u1: float) -> np.ndarray:
        out = np.empty(Z.shape[1])
        kernel().events.linear_crossings(
            np.ascontiguousarray(Z[0], dtype=float),
            np.ascontiguousarray(Z[1], dtype=float),
            np.ascontiguousarray(tol, dtype=float),
            float(u0),
            float(u1),
            out,
        )
        return out

    def _harmonic(
        self, a: np.ndarray, lin: np.ndarray, alpha: np.ndarray, beta: np.ndarray, tol: np.ndarray, u0: float, u1: float
    ) -> np.ndarray:
        """f(u) = a + alpha cos 2 pi u + beta sin 2 pi u = a + rho cos(theta - phi)
        (`crawlsim.kernel.events.harmonic_crossings`, compiled)."""
        out = np.empty(np.shape(a))
        a_, alpha_, beta_, tol_ = (np.ascontiguousarray(v, dtype=float) for v in (a, alpha, beta, tol))
        kernel().events.harmonic_crossings(a_, alpha_, beta_, tol_, float(u0), float(u1), out)
        return out

    def _sampled(self, Z: np.ndarray, tol: np.ndarray, u0: float, u1: float) -> np.ndarray:
        """Certified sampling, compiled (`crawlsim.kernel.sampling`, the rule of its module
        docstring): samples every 1/(64 H) cycle, and only the cells where the curvature bound
        allows a crossing searched (Brent's bounded maximisation and brentq)."""
        b = self.basis
        out = np.empty(Z.shape[1])
        kernel().sampling.crossings(
            np.ascontiguousarray(Z, dtype=float),
            np.ascontiguousarray(tol, dtype=float),
            float(u0),
            float(u1),
            b.linear,
            b.harmonics,
            self.cells_per_cycle,
            out,
        )
        if np.isnan(out).any():  # pragma: no cover - Brent's method converges on a bracket
            raise EventError(
                f"{self.process.name}: no zero crossing found in a sampled cell of the cycles ({u0:.15g}, {u1:.15g})"
            )
        return out

    # -- certificate of the sampled trajectory ---------------------------------------------------
    def _dual_scale(self, piece: _Piece, piece_index: int) -> float:
        """The roundoff of the slips a piece adds: the kernel's dual tolerance for its active
        set, at the size of its offsets and state."""
        if not piece.active.size:
            return 0.0
        coef = self.pieces.coefficients(piece_index)
        c_size = float(np.max(np.sum(np.abs(coef), axis=0)))
        w_size = float(np.max(np.abs(piece.base)) + np.sum(np.max(np.abs(piece.Wc), axis=1)))
        lam_size = float(np.max(np.abs(piece.lam0)) + np.sum(np.max(np.abs(piece.Y), axis=1)))
        return float(self.poly.tolerance(piece.active, c_size, w_size, lam_size).dual)

    def _certify_piece(
        self,
        Wg: np.ndarray,
        LAMC: np.ndarray,
        piece: _Piece,
        phi: np.ndarray,
        piece_index: int,
        times: np.ndarray,
        carried: float,
    ) -> float:
        """Every sampled state is in K(t_j) and the slip integrals between samples are >= 0,
        to roundoff (the kernel's tolerance policy). A grid interval that began on earlier
        pieces carries their roundoff (``carried``); returns this piece's, for the next one."""
        poly = self.poly
        C = phi @ self.pieces.coefficients(piece_index)
        slack = poly.apply(Wg) - C
        lam = np.diff(LAMC, axis=0)
        # sizes of the numbers summed (phi @ coef cancels on short pieces with steep offsets,
        # and so do the slips' lam0 - phi @ Y)
        tol = poly.tolerance(
            piece.active,
            np.max(np.abs(phi) @ np.abs(self.pieces.coefficients(piece_index)), axis=1),
            np.max(np.abs(piece.base) + np.abs(phi) @ np.abs(piece.Wc), axis=1),
            np.maximum(
                np.max(np.abs(LAMC[1:]), axis=1),
                np.max(np.abs(piece.lam0) + np.abs(phi) @ np.abs(piece.Y), axis=1, initial=0.0),
            ),
        )
        primal = np.max(slack, axis=1)
        dual = -np.min(lam, axis=1, initial=0.0)
        # slip integrals are differences of cumulative slips, which carry their own roundoff,
        # and the first one also that of the pieces since the previous sample
        own = self._dual_scale(piece, piece_index)
        dual_tol = np.maximum(np.maximum(tol.dual, own), 4 * RTOL * np.max(np.abs(LAMC), axis=1)[1:])
        dual_tol[0] = max(dual_tol[0], carried)
        idx = piece.active.index
        comp = np.max(np.abs(slack[:, idx]), axis=1, initial=0.0)
        # a sample off K by a little is refined (`_refine`), a negative slip never
        excess = np.where(dual > dual_tol, np.inf, np.maximum(primal, comp) / tol.primal)
        if np.any(excess > 1.0):
            i = int(np.argmax(excess > 1.0))
            rows = np.flatnonzero((slack[i] > tol.primal[i]) | (lam[i] < -dual_tol[i]))
            raise _Uncertified(
                f"{self.process.name}: the exact trajectory failed its certificate at t = "
                f"{times[i]:.12g}: constraint violation {primal[i]:.3g}, negative slip "
                f"integral {dual[i]:.3g} (tolerance {float(tol.primal[i]):.3g} / "
                f"{float(dual_tol[i]):.3g}), complementarity {comp[i]:.3g}; rows "
                f"{self.process.describe_active(rows)}; active set "
                f"{self.process.describe_active(idx)}. An internal error of crawlsim: please "
                "report it with the gait file and the command",
                i,
                float(excess[i]),
            )
        return own

    def _refine(
        self, piece_index: int, u: float, W: np.ndarray, LAMC: np.ndarray, j: int, time: float, ledger: Any
    ) -> tuple[np.ndarray, np.ndarray]:
        """A sample whose certificate failed within `REFINE_LIMIT` of its tolerance: the closed
        form's roundoff there is replaced by the certified projection of its state onto K(u)
        (a jump of roundoff's size, booked like a jump of c), from which the next piece starts.
        Returns the state and cumulative slips there."""
        c = (self.basis.values(u) @ self.pieces.coefficients(piece_index))[0]
        proj = self.projector.project(W[j], c, time=time, warm=self.active)
        self._certify_jump(W[j], c, proj, time)
        if ledger is not None:
            ledger.jump(piece_index, u, W[j], proj.point, proj.multipliers)
        self.active = proj.active
        W[j], LAMC[j] = proj.point, LAMC[j] + proj.multipliers
        return proj.point, LAMC[j].copy()

    def _certify_jump(self, w: np.ndarray, c: np.ndarray, proj: Projection, time: float) -> None:
        """The state after a jump of c is written to the grid as it is: it must be the certified
        projection of the state before it onto K(t+) (feasible, slips >= 0, complementary)."""
        poly = self.poly
        slack = poly.apply(proj.point) - c
        tol = poly.step_tolerance(proj.active, c, w, proj.multipliers)
        cert = poly.certify(slack, proj.multipliers, proj.active, tol)
        if not cert.ok:
            raise CertificateError(
                f"{self.process.name}: the projection at the jump of c at "
                f"t = {time:.12g} failed its certificate: {cert}; rows "
                f"{self.process.describe_active(np.flatnonzero(slack > tol.primal))}"
                f"; active set {self.process.describe_active(proj.active.index)}"
            )

    def _verify(self, W: np.ndarray, start: float) -> None:
        """``check_every_step``: Clarabel confirms every sampled state is its own projection."""
        p = self.process
        for j in range(len(W)):
            proj = self.projector.project(W[j], p.offsets[j], time=start + p.times[j], verify=True)
            moved = float(np.max(np.abs(proj.point - W[j])))
            tol = self.poly.step_tolerance(proj.active, p.offsets[j], W[j], proj.multipliers)
            if moved > 100 * tol.primal:
                raise CertificateError(
                    f"{p.name}: Clarabel moves the exact state at t = {start + p.times[j]:.12g} by {moved:.3g}"
                )


class _Uncertified(CertificateError):
    """A grid sample's certificate failed: the ``index`` of the sample, ``excess`` the largest
    ratio of a measure to its tolerance there."""

    def __init__(self, message: str, index: int, excess: float) -> None:
        super().__init__(message)
        self.index, self.excess = index, excess


@dataclass(frozen=True, eq=False)
class _Velocity:
    """A velocity problem solved by the projector: point, multipliers, tolerance."""

    point: np.ndarray
    multipliers: np.ndarray
    tolerance: Tolerance
