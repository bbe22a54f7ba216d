"""T-periodic scalar signals: the actuator lengths L_i(t) and friction coefficients mu_j^+-(t).

Time inside a signal is measured in cycles, u = t / T, so every signal has period 1 whatever
the gait's period T. This keeps the gait description independent of T, which is what
rate-independence promises (docs/model.md §4: rescaling T leaves the displacement per period
unchanged).

Every kind accepts a `phase` in cycles, s(t) = profile(t/T - phase). Non-smooth kinds
(piecewise-linear, steps) report their kinks and jumps as breakpoints, because the stepping grid
must contain them (docs/model.md §4, "Breakpoints") and because the uniqueness check of
`crawlsim.gait.document` relies on every signal being analytic between breakpoints.

Signals are checked by the helpers of `crawlsim.gait.schemaerrors`, shared with every gait
document, so a signal found anywhere in a gait file is reported with the same key path style
(`links[0].amplitude`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.schemaerrors import LARGEST, check_finite, check_schema, join_keypath

JUMP_TOLERANCE = 1e-12
"""Cycles within which a time counts as sitting on a jump or kink.

Phase arithmetic in floating point moves a jump by a few ulps (1/3 + phase - phase != 1/3), so
a grid point meant to land on a jump may fall just before it. Treating such a point as on the
jump makes step signals right-continuous in practice, not only in exact arithmetic.
"""

MINIMUM_GRID = 4096
"""Samples per cycle used to locate the minimum of a smooth signal before refining it."""

MAX_PHASE = 1e6
"""Largest |phase|, in cycles. A phase shifts by whole cycles without effect, and a double of
magnitude 2^52 or more holds no fraction of a cycle at all (``phase: 1e308`` is a whole number of
cycles): a phase this large is a slip (degrees or radians typed as cycles), not a gait."""

MAX_HARMONICS = 1000
"""Most coefficients in a Fourier signal's ``cos`` or ``sin`` list."""

MAX_KNOTS = 10000
"""Most knots (times) in a piecewise-linear or steps signal: each is a breakpoint that the
stepping grid must contain, so they cost memory in every period."""

_CHUNK_ENTRIES = 1 << 18
"""Fourier signals are evaluated on chunks of this many (time, harmonic) pairs: their memory is
bounded whatever the number of times asked for."""


def _cycles(u: Any) -> np.ndarray:
    return np.asarray(u, dtype=float)


def _reduced(phase: float) -> float:
    """The phase modulo one cycle, keeping its sign. fmod is exact in floating point, so this
    loses nothing, while ``u - phase`` for a phase of many cycles would lose the low bits of u."""
    return math.fmod(float(phase), 1.0)


def _wrap(v: np.ndarray) -> np.ndarray:
    """Reduce cycles to [0, 1), sending points within JUMP_TOLERANCE below 1 to 0."""
    w = np.mod(v, 1.0)
    return np.where(w >= 1.0 - JUMP_TOLERANCE, w - 1.0, w)


def union_breakpoints(arrays: Sequence[np.ndarray]) -> np.ndarray:
    """Sorted union of breakpoint arrays in [0, 1), merging points closer than JUMP_TOLERANCE."""
    if not arrays:
        return np.empty(0)
    allpoints = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in arrays])
    if allpoints.size == 0:
        return np.empty(0)
    points = np.sort(np.maximum(_wrap(allpoints), 0.0))
    keep = np.concatenate([[True], np.diff(points) > JUMP_TOLERANCE])
    return points[keep]


