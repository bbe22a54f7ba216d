"""Ground that changes under the crawler: friction factors by intervals of position
(docs/model.md §8).

A ``terrain:`` block multiplies block j's friction coefficients by factors a^+(x_j) and a^-(x_j)
of the ground under it, forward and backward separately, so that with loads (docs/model.md §6)

    mu~_j^+ = a^+(x_j) mu_j^+(t) cos alpha - F~_j(t),   mu~_j^- = a^-(x_j) mu_j^-(t) cos alpha + F~_j(t).

The factors are piecewise constant, 1 outside every patch; at a boundary, where they jump, the
admissible force is the closure of both sides: the larger factor, each direction on its own.
This module holds the block's schema, its checks (every refusal names its key), the ground as
cells between the boundaries where a factor changes (`Terrain`: a patch of factor 1 or two
neighbours alike leave no boundary), and the uniqueness condition on a given ground.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.loads import combination
from crawlsim.gait.settings import positive_schema
from crawlsim.gait.uniqueness import UniquenessUndecidable, find_violation

#: The most patches a terrain may list.
MAX_PATCHES = 1000

_POSITION = {"type": "number", "x-expected": "a position x (a length)"}
_FACTOR = positive_schema("a friction factor > 0")

TERRAIN_SCHEMA: dict = {
    "type": "object",
    "x-expected": "a mapping {patches: [...], repeat: R}",
    "required": ["patches"],
    "additionalProperties": False,
    "description": "Friction factors along the ground (docs/model.md §8): patches of x where each "
    "block's mu+ and mu- are multiplied by forward and backward; 1 elsewhere.",
    "properties": {
        "repeat": positive_schema("the length after which the patches repeat"),
        "patches": {
            "type": "array",
            "maxItems": MAX_PATCHES,
            "x-expected": f"a list of at most {MAX_PATCHES} patches {{from: x, to: x, forward: a+, backward: a-}}",
            "items": {
                "type": "object",
                "x-expected": "a mapping {from: x, to: x, forward: a+, backward: a-} (from and to optional)",
                "required": ["forward", "backward"],
                "additionalProperties": False,
                "properties": {"from": _POSITION, "to": _POSITION, "forward": _FACTOR, "backward": _FACTOR},
            },
        },
    },
}
"""JSON Schema (Draft 2020-12) of the `terrain:` block of a crawler gait."""


@dataclass(frozen=True, eq=False)
class Terrain:
    """The ground as cells between the boundaries where a factor changes.

    On a line (``repeat`` 0) cell k lies between boundaries k - 1 and k (k = 0..K, the first
    and last unbounded). Periodic, boundary g is at ``boundaries[g mod K] + repeat * (g div K)``
    and cell g, between boundaries g - 1 and g, has the factors of cell g mod K. Without a
    boundary the ground is uniform (one cell)."""

    boundaries: np.ndarray  # (K,) sorted; in [0, repeat) when periodic
    forward: np.ndarray  # factors on mu^+ of the cells: (K+1,) on a line, (K,) periodic (1 when K = 0)
    backward: np.ndarray  # factors on mu^-
    repeat: float = 0.0

    def boundary(self, g: int) -> float:
        """The position of boundary g (+-inf beyond the ends of a line)."""
        K = len(self.boundaries)
        if self.repeat:
            q, r = divmod(g, K)
            return float(self.boundaries[r] + self.repeat * q)
        return -math.inf if g < 0 else (math.inf if g >= K else float(self.boundaries[g]))

    def cell(self, g: int) -> tuple[float, float]:
        """The factors (a^+, a^-) of cell g."""
        c = g % len(self.forward) if self.repeat else min(max(g, 0), len(self.forward) - 1)
        return float(self.forward[c]), float(self.backward[c])

    def locate(self, x: float) -> tuple[int, bool]:
        """(g, at): x in cell g, or at its right boundary g (``at``) to within roundoff."""
        K = len(self.boundaries)
        if K == 0:
            return 0, False
        q = math.floor(x / self.repeat) if self.repeat else 0
        r = x - q * self.repeat
        g = int(np.searchsorted(self.boundaries, r, side="left")) + q * K
        for h in (g - 1, g):
            if abs(x - self.boundary(h)) <= 1e-12 * max(1.0, abs(x)):
                return h, True
        return g, False

    def factors(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(a^+, a^-) of the ground under positions x: at a boundary the larger of both sides."""
        plus, minus = np.empty(len(x)), np.empty(len(x))
        for j, xj in enumerate(np.asarray(x, dtype=float)):
            g, at = self.locate(float(xj))
            plus[j], minus[j] = self.cell(g)
            if at:
                plus[j], minus[j] = np.maximum((plus[j], minus[j]), self.cell(g + 1))
        return plus, minus


