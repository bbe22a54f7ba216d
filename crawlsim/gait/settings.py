"""The numerical settings of a gait file (``simulation:``) and the bounds every gait document
shares; none of them changes the model, only how it is stepped.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from crawlsim.gait.schemaerrors import LARGEST

ROUNDOFF = 1e-12
"""Relative tolerance of the admissibility checks: roundoff, not a modelling slack."""


@dataclass(frozen=True)
class Simulation:
    """Numerical settings of a run; none of them changes the model, only how it is stepped."""

    steps_per_period: int = 1000
    max_periods: int = 1000
    tolerance: float = 1e-12
    integrator: str = "exact"
    limit: str = "newton"  # how the periodic limit is found (crawlsim.integrate.limit), or "iterate"
    unchecked_uniqueness: bool = False  # run even where uniqueness is beyond an exact check


ROUNDOFF_FLOOR = 1e-13
"""Relative Poincare steps below this are roundoff: a smaller tolerance is clamped to it."""


def effective_tolerance(tolerance: float) -> float:
    """The Poincare-step tolerance actually used: relative steps below roundoff are clamped."""
    return max(float(tolerance), ROUNDOFF_FLOOR)


MAX_BLOCKS = 100_000
"""Most blocks in a crawler. A step costs O(N) once the kernel uses the crawler's structure, but
every period tabulates (steps per period) x 2N numbers; the memory estimate decides the rest."""

MAX_STEPS_PER_PERIOD = 100_000_000
"""Most uniform steps per period: a period's grid alone is then 0.8 GB per tabulated column."""

MAX_PERIODS = 1_000_000
"""Most periods of one run. With the largest step count, max_periods x steps_per_period stays
below 2^52 / 16, so every time of a run resolves its step."""

MIN_PERIOD, MAX_PERIOD = 1e-9, 1e9
"""Bounds of the period T. The model is rate-independent (docs/model.md §4): T only rescales
time, so these lose nothing, and within them every time of a run (up to max_periods x T) and
every rate (up to amplitude x 2 pi x harmonics / T) is far from overflow and resolves a step."""


def positive_schema(what: str, description: str = "") -> dict:
    return {
        "type": "number",
        "exclusiveMinimum": 0,
        "maximum": LARGEST,
        "x-expected": f"a positive number ({what})",
        **({"description": description} if description else {}),
    }


def count_schema(what: str, most: int, description: str) -> dict:
    return {
        "type": "integer",
        "minimum": 1,
        "maximum": most,
        "x-expected": f"an integer from 1 to {most:,} ({what})",
        "description": description,
    }


def list_schema(most: int, what: str, items: Any) -> dict:
    # maxItems before items: a refused huge list is refused before its items are validated
    return {"type": "array", "maxItems": most, "x-expected": what, "items": items}


SIMULATION_SCHEMA: dict = {
    "type": "object",
    "x-expected": "a mapping of simulation settings",
    "additionalProperties": False,
    "properties": {
        "steps_per_period": count_schema(
            "time steps per period",
            MAX_STEPS_PER_PERIOD,
            "Uniform catch-up steps per period (the breakpoints are added). "
            "Memory grows with it; the run estimates it before starting.",
        ),
        "max_periods": count_schema("the most periods to simulate", MAX_PERIODS, "Give up after this many periods."),
        "tolerance": positive_schema(
            "the convergence tolerance", "Stop when the Poincare step is at most this, relative to |w|."
        ),
        "integrator": {
            "enum": ["exact", "catch-up"],
            "description": "exact: event-driven, v0 to roundoff (the default). "
            "catch-up: the paper's time discretisation, first order in "
            "the step.",
        },
        "limit": {
            "enum": ["newton", "iterate"],
            "description": "How the periodic limit is found: newton, the periodic-limit "
            "solver (the default), or iterate, plain period after period.",
        },
        "unchecked_uniqueness": {
            "type": "boolean",
            "x-expected": "true or false",
            "description": "Run a crawler whose friction is beyond an exact check of the uniqueness "
            "condition (docs/model.md §3) instead of refusing it. The condition is "
            "still checked where it can be; the run warns and its results file "
            "records unchecked_uniqueness = 1.",
        },
    },
}


_SIMULATION_TYPES: dict[str, Callable[[Any], Any]] = {
    "steps_per_period": int,
    "max_periods": int,
    "tolerance": float,
    "integrator": str,
    "limit": str,
    "unchecked_uniqueness": bool,
}


def simulation_from(settings: Mapping[str, Any]) -> Simulation:
    """The settings of a schema-checked ``simulation:`` mapping, each of its type."""
    return Simulation(**{key: _SIMULATION_TYPES[key](value) for key, value in settings.items()})


PERIOD_SCHEMA: dict = {
    **positive_schema("the period T of the gait"),
    "minimum": MIN_PERIOD,
    "maximum": MAX_PERIOD,
    "x-expected": f"a positive number from {MIN_PERIOD:g} to {MAX_PERIOD:g} (the period T)",
    "description": "T, the period of the gait. The model is rate-independent, so T "
    "only rescales time; within [1e-9, 1e9] every time and rate of "
    "a run is representable to a step's resolution.",
}
"""The schema of a document's period T, the same for every kind."""
