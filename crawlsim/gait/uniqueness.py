"""The uniqueness condition of the crawler model, decided exactly for any number of blocks.

The multipliers of a catch-up step are the block slips, and they are unique exactly when the
active normals are independent (docs/model.md §3). For a crawler this is the paper's
eq. (uniqueness): for every subset J of blocks (J = all blocks and J = no block included),

    g_J(t) = sum_{j in J} mu_j^+(t) - sum_{j not in J} mu_j^-(t)

must not vanish on an interval of time. With a_j = mu_j^+ + mu_j^- and R = sum_j mu_j^-,
g_J = sum_{j in J} a_j - R: a subset-sum problem on functions of time.

**Sampling.** Between the friction breakpoints every coefficient is a trigonometric polynomial of
degree <= H plus (for piecewise-linear friction) a linear part, so g_J has at most 2H + 1 zeros
on such a piece unless it vanishes identically. Sampling ``2H + 2`` (``2H + 3`` with a linear
part) interior points of each piece, unevenly spaced, therefore decides "g_J vanishes on a
sub-interval" piece by piece: it does exactly when g_J is zero, to roundoff, at every sample of
a piece. Zero to roundoff means |g_J| <= `TOLERANCE` * sum_j a_j at each sample (about 1.4e-14 of it).

**Exact search.** On one piece each block is a vector a_j of samples. Blocks with equal vectors
are interchangeable, so only how many of each group are in J matters: N identical blocks give
N + 1 candidates, not 2^N. The groups are split in two halves; each half's achievable sums are
built by dynamic programming (a group of n blocks enters as items of 1, 2, 4, ... blocks), and
sums equal to within a fraction of the tolerance are merged, so commensurate friction values
(integers, say) keep the lists short. The two lists meet in the middle: the left one sorted by
a fixed linear key, each right sum looks up the left sums whose key lies within the tolerance
window of its complement, and each candidate pair is then verified on every sample. Merging
moves a sum by at most a quarter of the tolerance per half, so every J with |g_J| <= tolerance
is found, and every J reported satisfies |g_J| <= 1.5 tolerance: the decision is exact up to
that band of roundoff.

**Constant friction.** On a piece where the friction is constant (constant and ``steps``
friction: every piece) a piece is first decided without the search above, which only then
finds the subset. Friction written with at most `MAX_DECIMALS` decimals makes every g_J a
whole number of units of the last decimal, so g_J = 0 exactly in the file's decimals or
|g_J| >= that unit, far above the tolerance: whether the target sum_j mu_j^- is reachable by
the sums of the a_j is a set of reachable whole numbers (a bitset, `MAX_LATTICE` of them),
milliseconds at 40 blocks. Other constant friction goes to `nearest_subset_sum`, the smallest
|g_J| on the piece by a meet in the middle on scalars, whose halves the next piece reuses
where their friction has not changed. A computed g_J within the tolerance but not exactly 0 is
reported as such (`Violation.residual`).

**Bounds.** A half may hold at most `MAX_HALF_ENTRIES` (distinct sums x samples per piece),
about 2^20 sums of 4 samples, which is 40 blocks of distinct cosine friction; and at most
`MAX_CANDIDATES` candidate pairs are verified. Beyond that the check raises
`UniquenessUndecidable`, saying why: the gait file then has to opt in explicitly
(``simulation: {unchecked_uniqueness: true}``).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from decimal import Decimal

import numpy as np

from crawlsim.gait.signals import JUMP_TOLERANCE, PiecewiseLinear, Signal, evaluate_many, union_breakpoints

TOLERANCE = 64 * float(np.finfo(float).eps)
"""g_J counts as zero where |g_J| <= TOLERANCE * sum_j (mu_j^+ + mu_j^-), about 1.4e-14 of it.

