"""External loads and slopes on a crawler (docs/model.md §6).

A force F_j(t) on block j (forward positive) and a slope of angle alpha with block weights W_j
shift the friction thresholds to

    mu~_j^+ = mu_j^+ cos alpha - F~_j,   mu~_j^- = mu_j^- cos alpha + F~_j,   F~_j = F_j - W_j sin alpha,

and the crawler is the crawler of docs/model.md §1-§4 with mu~ in place of mu. This module holds
the `loads:` block's schema and parsing, the shifted thresholds as signals (`Combination`, for the
exact uniqueness check), the body's admissibility (docs/model.md §6: C(t) nonempty iff
-sum mu~^- <= 0 <= sum mu~^+) and the default initial state when the stress-free one is not
admissible.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.settings import MAX_BLOCKS
from crawlsim.gait.signals import (
    LARGEST,
    SIGNAL_SCHEMA,
    Constant,
    PiecewiseLinear,
    Signal,
    Steps,
    evaluate_many,
    parse_signal,
    union_breakpoints,
)

_WEIGHT = {"type": "number", "minimum": 0, "maximum": LARGEST, "x-expected": "a weight W >= 0 (a force)"}

LOADS_SCHEMA: dict = {
    "type": "object",
    "x-expected": "a mapping {force: F, slope: {angle: degrees, weight: W}} (both optional)",
    "additionalProperties": False,
    "description": "External loads (docs/model.md §6): forces on the blocks and a slope.",
    "properties": {
        "force": {
            "type": ["number", "object", "array"],
            "x-expected": "a signal F(t) for every block, or a list of N signals (forward positive)",
            "maxItems": MAX_BLOCKS,
            "items": SIGNAL_SCHEMA,
            "description": "F_j(t), the force on block j, forward positive: one signal for every block or a list of N.",
        },
        "slope": {
            "type": "object",
            "x-expected": "a mapping {angle: degrees, weight: W or a list of N}",
            "required": ["angle", "weight"],
            "additionalProperties": False,
            "properties": {
                "angle": {
                    "type": "number",
                    "exclusiveMinimum": -90,
                    "exclusiveMaximum": 90,
                    "x-expected": "an angle in degrees strictly between -90 and 90 "
                    "(positive: the crawler heads uphill)",
                },
                "weight": {
                    "type": ["number", "array"],
                    "minimum": 0,
                    "maximum": LARGEST,
                    "maxItems": MAX_BLOCKS,
                    "items": _WEIGHT,
                    "x-expected": "a weight W >= 0 for every block, or a list of N",
                },
            },
        },
    },
}
"""JSON Schema (Draft 2020-12) of the `loads:` block of a crawler gait."""


@dataclass(frozen=True)
class Combination(Signal):
    """constant + sum_i coefficient_i * signal_i: a shifted threshold mu~ as one signal.

    Only what the uniqueness check and the minimum need is implemented (values, rates,
    breakpoints, harmonics); it has no YAML form.
    """

    terms: tuple[tuple[float, Signal], ...]
    constant: float = 0.0

    kind = "combination"

    def __call__(self, u: np.ndarray) -> np.ndarray:
        out = np.full(np.shape(u), self.constant, dtype=float)
        for a, s in self.terms:
            out = out + a * s(u)
        return out

    def rate(self, u: np.ndarray) -> np.ndarray:
        out = np.zeros(np.shape(u))
        for a, s in self.terms:
            out = out + a * s.rate(u)
        return out

    def breakpoints(self) -> np.ndarray:
        return union_breakpoints([s.breakpoints() for _, s in self.terms] + [np.empty(0)])

    @property
    def harmonics(self) -> int:  # type: ignore[override]
        return max((s.harmonics for _, s in self.terms), default=0)

    @property
    def is_smooth(self) -> bool:  # type: ignore[override]
        return all(s.is_smooth for _, s in self.terms)

    @property
    def has_linear(self) -> bool:
        """A piecewise-linear part (the uniqueness check samples one more point per piece)."""
        return any(isinstance(s, PiecewiseLinear) for _, s in self.terms)

    def to_dict(self) -> dict:  # pragma: no cover - never written to a file
        raise TypeError("a shifted threshold has no YAML form")

    def minimum(self) -> tuple[float, float]:
        """The least value over the cycle. Between breakpoints a sum of constants, steps and
        piecewise-linear signals is affine, so its minimum is a one-sided limit at a piece's
        end (exact); with smooth parts each piece is also sampled (256 points) and the
        generic golden-section refinement of `Signal.minimum` is added."""
        edges = np.concatenate([[0.0], self.breakpoints(), [1.0]])
        edges = np.unique(edges)
        lo, hi = edges[:-1], edges[1:]
        mid = 0.5 * (lo + hi)
        if all(isinstance(s, (Constant, Steps, PiecewiseLinear)) for _, s in self.terms):
            value, slope = self(mid), self.rate(mid)
            ends = np.concatenate([value - slope * (mid - lo), value + slope * (hi - mid)])
            where = np.concatenate([lo, hi])
        else:  # one-sided limits at the pieces' ends, a dense sample inside, and refinement
            inside = np.concatenate([lo + 1e-12 * (hi - lo), hi - 1e-12 * (hi - lo)])
            ends, where = self(inside), inside
            grid = (lo[:, None] + (hi - lo)[:, None] * (np.arange(256) + 0.5)[None, :] / 256).ravel()
            ends = np.concatenate([ends, self(grid)])
            where = np.concatenate([where, grid])
            generic = Signal.minimum(self)
            ends = np.append(ends, generic[0])
            where = np.append(where, generic[1])
        i = int(np.argmin(ends))
        return float(ends[i]), float(np.mod(where[i], 1.0))


def combination(terms: Sequence[tuple[float, Signal]], constant: float = 0.0) -> Signal:
    """The signal constant + sum a_i s_i, as a `Constant` when every term is one, as the signal
    itself when it is ``1 * s``."""
    terms = tuple((float(a), s) for a, s in terms if a != 0.0)
    if all(isinstance(s, Constant) for _, s in terms):
        return Constant(constant + math.fsum(a * s.value for a, s in terms))  # type: ignore[attr-defined]
    if constant == 0.0 and len(terms) == 1 and terms[0][0] == 1.0:
        return terms[0][1]
    return Combination(terms, float(constant))


@dataclass(frozen=True, eq=False)
class Loads:
    """The parsed `loads:` block: forces F_j(t) (N signals), slope angle (degrees), weights W_j."""

    forces: tuple[Signal, ...]
    angle: float = 0.0
    weights: np.ndarray | None = None

    @property
    def cos(self) -> float:
        return math.cos(math.radians(self.angle))

    @property
    def sin(self) -> float:
        return math.sin(math.radians(self.angle))

    @property
    def gravity(self) -> np.ndarray:
        """-W_j sin alpha, the constant part of the total load on each block."""
        n = len(self.forces)
        if self.weights is None or self.angle == 0.0:
            return np.zeros(n)
        return -np.asarray(self.weights, dtype=float) * self.sin

    def total(self, u: np.ndarray) -> np.ndarray:
        """F~(u) = F(u) - W sin alpha at cycles u: (len(u), N)."""
        return evaluate_many(self.forces, u) + self.gravity

    def shifted(
        self, forward: Sequence[Signal], backward: Sequence[Signal]
    ) -> tuple[tuple[Signal, ...], tuple[Signal, ...]]:
        """(mu~^+, mu~^-) as signals, one per block (docs/model.md §6)."""
        c, g = self.cos, self.gravity
        memo: dict[tuple[Any, ...], Signal] = {}

        def make(mu: Signal, sign: float, force: Signal, gj: float) -> Signal:
            key = (mu, sign, force, gj)
            if key not in memo:
                memo[key] = combination([(c, mu), (-sign, force)], -sign * gj)
            return memo[key]

        plus = tuple(make(m, 1.0, f, float(gj)) for m, f, gj in zip(forward, self.forces, g))
        minus = tuple(make(m, -1.0, f, float(gj)) for m, f, gj in zip(backward, self.forces, g))
        return plus, minus


def parse_loads(block: dict, n: int, source: str) -> Loads:
    """The `loads:` block of a document whose structure the schema has checked."""
    force = block.get("force", 0.0)
    if isinstance(force, list):
        if len(force) != n:
            raise GaitError(source, "loads.force", f"expected {n} force signals (one per block), got {len(force)}")
        forces = tuple(parse_signal(f, f"loads.force[{j}]", source) for j, f in enumerate(force))
    else:
        forces = (parse_signal(force, "loads.force", source),) * n
    angle, weights = 0.0, None
    slope = block.get("slope")
    if slope is not None:
        angle = float(slope["angle"])
        weight = slope["weight"]
        if isinstance(weight, list):
            if len(weight) != n:
                raise GaitError(
                    source, "loads.slope.weight", f"expected {n} weights (one per block), got {len(weight)}"
                )
            weights = np.array(weight, dtype=float)
        else:
            weights = np.full(n, float(weight))
        weights.setflags(write=False)
    return Loads(forces, angle, weights)


def hold_violation(forward: Sequence[Signal], backward: Sequence[Signal], loads: Loads, period: float) -> str | None:
    """Why the body as a whole cannot hold its loads, or None (docs/model.md §6): C(t) is
    nonempty with room iff min_t sum_j mu~_j^+ > 0 and min_t sum_j mu~_j^- > 0."""
    plus, minus = loads.shifted(forward, backward)
    n = len(plus)
    for total, sign, word, limit in ((plus, 1.0, "forward", "mu+"), (minus, -1.0, "backward", "mu-")):
        value, at = _sum(total).minimum()
        friction = _sum([combination([(loads.cos, m)]) for m in (forward if sign > 0 else backward)])
        mu_sum = float(friction(np.array([at]))[0])
        if not value > 1e-12 * max(mu_sum, 1e-300):
            load = float(np.sum(loads.total(np.array([at]))[0]))
            what = "forces and gravity" if loads.weights is not None else "forces"
            return (
                f"the loads are too large for any quasistatic motion: at t = {at * period:.6g} "
                f"the total load sum_j F~_j = {load:.6g} ({what}) "
                f"{'is at or above' if sign > 0 else 'is at or below'} "
                f"{'-' if sign < 0 else ''}{mu_sum:.6g}, {'minus ' if sign < 0 else ''}the total "
                f"{word} friction sum_j {limit}{' cos(angle)' if loads.angle else ''}, so the "
                f"whole crawler is dragged {'forward' if sign > 0 else 'backward'} by it (the set of admissible "
                f"stresses C(t) has no interior; docs/model.md §6, {n} blocks). Reduce the load"
                f"{' or the slope' if loads.angle else ''}"
            )
    return None


def _distinct_sum(signals: Sequence[Signal]) -> tuple[list[Signal], list[int]]:
    counts: dict[Signal, int] = {}
    for s in signals:
        counts[s] = counts.get(s, 0) + 1
    return list(counts), list(counts.values())


def _sum(signals: Sequence[Signal]) -> Signal:
    """sum_j s_j as one signal (equal signals grouped)."""
    distinct, counts = _distinct_sum(signals)
    constant = 0.0
    terms: list[tuple[float, Signal]] = []
    for s, m in zip(distinct, counts):
        if isinstance(s, Combination):
            constant += m * s.constant
            terms.extend((m * a, t) for a, t in s.terms)
        else:
            terms.append((float(m), s))
    return combination(terms, constant)


def held_positions(lengths0: np.ndarray, stiffness: np.ndarray, plus0: np.ndarray, minus0: np.ndarray) -> np.ndarray:
    """Positions whose elastic forces put every block at the same fraction theta of its
    friction interval at t = 0 (docs/model.md §6): f_j = -mu~_j^- + theta (mu~_j^+ + mu~_j^-),
    theta = sum mu~^- / sum (mu~^+ + mu~^-); sigma_i = -(f_1 + ... + f_i), z = L(0) - sigma/k."""
    width = plus0 + minus0
    theta = math.fsum(minus0) / math.fsum(width)
    f = -minus0 + theta * width
    sigma = -np.cumsum(f)[:-1]
    z = lengths0 - sigma / stiffness
    return np.concatenate([[0.0], np.cumsum(z)])
