"""The exact integrator's compiled path (`crawlsim.kernel.eventloop`) seen from Python: the driver
that hands a crawler's period to the compiled event loop and turns its arrays into a
`PeriodRecord` whose transitions, visited active sets and energy ledger are formed only when they
are read (`crawlsim.integrate.limit`, `crawlsim.analysis.energy`). The stepper that owns it, and
the Python loop that takes the periods the compiled one hands back, are `crawlsim.integrate.exact`.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple, cast, overload

import numpy as np

from crawlsim.errors import EventError
from crawlsim.integrate.ground import no_ground
from crawlsim.integrate.ledger import ExactLedger, PeriodEnergy
from crawlsim.integrate.stepping import PeriodRecord, Transition, TransitionCause
from crawlsim.kernel.jit import kernel
from crawlsim.projection.kkt import ActiveSet, ChainPolyhedron, Polyhedron

if TYPE_CHECKING:
    from crawlsim.integrate.exact import EventStepper


class EventTrajectory(NamedTuple):
    """The exact trajectory at event times (absolute), after each event is processed.

    Between two consecutive entries the active set is fixed and w follows the closed form of the
    module docstring. Period starts and breakpoints are included.
    """

    t: np.ndarray  # (E,)
    w: np.ndarray  # (E, n)
    x: np.ndarray | None  # (E, N) block positions (crawlers)


class _Transitions(Sequence[Transition]):
    """The period's `Transition` records from the compiled loop's arrays, their active sets
    factored by `crawlsim.projection.kkt` only when they are read (`crawlsim.integrate.limit`,
    sensitivities)."""

    def __init__(
        self, poly: Polyhedron, u: np.ndarray, piece: np.ndarray, signs: np.ndarray, cause: np.ndarray, hit: np.ndarray
    ) -> None:
        self._poly = poly
        self._arrays = (u, piece, signs, cause, hit)
        self._built: list[Transition] | None = None

    def _list(self) -> list[Transition]:
        if self._built is None:
            from crawlsim.integrate.catchup import rows_of
            from crawlsim.kernel.eventloop import CAUSES

            u, piece, signs, cause, hit = self._arrays
            self._built = [
                Transition(
                    float(u[i]),
                    int(piece[i]),
                    self._poly.factor(rows_of(signs[i])),
                    cast(TransitionCause, CAUSES[int(cause[i])]),
                    np.flatnonzero(hit[i]),
                )
                for i in range(len(u))
            ]
        return self._built

    def __len__(self) -> int:
        return len(self._arrays[0])

    @property
    def arrays(self) -> tuple[np.ndarray, ...]:
        """(u, piece, signs, cause, hit) as the compiled loop wrote them, with no set factored
        (the tangent walk of `crawlsim.analysis.sensitivity_walk` reads these)."""
        return self._arrays

    @overload
    def __getitem__(self, i: int) -> Transition: ...

    @overload
    def __getitem__(self, i: slice) -> list[Transition]: ...

    def __getitem__(self, i: int | slice) -> Transition | list[Transition]:
        return self._list()[i]


class _Visited(Sequence[ActiveSet]):
    """`PeriodRecord.visited` of a compiled period: `crawlsim.integrate.catchup.VisitedSets` of
    its transitions' sets, formed when first read (`crawlsim.integrate.limit`)."""

    def __init__(self, poly: Polyhedron, signs: np.ndarray) -> None:
        self._args: tuple[Polyhedron, np.ndarray] | None = (poly, signs)
        self._sets: Sequence[ActiveSet] = ()

    def _list(self) -> Sequence[ActiveSet]:
        if self._args is not None:
            from crawlsim.integrate.catchup import VisitedSets

            self._sets, self._args = VisitedSets(*self._args), None
        return self._sets

    def __len__(self) -> int:
        return len(self._list())

    @overload
    def __getitem__(self, i: int) -> ActiveSet: ...

    @overload
    def __getitem__(self, i: slice) -> Sequence[ActiveSet]: ...

    def __getitem__(self, i: int | slice) -> ActiveSet | Sequence[ActiveSet]:
        return self._list()[i]