This is the roundoff of computing g_J (each coefficient is rounded from its decimal, evaluated,
and summed), not a modelling slack; it is also the relative precision at which a certified step
tells a tight friction limit from a slack one. It cannot be much larger: with 2^N subsets, sums
within 1e-12 of zero occur by chance from about 36 blocks of random friction, but within 1.4e-14
only from about 42."""

MAX_HALF_ENTRIES = 1 << 22
"""Most (distinct partial sums) x (samples per piece) held for one half of the search: 32 MiB
of doubles, about 200 MiB at the peak of a merge."""

MAX_CANDIDATES = 1 << 24
"""Most candidate pairs the meet-in-the-middle verifies on one piece."""

MAX_LISTED = 1 << 16
"""Most combinations (prod_p (multiplicity_p + 1) over the distinct friction pairs) that
`analyse` enumerates to list every violating subset: 16 blocks of distinct friction."""

MAX_SAMPLE_ENTRIES = 1 << 22
"""Friction samples evaluated at once: (distinct friction pairs) x (samples)."""

MAX_DECIMALS = 9
"""Most decimals of friction values for the proof on whole numbers (`_may_vanish`)."""

MAX_LATTICE = 1 << 27
"""Most whole numbers (bits: 16 MiB) in the proof's set of reachable sums."""

_MATCH = 1.5  # the band of the decision, in tolerances: 1 + a quarter per half for merging
_KEY_WEIGHTS_SEED = 0x5EED


class UniquenessUndecidable(Exception):
    """The uniqueness condition is beyond an exact check within the bounds; the message says
    which bound and by how much."""


@dataclass(frozen=True)
class Violation:
    """A subset J of blocks for which g_J vanishes on intervals of time."""

    subset: np.ndarray  # (N,) bool: blocks in J (at their forward limit)
    intervals: tuple[tuple[float, float], ...]  # in cycles, within [0, 1]
    #: How many subsets violate alike: J and those that exchange its blocks for blocks of the
    #: same friction (they have the same g_J).
    alike: int = 1
    #: The largest |g_J| on the intervals, relative to the sum of the friction: 0 for a tie in
    #: double precision, else the roundoff of the file's decimals that stands for one.
    residual: float = 0.0

    def value_text(self) -> str:
        """ "= 0", or how near a tie the computed sums are ("within 1e-14 of a tie")."""
        if self.residual == 0.0:
            return "= 0"
        bound = 10.0 ** math.ceil(math.log10(self.residual))
        return f"is within {bound:.0e} of a tie ({self.residual:.2g} of the sum of the friction: zero to roundoff)"

    def subsets_text(self) -> str:
        """ "J = {1, 2} (forward) and the rest {3} (backward)", and the subsets alike."""
        inside = np.nonzero(self.subset)[0]
        outside = np.nonzero(~self.subset)[0]
        text = f"J = {_blocks_text(inside)} (forward) and the rest {_blocks_text(outside)} (backward)"
        if self.alike > 1:
            text += f" (and {self.alike - 1:,} more subsets that exchange blocks of J for blocks of the same friction)"
        return text

    def where(self, period: float) -> str:
        """The intervals of time on which g_J vanishes, "[0, 0.5] and [0.75, 1]"."""
        return " and ".join(f"[{lo * period:g}, {hi * period:g}]" for lo, hi in self.intervals)


@dataclass(frozen=True)
class UniquenessAnalysis:
    """Every subset J for which g_J vanishes on an interval (`analyse`). ``complete`` is False
    when there are too many combinations of friction to list them all (`MAX_LISTED`): then
    ``violations`` holds the one subset the exact search found."""

    violations: tuple[Violation, ...]
    complete: bool
    #: The friction pair of each block (N,): blocks of one pair are exchangeable in every g_J.
    pair_of: np.ndarray | None = None

    def message(self, period: float, remedy: str = "") -> str:
        """The refusal text: names every J with the rest and its intervals in units of time,
        then ``remedy``, the change that fixes them."""
        first, *others = self.violations
        text = (
            f"uniqueness condition violated: for {first.subsets_text()}, sum mu+ over J - "
            f"sum mu- over the rest {first.value_text()} for t in {first.where(period)} (a whole interval)"
        )
        if others:
            text += f"; and for {len(others)} more subset{'s' if len(others) > 1 else ''}: " + "; ".join(
                f"{v.subsets_text()} for t in {v.where(period)}" for v in others
            )
        if not self.complete:
            text += "; other subsets may violate it too (too many combinations of friction to list them all)"
        text += ": the model does not determine how the crawler moves (docs/model.md §3, paper eq. (uniqueness))."
        return text + (f" {remedy}" if remedy else "")


