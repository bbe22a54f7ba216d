"""What to change when a gait's friction violates the uniqueness condition (docs/model.md §3).

The refusal lists every violating subset J (`crawlsim.gait.uniqueness.analyse`) and the
smallest change of one friction coefficient of the file that restores the condition, so that a
gait is fixed in one round.

**The search.** Researchers write round numbers, and those hit the equalities g_J = 0: a
coefficient moved off them by a round step is the natural fix. Every number of the ``friction:``
block that sets a friction value (a constant, a ``steps`` or ``piecewise-linear`` value, a
cosine's mean or amplitude, a Fourier coefficient; not times or phases) is a candidate, and
each is moved up or down by 1, 2, 5 x 10^e, from 1 % of its own size up to its size. Candidates
are tried in order of the size of the change, and the first that leaves the friction positive,
the start admissible and no g_J vanishing on an interval (the caller's test, the file's own
checks) is the suggestion: the smallest change on that grid. A coefficient that does not enter
some violating g_J (mu_j^+ of a block outside that J, mu_j^- of a block in it) cannot fix it
and is skipped without a test. At most `MAX_TRIALS` candidates are tested (`MAX_TRIALS_LARGE`
when the frictions are too many to list every violating subset).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.signals import Signal, parse_signal
from crawlsim.gait.uniqueness import UniquenessAnalysis

MAX_TRIALS = 400
"""Most candidate changes tested (each a uniqueness check of the changed friction) when every
violating subset is known (`UniquenessAnalysis.complete`: at most 16 distinct frictions, each
check fast)."""

MAX_TRIALS_LARGE = 4
"""Most candidate changes tested when there are too many frictions to list every violating
subset: each check is then a full exact search, and with so many coincident sums one change
rarely fixes them all."""

_VALUE_KEYS = ("value", "mean", "amplitude", "values", "cos", "sin")
"""Keys of a signal's mapping whose numbers are friction values (times and phases are not)."""

_MANTISSAS = (1, 2, 5)

Friction = tuple[tuple[Signal, ...], tuple[Signal, ...]]
FrictionTest = Callable[[tuple[Signal, ...], tuple[Signal, ...]], bool]


@dataclass(frozen=True)
class Slot:
    """One number of the ``friction:`` block: where it is and which thresholds it sets."""

    signal_path: str  # key path of its signal: "friction[2].backward", "friction.forward"
    inner: tuple[str | int, ...]  # keys inside the signal: () for a bare number, ("values", 1)
    direction: str  # "forward" (mu^+) or "backward" (mu^-)
    blocks: tuple[int, ...]  # the blocks whose threshold it sets (0-based)
    value: float

    @property
    def keypath(self) -> str:
        """The number's key path, as errors name it: "friction[2].backward.values[1]"."""
        text = self.signal_path
        for key in self.inner:
            text += f"[{key}]" if isinstance(key, int) else f".{key}"
        return text

    @property
    def dotted(self) -> str:
        """The number's dotted path, as ``--sweep`` and `Gait.replace` take it."""
        return self.keypath.replace("[", ".").replace("]", "")


@dataclass(frozen=True)
class Change:
    """A suggested change of one coefficient."""

    slot: Slot
    new: float

    def text(self) -> str:
        path = "" if self.slot.dotted == self.slot.keypath else f" (path {self.slot.dotted})"
        return (
            f"To restore it, change {self.slot.keypath} from {self.slot.value:g} to "
            f"{self.new!r}{path}: the smallest change of one friction coefficient that does, "
            "in round steps from 1 % of it"
        )


def friction_slots(document: dict, blocks: int) -> list[Slot]:
    """Every friction value of a crawler document, in document order."""
    friction = document["friction"]
    entries: list[tuple[str, Any, tuple[int, ...]]]
    if isinstance(friction, dict):
        entries = [("friction", friction, tuple(range(blocks)))]
    else:
        entries = [(f"friction[{j}]", entry, (j,)) for j, entry in enumerate(friction)]
    slots = []
    for path, entry, owners in entries:
        for direction in ("forward", "backward"):
            for inner, value in _numbers(entry[direction]):
                slots.append(Slot(f"{path}.{direction}", inner, direction, owners, value))
    return slots


def _numbers(signal: Any) -> Iterator[tuple[tuple[str | int, ...], float]]:
    if not isinstance(signal, dict):
        yield (), float(signal)
        return
    for key in _VALUE_KEYS:
        value = signal.get(key)
        if isinstance(value, list):
            for i, item in enumerate(value):
                yield (key, i), float(item)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            yield (key,), float(value)


def _steps(value: float, scale: float) -> list[Decimal]:
    """Round steps 1, 2, 5 x 10^e from 1 % of |value| (of ``scale`` for a zero) up to it."""
    size = abs(value) or scale
    low = math.floor(math.log10(0.01 * size))
    steps = [Decimal(m) * Decimal(10) ** e for e in range(low, math.floor(math.log10(size)) + 1) for m in _MANTISSAS]
    return [s for s in steps if 0.01 * size * (1 - 1e-9) <= float(s) <= size * (1 + 1e-9)]


