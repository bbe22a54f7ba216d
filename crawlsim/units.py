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
    "properties": {base: {"type": "string", "minLength": 1, "pattern": r"\S",
                          "x-expected": f"a non-blank unit name for {base} (a string such "
                                        f"as {example!r})"}
                   for base, example in zip(BASES, ("mm", "s", "N"))},
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

    def to_json(self) -> dict[str, str]:
        """The block as given: only the base dimensions that have a unit."""
        return {base: value for base in BASES if (value := getattr(self, base)) is not None}

    @property
    def dimensionless(self) -> bool:
        return not self.to_json()

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

    def suffix(self, quantity: str) -> str:
        """" mm/s" to append to a printed number, or "" when the quantity is dimensionless."""
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
    if names[-1] in ("phase", "times"):
        return "1"
    first = names[0]
    if first == "period":
        return "time"
    if kind == "sweeping-process":
        return "length" if first in ("offsets", "initial") else "1"
    if first == "loads":  # forces and weights; a slope's angle in degrees (docs/model.md §6)
        return "angle" if names[-1] == "angle" else "force"
    return {"stiffness": "stiffness", "links": "length", "friction": "force",
            "initial": "length"}.get(first, "1")