def parse_terrain(block: dict, source: str) -> Terrain:
    """The ground of a `terrain:` block whose structure the schema has checked; refuses, naming
    the key, patches out of order or overlapping, ``to <= from`` and patches outside
    [0, repeat)."""
    patches, repeat = block["patches"], float(block.get("repeat", 0.0))
    where = "terrain.patches"
    spans: list[tuple[float, float, float, float]] = []
    for i, patch in enumerate(patches):
        lo, hi = float(patch.get("from", -math.inf)), float(patch.get("to", math.inf))
        key = f"{where}[{i}]"
        if not hi > lo:
            raise GaitError(source, f"{key}.to", f"a patch must end after it starts: to = {hi:g} <= from = {lo:g}")
        if repeat and ("from" not in patch or "to" not in patch or lo < 0 or hi > repeat):
            raise GaitError(
                source,
                f"{key}.{'from' if 'from' not in patch or lo < 0 else 'to'}",
                f"with repeat: {repeat:g} every patch lies in [0, {repeat:g}] with both from and to "
                f"(got [{lo:g}, {hi:g}])",
            )
        if spans and lo < spans[-1][1]:
            raise GaitError(
                source,
                f"{key}.from",
                f"patches must be sorted and disjoint: this one starts at {lo:g}, before patches[{i - 1}] "
                f"ends at {spans[-1][1]:g}",
            )
        spans.append((lo, hi, float(patch["forward"]), float(patch["backward"])))
    return _cells(spans, repeat)


def _cells(spans: list[tuple[float, float, float, float]], repeat: float) -> Terrain:
    """The cells of sorted, disjoint patches: a boundary wherever the factors change."""

    def at(x: float) -> tuple[float, float]:
        for lo, hi, a, b in spans:
            if lo < x < hi:
                return a, b
        return 1.0, 1.0

    points = sorted({p for lo, hi, _, _ in spans for p in (lo, hi) if math.isfinite(p)} - {repeat})
    if repeat:
        points = sorted(set(points) | {0.0})
        mids = [(p + q) / 2 for p, q in zip(points, points[1:] + [points[0] + repeat])]
        values = [at(m) for m in mids]  # values[i]: between points[i] and the next
        keep = [i for i in range(len(points)) if values[i] != values[i - 1]]
        cells = [values[i - 1] for i in keep]  # cell k ends at boundary k
    else:
        mids = [points[0] - 1.0] if points else [0.0]
        mids += [(p + q) / 2 for p, q in zip(points, points[1:])] + ([points[-1] + 1.0] if points else [])
        values = [at(m) for m in mids]  # values[i]: before points[i]; the last after them all
        keep = [i for i in range(len(points)) if values[i] != values[i + 1]]
        cells = [values[i] for i in keep] + [values[-1]]
    if not keep:  # uniform ground
        cells = [values[0]]
    forward, backward = np.array(cells, dtype=float).T.copy()  # contiguous: the kernel's one signature
    return Terrain(np.array([points[i] for i in keep], dtype=float), forward, backward, repeat)


def boundaries(count: int) -> str:
    return f"{count} boundar{'y' if count == 1 else 'ies'}"


def terrain_text(terrain: Terrain) -> str:
    """The ground in one line (``crawlsim validate --explain``, ``crawlsim info``)."""
    cells = ", ".join(f"{a:g}/{b:g}" for a, b in zip(terrain.forward, terrain.backward))
    where = ", ".join(f"{x:g}" for x in terrain.boundaries)
    repeat = f", repeated every {terrain.repeat:g}" if terrain.repeat else ""
    return (
        f"{boundaries(len(terrain.boundaries))} at x = {where}{repeat}; factors (forward/backward) of the cells "
        f"between them {cells}; at a boundary the larger of both sides (docs/model.md §8)"
    )


