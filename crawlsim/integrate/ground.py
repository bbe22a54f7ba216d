"""Where a crawler's blocks stand on the ground between periods (docs/model.md §8): the record the
compiled integrators take (`crawlsim.kernel.terrain.Ground`), the ground events of a period in
absolute time, and the uniqueness condition checked on every ground the blocks stood on.
"""

from __future__ import annotations

import numpy as np

from crawlsim.errors import DegenerateModelError
from crawlsim.kernel.terrain import CROSS, HOLD, L_BLOCK, L_BOUNDARY, L_DIRECTION, L_KIND, L_U, LEAVE, Ground
from crawlsim.model.process import SweepingProcess


def no_ground(blocks: int) -> Ground:
    """The record of uniform ground: nothing of it is read (one signature for the kernel)."""
    return Ground(
        np.empty(0),
        np.empty(0),
        np.empty(0),
        0.0,
        np.zeros(blocks, dtype=np.int64),
        np.zeros(blocks, dtype=np.bool_),
        np.empty((0, 5)),
        np.zeros(1, dtype=np.int64),
        np.empty((0, 2 * blocks)),
        np.empty(0, dtype=np.bool_),
    )


class GroundState:
    """The ground of a process and where its blocks stand, kept from period to period."""

    def __init__(self, process: SweepingProcess, x: np.ndarray):
        terrain = process.terrain
        assert terrain is not None
        self.process = process
        self.terrain = terrain
        N = len(x)
        self.cell, self.at = np.zeros(N, dtype=np.int64), np.zeros(N, dtype=np.bool_)
        self._checked: set[bytes] = set()
        self.locate(x)

    def locate(self, x: np.ndarray) -> None:
        """Where the blocks at positions x stand (a new start: `PeriodStepper.reset`)."""
        for i, xi in enumerate(np.asarray(x, dtype=float)):
            self.cell[i], self.at[i] = self.terrain.locate(float(xi))
        self.check(0.0)

    def record(self, events: int, jumps: int) -> Ground:
        """A record for one period, with room for ``events`` ground events and ``jumps`` jumps,
        the blocks where the last period left them (copies: a period run again starts there)."""
        t = self.terrain
        return Ground(
            t.boundaries,
            t.forward,
            t.backward,
            float(t.repeat),
            self.cell.copy(),
            self.at.copy(),
            np.empty((events, 5)),
            np.zeros(1, dtype=np.int64),
            np.empty((jumps, 2 * len(self.cell))),
            np.zeros(jumps, dtype=np.bool_),
        )

    def adopt(self, ground: Ground, start: float, period: float) -> np.ndarray:
        """The blocks where a finished period left them; returns its ground events (E, 5) with
        absolute times, after checking the uniqueness condition on every ground they stood on."""
        events = ground.log[: int(ground.logged[0])].copy()
        for e in events:  # replayed: the factors under the blocks after each event
            i, g, kind, s = int(e[L_BLOCK]), int(e[L_BOUNDARY]), int(e[L_KIND]), int(e[L_DIRECTION])
            if kind == HOLD:
                self.cell[i], self.at[i] = g, True
            elif kind in (CROSS, LEAVE):
                self.cell[i], self.at[i] = (g + 1 if s > 0 else g), False
            self.check(start + e[L_U] * period)
        self.cell[:], self.at[:] = ground.cell, ground.at
        self.check(start + period)
        events[:, L_U] = start + events[:, L_U] * period
        return events

    def factors(self) -> tuple[np.ndarray, np.ndarray]:
        """(a^+, a^-) under the blocks now (at a boundary the larger of both sides)."""
        t = self.terrain
        plus, minus = np.empty(len(self.cell)), np.empty(len(self.cell))
        for i, (g, at) in enumerate(zip(self.cell, self.at)):
            plus[i], minus[i] = t.cell(int(g))
            if at:
                plus[i], minus[i] = np.maximum((plus[i], minus[i]), t.cell(int(g) + 1))
        return plus, minus

    def check(self, time: float) -> None:
        """The uniqueness condition on the ground under the blocks now, once per ground."""
        plus, minus = self.factors()
        key = plus.tobytes() + minus.tobytes()
        if key in self._checked or self.process.ground_check is None:
            return
        problem = self.process.ground_check(plus, minus)
        if problem is not None:
            raise DegenerateModelError(self.process.name, "terrain", f"{problem} (from t = {time:.12g})")
        self._checked.add(key)
