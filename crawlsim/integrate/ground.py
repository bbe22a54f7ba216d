"""Where a crawler's blocks stand on the ground between periods (docs/model.md §8): the record the
compiled integrators take (`crawlsim.kernel.terrain.Ground`), the ground events of a period in
absolute time, and the uniqueness condition checked on every ground the blocks stood on.
"""

from __future__ import annotations

import numpy as np

from crawlsim.errors import DegenerateModelError
from crawlsim.kernel.terrain import L_BLOCK, L_MINUS, L_PLUS, L_U, Ground
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
        np.empty((0, 7)),
        np.zeros(1, dtype=np.int64),
        np.empty((0, 2 * blocks)),
        np.empty(0, dtype=np.bool_),
    )


class GroundState:
    """The ground of a process and where its blocks stand, kept from period to period, with the
    factors under them and how many blocks of each class stand on each kind of ground (the key
    of the uniqueness condition's check, `crawlsim.gait.terrain.GroundCheck`), kept up to date
    event by event."""

    def __init__(self, process: SweepingProcess, x: np.ndarray):
        terrain, check = process.terrain, process.ground_check
        assert terrain is not None and check is not None
        self.process, self.terrain, self.check_ground = process, terrain, check
        N = len(x)
        self.cell, self.at = np.zeros(N, dtype=np.int64), np.zeros(N, dtype=np.bool_)
        self.plus, self.minus = np.ones(N), np.ones(N)
        self._arrays = np.empty((0, 7)), np.empty((0, 2 * N)), np.empty(0, bool)
        self.locate(x)

    def locate(self, x: np.ndarray) -> None:
        """Where the blocks at positions x stand (a new start: `PeriodStepper.reset`)."""
        for i, xi in enumerate(np.asarray(x, dtype=float)):
            self.cell[i], self.at[i] = self.terrain.locate(float(xi))
        self.locate_counts()
        self.check(0.0)

    def _move(self, i: int, a: float, b: float) -> None:
        """Block i onto ground of factors (a, b): the counts of kinds of ground follow."""
        c = self.check_ground.classes[i]
        old = (c, float(self.plus[i]), float(self.minus[i]))
        count = self.counts[old] - 1
        if count:
            self.counts[old] = count
        else:
            del self.counts[old]
        self.plus[i], self.minus[i] = a, b
        self.counts[(c, a, b)] = self.counts.get((c, a, b), 0) + 1

    def record(self, events: int, jumps: int) -> Ground:
        """A record for one period, with room for ``events`` ground events and ``jumps`` jumps,
        the blocks where the last period left them (copies: a period run again starts there);
        its log and jump arrays are those of the last period (whose record copied them out)."""
        t = self.terrain
        log, fac, pinned = self._arrays
        if len(log) != events or len(fac) != jumps:  # kept from period to period
            log, fac, pinned = np.empty((events, 7)), np.empty((jumps, 2 * len(self.cell))), np.empty(jumps, bool)
            self._arrays = log, fac, pinned
        return Ground(
            t.boundaries,
            t.forward,
            t.backward,
            float(t.repeat),
            self.cell.copy(),
            self.at.copy(),
            log,
            np.zeros(1, dtype=np.int64),
            fac,
            pinned,
        )

    def adopt(self, ground: Ground, start: float, period: float) -> np.ndarray:
        """The blocks where a finished period left them; returns its ground events (E, 5) with
        absolute times, after checking the uniqueness condition on every ground they stood on."""
        logged = int(ground.logged[0])
        events = ground.log[:logged, :5].copy()
        for u, i, a, b in ground.log[:logged, [L_U, L_BLOCK, L_PLUS, L_MINUS]].tolist():
            self._move(int(i), a, b)  # the ground under the blocks after each event
            self.check(start + u * period)
        self.cell[:], self.at[:] = ground.cell, ground.at
        if logged == len(ground.log):  # catch-up's log may be full: from where the blocks stand
            self.locate_counts()
            self.check(start + period)
        events[:, L_U] = start + events[:, L_U] * period
        return events

    def locate_counts(self) -> None:
        """The factors and counts of every block from where it stands."""
        self.counts: dict[tuple[int, float, float], int] = {}
        t, classes = self.terrain, self.check_ground.classes
        for i, (g, at) in enumerate(zip(self.cell.tolist(), self.at.tolist())):
            a, b = t.cell(g)
            if at:
                a, b = (max(u, v) for u, v in zip((a, b), t.cell(g + 1)))
            self.plus[i], self.minus[i] = a, b
            self.counts[(classes[i], a, b)] = self.counts.get((classes[i], a, b), 0) + 1

    def check(self, time: float) -> None:
        """The uniqueness condition on the ground under the blocks now (decided once per kind)."""
        problem = self.check_ground(self.plus, self.minus, self.check_ground.key(self.counts))
        if problem is not None:
            raise DegenerateModelError(self.process.name, "terrain", f"{problem} (from t = {time:.12g})")