def on_ground(gait: Any, plus: np.ndarray, minus: np.ndarray) -> Any:
    """``gait`` with its friction multiplied block by block by the factors (a^+, a^-): the crawler
    of docs/model.md §1-§6 while the ground under each block stays the same."""
    memo: dict[tuple[int, float], Any] = {}  # one signal per friction and factor (100 blocks, two grounds)

    def scaled(a: float, s: Any) -> Any:
        return memo.setdefault((id(s), float(a)), combination([(a, s)]))

    forward = tuple(scaled(a, s) for a, s in zip(plus, gait.forward))
    backward = tuple(scaled(a, s) for a, s in zip(minus, gait.backward))
    return dataclasses.replace(gait, forward=forward, backward=backward, terrain=None)


class GroundCheck:
    """The uniqueness condition on the ground under the blocks (`ground_violation`), decided
    once per *kind* of ground: g_J ranges over every subset J, so it depends on the multiset of
    the blocks' thresholds, not on which block has which. ``classes[j]`` numbers the blocks whose
    thresholds are alike on uniform ground (the same friction and load signals); a ground is the
    multiset of (class, a^+, a^-) of the blocks, as `key` forms it."""

    def __init__(self, gait: Any):
        self.gait = gait
        plus, minus = gait.thresholds()
        seen: dict[tuple[int, ...], int] = {}
        signals = zip(plus, minus, gait.forward, gait.backward)
        self.classes = [seen.setdefault(tuple(map(id, four)), len(seen)) for four in signals]
        self._known: dict[frozenset[tuple[tuple[int, float, float], int]], str | None] = {}

    @staticmethod
    def key(counts: dict[tuple[int, float, float], int]) -> frozenset[tuple[tuple[int, float, float], int]]:
        return frozenset(counts.items())

    def __call__(self, plus: np.ndarray, minus: np.ndarray, key: Any = None) -> str | None:
        """Why the condition fails with the factors (a^+, a^-) under the blocks, or None."""
        if key is None:
            counts: dict[tuple[int, float, float], int] = {}
            for c, a, b in zip(self.classes, plus, minus):
                counts[(c, float(a), float(b))] = counts.get((c, float(a), float(b)), 0) + 1
            key = self.key(counts)
        if key not in self._known:
            if len(self._known) > 4096:
                self._known.clear()
            self._known[key] = ground_violation(self.gait, plus, minus)
        return self._known[key]


def ground_violation(gait: Any, plus: np.ndarray, minus: np.ndarray) -> str | None:
    """Why the uniqueness condition (docs/model.md §3) fails on the ground (a^+, a^-) under the
    blocks, or None where it holds (or is beyond an exact check, which the gait file's own
    friction was already subject to)."""
    try:
        violation = find_violation(*on_ground(gait, plus, minus).thresholds())
    except UniquenessUndecidable:
        return None
    if violation is None:
        return None
    grounds: dict[tuple[float, float], list[int]] = {}
    for j, key in enumerate(zip(plus, minus)):
        grounds.setdefault((float(key[0]), float(key[1])), []).append(j + 1)
    ground = "; ".join(f"{_blocks(blocks)} on {a:g}/{b:g}" for (a, b), blocks in grounds.items())
    return (
        f"on the terrain the uniqueness condition (docs/model.md §3, §8) fails where the blocks stand on "
        f"grounds of factors (forward/backward): {ground}: g_J = 0 for {violation.subsets_text()} at t in "
        f"{violation.where(gait.period)}; the model does not determine how the crawler moves there"
    )


def _blocks(blocks: list[int]) -> str:
    """ "block 3", "blocks 1-2, 5" (at most eight runs, then how many more)."""
    runs: list[list[int]] = []
    for j in blocks:
        if runs and j == runs[-1][1] + 1:
            runs[-1][1] = j
        else:
            runs.append([j, j])
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:8])
    more = f" and {len(runs) - 8} more runs" if len(runs) > 8 else ""
    return f"block{'s' if len(blocks) > 1 else ''} {text}{more}"