def _blocks_text(blocks: np.ndarray) -> str:
    return "{" + ", ".join(str(int(j) + 1) for j in blocks) + "}"


def find_violation(forward: Sequence[Signal], backward: Sequence[Signal]) -> Violation | None:
    """A subset J violating the uniqueness condition, or None if there is none.

    ``forward[j]`` and ``backward[j]`` are mu_j^+ and mu_j^- as signals of the cycle; they must
    be positive (checked before). Raises `UniquenessUndecidable` when the search would exceed
    its bounds.
    """
    friction = _Friction(forward, backward)
    samples, per_piece = friction.samples()
    for first, last, mu_plus, mu_minus in samples.chunks():
        for k in range(last - first):
            columns = slice(k * per_piece, (k + 1) * per_piece)
            plus, minus = mu_plus[:, columns], mu_minus[:, columns]
            if not _may_vanish(plus, minus, friction.multiplicity):
                continue
            counts = _search_piece(plus + minus, friction.multiplicity @ minus, friction.multiplicity)
            if counts is None:
                continue
            violation = friction.violation(samples, _subset(counts, friction.pair_of, friction.blocks))
            if violation is not None:
                return violation
    return None


#: `analyse`'s answers by friction (the signals are frozen values, equal only when they are the
#: same functions): a sweep validates every point like a file, and the points of a sweep over
#: the links share the base's friction, whose analysis was a third of a point's validation.
#: Bounded, and kept only for crawlers of at most `_ANALYSED_BLOCKS` blocks (a key holds the
#: signals).
_ANALYSED: dict[tuple[tuple[Signal, ...], tuple[Signal, ...]], UniquenessAnalysis | None] = {}
_ANALYSED_MAX = 32
_ANALYSED_BLOCKS = 4096


def analyse(forward: Sequence[Signal], backward: Sequence[Signal]) -> UniquenessAnalysis | None:
    """Every subset J violating the uniqueness condition, or None if there is none (remembered
    for the friction of the last few gaits: `_ANALYSED`).

    The exact search (`find_violation`) decides; when it finds a J and the count vectors
    c (0 <= c_p <= multiplicity_p blocks of each distinct friction pair p) number at most
    `MAX_LISTED`, all of them are tested on every sample of every piece, vectorised: g_J
    depends on J only through c, so this lists every violating J, those alike grouped. The
    subset the search found comes first.
    """
    if len(forward) > _ANALYSED_BLOCKS:
        return _analyse(forward, backward)
    key = (tuple(forward), tuple(backward))
    try:
        return _ANALYSED[key]  # one look-up: another thread may empty the table
    except KeyError:
        pass
    found = _analyse(forward, backward)
    if len(_ANALYSED) >= _ANALYSED_MAX:
        _ANALYSED.clear()
    _ANALYSED[key] = found
    return found


