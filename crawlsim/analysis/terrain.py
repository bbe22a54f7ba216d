"""A run on terrain (docs/model.md §8): when its motion has settled, its v0, and what it met on
the way (the times each block crossed each boundary, and where blocks were held).

Translation invariance is lost on terrain: the period map acts on the state and on where the
blocks stand, so the iterates of w alone need not settle. A run stops when

* **one ground**: a period with no ground event ends periodic to the tolerance with every block
  on a cell that runs on without end in the direction of motion (a line's first or last cell,
  or uniform ground): from then on the run is that of uniform ground (docs/model.md §4), and
  v0 and its error are the usual ones;
* **locked**: the state after a period repeats the state n periods before, n <= `MAX_LOCK`,
  every block moved by the same m ground periods (m = 0 on a line: the crawler does not get
  through): v0 = m R / (n T), its error the roundoff of the n periods and their residual;
* else max_periods runs out: on a periodic ground the long-run average over the second half
  of the run (**quasi-periodic**), its error estimate the larger of twice the largest
  deviation of the barycentre from the fitted line over the span and the difference of the
  averages of its two halves; on a line the run has not settled.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from crawlsim.analysis.convergence import displacement_roundoff
from crawlsim.analysis.energy import period_dissipation
from crawlsim.errors import GaitError
from crawlsim.gait.crawler_spec import Gait
from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.stepping import PeriodRecord
from crawlsim.kernel.terrain import CROSS, HOLD, L_BLOCK, L_BOUNDARY, L_DIRECTION, L_KIND, L_U, LEAVE
from crawlsim.model.process import SweepingProcess

if TYPE_CHECKING:
    from crawlsim.analysis.run import Settled

#: The longest lock sought, in periods.
MAX_LOCK = 24
#: Memory the kept periods may take, in bytes.
KEPT_BYTES = 64 << 20


@dataclass(frozen=True, eq=False)
class TerrainReport:
    """What a run met on the ground (module docstring)."""

    regime: str  # "one-ground", "locked", "quasi-periodic" or "not-settled"
    lock: tuple[int, int] | None  # (n periods, m ground periods) of a locked motion
    crossings: np.ndarray  # (C, 4): time, block (0-based), boundary position, direction (+1, -1)
    holds: np.ndarray  # (H, 4): block, boundary position, start, end (NaN: still held)
    held_periods: np.ndarray  # the periods in which some block was held at a boundary

    @classmethod
    def from_group(cls, group: dict, attrs: dict, period: float, periods: int) -> TerrainReport:
        """The report of a results file's /terrain group (`crawlsim.io.runread`)."""
        n, m = (int(v) for v in attrs.get("lock", (0, 0)))
        crossings = np.column_stack(
            [
                group["crossing_time"],
                group["crossing_block"] - 1,
                group["crossing_position"],
                group["crossing_direction"],
            ]
        )
        holds = np.column_stack(
            [group["hold_block"] - 1, group["hold_position"], group["hold_start"], group["hold_end"]]
        )
        regime = str(attrs.get("regime", "not-settled"))
        return cls(regime, (n, m) if n else None, crossings, holds, held_periods(holds, period, periods * period))

    def summary(self) -> dict[str, Any]:
        """The JSON-ready report: blocks and boundaries as in the results file (1..N, x)."""
        return {
            "regime": self.regime,
            "lock": None if self.lock is None else list(self.lock),
            "crossings": [
                {"time": t, "block": int(b) + 1, "position": x, "direction": int(s)} for t, b, x, s in self.crossings
            ],
            "holds": [
                {"block": int(b) + 1, "position": x, "start": t0, "end": None if math.isnan(t1) else t1}
                for b, x, t0, t1 in self.holds
            ],
            "held_periods": self.held_periods.tolist(),
        }

    def text(self, period: float) -> list[tuple[str, str]]:
        """The lines `crawlsim run` prints for the ground: (label, value)."""
        lines = [("ground", _regime_text(self, period))]
        if len(self.crossings):
            shown = (f"{int(b) + 1}@{x:g}{'' if s > 0 else ' back'} t={t:.6g}" for t, b, x, s in self.crossings[:6])
            first = ", ".join(shown) + (f", ... ({len(self.crossings)} in all)" if len(self.crossings) > 6 else "")
            lines.append(("crossings", first))
        if len(self.held_periods):
            periods = ", ".join(str(int(q)) for q in self.held_periods[:10])
            more = f", ... ({len(self.held_periods)} periods)" if len(self.held_periods) > 10 else ""
            lines.append(("held at a boundary", f"in periods {periods}{more}"))
        return lines


