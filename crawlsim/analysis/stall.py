"""The marks of a force-velocity (or slope-velocity) curve: where v0 jumps across 0 because the
shifted uniqueness condition fails (docs/model.md §3, §6), and the stall load read off a sweep's
samples, with its cause (`StallCause`). The stall load itself is searched by
`crawlsim.design.stall`, which runs the gait at the loads it probes; the sweep figures
(`crawlsim.plotting.sweeps`) draw these marks.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from crawlsim.analysis.rigid import RigidLimit, rigid_limit
from crawlsim.errors import GaitError, InputError
from crawlsim.gait.docpaths import path_keys, value_at
from crawlsim.gait.document import Gait, gait_from_document
from crawlsim.gait.signals import evaluate_many

MOVING = 1e-9
"""The crawler still moves its way at a load where v0 has the sign of v0(s0) and more than this
fraction of its size: a v0 of 3.7e-17 beyond a jump (the roundoff of a run that does not move)
does not count as motion."""


class StallCause(StrEnum):
    """Why v0 stops having its sign at the stall load."""

    SMOOTH_ZERO = "smooth-zero"  # v0 reaches 0 continuously
    JUMP = "jump"  # v0 jumps across 0 (or to 0) where the shifted uniqueness condition fails
    HOLD = "hold"  # the body can no longer hold its loads before v0 reaches 0 (docs/model.md §6)


@dataclass(frozen=True)
class CurveMarks:
    """What a force-velocity (or slope-velocity) sweep figure marks: the loads between swept
    points where v0 jumps (the shifted uniqueness condition fails on the whole cycle), and the
    stall load with its cause."""

    jumps: tuple[float, ...]
    stall: float | None
    cause: StallCause | None
    label: str  # "stall force" or "steepest slope"
    jump_label: str = "jump of $v_0$"
    rigid: RigidLimit | None = None  # a sweep of the stiffness: its asymptote


def curve_marks(gait_yaml: str, path: str, values, v0) -> CurveMarks | None:
    """The marks of a sweep of one load path (``loads.force...`` or ``loads.slope.angle``), one
    friction path (``friction...``: the jumps only, where the uniqueness margin reaches 0) or the
    stiffness (its rigid limit, `crawlsim.analysis.rigid`), or None for any other sweep (or when
    the gait cannot be rebuilt).

    Jumps: between consecutive swept values, a subset J whose shifted uniqueness sum g~_J changes
    sign at every sample time of the cycle (N <= 12) is bisected to the load where it vanishes
    (to 1e-12 of the interval); there v0 can jump, and the curve is broken there instead of
    interpolated. Stall: from the swept value nearest the gait's own load, the first interval
    where v0 loses that point's sign; at a jump inside it the stall is the jump (cause jump),
    otherwise the linear interpolation of the zero (cause smooth-zero, to the grid's resolution).
    Moving means what it means to `crawlsim.design.stall`: the sign of v0 at the start and more
    than `MOVING` of its size.
    """
    import yaml

    friction, stiffness = path.startswith("friction"), path.split(".")[0] == "stiffness"
    if not (friction or stiffness or path.startswith("loads.force") or path == "loads.slope.angle"):
        return None
    try:
        document = yaml.safe_load(gait_yaml)
        gait = gait_from_document(document, "<sweep>")
    except Exception:  # a figure is drawn without marks rather than not at all
        return None
    if stiffness and isinstance(gait, Gait):
        try:
            return CurveMarks((), None, None, "", rigid=rigid_limit(gait))
        except InputError:  # a balance that does not fix the motion: no asymptote
            return None
    if not isinstance(gait, Gait) or gait.blocks > 12:
        return None
    x = np.asarray(values, dtype=float)
    v = np.asarray(v0, dtype=float)
    label = "steepest slope" if path == "loads.slope.angle" else "stall force"
    jumps = _UniquenessSums(gait, path).jumps(x)
    if friction:
        return CurveMarks(tuple(jumps), None, None, "", "uniqueness margin 0: $v_0$ can jump")
    stall_at, cause = None, None
    try:
        own = float(value_at(gait.document, path_keys(path)))
    except (KeyError, IndexError, TypeError, ValueError):
        own = None
    finite = np.isfinite(v)
    if own is not None and np.any(finite):
        index = np.flatnonzero(finite)
        start = int(index[np.argmin(np.abs(x[index] - own))])
        if np.sign(v[start]) != 0:
            # walk away from the start, either way, to where v0 first loses its sign
            for direction in (1, -1):
                stall_at, cause = _first_stall(x, v, start, direction, jumps)
                if stall_at is not None:
                    break
    return CurveMarks(tuple(jumps), stall_at, cause, label)


class _UniquenessSums:
    """The shifted uniqueness sums g~_J of every proper subset J at 16 sample times of the
    cycle, as the load at ``path`` varies (docs/model.md §3, §6)."""

    def __init__(self, gait: Gait, path: str):
        self.gait, self.path = gait, path
        self.u = np.linspace(0.0, 1.0, 17)[:-1]
        N = gait.blocks
        self.masks = np.array([[(m >> j) & 1 for j in range(N)] for m in range(1, 2**N - 1)], dtype=bool)

    def __call__(self, s: float) -> np.ndarray | None:
        """g~_J at the sample times (subsets, samples), or None where the gait is refused for
        another reason than uniqueness (zeros exactly on a uniqueness failure)."""
        try:
            g = self.gait.replace(self.path, float(s))
        except GaitError as error:
            if "uniqueness" not in str(error):
                return None
            return np.zeros((len(self.masks), len(self.u)))
        plus, minus = g.thresholds()
        a, b = evaluate_many(plus, self.u), evaluate_many(minus, self.u)
        return self.masks.astype(float) @ a.T - (~self.masks).astype(float) @ b.T

    def jumps(self, x: np.ndarray) -> list[float]:
        """The loads where some g~_J vanishes on the whole cycle: swept values exactly there,
        and between consecutive values where it changes sign at every sample, bisected."""
        jumps: list[float] = []
        xs = np.sort(x)
        table = [self(s) for s in xs]
        for s, g in zip(xs, table):  # a swept value exactly on a uniqueness failure
            if g is not None and np.any(np.all(g == 0.0, axis=1)):
                jumps.append(float(s))
        for left, right, previous, current in zip(xs[:-1], xs[1:], table[:-1], table[1:]):
            if previous is None or current is None:
                continue
            flips = np.all(np.sign(previous) * np.sign(current) < 0, axis=1)
            for k in np.flatnonzero(flips):
                jumps.append(self._root(int(k), float(left), float(right), previous[k, 0]))
        return sorted(set(jumps))

    def _root(self, k: int, left: float, right: float, g_left: float) -> float:
        """Bisection of subset k's sum between two swept values, to 1e-12 of the interval."""
        lo, hi = left, right
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            g_mid = self(mid)
            if g_mid is None:
                break
            if np.sign(g_mid[k, 0]) == np.sign(g_left):
                lo = mid
            else:
                hi = mid
            if hi - lo <= 1e-12 * (right - left):
                break
        return 0.5 * (lo + hi)


def _first_stall(
    x: np.ndarray, v: np.ndarray, start: int, direction: int, jumps: list[float]
) -> tuple[float | None, StallCause | None]:
    """Walking from ``start`` in ``direction``, the first interval where v0 loses its sign:
    a jump inside it (the nearest), else the zero of the secant (cause smooth-zero); (None,
    None) when v0 keeps its sign to the end of the sweep."""
    sign = np.sign(v[start])
    i = start
    while 0 <= i + direction < len(x):
        j = i + direction
        if np.isfinite(v[j]) and v[j] * sign > MOVING * abs(v[start]):
            i = j
            continue
        inside = [s for s in jumps if 0 < (s - x[i]) / (x[j] - x[i]) <= 1]
        if inside:
            nearest = int(np.argmin([abs(s - x[i]) for s in inside]))
            return inside[nearest], StallCause.JUMP
        if not np.isfinite(v[j]):
            return None, None
        return _secant_zero(x, v, i, j, direction), StallCause.SMOOTH_ZERO
    return None, None


def _secant_zero(x: np.ndarray, v: np.ndarray, i: int, j: int, direction: int) -> float:
    """The zero of v0 between swept points i (moving) and j (stopped): linear interpolation,
    or, where v0 = 0 on an interval from the zero on, the secant of the moving side
    extrapolated within (x_i, x_j]."""
    stall_at = float(x[i] + (x[j] - x[i]) * v[i] / (v[i] - v[j]))
    behind = i - direction
    if v[j] == 0.0 and 0 <= behind < len(x) and np.isfinite(v[behind]) and v[behind] != v[i]:
        root = float(x[i] - v[i] * (x[i] - x[behind]) / (v[i] - v[behind]))
        if 0 < (root - x[i]) / (x[j] - x[i]) <= 1:
            stall_at = root
    return stall_at
