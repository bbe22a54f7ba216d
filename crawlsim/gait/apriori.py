"""What a gait says before any run: the margin to the uniqueness condition, and whether the cell
theorem makes every solution periodic from the first period on (docs/model.md §3, §5).

**The margin** is min over subsets J of blocks and times t of |g_J(t)|, g_J = sum_{j in J}
mu~_j^+ - sum_{j not in J} mu~_j^- (the thresholds shifted by the loads, §6): how far the
friction is from a subset whose balance leaves the motion undetermined. At each sample time the
subset-sum search of `crawlsim.gait.uniqueness` (distinct friction pairs, two halves met in the
middle) looks for the nearest sum instead of an equal one. Friction that is piecewise constant
needs one sample per piece; otherwise each piece is sampled (its ends and `SAMPLES` points per
harmonic) and the time of the nearest J is refined (a zero of g_J between two samples, else the
least |g_J| between them). The change that closes the margin is that of one number of the
``friction:`` block (`crawlsim.gait.uniqueness_advice.friction_slots`) that makes this g_J vanish
at that time: g_J is linear in each, and the smallest change is named.

**The cell theorem** (paper Theorem th:1dim, Corollary cor:cell): when the moving set is a
product of intervals in coordinates orthogonal in the metric, each coordinate is a
one-dimensional sweeping process and every solution is periodic from t0 + T. For a crawler the
normals d_j of blocks j and l are orthogonal in the metric iff |j - l| >= 2, so K(t) is such a
product for two blocks, and for three when the middle block never reaches a friction limit:
mu~_2^+ >= mu~_1^- + mu~_3^- and mu~_2^- >= mu~_1^+ + mu~_3^+ at every time (the stresses the
outer blocks admit never load it more). A generic process is one when its normals lie on n
directions, each bounded both ways, pairwise orthogonal in the metric's inverse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.gait.crawler_spec import Gait
from crawlsim.gait.loads import combination
from crawlsim.gait.process_spec import ProcessSpec
from crawlsim.gait.signals import Constant, Steps, evaluate_many, union_breakpoints
from crawlsim.gait.uniqueness import TOLERANCE, _Friction, _search_piece, _subset, find_violation
from crawlsim.gait.uniqueness_advice import _changed, friction_slots

SAMPLES = 16
"""Interior samples per harmonic of a piece where the friction is not piecewise constant."""


@dataclass(frozen=True, eq=False)
class Margin:
    """The margin to the uniqueness condition: |g_J(t)| for the nearest subset J and time t."""

    value: float
    subset: np.ndarray  # (N,) bool: J, the blocks at their forward limit
    time: float
    change: str  # the change of one friction number that makes g_J(t) vanish, or ""
    scale: float  # sum_j (mu~_j^+ + mu~_j^-) at that time: the size of the g_J
    failing: bool = False  # g_J vanishes on an interval: the condition fails

    @property
    def blocks(self) -> tuple[int, ...]:
        """J, numbered from 1."""
        return tuple(int(j) + 1 for j in np.flatnonzero(self.subset))

    def text(self) -> str:
        """The margin in one line, as ``crawlsim validate --explain`` and ``crawlsim info`` print it."""
        inside = [str(j) for j in self.blocks]
        blocks = ", ".join(inside if len(inside) <= 12 else [*inside[:10], "...", inside[-1]])
        text = f"{self.value:.6g}, for J = {{{blocks}}} at t = {self.time:.6g}"
        if self.failing:
            return text + " (on an interval of time: the condition fails)"
        if self.value == 0:
            return text + " (an isolated instant, which the theory allows: the run steps past it)"
        return text + (f"; {self.change} closes it" if self.change else "")

    def summary(self) -> dict[str, Any]:
        """The JSON form (``crawlsim info --json``): value, subset (from 1), time, change."""
        return {"value": self.value, "subset": list(self.blocks), "time": self.time, "change": self.change or None}


def margin(gait: Gait) -> Margin:
    """The margin to the uniqueness condition of ``gait`` (module docstring)."""
    plus, minus = gait.thresholds()
    friction = _Friction(plus, minus)
    signals = [s for pair in friction.distinct for s in pair]
    edges = np.concatenate([[0.0], union_breakpoints([s.breakpoints() for s in signals]), [1.0]])
    # piecewise constant: constants and steps, and loads' combinations of them
    constant = all(isinstance(t, (Constant, Steps)) for s in signals for _, t in getattr(s, "terms", ((1, s),)))
    inside = np.zeros(1)  # a piece's start: steps are right-continuous
    if not constant:
        inside = np.clip(np.linspace(0.0, 1.0, SAMPLES * max(s.harmonics for s in signals) + 2), 1e-9, 1.0 - 1e-9)
    u = (edges[:-1, None] + np.diff(edges)[:, None] * inside).ravel()
    mu_plus = evaluate_many([f for f, _ in friction.distinct], u).T
    mu_minus = evaluate_many([b for _, b in friction.distinct], u).T
    a, rest = mu_plus + mu_minus, friction.multiplicity @ mu_minus
    best = (math.inf, 0, np.zeros(0))
    for s in range(len(u)):
        counts = _search_piece(a[:, s : s + 1], rest[s : s + 1], friction.multiplicity, nearest=True)
        assert counts is not None  # the nearest sum always exists
        g = abs(float(counts @ a[:, s] - rest[s]))
        if g < best[0]:
            best = (g, s, counts)
    value, s, counts = best
    subset = _subset(counts, friction.pair_of, friction.blocks)

    def g_of(x: float) -> float:
        at = np.array([x])
        return float(np.sum(evaluate_many(plus, at)[0][subset]) - np.sum(evaluate_many(minus, at)[0][~subset]))

    at = float(u[s])
    if not constant:
        first = s - s % len(inside)
        value, at = _refined(g_of, u[max(s - 1, first)], at, u[min(s + 1, first + len(inside) - 1)])
    scale = float(a[:, s] @ friction.multiplicity)
    closing = _closing(gait, subset, at, g_of(at)) if value else ""
    failing = value <= TOLERANCE * scale and find_violation(plus, minus) is not None
    return Margin(value, subset, at * gait.period, closing, scale, failing)


def _refined(g_of, lo: float, mid: float, hi: float) -> tuple[float, float]:
    """(|g_J|, the cycle) at the least |g_J| on [lo, hi] near the sample ``mid``: a zero where
    g_J changes sign (bisection), else golden-section search."""
    for a, b in ((lo, mid), (mid, hi)):
        if b > a and g_of(a) * g_of(b) <= 0:
            for _ in range(60):
                a, b = (a, 0.5 * (a + b)) if g_of(a) * g_of(0.5 * (a + b)) <= 0 else (0.5 * (a + b), b)
            return 0.0, 0.5 * (a + b)
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    for _ in range(60):
        x, y = b - ratio * (b - a), a + ratio * (b - a)
        a, b = (a, y) if abs(g_of(x)) < abs(g_of(y)) else (x, b)
    return min((abs(g_of(mid)), mid), (abs(g_of(0.5 * (a + b))), 0.5 * (a + b)))


def _closing(gait: Gait, subset: np.ndarray, u: float, g: float) -> str:
    """The smallest change of one friction number after which g_J(u) = 0: each number enters
    g_J linearly, cos(angle) times its signal's change per unit, + for mu^+ of blocks in J and
    - for mu^- of blocks outside it."""
    at = np.array([u])
    scale = 1.0 if gait.loads is None else gait.loads.cos
    best: tuple[float, str] = (math.inf, "")
    for slot in friction_slots(gait.document, gait.blocks):
        moved = _changed(gait.document, slot, slot.value + 1.0, gait.source)
        if moved is None:
            continue
        signal = (gait.forward if slot.direction == "forward" else gait.backward)[slot.blocks[0]]
        per_unit = scale * float(moved(at)[0] - signal(at)[0])
        owners = [j for j in slot.blocks if subset[j] == (slot.direction == "forward")]
        rate = len(owners) * per_unit * (1.0 if slot.direction == "forward" else -1.0)
        if rate != 0 and abs(g / rate) < best[0]:
            new = slot.value - g / rate
            best = (abs(g / rate), f"{slot.dotted} from {slot.value:g} to {new:.6g}")
    return best[1]


def cell_verdict(spec: Gait | ProcessSpec) -> str | None:
    """Why the cell theorem makes every solution periodic from t0 + T, or None when it does not
    apply (module docstring)."""
    if isinstance(spec, ProcessSpec):
        normals = np.asarray(spec.normals, dtype=float)
        scaled = normals / np.linalg.norm(normals, axis=1)[:, None]
        gram = scaled @ np.linalg.solve(spec.metric, scaled.T)
        norms = np.sqrt(np.diag(gram))
        cosine = gram / np.outer(norms, norms)
        parallel = np.abs(np.abs(cosine) - 1.0) <= 1e-12
        if not np.all(parallel | (np.abs(cosine) <= 1e-12)):
            return None
        groups = {tuple(np.flatnonzero(row)) for row in parallel}
        if len(groups) != normals.shape[1] or not all(np.ptp(np.sign(cosine[g[0], list(g)])) == 2 for g in groups):
            return None
        return f"C(t) is a product of {len(groups)} intervals (paper Corollary cor:cell)"
    if spec.blocks == 2:
        return "two blocks: K(t) is an interval (paper Theorem th:1dim)"
    if spec.blocks == 3:
        plus, minus = spec.thresholds()
        forward = combination([(1.0, plus[1]), (-1.0, minus[0]), (-1.0, minus[2])]).minimum()[0]
        backward = combination([(1.0, minus[1]), (-1.0, plus[0]), (-1.0, plus[2])]).minimum()[0]
        if forward >= 0 and backward >= 0:
            return (
                "three blocks whose middle one never reaches a friction limit (mu2+ >= mu1- + mu3- "
                "and mu2- >= mu1+ + mu3+): K(t) is a rectangle (paper Corollary cor:cell)"
            )
    return None


def apriori_lines(spec: Gait | ProcessSpec) -> list[str]:
    """The lines ``crawlsim validate --explain`` adds: the margin of a crawler, and the cell
    theorem's verdict or that only the run can tell."""
    lines = []
    if isinstance(spec, Gait):
        lines.append(
            "uniqueness margin: min over J and t of |sum mu+ over J - sum mu- over the rest| = " + margin(spec).text()
        )
    verdict = cell_verdict(spec)
    if verdict is None:
        lines.append(
            "a priori: only the run can tell whether the motion is periodic in finite time (the "
            "cell theorem needs a moving set that is a product of intervals)"
        )
    else:
        lines.append(f"a priori: every solution is periodic from the first period on: {verdict}")
    return lines
