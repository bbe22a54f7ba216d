"""Physical units: a gait file's ``units:`` block and the units of every derived quantity.

The model has three base dimensions (docs/model.md §1): length (positions, shape, actuator
lengths, slips), time (t, the period T) and force (stresses, friction coefficients, the state
w = -K z of a crawler). A gait file may name a unit for each:

    units: {length: mm, time: s, force: N}

Each key is optional; a base dimension without a unit counts as dimensionless, so a file without
the block is dimensionless throughout ("1", the CF/UDUNITS spelling). Every other unit is built
from the three: velocity = length/time, stress = force, dissipation = force length,
stiffness = force/length. Unit strings are written as given, products with a space and
quotients with "/" (UDUNITS syntax), so "mm/s" and "N mm".

This module imports nothing heavy: the gait schema and the results files both use it.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

BASES = ("length", "time", "force")

UNITS_SCHEMA: dict[str, Any] = {
    "type": "object",
    "x-expected": "a mapping {length: ..., time: ..., force: ...} of unit names, for example "
    "{length: mm, time: s, force: N}",
    "additionalProperties": False,
    "properties": {
        base: {
            "type": "string",
            "minLength": 1,
            "pattern": r"\S",
            "x-expected": f"a non-blank unit name for {base} (a string such as {example!r})",
        }
        for base, example in zip(BASES, ("mm", "s", "N"))
    },
}
"""JSON Schema of the ``units:`` block (unknown keys are refused like everywhere else)."""

#: Exponents of the base dimensions of each quantity crawlsim writes.
QUANTITIES: dict[str, dict[str, Fraction]] = {
    "1": {},
    "length": {"length": Fraction(1)},
    "time": {"time": Fraction(1)},
    "force": {"force": Fraction(1)},
    "velocity": {"length": Fraction(1), "time": Fraction(-1)},
    "stiffness": {"force": Fraction(1), "length": Fraction(-1)},
    "compliance": {"length": Fraction(1), "force": Fraction(-1)},
    "dissipation": {"force": Fraction(1), "length": Fraction(1)},
    # The L^2(t0, t0+T) norm of a rate: sqrt(int |dx/dt|^2 dt) is a length per sqrt(time).
    "velocity_l2": {"length": Fraction(1), "time": Fraction(-1, 2)},
    "force_l2": {"force": Fraction(1), "time": Fraction(1, 2)},
}


#: The unit names a gait file may give, by base dimension: SI symbols with the common prefixes
#: (UDUNITS/CF spelling, so the results files' ``units`` attributes are read by every CF tool),
#: "u" or "µ" for micro, and a few customary units. docs/model.md lists them.
UNIT_NAMES: dict[str, tuple[str, ...]] = {
    "length": ("m", "km", "dm", "cm", "mm", "um", "µm", "nm", "in", "ft"),
    "time": ("s", "ms", "us", "µs", "ns", "min", "h"),
    "force": ("N", "kN", "mN", "uN", "µN", "nN", "dyn", "lbf"),
}

#: Names written out (lower case, singular or plural, British or American), and the symbol
#: they stand for: suggested, never accepted, so that every file spells a unit one way.
_SPELLED_OUT = {
    "meter": "m",
    "metre": "m",
    "kilometer": "km",
    "kilometre": "km",
    "centimeter": "cm",
    "centimetre": "cm",
    "millimeter": "mm",
    "millimetre": "mm",
    "micrometer": "um",
    "micrometre": "um",
    "micron": "um",
    "nanometer": "nm",
    "nanometre": "nm",
    "inch": "in",
    "inches": "in",
    "foot": "ft",
    "feet": "ft",
    "second": "s",
    "sec": "s",
    "millisecond": "ms",
    "msec": "ms",
    "microsecond": "us",
    "nanosecond": "ns",
    "minute": "min",
    "hour": "h",
    "hr": "h",
    "newton": "N",
    "kilonewton": "kN",
    "millinewton": "mN",
    "micronewton": "uN",
    "nanonewton": "nN",
    "dyne": "dyn",
    "pound-force": "lbf",
    "pound force": "lbf",
    "lb": "lbf",
}


def unit_problem(base: str, name: str) -> str | None:
    """Why ``name`` is not a unit of the base dimension ``base`` (None when it is one of
    `UNIT_NAMES`): what was expected, a unit of another dimension named as such, and the
    nearest accepted names (a spelled-out name such as "Newtons" gets its symbol)."""
    accepted = UNIT_NAMES[base]
    if name in accepted:
        return None
    expected = f"a unit of {base}, one of {', '.join(accepted)}"
    word = name.strip().lower()
    singular = word[:-1] if word.endswith("s") and word[:-1] in _SPELLED_OUT else word
    if singular in _SPELLED_OUT:
        symbol = _SPELLED_OUT[singular]
        if symbol in accepted:
            return f"expected {expected}; got {name!r}: write its symbol, {symbol!r} (did you mean {symbol!r}?)"
    for other, names in UNIT_NAMES.items():
        if name in names or _SPELLED_OUT.get(singular) in names:
            return f"expected {expected}; got {name!r}, a unit of {other}"
    same_letters = [a for a in accepted if a.lower() == word]
    if len(same_letters) == 1:  # "MM": the case is wrong, not the unit
        return f"expected {expected}; got {name!r}; did you mean {same_letters[0]!r}?"
    pool = list(accepted) + [k for k, v in _SPELLED_OUT.items() if v in accepted]
    close = difflib.get_close_matches(name, pool, n=3, cutoff=0.5) or difflib.get_close_matches(
        word, pool, n=3, cutoff=0.5
    )
    suggestions = list(dict.fromkeys(_SPELLED_OUT.get(c, c) for c in close))
    hint = f"; did you mean {' or '.join(map(repr, suggestions))}?" if suggestions else ""
    return f"expected {expected}; got {name!r}{hint}"


def unit_problems(block: Mapping[str, Any] | None) -> list[tuple[str, str]]:
    """(key path, message) for each unit of a gait file's ``units:`` block that is not in
    `UNIT_NAMES` (the block's structure is the schema's to check)."""
    if not isinstance(block, Mapping):
        return []
    found = []
    for base in BASES:
        name = block.get(base)
        if isinstance(name, str):
            problem = unit_problem(base, name)
            if problem is not None:
                found.append((f"units.{base}", problem))
    return found


@dataclass(frozen=True)
class Units:
    """The unit names of the base dimensions; None where the gait file gives none."""

    length: str | None = None
    time: str | None = None
    force: str | None = None

    @classmethod
    def from_block(cls, block: Mapping[str, str] | None) -> Units:
        """From a validated ``units:`` mapping (None or absent keys: dimensionless)."""
        block = block or {}
        return cls(**{base: block.get(base) for base in BASES})

    @classmethod
    def parse(cls, value: Any) -> Units:
        """From a results file's ``units_json`` attribute (a JSON object), a mapping, or None.

        Lenient, unlike `from_block`: anything that is not a mapping of non-blank strings gives
        no units, because a figure or a report is never refused for its labels.
        """
        if isinstance(value, bytes):
            value = value.decode("utf-8", "replace")
        if isinstance(value, str):
            try:
                value = json.loads(value)
            except ValueError:
                return cls()
        if not isinstance(value, Mapping):
            return cls()
        return cls(**{k: str(value[k]) for k in BASES if isinstance(value.get(k), str) and value[k].strip()})

    def to_json(self) -> dict[str, str]:
        """The block as given: only the base dimensions that have a unit."""
        return {base: value for base in BASES if (value := getattr(self, base)) is not None}

    def of(self, quantity: str) -> str:
        """The unit of ``quantity`` (a key of `QUANTITIES`), "1" when it is dimensionless; a
        slope's ``angle`` is always in degrees (docs/model.md §6)."""
        if quantity == "angle":
            return "degree"
        return self.compose(QUANTITIES[quantity])

    def compose(self, exponents: Mapping[str, Fraction]) -> str:
        """A unit string from base exponents, UDUNITS style: "N mm", "mm/s", "mm/s^(1/2)"."""
        numerator: list[str] = []
        denominator: list[str] = []
        for base in ("force", "length", "time"):  # "N mm" for energy, as "N m" is written
            power = Fraction(exponents.get(base, 0))
            name = getattr(self, base)
            if power == 0 or name is None:
                continue
            target = numerator if power > 0 else denominator
            target.append(_power(name, abs(power)))
        text = " ".join(numerator) or "1"
        if denominator:
            below = denominator[0] if len(denominator) == 1 else f"({' '.join(denominator)})"
            text = f"{text}/{below}"
        return text

    def derivative(self, kind: str, path: str) -> str:
        """The unit of dv0/dPATH: v0's over PATH's (``mm/s`` over ``N``: ``mm/(N s)``, composed
        from the base exponents; per degree for a slope's angle)."""
        quantity = path_quantity(kind, tuple(int(k) if k.isdigit() else k for k in path.split(".")))
        velocity = self.of("velocity")
        if quantity == "angle":
            return f"{velocity}/degree" if velocity != "1" else "1/degree"
        v, q = QUANTITIES["velocity"], QUANTITIES[quantity]
        return self.compose({b: Fraction(v.get(b, 0)) - Fraction(q.get(b, 0)) for b in set(v) | set(q)})

    def suffix(self, quantity: str) -> str:
        """ " mm/s" to append to a printed number, or "" when the quantity is dimensionless."""
        unit = self.of(quantity)
        return "" if unit == "1" else f" {unit}"


def _power(name: str, power: Fraction) -> str:
    if any(c in name for c in " /*^"):
        name = f"({name})"
    if power == 1:
        return name
    return f"{name}^{power}" if power.denominator == 1 else f"{name}^({power})"


def path_quantity(kind: str, keys: tuple[str | int, ...]) -> str:
    """The quantity of the number at a dotted path of a gait document, for the units of swept
    values: ``links.*.amplitude`` is a length, ``friction.backward`` a force, ``period`` a time,
    a signal's ``phase`` and ``times`` are in cycles (dimensionless)."""
    names = [k for k in keys if isinstance(k, str)]
    if not names or names[0] in ("simulation", "blocks", "units"):
        return "1"
    if names[-1] in ("phase", "times", "phase_step"):
        return "1"
    first = names[0]
    if first == "period":
        return "time"
    if kind == "sweeping-process":
        return "length" if first in ("offsets", "initial") else "1"
    if first == "loads":  # forces and weights; a slope's angle in degrees (docs/model.md §6)
        return "angle" if names[-1] == "angle" else "force"
    return {"stiffness": "stiffness", "links": "length", "friction": "force", "initial": "length"}.get(first, "1")