class _CompiledLoop:
    """The arrays of one crawler's compiled event loop (`crawlsim.kernel.eventloop.period`): the
    offsets' coefficients per piece, the jump targets and the energy terms, built once; the
    output arrays, sized to the events of the last period."""

    def __init__(self, stepper: EventStepper) -> None:
        from crawlsim.integrate import catchup
        from crawlsim.kernel import eventloop

        # the kernel's modules, imported here (not with this module: `crawlsim validate` loads
        # no kernel) and kept, since a period at N = 4 costs a few import look-ups
        self._catchup, self._kernel = catchup, eventloop
        pieces, basis = stepper.pieces, stepper.basis
        P, n, m, nb = pieces.pieces, stepper.poly.n, stepper.poly.m, basis.size
        poly = stepper.poly
        assert isinstance(poly, ChainPolyhedron)
        self.k = np.ascontiguousarray(poly.stiffness, dtype=np.float64)
        self.c_scale = float(poly.c_scale)
        self.coef = np.ascontiguousarray([pieces.coefficients(q) for q in range(P)], dtype=float)
        self.target = np.zeros((P + 1, m))
        for edge in map(int, np.flatnonzero(stepper._jump)):
            self.target[edge] = pieces.evaluate(pieces.edges[edge] if edge < P else 0.0, piece=edge % P)[0]
        self.terms = np.zeros((4, P, nb, n))
        self.rows = np.zeros((2, P, nb, m))
        if stepper._ledger is not None:
            for q in range(P):
                _, KLc, dLc, Mc, lc = stepper._ledger.terms(q)
                self.terms[0, q], self.terms[1, q] = KLc, dLc
                self.rows[0, q], self.rows[1, q] = Mc, lc
        self.phi = np.ascontiguousarray(basis.values(stepper._grid))
        self.capacity = 64
        self.handoffs = 0
        self._scratch: dict[str, Any] = {}
        self._spare: dict[str, np.ndarray] = {}
        self._lamc = np.empty((0, 0))
        self._final: tuple[bytes, ActiveSet] = (b"", stepper.poly.empty)
        self._final_signs = np.zeros(stepper.process.blocks, dtype=np.int8)
        self._no_ground = no_ground(stepper.process.blocks)

    @staticmethod
    def of(stepper: EventStepper) -> _CompiledLoop | None:
        """The loop for crawlers (every basis of offsets); None for a generic process, whose
        only loop is the Python one."""
        if not isinstance(stepper.poly, ChainPolyhedron):
            return None
        return _CompiledLoop(stepper)

    def period(self, s: EventStepper) -> PeriodRecord | None:
        """One period of ``s`` in the compiled loop, or None where it hands the period over."""
        loop = self._kernel

        while True:
            out = self._run(s)
            status = out["status"]
            if status != loop.OVERFLOW:
                break
            self.capacity *= 2
        if status == loop.DONE:
            return self._record(s, out)
        start = s.period_index * s.process.period
        report = out["report"]
        u = float(report[loop.R_U])
        if status == loop.TOO_MANY:
            raise s._too_many(u, start)
        if status == loop.ZENO:
            e = int(out["counts"][loop.C_EVENTS])
            width = float(out["ev_t"][e - 1] - out["ev_t"][e - s.zeno_events])
            rows = np.flatnonzero(out["tr_hit"][out["counts"][loop.C_TRANSITIONS]])
            raise s._zeno(width, u, start, rows)
        if s.ground is not None:  # the Python loop does not walk terrain
            s.ground.adopt(out["ground"], start, s.process.period)  # uniqueness there (§8)?
            why = (
                "a piece it could not certify"
                if status == loop.FAILED_PIECE
                else loop.HANDOFF_REASONS[int(report[loop.R_REASON])]
            )
            raise EventError(
                f"{s.process.name}: the exact integrator cannot pass t = {start + u * s.process.period:.12g} "
                f"on this terrain ({why}: a step its compiled loop hands over); use --integrator catch-up"
            )
        return None  # HANDOFF, or a failed sample: the Python loop refines it, or says why not

    def _run(self, s: EventStepper) -> dict[str, Any]:
        catchup = self._catchup
        p = s.process
        N, n, m = p.blocks, s.poly.n, s.poly.m
        nb, P, G = s.basis.size, s.pieces.pieces, p.steps
        E = min(self.capacity, s.max_events + 1)
        out = self._scratch
        # work arrays kept from period to period while they hold E events and are not more
        # than twice that (a run's peak memory); made with room for a quarter more, so that a
        # period with a few more events than the last does not make them again
        if not E <= out.get("capacity", 0) <= 2 * E:
            out.clear()
            E = min(E + E // 4, s.max_events + 1)
        else:
            E = out["capacity"]
        T2 = E + P + 2
        J = P + 1 + (E if s.ground is not None else 0)  # jumps: of c, and the slides on terrain
        if "ev_t" not in out:
            out.update(
                {
                    "capacity": E,
                    "ev_t": np.empty(E),
                    "ev_w": np.empty((E, n)),
                    "ev_dx": np.empty((E, N)),
                    "tr_u": np.empty(T2),
                    "tr_piece": np.empty(T2, dtype=np.int64),
                    "tr_signs": np.empty((T2, N), dtype=np.int8),
                    "tr_cause": np.empty(T2, dtype=np.int8),
                    "tr_hit": np.zeros((T2, m), dtype=np.bool_),
                    "bounds": np.empty((E, 2)),
                    "products": np.empty((E, 3, nb, nb)),
                    "jump_piece": np.empty(J, dtype=np.int64),
                    "jump_u": np.empty(J),
                    "jump_w": np.empty((J, 2, n)),
                    "jump_lam": np.empty((J, m)),
                    "counts": np.zeros(4, dtype=np.int64),
                    "report": np.zeros(8),
                }
            )
        out["LAMC"] = self._lamc  # the cumulative slips on the grid: scratch of the loop
        if out["LAMC"].shape != (G + 1, m):
            out["LAMC"] = self._lamc = np.empty((G + 1, m))
        for name in ("W", "MU", "X"):  # the last record's, which it may still hold
            out.pop(name, None)
        out["W"] = self._array("W", (G + 1, n))
        out["MU"] = self._array("MU", (G, m))
        out["X"] = self._array("X", (G + 1, N)) if s.x is not None else np.empty((0, 0))
        x0 = np.ascontiguousarray(s.x, dtype=float) if s.x is not None else np.empty(0)
        # the set the last period ended on, when the stepper still has it (`_record`)
        out["signs"] = self._final_signs.copy() if s.active is self._final[1] else catchup.signs_of(s.active, N)
        out["ground"] = self._no_ground if s.ground is None else s.ground.record(E, J)
        out["status"] = kernel().eventloop.period(
            self.k,
            self.c_scale,
            s.basis.linear,
            s.basis.harmonics,
            self.coef,
            s.pieces.edges,
            s._jump,
            self.target,
            s._grid,
            self.phi,
            np.ascontiguousarray(s.w, dtype=float),
            out["signs"],
            s.max_events,
            s.zeno_events,
            s.zeno_window,
            0 if s._ledger is None else s._ledger.products,
            self.terms[0],
            self.terms[1],
            self.rows[0],
            self.rows[1],
            out["W"],
            out["LAMC"],
            out["MU"],
            x0,
            out["X"],
            out["ev_t"],
            out["ev_w"],
            out["ev_dx"],
            out["tr_u"],
            out["tr_piece"],
            out["tr_signs"],
            out["tr_cause"],
            out["tr_hit"],
            out["bounds"],
            out["products"],
            out["jump_piece"],
            out["jump_u"],
            out["jump_w"],
            out["jump_lam"],
            out["counts"],
            out["report"],
            s.cells_per_cycle,
            out["ground"],
        )
        return out

    def _array(self, name: str, shape: tuple[int, int]) -> np.ndarray:
        """A new array for a period's record, or the one of an earlier record when nothing
        refers to it any more (its reference count: this method's own two references), so
        that a period writes its W, MU and X into memory already mapped rather than faulting
        in fresh pages (32 MB a period at N = 1024)."""
        a = self._spare.pop(name, None)
        if a is None or a.shape != shape or sys.getrefcount(a) > 2:
            a = np.empty(shape)
        self._spare[name] = a
        return a

    def _record(self, s: EventStepper, out: dict[str, Any]) -> PeriodRecord:
        catchup = self._catchup
        T = s.process.period
        start = s.period_index * T
        e, t, q, nj = out["counts"].tolist()
        self.capacity = max(64, e + e // 4 + 16)  # room for a few more events next period
        W = out["W"]
        key = out["signs"].tobytes()
        if key != self._final[0]:  # a periodic regime ends every period on the same set
            self._final = key, s.poly.factor(catchup.rows_of(out["signs"]))
            self._final_signs = out["signs"].copy()
        s.active = self._final[1]
        if s.check_every_step:
            s._verify(W, start)
        X = x_events = None
        MU = out["MU"]  # the record's slips and positions, formed by the loop's samples
        if s.x is not None:
            X = out["X"]
            x_events = s.x + out["ev_dx"][:e]
            s.x = X[-1].copy()
        s.w = W[-1].copy()
        ground = None
        if s.ground is not None:
            ground = s.ground.adopt(out["ground"], start, T)
        energy = None
        if s._ledger is not None:
            energy = _Energy(
                s._ledger,
                out["bounds"][:q].copy(),
                out["products"][:q, : s._ledger.products].copy(),
                [
                    (
                        int(out["jump_piece"][i]),
                        float(out["jump_u"][i]),
                        out["jump_w"][i, 0].copy(),
                        out["jump_w"][i, 1].copy(),
                        out["jump_lam"][i].copy(),
                        None if s.ground is None else out["ground"].fac[i].copy(),
                        s.ground is not None and bool(out["ground"].pinned[i]),
                    )
                    for i in range(nj)
                ],
                W[0],
                W[-1],
            )
        signs = out["tr_signs"][:t].copy()
        transitions = _Transitions(
            s.poly,
            out["tr_u"][:t].copy(),
            out["tr_piece"][:t].copy(),
            signs,
            out["tr_cause"][:t].copy(),
            out["tr_hit"][:t].copy(),
        )
        events = EventTrajectory(start + out["ev_t"][:e] * T, out["ev_w"][:e].copy(), x_events)
        record = PeriodRecord(
            s.period_index,
            start,
            W,
            MU,
            X,
            0,
            events=events,
            visited=_Visited(s.poly, signs),
            transitions=transitions,
            energy_of=energy,
            ground=ground,
        )
        return record


@dataclass(frozen=True, eq=False)
class _Energy:
    """A period's energy ledger from the compiled loop's pieces and jumps, formed by the
    stepper's `ExactLedger` when it is first read (`PeriodRecord.energy`)."""

    ledger: ExactLedger
    bounds: np.ndarray
    products: np.ndarray
    jumps: list[tuple[int, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, bool]]
    w_start: np.ndarray
    w_end: np.ndarray

    def __call__(self) -> PeriodEnergy:
        ledger = self.ledger
        ledger.start()
        ledger.add_pieces(self.bounds, self.products)
        for jump in self.jumps:
            ledger.jump(*jump)
        return ledger.finish(self.w_start, self.w_end)
