"""Catch-up stepping of a tabulated sweeping process, one period at a time (docs/model.md §3).

    w_{j+1} = argmin { 1/2 |w - w_j|_M^2 : B w <= c(t_{j+1}) },   x_{j+1} = x_j + S lambda_{j+1}.

Every step is solved and certified by the KKT kernel (`crawlsim.projection.kkt`). While the active set A
does not change, runs of steps telescope (`kkt.Polyhedron.run`): one factorisation of G_A and
one multi-right-hand-side solve for the whole run, certified step by step. The first step whose
certificate fails is redone as a full projection (`crawlsim.projection.adapter.ExactProjector`): the
kernel's cheap updates from A, and Clarabel only when they do not settle.

``check_every_step=True`` runs Clarabel at every step instead, so that a user can verify that the
fast paths change nothing.

A crawler's steps run in the compiled kernel (`crawlsim.kernel`): the same step, certificate and
updates, one step at a time in machine code; a step whose updates do not settle is handed to the
projector as above, and a certificate that fails with no update left is a `CertificateError`.
``kernel=False`` keeps a crawler on the telescoped runs of `crawlsim.projection.kkt` (the path of generic
processes), for comparison.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

import numpy as np

from crawlsim.errors import CertificateError
from crawlsim.model.process import SweepingProcess
from crawlsim.projection.adapter import ExactProjector
from crawlsim.projection.kkt import Dependent
from crawlsim.projection.polyhedron import ActiveSet

_FIRST_BLOCK = 8


class Registered(NamedTuple):
    """An integrator of `STEPPERS`: where its class is (``module:name``, imported lazily), the
    order of its error in the step (a step h = T / steps_per_period; 0: exact, the error is
    roundoff), and whether it is exact."""

    target: str
    order: int
    exact: bool


#: Integrators by name. Each is a `PeriodStepper` built as ``cls(process, **options)``; tests are
#: parametrized over this registry.
STEPPERS: dict[str, Registered] = {
    "catch-up": Registered("crawlsim.integrate.stepping:CatchUpStepper", order=1, exact=False),
    "exact": Registered("crawlsim.integrate.exact:EventStepper", order=0, exact=True),
}


def stepper_class(integrator: str) -> type[PeriodStepper]:
    """The class registered under ``integrator``."""
    try:
        module, name = STEPPERS[integrator].target.split(":")
    except KeyError:
        raise ValueError(f"unknown integrator {integrator!r}; expected one of {', '.join(STEPPERS)}") from None
    cls: type[PeriodStepper] = getattr(importlib.import_module(module), name)
    return cls


def make_stepper(process: SweepingProcess, integrator: str = "catch-up", **options: Any) -> PeriodStepper:
    """Build the stepper registered under ``integrator``."""
    return stepper_class(integrator)(process, **options)


#: Why an event-driven integrator decided its active set anew (`Transition.cause`): the start
#: of the period or a piece of c(t) (a fixed time), a multiplier reaching zero (a release:
#: its time depends on c only), a gap reaching zero (a hit: its time moves with the start),
#: or the projection at a jump of c.
TransitionCause = Literal["edge", "release", "hit", "jump"]


class Transition(NamedTuple):
    """One decision of the active set by an event-driven integrator (`PeriodRecord`)."""

    u: float  # the cycle, in [0, 1]
    piece: int  # the piece of c(t) after it
    active: Any  # the set A on the following interval (`crawlsim.projection.kkt.ActiveSet`; may be empty)
    cause: TransitionCause
    hit: np.ndarray  # the rows whose gap reached zero (cause "hit"; empty otherwise)


@dataclass(frozen=True, eq=False)
class PeriodRecord:
    """One period of catch-up stepping on the grid of ``process.times`` shifted by ``start``."""

    index: int  # period q: t in [start, start + T]
    start: float
    w: np.ndarray  # (G+1, n), w at the grid times, both ends included
    multipliers: np.ndarray  # (G, m), lambda of each step
    x: np.ndarray | None  # (G+1, N) block positions (crawlers)
    clarabel_calls: int
    # The exact trajectory at event times, (t, w, x), from event-driven integrators
    # (`crawlsim.integrate.exact.EventTrajectory`); None for catch-up.
    events: tuple[Any, ...] | None = None
    # The active sets the period visited, in order (consecutive repeats and empty sets left
    # out): the period map is affine near this start, with Jacobian the product of their
    # projectors I - R_A B_A (`crawlsim.integrate.limit`).
    visited: Sequence[ActiveSet] = ()
    # The period's energy ledger integrated exactly on the event-driven integrator's pieces
    # (`crawlsim.analysis.energy.PeriodEnergy`), or a callable that forms it when `energy` is
    # first read (most periods' ledgers are never read); None for catch-up, whose ledger
    # follows from the grid.
    energy_of: Any = None
    # Event-driven integrators: every decision of the active set, in order (`Transition`).
    # `crawlsim.integrate.limit` adds the saltation of the events whose time depends on the start (the
    # hits) to the Jacobian.
    transitions: Sequence[Transition] = ()

    @property
    def energy(self) -> Any:
        """The period's `crawlsim.analysis.energy.PeriodEnergy` (event-driven integrators), or
        None."""
        source = self.energy_of
        if callable(source):
            source = source()
            object.__setattr__(self, "energy_of", source)
        return source

    @property
    def slips(self) -> np.ndarray | None:
        """Block increments of each step, ``dx = S lambda`` (G, N); None for generic processes.
        Formed once and kept read-only (v0's error, the limit period and its slip signs each
        read them)."""
        if self.x is None:
            return None
        dx: np.ndarray | None = self.__dict__.get("_slips")
        if dx is None:
            dx = np.diff(self.x, axis=0)
            dx.setflags(write=False)
            object.__setattr__(self, "_slips", dx)
        return dx


def positions_of(process: SweepingProcess, w: np.ndarray, barycentre: float) -> np.ndarray:
    """Block positions of a crawler in the state ``w`` with the given barycentre: the shape is
    z = D x = -K^{-1} w (docs/model.md §2), so x_i = x_1 + z_1 + ... + z_{i-1}."""
    assert process.crawler is not None
    return process.crawler.positions(w, barycentre)


class PeriodStepper:
    """The contract of every integrator of `STEPPERS`, in the manner of scipy's ``OdeSolver``:
    the base class owns the set-up (the process, its polyhedron, the certified projector, the
    state w and positions x, the warm active set) and the public `step_period`, which runs the
    subclass's `_step_impl` for the period ``period_index`` and counts it. It also restarts a
    period from a given state (`reset`) and records the active sets a period visits
    (`PeriodRecord.visited`)."""

    #: Whether a period must start in K(0) (the exact integrator's closed forms need it).
    needs_admissible_start = False

    def __init__(
        self, process: SweepingProcess, *, check_every_step: bool = False, persistent_solver: bool = True
    ) -> None:
        self.process = process
        self.polyhedron = process.polyhedron
        self.check_every_step = check_every_step
        # Crawlers: non-unique slips are a DegenerateModelError (docs/model.md §3); generic
        # processes keep their unique point with a LicqWarning.
        self.projector = ExactProjector(
            process.polyhedron,
            describe_active=process.describe_active,
            persistent=persistent_solver,
            on_dependent="raise" if process.crawler is not None else "warn",
        )
        self.w = np.array(process.initial, dtype=float)
        self.x = None if process.crawler is None else np.array(process.crawler.initial_positions, dtype=float)
        self.active = self.polyhedron.empty
        self.period_index = 0
        self._visited: list[ActiveSet] = []

    def step_period(self) -> PeriodRecord:
        """Advance by one period from the current state and return its record."""
        record = self._step_impl()
        self.period_index += 1
        return record

    def _step_impl(self) -> PeriodRecord:
        """One period from ``self.w`` (``self.x``), the period ``self.period_index``: the
        record, with ``self.w``, ``self.x`` and ``self.active`` left at its end."""
        raise NotImplementedError

    def reset(self, w: np.ndarray, x: np.ndarray | None = None) -> None:
        """Start the next period from the state ``w`` (positions ``x``; by default the
        positions of the shape of ``w``, `positions_of`, at the current barycentre), keeping
        the active set as a warm start. The exact integrator needs ``w`` in K(0)
        (`crawlsim.integrate.limit` projects it first)."""
        self.w = np.array(w, dtype=float)
        if self.x is not None:
            self.x = (
                positions_of(self.process, self.w, float(np.mean(self.x))) if x is None else np.array(x, dtype=float)
            )

    def _visit(self, active: ActiveSet) -> None:
        if active.size and (not self._visited or self._visited[-1] is not active):
            self._visited.append(active)


class CatchUpStepper(PeriodStepper):
    """Steps a `SweepingProcess` period by period from its initial state."""

    def __init__(
        self,
        process: SweepingProcess,
        *,
        check_every_step: bool = False,
        persistent_solver: bool = True,
        kernel: bool = True,
    ) -> None:
        super().__init__(process, check_every_step=check_every_step, persistent_solver=persistent_solver)
        self._kernel = None
        self._lazy_visited: Sequence[ActiveSet] | None = None  # the kernel's record (`VisitedSets`)
        if kernel and not check_every_step and process.crawler is not None:
            from crawlsim.integrate.catchup import ChainKernel

            self._kernel = ChainKernel(self.polyhedron)
            self._offsets = np.ascontiguousarray(process.offsets, dtype=float)

    def _step_impl(self) -> PeriodRecord:
        p = self.process
        G, n, m = p.steps, len(self.w), p.polyhedron.m
        start = self.period_index * p.period
        W = np.empty((G + 1, n))
        LAM = np.zeros((G, m))
        W[0] = self.w
        calls0 = self.projector.clarabel_calls
        self._visited = []
        self._lazy_visited = None
        j, block = 0, _FIRST_BLOCK
        if self._kernel is not None:
            self._kernel_period(W, LAM, start)
            j = G
        while j < G:
            if self.check_every_step:
                self._full_step(j, W, LAM, start, warm=False)
                j += 1
                continue
            length = min(G - j, block)
            run = self.polyhedron.run(self.active, W[j], p.offsets[j + 1 : j + 1 + length])
            k = run.accepted
            if k:
                self._visit(self.active)
            W[j + 1 : j + 1 + k] = run.w[:k]
            LAM[j : j + k] = run.multipliers[:k]
            j += k
            if k < length:
                if run.next_set is not None:
                    try:
                        self.active = self.polyhedron.factor(run.next_set)
                    except Dependent:
                        pass  # the full step starts from the old set, Clarabel decides
                self._full_step(j, W, LAM, start, warm=True)
                j += 1
                block = max(_FIRST_BLOCK, 2 * k)
            else:
                block *= 2
        X = None
        if self.x is not None:
            X = np.empty((G + 1, len(self.x)))
            if self._kernel is not None:
                from crawlsim.kernel.jit import kernel

                kernel().chain.positions(LAM, self.x, X)
            else:
                X[0] = self.x
                np.cumsum(p.slips(LAM), axis=0, out=X[1:])
                X[1:] += self.x
            self.x = X[-1].copy()
        self.w = W[-1].copy()
        record = PeriodRecord(
            self.period_index,
            start,
            W,
            LAM,
            X,
            self.projector.clarabel_calls - calls0,
            visited=(tuple(self._visited) if self._lazy_visited is None else self._lazy_visited),
        )
        return record

    def _kernel_period(self, W: np.ndarray, LAM: np.ndarray, start: float) -> None:
        """The period's steps in the compiled kernel; the steps it hands over go to the
        projector (`_full_step`), warm from the kernel's current set."""
        from crawlsim.integrate import catchup
        from crawlsim.kernel import chain

        kernel, p = self._kernel, self.process
        assert kernel is not None
        S = np.zeros((len(LAM), p.blocks), dtype=np.int8)
        kernel.load(self.active)
        j = 0
        while True:
            status, j = kernel.run(self._offsets, W, LAM, S, j)
            if status == chain.DONE:
                break
            if status == chain.FAILED:
                raise CertificateError(kernel.failure(p.name, start + p.times[j + 1], p.describe_active))
            self.active = kernel.active(self.active)
            self._full_step(j, W, LAM, start, warm=True)
            S[j] = catchup.signs_of(self.active, p.blocks)
            kernel.load(self.active)
            j += 1
        self.active = kernel.active(self.active)
        self._lazy_visited = catchup.VisitedSets(self.polyhedron, S)

    def _full_step(self, j: int, W: np.ndarray, LAM: np.ndarray, start: float, *, warm: bool) -> None:
        p = self.process
        proj = self.projector.project(
            W[j], p.offsets[j + 1], time=start + p.times[j + 1], warm=self.active if warm else None, verify=not warm
        )
        W[j + 1] = proj.point
        LAM[j] = proj.multipliers
        self.active = proj.active
        self._visit(proj.active)