def _regime_text(report: TerrainReport, period: float) -> str:
    if report.regime == "locked" and report.lock is not None:
        n, m = report.lock
        if m == 0:
            return f"stopped: the motion repeats every {_count(n, 'period')} without getting through"
        return f"locked to the ground: the same motion every {_count(n, 'period')}, {_count(m, 'ground period')} on"
    return {
        "one-ground": "every block on one ground from then on: v0 is that ground's",
        "quasi-periodic": "not locked to the ground: v0 is the long-run average",
        "not-settled": "not settled: some block had not reached one ground",
    }[report.regime]


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'s' if n != 1 else ''}"


class GroundWatch:
    """Follows a run's periods on terrain: whether it has settled (module docstring), and the
    ground events and v0 of the report."""

    def __init__(self, process: SweepingProcess, tol: float):
        assert process.terrain is not None and process.crawler is not None
        self.process, self.terrain, self.tol = process, process.terrain, tol
        G, N = process.steps, process.blocks
        size = 8 * (G + 1) * (3 * N) + 1
        self._kept: deque[PeriodRecord] = deque(maxlen=max(2, min(MAX_LOCK + 1, KEPT_BYTES // size)))
        self._events: list[np.ndarray] = []
        self._y: list[float] = []  # the barycentre at each period's start, then the last end
        self.lock: tuple[int, int] | None = None
        self.regime = "not-settled"
        self.quiet_since = 0  # the first period after the last with a ground event

    def add(self, record: PeriodRecord) -> None:
        assert record.x is not None
        if not self._y:
            self._y.append(float(np.mean(record.x[0])))
        self._y.append(float(np.mean(record.x[-1])))
        if record.ground is not None and len(record.ground):
            self._events.append(record.ground)
            self.quiet_since = len(self._y) - 1
        self._kept.append(record)

    def settled(self, rel_step: float) -> bool:
        """Whether the last period settles the run (module docstring)."""
        last = self._kept[-1]
        assert last.x is not None
        quiet = last.ground is None or not len(last.ground)
        if quiet and rel_step <= self.tol and self._on_one_ground(last):
            self.regime = "one-ground"
            return True
        self.lock = self._locked()
        if self.lock is not None:
            self.regime = "locked"
            return True
        return False

    def _on_one_ground(self, last: PeriodRecord) -> bool:
        t = self.terrain
        K = len(t.boundaries)
        if K == 0:
            return True
        if t.repeat:
            return False
        assert last.x is not None
        d = float(np.mean(last.x[-1] - last.x[0]))
        ends = {t.locate(float(x)) for x in np.concatenate([last.x.min(axis=0), last.x.max(axis=0)])}
        if d > 0:
            return all(g == K and not at for g, at in ends)
        if d < 0:
            return all(g == 0 and not at for g, at in ends)
        return False

    def _locked(self) -> tuple[int, int] | None:
        """(n, m) when the state after the last period repeats the one n periods before, every
        block m ground periods on."""
        kept = list(self._kept)
        last = kept[-1]
        assert last.x is not None
        scale = max(float(np.linalg.norm(last.w[-1])), self.process.scale)
        for n in range(1, len(kept)):
            before = kept[-1 - n]
            assert before.x is not None
            if float(np.linalg.norm(last.w[-1] - before.w[-1])) > self.tol * scale:
                continue
            shift = last.x[-1] - before.x[-1]
            spread = 1e-10 * max(1.0, float(np.max(np.abs(last.x[-1]))))
            if float(np.ptp(shift)) > spread:
                continue
            R = self.terrain.repeat
            m = round(float(shift[0]) / R) if R else 0
            if abs(float(shift[0]) - m * R) <= spread:
                return n, m
        return None

    def conclude(self) -> None:
        """After the last period: a run on periodic ground that did not lock is quasi-periodic."""
        if self.regime == "not-settled" and self.terrain.repeat and len(self._y) > 4:
            self.regime = "quasi-periodic"

    def motion(self) -> tuple[float, float, float, float] | None:
        """(displacement per period, v0, dissipation per period, v0's error) where the run is
        locked or quasi-periodic (None where it settled on one ground: the usual ones apply)."""
        p, T = self.process, self.process.period
        if self.regime == "one-ground":
            return None
        if self.lock is not None:
            n = self.lock[0]
            periods = list(self._kept)[-n:]
            y = np.array(self._y)
            d = float(y[-1] - y[-1 - n]) / n
            slips = sum(float(np.sum(np.abs(r.slips))) for r in periods if r.slips is not None)
            roundoff = displacement_roundoff(p, n * p.steps, slips / p.blocks)
            assert p.crawler is not None
            mismatch = float(np.abs(periods[-1].w[-1] - list(self._kept)[-1 - n].w[-1]).max()) / float(
                p.crawler.stiffness.min()
            )
            error = (roundoff + mismatch) / (n * T)
            dissipation = float(np.mean([period_dissipation(p, r) for r in periods]))
            return d, d / T, dissipation, error
        if self.regime != "quasi-periodic":  # on a line, a run that has not settled has no v0
            return None
        y = np.array(self._y)
        Q = len(y) - 1
        half = Q // 2
        span = y[half:]
        q = np.arange(len(span))
        v = float(span[-1] - span[0]) / ((len(span) - 1) * T)
        deviation = float(np.max(np.abs(span - span[0] - v * q * T)))
        mid = len(span) // 2
        v_a = float(span[mid] - span[0]) / (mid * T) if mid else v
        v_b = float(span[-1] - span[mid]) / ((len(span) - 1 - mid) * T) if len(span) - 1 > mid else v
        error = max(2.0 * deviation / ((len(span) - 1) * T), abs(v_a - v_b))
        dissipation = float(np.mean([period_dissipation(p, r) for r in self._kept]))
        return v * T, v, dissipation, error

    def report(self) -> TerrainReport:
        """The crossings and holds of the whole run (`TerrainReport`)."""
        events = np.concatenate(self._events) if self._events else np.empty((0, 5))
        crossings: list[tuple[float, int, float, int]] = []
        holds: list[list[float]] = []
        open_hold: dict[int, tuple[int, int]] = {}  # block: (boundary, direction it arrived in)
        for e in events:
            t, i, g = float(e[L_U]), int(e[L_BLOCK]), int(e[L_BOUNDARY])
            kind, s = int(e[L_KIND]), int(e[L_DIRECTION])
            x = self.terrain.boundary(g)
            if kind == CROSS:
                crossings.append((t, i, x, s))
            elif kind == HOLD:
                open_hold[i] = (g, s)
                holds.append([i, x, t, math.nan])
            elif kind == LEAVE:
                arrived = open_hold.pop(i, None)
                for h in reversed(holds):
                    if int(h[0]) == i and math.isnan(h[3]):
                        h[3] = t
                        break
                if arrived is not None and arrived[1] == s:  # on through the boundary it was held at
                    crossings.append((t, i, x, s))
        kept = np.array([h for h in holds if not h[3] == h[2]], dtype=float).reshape(-1, 4)  # a slide's stops
        T = self.process.period
        return TerrainReport(
            self.regime,
            self.lock,
            np.array(crossings, dtype=float).reshape(-1, 4),
            kept,
            held_periods(kept, T, (len(self._y) - 1) * T),
        )


def ground_gait(gait: Gait, run: Settled) -> Gait:
    """The gait on the one ground ``run`` (what the gait's run on terrain settled on) ends on:
    its v0 is that ground's, and the sensitivities of `crawlsim.analysis.sensitivity` are that gait's. Refused
    where the run does not settle on one ground: there v0 is not smooth in the crawler's phase
    relative to the ground (docs/model.md §8)."""
    terrain = gait.terrain
    assert terrain is not None
    report = run.result.history.terrain
    if report is None or report.regime != "one-ground":
        regime = "not settled" if report is None else report.regime
        raise GaitError(
            gait.source,
            "terrain",
            f"sensitivities are not defined here: the run on this terrain is {regime}, not on one ground, and "
            "a boundary makes v0 non-smooth in the crawler's phase relative to the ground (docs/model.md §8)",
        )
    assert run.record.x is not None
    a, b = terrain.factors(run.record.x[-1])  # every block on the same cell
    document = {**gait.document, "terrain": {"patches": [{"forward": float(a[0]), "backward": float(b[0])}]}}
    found = gait_from_document(document, gait.source, default_name=gait.name)
    assert isinstance(found, Gait)
    return found


def held_periods(holds: np.ndarray, T: float, end: float) -> np.ndarray:
    """The periods in which some block was held at a boundary (holds (H, 4): block, boundary,
    start, end or NaN while held at the run's ``end``)."""
    held: set[int] = set()
    for _, _, start, stop in holds:
        stop = end if math.isnan(stop) else stop
        first = int(start // T)
        held.update(range(first, max(first, math.ceil(stop / T) - 1) + 1))
    return np.array(sorted(held), dtype=int)