@dataclass(frozen=True)
class Signal:
    """A 1-periodic function of the cycle u = t / T (see the module docstring)."""

    kind: ClassVar[str] = ""
    is_smooth: ClassVar[bool] = True
    harmonics: ClassVar[int] = 0

    def __call__(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def rate(self, u: np.ndarray) -> np.ndarray:
        """d s / d u, per cycle (divide by T for a rate per unit time)."""
        raise NotImplementedError

    def breakpoints(self) -> np.ndarray:
        """Cycles in [0, 1) where the signal has a kink or jump; empty for smooth kinds."""
        return np.empty(0)

    def to_dict(self) -> dict | float:
        """The YAML form; `parse_signal(s.to_dict(), ...) == s`."""
        raise NotImplementedError

    def minimum(self) -> tuple[float, float]:
        """(min value, a cycle in [0, 1) where it is attained).

        Used to prove friction positive (docs/model.md §1: mu > 0). Smooth kinds are sampled on a
        fine grid, then the best sample is refined by golden-section search inside its cell.
        """
        grid = np.arange(MINIMUM_GRID) / MINIMUM_GRID
        values = self(grid)
        i = int(np.argmin(values))
        lo, hi = grid[i] - 1.0 / MINIMUM_GRID, grid[i] + 1.0 / MINIMUM_GRID
        ratio = (math.sqrt(5.0) - 1.0) / 2.0
        for _ in range(60):
            a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
            if self(np.array([a]))[0] < self(np.array([b]))[0]:
                hi = b
            else:
                lo = a
        best = 0.5 * (lo + hi)
        refined = float(self(np.array([best]))[0])
        if refined < values[i]:
            return refined, float(np.mod(best, 1.0))
        return float(values[i]), float(grid[i])


@dataclass(frozen=True)
class Constant(Signal):
    """A constant, written in YAML as a plain number."""

    value: float

    kind: ClassVar[str] = "constant"

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", float(self.value))

    def __call__(self, u: np.ndarray) -> np.ndarray:
        return np.full(np.shape(u), self.value)

    def rate(self, u: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(u))

    def to_dict(self) -> float:
        return self.value

    def minimum(self) -> tuple[float, float]:
        return self.value, 0.0


@dataclass(frozen=True)
class Cosine(Signal):
    """mean + amplitude * cos(2 pi (u - phase))."""

    mean: float
    amplitude: float
    phase: float = 0.0

    kind: ClassVar[str] = "cosine"
    harmonics: ClassVar[int] = 1

    def __post_init__(self) -> None:
        for name in ("mean", "amplitude"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "phase", _reduced(self.phase))

    def _angle(self, u: np.ndarray) -> np.ndarray:
        return 2.0 * np.pi * np.mod(_cycles(u) - self.phase, 1.0)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        return self.mean + self.amplitude * np.cos(self._angle(u))

    def rate(self, u: np.ndarray) -> np.ndarray:
        return -2.0 * np.pi * self.amplitude * np.sin(self._angle(u))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "mean": self.mean, "amplitude": self.amplitude, "phase": self.phase}

    def minimum(self) -> tuple[float, float]:
        at = 0.5 if self.amplitude > 0 else 0.0
        return self.mean - abs(self.amplitude), float(_wrap(np.array(at + self.phase)))


