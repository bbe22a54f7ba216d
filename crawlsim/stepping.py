"""Catch-up stepping of a tabulated sweeping process, one period at a time (MODEL.md §3).

    w_{j+1} = argmin { 1/2 |w - w_j|_M^2 : B w <= c(t_{j+1}) },   x_{j+1} = x_j + S lambda_{j+1}.

Every step is an exact, certified projection (`crawlsim.projection`). Two fast paths are used,
both with the same certificate as a full projection:

* **elastic steps** (active set empty): the trial state is already admissible;
* **reuse of the previous step's active set** A. With A fixed, ``B_A w_j = c_A(t_j)`` after
  every step, so the steps telescope:

      w_{j+k} = w_j - R_A (B_A w_j - c_A(t_{j+k})),
      lambda_{j+1} + ... + lambda_{j+k} = G_A^{-1} (B_A w_j - c_A(t_{j+k})).

  A block of steps is therefore computed with one matrix product and certified step by step
  (primal feasibility, multiplier signs, complementarity). The first step whose certificate
  fails is redone as a full projection, with Clarabel proposing the new active set.

``check_every_step=True`` runs Clarabel at every step instead, so that a user can verify that the
fast paths change nothing.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

import numpy as np

from .model import SweepingProcess
from .projection import ExactProjector

_FIRST_BLOCK = 8

#: Integrators by name, resolved lazily. Each is a class built as ``cls(process, **options)``
#: with a ``step_period() -> PeriodRecord`` method and a ``projector`` attribute; tests are
#: parametrized over this registry.
STEPPERS = {
    "catch-up": "crawlsim.stepping:CatchUpStepper",
    "exact": "crawlsim.exact:EventStepper",
}


def make_stepper(process, integrator: str = "catch-up", **options):
    """Build the stepper registered under ``integrator``."""
    try:
        module, name = STEPPERS[integrator].split(":")
    except KeyError:
        raise ValueError(f"unknown integrator {integrator!r}; expected one of "
                         f"{', '.join(STEPPERS)}") from None
    return getattr(importlib.import_module(module), name)(process, **options)


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
    # (`crawlsim.exact.EventTrajectory`); None for catch-up.
    events: tuple | None = None

    @property
    def slips(self) -> np.ndarray | None:
        """Block increments of each step, ``dx = S lambda`` (G, N); None for generic processes."""
        return None if self.x is None else np.diff(self.x, axis=0)


class CatchUpStepper:
    """Steps a `SweepingProcess` period by period from its initial state."""

    def __init__(self, process: SweepingProcess, *, check_every_step: bool = False,
                 persistent_solver: bool = True):
        self.process = process
        self.check_every_step = check_every_step
        self.projector = ExactProjector(
            process.normals, process.metric, process.scale,
            describe_active=process.describe_active, persistent=persistent_solver,
            on_dependent="raise" if process.is_crawler else "warn")
        self.w = np.array(process.initial, dtype=float)
        self.x = None if process.initial_positions is None else np.array(
            process.initial_positions, dtype=float)
        self.active = self.projector.empty
        self.period_index = 0

    def step_period(self) -> PeriodRecord:
        """Advance by one period and return its record."""
        p = self.process
        G, n, m = p.steps, len(self.w), p.normals.shape[0]
        start = self.period_index * p.period
        W = np.empty((G + 1, n))
        LAM = np.zeros((G, m))
        W[0] = self.w
        calls0 = self.projector.clarabel_calls
        j, block = 0, _FIRST_BLOCK
        while j < G:
            if self.check_every_step:
                self._full_step(j, W, LAM, start)
                j += 1
                continue
            accepted = self._reuse_block(j, min(G, j + block), W, LAM)
            j += accepted
            if j < G and accepted < block:
                self._full_step(j, W, LAM, start)
                j += 1
            block = 2 * block if accepted == block else max(_FIRST_BLOCK, 2 * accepted)
        X = None
        if self.x is not None:
            assert p.slip_map is not None
            X = np.empty((G + 1, len(self.x)))
            X[0] = self.x
            np.cumsum(LAM @ p.slip_map.T, axis=0, out=X[1:])
            X[1:] += self.x
            self.x = X[-1].copy()
        self.w = W[-1].copy()
        record = PeriodRecord(self.period_index, start, W, LAM, X,
                              self.projector.clarabel_calls - calls0)
        self.period_index += 1
        return record

    def _reuse_block(self, j, end, W, LAM) -> int:
        """Try steps j+1..end on the current active set; write and count the certified prefix."""
        p, A, tol = self.process, self.active, self.projector.tol
        w = W[j]
        c = p.offsets[j + 1:end + 1]
        if A.size == 0:
            # strictly inside: a row tight to roundoff goes to the full projection, which
            # checks LICQ there
            ok = np.all(p.normals @ w < c - tol.primal, axis=1)
            k = _prefix(ok)
            W[j + 1:j + 1 + k] = w
            return k
        residual = (A.normals @ w) - c[:, A.index]  # (k, a): B_A w_j - c_A(t_{j+i})
        cumulative = residual @ A.gram_inv.T  # sum of the multipliers up to each step
        Z = w - residual @ A.response.T
        lam = np.diff(cumulative, axis=0, prepend=np.zeros((1, A.size)))
        slack = Z @ p.normals.T - c
        inactive = np.ones(slack.shape[1], dtype=bool)
        inactive[A.index] = False
        # Rows outside A must be strictly feasible: one tight to roundoff is a degenerate
        # contact, left to the full projection and its LICQ check.
        ok = ((np.max(slack[:, inactive], axis=1, initial=-np.inf) < -tol.primal)
              & (np.min(lam, axis=1) >= -tol.dual)
              & (np.max(np.abs(slack[:, A.index]), axis=1) <= tol.primal))
        k = _prefix(ok)
        W[j + 1:j + 1 + k] = Z[:k]
        LAM[j:j + k, A.index] = lam[:k]
        return k

    def _full_step(self, j, W, LAM, start):
        p = self.process
        proj = self.projector.project(W[j], p.offsets[j + 1], time=start + p.times[j + 1])
        W[j + 1] = proj.point
        LAM[j] = proj.multipliers
        self.active = proj.active


def _prefix(ok: np.ndarray) -> int:
    """Length of the leading run of True."""
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if bad.size else len(ok)