def _enters_every(slot: Slot, analysis: UniquenessAnalysis) -> bool:
    """Whether the slot's threshold enters g_J of every violating J, those alike included:
    mu_j^+ enters for j in J, mu_j^- for j outside it. Of the s_p slot blocks of friction pair p
    (m_p blocks, c_p of them in J), at least max(0, c_p - m_p + s_p) are in every alike J and at
    least max(0, s_p - c_p) outside it."""
    pair_of = analysis.pair_of
    if pair_of is None:  # pragma: no cover - `analyse` always records the pairs
        return True
    pairs = int(pair_of.max()) + 1
    owned = np.bincount(pair_of[list(slot.blocks)], minlength=pairs)
    multiplicity = np.bincount(pair_of, minlength=pairs)
    for violation in analysis.violations:
        inside = np.bincount(pair_of[violation.subset], minlength=pairs)
        least = (
            np.maximum(0, inside - multiplicity + owned)
            if slot.direction == "forward"
            else np.maximum(0, owned - inside)
        )
        if not least.sum() > 0:
            return False
    return True


@dataclass(frozen=True)
class NoChange:
    """Why no change of one coefficient is suggested: ``impossible`` when no coefficient enters
    the g_J of every violating J, else none of the candidates tried worked."""

    impossible: bool


def smallest_change(
    document: dict, friction: Friction, analysis: UniquenessAnalysis, acceptable: FrictionTest, source: str
) -> Change | NoChange:
    """The smallest change of one coefficient (module docstring) after which ``acceptable``
    holds for the changed friction, or why there is none within `MAX_TRIALS`
    (`MAX_TRIALS_LARGE`) tests."""
    forward, backward = friction
    slots = [s for s in friction_slots(document, len(forward)) if _enters_every(s, analysis)]
    if not slots:
        return NoChange(impossible=True)
    scale = max((abs(s.value) for s in slots), default=1.0) or 1.0
    candidates = sorted(
        ((step, i, sign) for i, slot in enumerate(slots) for step in _steps(slot.value, scale) for sign in (1, -1)),
        key=lambda c: (c[0], c[1], -c[2]),
    )
    for step, i, sign in candidates[: MAX_TRIALS if analysis.complete else MAX_TRIALS_LARGE]:
        slot = slots[i]
        new = float(Decimal(repr(slot.value)) + sign * step)
        changed = _changed(document, slot, new, source)
        if changed is None or not changed.minimum()[0] > 0:
            continue
        signals = list(forward if slot.direction == "forward" else backward)
        for j in slot.blocks:
            signals[j] = changed
        trial = (tuple(signals), backward) if slot.direction == "forward" else (forward, tuple(signals))
        if acceptable(*trial):
            return Change(slot, new)
    return NoChange(impossible=False)


def _changed(document: dict, slot: Slot, new: float, source: str) -> Signal | None:
    """The slot's signal with its number set to ``new``; None if that is not a valid signal."""
    head, _, direction = slot.signal_path.rpartition(".")
    friction = document["friction"]
    entry = friction if head == "friction" else friction[int(head[len("friction[") : -1])]
    signal = copy.deepcopy(entry[direction])
    if not slot.inner:
        signal = new
    else:
        node = signal
        for key in slot.inner[:-1]:
            node = node[key]
        node[slot.inner[-1]] = new
    try:
        return parse_signal(signal, slot.keypath, source)
    except GaitError:
        return None


def uniqueness_message(
    document: dict,
    forward: Sequence[Signal],
    backward: Sequence[Signal],
    analysis: UniquenessAnalysis,
    period: float,
    acceptable: FrictionTest,
    loaded: bool = False,
    source: str = "",
) -> str:
    """The refusal: every violating J with its intervals, then the fix (`smallest_change`)."""
    note = (
        " Here mu+ and mu- are the thresholds shifted by the loads, mu cos(angle) -+ F "
        "(docs/model.md §6): change the load or the friction."
        if loaded
        else ""
    )
    change = smallest_change(document, (tuple(forward), tuple(backward)), analysis, acceptable, source)
    return analysis.message(period, remedy_text(change)) + note


def remedy_text(change: Change | NoChange) -> str:
    """The sentence that ends a refusal: the change, or why there is none."""
    if isinstance(change, Change):
        return change.text() + "."
    if change.impossible:
        return (
            "No single friction coefficient of the file enters the g_J of every subset "
            "above (blocks of the same friction are exchanged between them), so no change "
            "of one coefficient restores it: change the friction of those blocks together "
            "(one shared 'friction: {forward: ..., backward: ...}' moves all blocks at "
            "once), or one coefficient in the g_J of each subset (mu+ of a block in J or mu- "
            "of a block outside it)."
        )
    return (
        "No change of one friction coefficient among the smallest tried restores it: "
        "change one coefficient in the g_J of each subset above (mu+ of a block in J "
        "or mu- of a block outside it)."
    )