@dataclass(frozen=True)
class Fourier(Signal):
    """mean + sum_n cos[n-1] cos(2 pi n v) + sin[n-1] sin(2 pi n v), v = u - phase.

    `cos` and `sin` may differ in length; missing coefficients are zero, and both empty is a
    constant.
    """

    mean: float
    cos: tuple[float, ...] = ()
    sin: tuple[float, ...] = ()
    phase: float = 0.0

    kind: ClassVar[str] = "fourier"

    def __post_init__(self) -> None:
        object.__setattr__(self, "mean", float(self.mean))
        object.__setattr__(self, "phase", _reduced(self.phase))
        object.__setattr__(self, "cos", tuple(float(c) for c in self.cos))
        object.__setattr__(self, "sin", tuple(float(c) for c in self.sin))

    @property
    def harmonics(self) -> int:  # type: ignore[override]
        return max(len(self.cos), len(self.sin))

    def _terms(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        h = self.harmonics
        a = np.zeros(h)
        b = np.zeros(h)
        a[: len(self.cos)] = self.cos
        b[: len(self.sin)] = self.sin
        n = np.arange(1, h + 1)
        angle = 2.0 * np.pi * np.mod(_cycles(u) - self.phase, 1.0)[..., None] * n
        return np.cos(angle), np.sin(angle), a, b, n

    def _chunked(self, u: np.ndarray, part) -> np.ndarray:
        u = _cycles(u)
        flat = np.ravel(u)
        step = max(1, _CHUNK_ENTRIES // max(1, self.harmonics))
        if flat.size <= step:
            return part(u)
        out = np.empty(flat.size)
        for start in range(0, flat.size, step):
            out[start : start + step] = part(flat[start : start + step])
        return out.reshape(u.shape)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        def part(v):
            c, s, a, b, _ = self._terms(v)
            return self.mean + c @ a + s @ b

        return self._chunked(u, part)

    def rate(self, u: np.ndarray) -> np.ndarray:
        def part(v):
            c, s, a, b, n = self._terms(v)
            return 2.0 * np.pi * (c @ (n * b) - s @ (n * a))

        return self._chunked(u, part)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "mean": self.mean, "cos": list(self.cos), "sin": list(self.sin), "phase": self.phase}


def _check_knots(times: tuple[float, ...], values: tuple[float, ...], last_time_allowed: bool) -> None:
    """Refuse knot lists that do not describe one cycle [0, 1] in increasing order."""
    if len(values) != len(times):
        raise GaitError("signal", "values", f"expected as many values as times ({len(times)}), got {len(values)}")
    if times[0] != 0.0:
        raise GaitError(
            "signal", "times[0]", f"expected 0, got {times[0]:g}: the times are in cycles and cover one cycle from 0"
        )
    for i in range(1, len(times)):
        if not times[i] > times[i - 1]:
            raise GaitError(
                "signal",
                f"times[{i}]",
                f"expected times strictly increasing, but times[{i}] = {times[i]:g} "
                f"<= times[{i - 1}] = {times[i - 1]:g}",
            )
    last = len(times) - 1
    if last_time_allowed and times[last] != 1.0:
        raise GaitError(
            "signal",
            f"times[{last}]",
            f"expected 1, got {times[last]:g}: a piecewise-linear signal spans one cycle [0, 1]",
        )
    if not last_time_allowed and times[last] >= 1.0:
        raise GaitError(
            "signal",
            f"times[{last}]",
            f"expected a time < 1 cycle, got {times[last]:g}: a step at 1 is the step at 0 of the next cycle",
        )


@dataclass(frozen=True)
class PiecewiseLinear(Signal):
    """Periodic linear interpolation through (times[i], values[i]), times spanning [0, 1].

    values[0] must equal values[-1] exactly: the signal is T-periodic, and a mismatch would be a
    jump at the end of every cycle that the user did not ask for.
    """

    times: tuple[float, ...]
    values: tuple[float, ...]
    phase: float = 0.0

    kind: ClassVar[str] = "piecewise-linear"
    is_smooth: ClassVar[bool] = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "times", tuple(float(t) for t in self.times))
        object.__setattr__(self, "values", tuple(float(v) for v in self.values))
        object.__setattr__(self, "phase", _reduced(self.phase))
        if len(self.times) < 2:
            raise GaitError("signal", "times", "expected at least two knots (times 0 and 1)")
        _check_knots(self.times, self.values, last_time_allowed=True)
        if self.values[0] != self.values[-1]:
            raise GaitError(
                "signal",
                "values",
                f"a piecewise-linear signal must be periodic: values[0] = {self.values[0]:g} "
                f"and values[-1] = {self.values[-1]:g} must be equal (the last knot at 1 "
                "is the first knot of the next cycle)",
            )

    def _local(self, u: np.ndarray) -> np.ndarray:
        return _wrap(_cycles(u) - self.phase)

    def _slopes(self) -> np.ndarray:
        return np.diff(self.values) / np.diff(self.times)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        return np.interp(np.maximum(self._local(u), 0.0), self.times, self.values)

    def rate(self, u: np.ndarray) -> np.ndarray:
        v = self._local(u)
        piece = np.searchsorted(self.times, v + JUMP_TOLERANCE, side="right") - 1
        return self._slopes()[np.clip(piece, 0, len(self.times) - 2)]

    def breakpoints(self) -> np.ndarray:
        slopes = self._slopes()
        kinks = np.asarray(self.times[:-1])[slopes != np.roll(slopes, 1)]
        return union_breakpoints([kinks + self.phase])

    def to_dict(self) -> dict:
        return {"kind": self.kind, "times": list(self.times), "values": list(self.values), "phase": self.phase}

    def minimum(self) -> tuple[float, float]:
        i = int(np.argmin(self.values))
        return self.values[i], max(float(_wrap(np.array(self.times[i] + self.phase))), 0.0)