def _analyse(forward: Sequence[Signal], backward: Sequence[Signal]) -> UniquenessAnalysis | None:
    """`analyse`, computed."""
    found = find_violation(forward, backward)
    if found is None:
        return None
    friction = _Friction(forward, backward)
    if np.prod(friction.multiplicity + 1.0) > MAX_LISTED:
        return UniquenessAnalysis((found,), complete=False, pair_of=friction.pair_of)
    samples, per_piece = friction.samples()
    grids = np.meshgrid(*[np.arange(m + 1) for m in friction.multiplicity], indexing="ij")
    counts = np.stack([g.ravel() for g in grids], axis=1).astype(float)  # (C, pairs)
    hit = np.zeros(len(counts), dtype=bool)
    for _, _, mu_plus, mu_minus in samples.chunks():
        a = mu_plus + mu_minus
        rest = friction.multiplicity @ mu_minus
        band = _MATCH * TOLERANCE * (friction.multiplicity @ a)
        rows = max(1, MAX_SAMPLE_ENTRIES // a.shape[1])
        for start in range(0, len(counts), rows):
            g = counts[start : start + rows] @ a - rest  # (rows, samples)
            zero = (np.abs(g) <= band).reshape(len(g), -1, per_piece)
            hit[start : start + rows] |= np.any(np.all(zero, axis=2), axis=1)
    violations = [found]
    key = tuple(friction.counts_of(found.subset))
    for c in counts[hit].astype(np.int64):
        if tuple(c) == key:
            continue
        violation = friction.violation(samples, _subset(c, friction.pair_of, friction.blocks))
        if violation is not None:
            violations.append(violation)
    return UniquenessAnalysis(tuple(violations), complete=True, pair_of=friction.pair_of)


def alike_subsets(
    violation: Violation, forward: Sequence[Signal], backward: Sequence[Signal], limit: int = 64
) -> list[np.ndarray]:
    """J and the subsets that exchange its blocks for blocks of the same friction pair (the same
    g_J), in lexicographic order of their blocks; at most ``limit`` of them."""
    friction = _Friction(forward, backward)
    counts = friction.counts_of(violation.subset)
    choices = [itertools.combinations(np.flatnonzero(friction.pair_of == p), int(c)) for p, c in enumerate(counts)]
    out = []
    for chosen in itertools.islice(itertools.product(*choices), limit):
        subset = np.zeros(friction.blocks, dtype=bool)
        for blocks in chosen:
            subset[list(blocks)] = True
        out.append(subset)
    return sorted(out, key=lambda s: tuple(np.flatnonzero(s)))


class _Friction:
    """The blocks' friction as distinct (mu^+, mu^-) pairs, each with its multiplicity: blocks of
    the same pair are interchangeable in every g_J."""

    def __init__(self, forward: Sequence[Signal], backward: Sequence[Signal]):
        self.blocks = len(forward)
        pairs: dict[tuple[Signal, Signal], int] = {}
        self.pair_of = np.array([pairs.setdefault((f, b), len(pairs)) for f, b in zip(forward, backward)])
        self.distinct = list(pairs)
        self.multiplicity = np.bincount(self.pair_of, minlength=len(self.distinct))

    def samples(self) -> tuple[_Samples, int]:
        """The sampled pieces (module docstring, "Sampling") and the samples per piece."""
        signals = [s for pair in self.distinct for s in pair]
        edges = np.append(union_breakpoints([s.breakpoints() for s in signals] + [np.zeros(1)]), 1.0)
        degree = max(s.harmonics for s in signals)
        linear = any(isinstance(s, PiecewiseLinear) or getattr(s, "has_linear", False) for s in signals)
        per_piece = 2 * degree + 2 + int(linear)
        fractions = (np.arange(per_piece) + 1.0) / (per_piece + 1.0)
        fractions = fractions + 0.3 * np.sin(7.0 * fractions) / (per_piece + 1.0)
        return _Samples(self.distinct, edges, fractions), per_piece

    def counts_of(self, subset: np.ndarray) -> np.ndarray:
        """How many blocks of each friction pair J holds."""
        return np.bincount(self.pair_of[subset], minlength=len(self.distinct))

    def violation(self, samples: _Samples, subset: np.ndarray) -> Violation | None:
        """J = ``subset`` with the intervals where g_J vanishes, verified from the signals; None
        when it vanishes on no piece."""
        inside = self.counts_of(subset)
        intervals, residual = samples.vanishing_intervals(inside, self.multiplicity - inside)
        if not intervals:
            return None
        alike = math.prod(math.comb(int(m), int(c)) for m, c in zip(self.multiplicity, inside))
        return Violation(subset, intervals, alike, residual)


class _Samples:
    """The distinct friction pairs sampled on the pieces, a bounded number of pieces at a time."""

    def __init__(self, distinct: list[tuple[Signal, Signal]], edges: np.ndarray, fractions: np.ndarray):
        self.distinct, self.edges, self.fractions = distinct, edges, fractions
        self.pieces = len(edges) - 1
        self.step = max(1, MAX_SAMPLE_ENTRIES // (2 * len(distinct) * len(fractions)))

    def chunks(self):
        """(first piece, end piece, mu^+ (pairs, samples), mu^- (pairs, samples))."""
        for first in range(0, self.pieces, self.step):
            last = min(self.pieces, first + self.step)
            lo, width = self.edges[first:last], np.diff(self.edges[first : last + 1])
            u = (lo[:, None] + width[:, None] * self.fractions).ravel()
            yield (
                first,
                last,
                evaluate_many([f for f, _ in self.distinct], u).T,
                evaluate_many([b for _, b in self.distinct], u).T,
            )

    def vanishing_intervals(
        self, inside: np.ndarray, outside: np.ndarray
    ) -> tuple[tuple[tuple[float, float], ...], float]:
        """The unions of pieces on which g_J vanishes at every sample, for J holding ``inside[p]``
        blocks of friction pair p and leaving out ``outside[p]``: the search's answer verified
        from the signals themselves; and the largest |g_J| / sum of the friction there."""
        intervals: list[list[float]] = []
        residual = 0.0
        for first, _, mu_plus, mu_minus in self.chunks():
            g = inside @ mu_plus - outside @ mu_minus
            scale = (inside + outside) @ (mu_plus + mu_minus)
            ok = (np.abs(g) <= _MATCH * TOLERANCE * scale).reshape(-1, len(self.fractions))
            vanish = np.all(ok, axis=1)
            if vanish.any():
                relative = (np.abs(g) / scale).reshape(-1, len(self.fractions))[vanish]
                residual = max(residual, float(relative.max()))
            for piece in np.nonzero(vanish)[0] + first:
                lo, hi = float(self.edges[piece]), float(self.edges[piece + 1])
                if intervals and abs(intervals[-1][1] - lo) <= JUMP_TOLERANCE:
                    intervals[-1][1] = hi
                else:
                    intervals.append([lo, hi])
        return tuple((lo, hi) for lo, hi in intervals), residual


def _may_vanish(plus: np.ndarray, minus: np.ndarray, multiplicity: np.ndarray) -> bool:
    """False where no g_J can vanish on a piece of constant friction ("Constant friction" in the
    module docstring): on whole numbers, or by the scalar search; True where neither applies,
    or a g_J may vanish (the vector search then decides and finds the subset)."""
    if np.any(plus != plus[:, :1]) or np.any(minus != minus[:, :1]):
        return True  # not constant on the piece
    values = np.concatenate([plus[:, 0], minus[:, 0]])
    digits = max(max(0, -int(Decimal(repr(float(v))).as_tuple().exponent)) for v in values)
    a, rest = plus[:, 0] + minus[:, 0], float(multiplicity @ minus[:, 0])
    tolerance = TOLERANCE * float(multiplicity @ a)
    decimal = digits <= MAX_DECIMALS and 10.0**-digits > 4 * _MATCH * tolerance
    if decimal:
        scale = 10.0**digits
        whole = np.rint(values * scale)
        target = int(multiplicity @ whole[len(plus) :])
        decimal = target < MAX_LATTICE and bool(np.all(whole / scale == values))
    if not decimal:
        # not short decimals of the file: the nearest sum, in units of a power of 2 at most
        # the tolerance (exact scaling: the halves of the pieces before are reused)
        unit = math.ldexp(1.0, math.frexp(tolerance)[1] - 1)
        return nearest_subset_sum(a / unit, multiplicity, rest / unit) * unit <= _MATCH * tolerance
    pair_weights = whole[: len(plus)] + whole[len(plus) :]
    reach = np.zeros(target // 64 + 1, dtype=np.uint64)
    reach[0] = 1
    for weight, size in zip(pair_weights.astype(np.int64), multiplicity):
        left, take = int(size), 1
        while left > 0:  # a pair of n blocks as items of 1, 2, 4, ... blocks
            words, bits = divmod(int(weight) * min(take, left), 64)
            if words < len(reach):
                shifted = np.zeros_like(reach)
                shifted[words:] = reach[: len(reach) - words] << np.uint64(bits)
                if bits:
                    shifted[words + 1 :] |= reach[: len(reach) - words - 1] >> np.uint64(64 - bits)
                reach |= shifted
            left -= min(take, left)
            take *= 2
    return bool((reach[target // 64] >> np.uint64(target % 64)) & np.uint64(1))


#: The last halves of `nearest_subset_sum`, by their items: a piece of a step-switched friction
#: changes one pair's value, and so one half.
_HALVES: dict[str, np.ndarray] = {}


def nearest_subset_sum(values: np.ndarray, sizes: np.ndarray, target: float) -> float:
    """The smallest |sum_g c_g values_g - target| over the counts 0 <= c_g <= sizes_g (values
    and target in units of the resolution wanted; answered to within 1/2 of it): the distance
    of the subset sums of a friction to a tie, min_J |g_J| at one time for values = mu^+ + mu^-
    of each distinct pair, sizes its blocks and target sum_j mu_j^- (module docstring).

    Meet in the middle on scalars: each half's distinct sums, built item by item and kept
    sorted (a merge of two sorted runs per item), sums within 1/(4 items) of each other
    merged; then, for each sum of one half, the nearest of the other by binary search.
    `UniquenessUndecidable` where a half would hold more than `MAX_HALF_ENTRIES` sums."""
    items: list[tuple[float, int]] = []
    for v, n in zip(np.asarray(values, dtype=float), np.asarray(sizes, dtype=np.int64)):
        left, take = int(n), 1
        while left > 0:
            items.append((float(v), min(take, left)))
            left -= min(take, left)
            take *= 2
    quantum = 0.25 / max(1, len(items))
    halves = []
    for part in (items[::2], items[1::2]):
        key = repr(part)
        if key in _HALVES:  # a piece before had the same half
            halves.append(_HALVES[key])
            continue
        sums = np.zeros(1)
        for v, weight in part:
            if 2 * len(sums) > MAX_HALF_ENTRIES:
                raise UniquenessUndecidable(
                    f"the search would hold more than {MAX_HALF_ENTRIES:,} subset sums of friction coefficients "
                    f"for one half: {len(values)} groups of blocks with distinct friction are too many to check exactly"
                )
            sums = np.sort(np.concatenate([sums, sums + weight * v]), kind="stable")
            cells = np.floor(sums / quantum)
            sums = sums[np.concatenate([[True], cells[1:] != cells[:-1]])]
        if len(_HALVES) >= 4:
            _HALVES.clear()
        _HALVES[key] = sums
        halves.append(sums)
    left_sums, right_sums = halves
    i = np.searchsorted(left_sums, target - right_sums)
    below = left_sums[np.maximum(i - 1, 0)] + right_sums - target
    above = left_sums[np.minimum(i, len(left_sums) - 1)] + right_sums - target
    return float(min(np.abs(below).min(), np.abs(above).min()))


def _subset(counts: np.ndarray, pair_of: np.ndarray, n: int) -> np.ndarray:
    """J with ``counts[p]`` blocks of friction pair p: the first ones, in block order."""
    subset = np.zeros(n, dtype=bool)
    taken = np.zeros(len(counts), dtype=np.int64)
    for j in range(n):
        p = pair_of[j]
        if taken[p] < counts[p]:
            subset[j] = True
            taken[p] += 1
    return subset


def _unique_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``x`` in lexicographic order, and the index of each row of ``x``
    among them: ``np.unique(x, axis=0, return_inverse=True)``, without the import of numpy.ma
    that it makes."""
    order = np.lexsort(x.T[::-1])
    ordered = x[order]
    new = np.ones(len(x), dtype=bool)
    new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    inverse = np.empty(len(x), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], inverse


def _search_piece(
    a: np.ndarray, rest: np.ndarray, multiplicity: np.ndarray, nearest: bool = False
) -> np.ndarray | None:
    """Counts c_p (0 <= c_p <= multiplicity_p) of blocks of each friction pair with
    sum_p c_p a_p = rest to within the band, or None; with ``nearest`` (one sample), those whose
    sum is nearest to ``rest``, to within the band (`crawlsim.gait.apriori`'s margin).

    ``a`` is (pairs, samples): a_j = mu_j^+ + mu_j^- of each pair at the piece's samples;
    ``rest`` is sum_j mu_j^- at the same samples.
    """
    tolerance = TOLERANCE * (multiplicity @ a)
    # Identical samples are one condition (constant friction: every sample of the piece).
    table = np.vstack([a, rest, tolerance])
    table = _unique_rows(table.T)[0].T
    a, rest, tolerance = table[:-2], table[-2], table[-1]
    # Pairs equal on this piece are one group whose count is the sum of theirs.
    values, group_of = _unique_rows(a)
    sizes = np.bincount(group_of, weights=multiplicity, minlength=len(values)).astype(np.int64)
    scaled = values / tolerance  # in tolerances: a match is |sum - target| <= _MATCH
    target = rest / tolerance

    order = np.argsort(-sizes, kind="stable")
    halves: tuple[list[int], list[int]] = ([], [])
    logs = [0.0, 0.0]
    for g in order:
        side = 0 if logs[0] <= logs[1] else 1
        halves[side].append(int(g))
        logs[side] += math.log(sizes[g] + 1.0)
    left = _HalfSums(scaled, sizes, halves[0])
    right = _HalfSums(scaled, sizes, halves[1])
    pair = _nearest(left.sums[:, 0], right.sums[:, 0], target[0]) if nearest else _meet(left.sums, right.sums, target)
    if pair is None:
        return None
    group_counts = left.counts(pair[0]) + right.counts(pair[1])
    # back from groups to friction pairs: fill each group's pairs in order
    counts = np.zeros(len(multiplicity), dtype=np.int64)
    for p in range(len(multiplicity)):
        g = group_of[p]
        take = min(int(multiplicity[p]), int(group_counts[g]))
        counts[p] = take
        group_counts[g] -= take
    return counts


class _HalfSums:
    """The distinct sums sum_g c_g v_g over the groups of one half (0 <= c_g <= size_g), built
    item by item (a group of n blocks as items of 1, 2, 4, ..., rest blocks), merging sums that
    fall in the same cell of side `quantum` tolerances after each item."""

    def __init__(self, scaled: np.ndarray, sizes: np.ndarray, groups: list[int]):
        r = scaled.shape[1]
        items: list[tuple[int, int]] = []
        for g in groups:
            left, weight = int(sizes[g]), 1
            while left > 0:
                take = min(weight, left)
                items.append((g, take))
                left -= take
                weight *= 2
        self.groups = len(scaled)
        self.items = items
        quantum = 0.25 / max(1, len(items))  # merging moves a sum by < quantum per item
        sums = np.zeros((1, r))
        self.parents: list[np.ndarray] = []
        self.taken: list[np.ndarray] = []
        for g, weight in items:
            size = 2 * len(sums)
            if size * r > MAX_HALF_ENTRIES:
                raise UniquenessUndecidable(
                    f"the search would hold more than {MAX_HALF_ENTRIES:,} values for one half "
                    f"({size:,} distinct sums of friction coefficients x {r} samples per "
                    f"piece): {len(scaled)} groups of blocks with distinct friction are too many "
                    "to check exactly"
                )
            grown = np.concatenate([sums, sums + weight * scaled[g]])
            keep = _distinct_cells(np.floor(grown / quantum).astype(np.int64))
            self.parents.append(keep % len(sums))
            self.taken.append(keep >= len(sums))
            sums = grown[keep]
        self.sums = sums

    def counts(self, index: int) -> np.ndarray:
        """The count of each group in the sum ``self.sums[index]``."""
        out = np.zeros(self.groups, dtype=np.int64)
        for (g, weight), parents, taken in zip(reversed(self.items), reversed(self.parents), reversed(self.taken)):
            if taken[index]:
                out[g] += weight
            index = int(parents[index])
        return out


def _splitmix64(count: int) -> np.ndarray:
    """The first ``count`` words of the SplitMix64 sequence from `_KEY_WEIGHTS_SEED` (Steele,
    Lea and Flood 2014): fixed, well-mixed 64-bit words for the hash and the key weights below,
    without importing numpy.random (a tenth of `crawlsim validate`'s start-up)."""
    with np.errstate(over="ignore"):
        z = np.uint64(_KEY_WEIGHTS_SEED) + (np.arange(1, count + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15))
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


@functools.cache
def _hash_words() -> np.ndarray:
    """64 odd 64-bit multipliers of `_distinct_cells`'s row hash, below 2^63."""
    return (_splitmix64(64) >> np.uint64(1)) | np.uint64(1)


def _distinct_cells(cells: np.ndarray) -> np.ndarray:
    """Sorted indices of one row per distinct row of the integer array ``cells`` (n, r).

    Rows are hashed to one word, and (hash, index) pairs packed into one integer are sorted
    (an argsort or a lexicographic sort of rows is several times slower). A row whose hash
    collides with a different row's is kept as well, so no cell is lost.
    """
    n = len(cells)
    bits = max(1, int(n - 1).bit_length())
    words = cells.view(np.uint64)
    weights = _hash_words()
    with np.errstate(over="ignore"):
        hashes = words[:, 0] * weights[0]
        for k in range(1, cells.shape[1]):
            hashes = (hashes ^ (hashes >> np.uint64(29))) + words[:, k] * weights[k % len(weights)]
    low = np.uint64((1 << bits) - 1)
    packed = np.sort((hashes & ~low) | np.arange(n, dtype=np.uint64))
    index = (packed & low).astype(np.int64)
    starts = np.concatenate([[True], (packed[1:] & ~low) != (packed[:-1] & ~low)])
    first = index[starts]
    representative = np.empty(n, dtype=np.int64)
    representative[index] = index[np.maximum.accumulate(np.where(starts, np.arange(n), 0))]
    keep = np.any(cells != cells[representative], axis=1)
    keep[first] = True
    return np.flatnonzero(keep)


def _nearest(left: np.ndarray, right: np.ndarray, target: float) -> tuple[int, int]:
    """Indices (i, k) with left[i] + right[k] nearest to ``target``: for each right sum, the left
    sums on either side of its complement in sorted order."""
    order = np.argsort(left, kind="stable")
    want = target - right
    above = np.clip(np.searchsorted(left[order], want), 0, len(left) - 1)
    below = np.maximum(above - 1, 0)
    miss = np.minimum(np.abs(left[order][above] - want), np.abs(left[order][below] - want))
    k = int(np.argmin(miss))
    i = min((above[k], below[k]), key=lambda j: abs(left[order][j] - want[k]))
    return int(order[i]), k


def _meet(left: np.ndarray, right: np.ndarray, target: np.ndarray) -> tuple[int, int] | None:
    """Indices (i, k) with |left[i] + right[k] - target| <= _MATCH on every sample, or None.

    The left sums are sorted by a key, a fixed positive combination of the samples: a match
    needs |key(left) + key(right) - key(target)| <= _MATCH * sum(weights), a window found by
    binary search; every pair in a window is then verified on all samples.
    """
    r = left.shape[1]
    weights = 1.0 + (_splitmix64(r) >> np.uint64(11)).astype(float) * 2.0**-53  # in [1, 2)
    key_left = left @ weights
    key_right = right @ weights
    right_order = np.argsort(key_right, kind="stable")
    order = np.argsort(key_left, kind="stable")
    sorted_keys = key_left[order]
    # the right sums in key order, so the binary searches walk memory in order
    right = right[right_order]
    centre = target @ weights - right @ weights
    # the keys' own roundoff, a small fraction of a tolerance
    slack = (r + 8) * float(np.finfo(float).eps) * (np.abs(centre) + np.max(np.abs(key_left)) + 1.0)
    half = _MATCH * float(weights.sum()) + slack
    lo = np.searchsorted(sorted_keys, centre - half, side="left")
    hi = np.searchsorted(sorted_keys, centre + half, side="right")
    width = hi - lo
    total = int(width.sum())
    if total == 0:
        return None
    if total > MAX_CANDIDATES:
        raise UniquenessUndecidable(
            f"{total:,} candidate subsets would have to be verified (more than "
            f"{MAX_CANDIDATES:,}): the friction coefficients have too many nearly equal sums to "
            "check exactly"
        )
    rights = np.nonzero(width)[0]
    cumulative = np.cumsum(width[rights])
    start = 0
    while start < len(rights):
        # a batch of right sums whose windows hold about 2^20 candidates together
        before = cumulative[start] - width[rights[start]]
        end = max(start + 1, int(np.searchsorted(cumulative, before + (1 << 20), side="right")))
        ks = rights[start:end]
        start = end
        k = np.repeat(ks, width[ks])
        offset = np.arange(k.size) - np.repeat(np.cumsum(width[ks]) - width[ks], width[ks])
        i = order[lo[k] + offset]
        ok = np.all(np.abs(left[i] + right[k] - target) <= _MATCH, axis=1)
        hit = np.flatnonzero(ok)
        if hit.size:
            return int(i[hit[0]]), int(right_order[k[hit[0]]])
    return None