@dataclass(frozen=True)
class Steps(Signal):
    """Piecewise-constant: values[i] on [times[i], times[i+1]), periodically, right-continuous.

    A time within JUMP_TOLERANCE cycles below a jump already takes the new value, so a grid
    point placed on a phase-shifted jump gets the right-hand value despite roundoff.
    """

    times: tuple[float, ...]
    values: tuple[float, ...]
    phase: float = 0.0

    kind: ClassVar[str] = "steps"
    is_smooth: ClassVar[bool] = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "times", tuple(float(t) for t in self.times))
        object.__setattr__(self, "values", tuple(float(v) for v in self.values))
        object.__setattr__(self, "phase", _reduced(self.phase))
        if len(self.times) < 1:
            raise GaitError("signal", "times", "expected at least one step (at time 0)")
        _check_knots(self.times, self.values, last_time_allowed=False)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        v = _wrap(_cycles(u) - self.phase)
        step = np.searchsorted(self.times, v + JUMP_TOLERANCE, side="right") - 1
        return np.asarray(self.values)[np.clip(step, 0, len(self.times) - 1)]

    def rate(self, u: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(u))

    def breakpoints(self) -> np.ndarray:
        values = np.asarray(self.values)
        jumps = np.asarray(self.times)[values != np.roll(values, 1)]
        return union_breakpoints([jumps + self.phase])

    def to_dict(self) -> dict:
        return {"kind": self.kind, "times": list(self.times), "values": list(self.values), "phase": self.phase}

    def minimum(self) -> tuple[float, float]:
        i = int(np.argmin(self.values))
        return self.values[i], max(float(_wrap(np.array(self.times[i] + self.phase))), 0.0)


KINDS: dict[str, type[Signal]] = {cls.kind: cls for cls in (Cosine, Fourier, PiecewiseLinear, Steps)}
"""Signal kinds written as a mapping with 'kind' (constants are plain numbers)."""

_NUMBER = {
    "type": "number",
    "minimum": -LARGEST,
    "maximum": LARGEST,
    "x-expected": "a number",
    "description": "A finite number of magnitude at most 1e100 (every number of a gait is: "
    "within it no product the model forms overflows a double).",
}
_NUMBERS = {"type": "array", "items": _NUMBER, "x-expected": "a list of numbers"}
_PHASE = {
    "type": "number",
    "minimum": -MAX_PHASE,
    "maximum": MAX_PHASE,
    "x-expected": f"a phase in cycles, at most {MAX_PHASE:g} in magnitude",
    "description": "Shift in cycles: s(t) = profile(t/T - phase). Whole cycles change nothing; "
    "|phase| <= 1e6, since a double that large holds almost no fraction of a "
    "cycle (from 2^52 on, none).",
}
# maxItems before items: a refused huge list is refused before its items are validated
_COEFFICIENTS = {
    "type": "array",
    "maxItems": MAX_HARMONICS,
    **_NUMBERS,
    "description": f"Fourier coefficients of harmonics 1, 2, ...; at most {MAX_HARMONICS}.",
}
_KNOTS = {
    "type": "array",
    "maxItems": MAX_KNOTS,
    **_NUMBERS,
    "description": f"At most {MAX_KNOTS} knots: each is a breakpoint the stepping grid must contain.",
}
_KIND_SCHEMAS: dict[str, dict[str, Any]] = {
    "cosine": {
        "required": ["mean", "amplitude"],
        "properties": {"mean": _NUMBER, "amplitude": _NUMBER, "phase": _PHASE},
    },
    "fourier": {
        "required": ["mean"],
        "properties": {"mean": _NUMBER, "cos": _COEFFICIENTS, "sin": _COEFFICIENTS, "phase": _PHASE},
    },
    "piecewise-linear": {
        "required": ["times", "values"],
        "properties": {"times": {"minItems": 2, **_KNOTS}, "values": _KNOTS, "phase": _PHASE},
    },
    "steps": {
        "required": ["times", "values"],
        "properties": {"times": {"minItems": 1, **_KNOTS}, "values": _KNOTS, "phase": _PHASE},
    },
}

SIGNAL_SCHEMA: dict = {
    "type": ["number", "object"],
    "x-expected": "a number or a signal mapping with 'kind'",
    "description": "A T-periodic signal of the cycle u = t/T: a constant (a plain number) or a "
    "mapping with 'kind' (cosine, fourier, piecewise-linear, steps).",
    "minimum": -LARGEST,
    "maximum": LARGEST,
    "if": {"type": "object"},
    "then": {
        "required": ["kind"],
        "properties": {"kind": {"enum": list(KINDS)}},
        "allOf": [
            {
                "if": {"properties": {"kind": {"const": kind}}, "required": ["kind"]},
                "then": {
                    **schema,
                    "properties": {"kind": {"const": kind}, **schema["properties"]},
                    "additionalProperties": False,
                },
            }
            for kind, schema in _KIND_SCHEMAS.items()
        ],
    },
}
"""JSON Schema (Draft 2020-12) of one signal; `x-expected` phrases the error message."""

#: Signals already found valid, by their repr: a crawler of 10^5 blocks repeats a few signals
#: 10^5 times, and validating one costs ~0.1 ms.
_VALID_SIGNALS: set[str] = set()
_VALID_SIGNALS_MAX = 1 << 16


def parse_signal(value: Any, keypath: str, source: str) -> Signal:
    """Build a signal from its YAML form, raising GaitError naming `keypath` in `source`."""
    check_finite(value, source, keypath)
    key = repr(value)
    if key not in _VALID_SIGNALS:
        check_schema(value, SIGNAL_SCHEMA, source, keypath)
        if len(_VALID_SIGNALS) >= _VALID_SIGNALS_MAX:
            _VALID_SIGNALS.clear()
        _VALID_SIGNALS.add(key)
    if not isinstance(value, dict):
        return Constant(value)
    fields = {key: item for key, item in value.items() if key != "kind"}
    try:
        return KINDS[value["kind"]](**fields)
    except GaitError as error:
        raise GaitError(source, join_keypath(keypath, error.keypath), error.message) from None


def evaluate_many(signals: Sequence[Signal], u: np.ndarray) -> np.ndarray:
    """Values of several signals at cycles u, shape (len(u), len(signals))."""
    u = np.ravel(_cycles(u))
    if not signals:
        return np.empty((u.size, 0))
    # each distinct signal once: a crawler of 10^5 blocks shares one or two friction signals
    index: dict[Signal, int] = {}
    columns = [index.setdefault(signal, len(index)) for signal in signals]
    values = np.column_stack([signal(u) for signal in index])
    return values if len(index) == len(columns) else values[:, columns]


def without_signals(schema: Any, signal: dict | None = None) -> Any:
    """A copy of ``schema`` that accepts anything where a signal goes (`SIGNAL_SCHEMA`).

    A document's structure is validated with it, then each signal on its own (`parse_signal`,
    which remembers valid signals): a crawler of 10^5 blocks repeats a few signals 10^5 times.
    """
    signal = SIGNAL_SCHEMA if signal is None else signal
    if schema is signal:
        return True
    if isinstance(schema, dict):
        return {key: without_signals(value, signal) for key, value in schema.items()}
    if isinstance(schema, list):
        return [without_signals(value, signal) for value in schema]
    return schema
