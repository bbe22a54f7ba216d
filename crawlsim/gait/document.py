"""Gait files: the YAML description of a crawler and its periodic actuation (docs/model.md §1).

A gait is validated completely before anything is computed. The file is read safely
(`crawlsim.gait.yamlsafe`: a size limit, bounded YAML); jsonschema checks structure, types and
bounds (the schemas state every bound and why); the semantic checks that follow each refuse
something the model cannot handle, and say why: non-positive friction (docs/model.md §1:
mu > 0), stiffness ratios too wide for a certified step in double precision, an initial state
outside the admissible set C(0) (docs/model.md §1), and friction coefficients that violate the
uniqueness condition (docs/model.md §3; decided exactly by `crawlsim.model.uniqueness`), under which
the model does not determine how the crawler moves.

An optional `loads:` block (`crawlsim.model.loads`, docs/model.md §6) puts forces on the blocks and the
crawler on a slope: the friction thresholds are shifted, the body as a whole must be able to hold
its loads, the uniqueness condition is checked on the shifted thresholds, and when the
stress-free start is not admissible a held one is chosen.

`validation_errors` lists every error of a file instead of stopping at the first
(``crawlsim validate``).

Documents are dispatched on their `kind` key (`_KINDS`): `crawler` (the default) builds a `Gait`,
`sweeping-process` a `ProcessSpec`, a generic polyhedral sweeping process of docs/model.md §5. A
process is refused when its dimensions do not match, when C(t) is empty at a time the run steps
on, when C(t) is unbounded (the paper's theorem needs a compact set; `allow_unbounded: true`
accepts it), when the metric is not symmetric positive definite, or when the initial point is
outside C(0).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from crawlsim.errors import GaitError
from crawlsim.gait.signals import (
    LARGEST,
    SIGNAL_SCHEMA,
    Constant,
    Cosine,
    Fourier,
    Signal,
    check_finite,
    check_schema,
    evaluate_many,
    finite_errors,
    parse_signal,
    schema_errors,
    union_breakpoints,
    without_signals,
)
from crawlsim.gait.units import UNITS_SCHEMA, Units, unit_problems
from crawlsim.gait.yamlsafe import load_yaml, read_limited
from crawlsim.model.loads import LOADS_SCHEMA, Loads, held_positions, hold_violation, parse_loads
from crawlsim.model.uniqueness import UniquenessUndecidable, find_violation

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


@dataclass(frozen=True, eq=False)
class Gait:
    """A validated crawler gait. Arrays are read-only; signals take cycles u = t / period."""

    name: str
    description: str
    source: str
    source_text: str
    document: dict
    blocks: int
    period: float
    stiffness: np.ndarray
    links: tuple[Signal, ...]
    forward: tuple[Signal, ...]
    backward: tuple[Signal, ...]
    initial_positions: np.ndarray
    simulation: Simulation
    units: Units = Units()
    #: True when the uniqueness condition could not be checked exactly and the file opted in
    #: (``simulation: {unchecked_uniqueness: true}``); runs warn and record it.
    uniqueness_unchecked: bool = False
    #: External forces and a slope (docs/model.md §6), or None for none.
    loads: Loads | None = None

    def replace(self, *changes: Any) -> Gait:
        """A new validated gait with values set at dotted paths, the syntax of ``--sweep``:
        ``gait.replace("links.*.amplitude", 0.2)``, several pairs
        ``gait.replace("period", 2.0, "links.1.phase", 0.25)`` or one mapping
        ``gait.replace({"period": 2.0})`` (`crawlsim.gait.docpaths`)."""
        from crawlsim.gait.docpaths import replaced

        new = replaced(self, changes)
        assert isinstance(new, Gait)  # a path cannot change the kind: `kind` is not a number
        return new

    def breakpoints(self) -> np.ndarray:
        """Union of all signals' breakpoints, in cycles in [0, 1): the stepping grid needs them."""
        forces = self.loads.forces if self.loads is not None else ()
        return union_breakpoints([s.breakpoints()
                                  for s in self.links + self.forward + self.backward + forces])

    def thresholds(self) -> tuple[tuple[Signal, ...], tuple[Signal, ...]]:
        """The friction thresholds in the elastic force, as signals: (mu^+, mu^-), shifted by
        the loads to (mu~^+, mu~^-) (docs/model.md §6)."""
        if self.loads is None:
            return self.forward, self.backward
        return self.loads.shifted(self.forward, self.backward)

    def lengths(self, t: np.ndarray) -> np.ndarray:
        """Actuator lengths L(t) at times t, shape (len(t), N-1)."""
        return evaluate_many(self.links, np.ravel(np.asarray(t, dtype=float)) / self.period)

    def mu_plus(self, t: np.ndarray) -> np.ndarray:
        """Forward friction coefficients mu^+(t) at times t, shape (len(t), N)."""
        return evaluate_many(self.forward, np.ravel(np.asarray(t, dtype=float)) / self.period)

    def mu_minus(self, t: np.ndarray) -> np.ndarray:
        """Backward friction coefficients mu^-(t) at times t, shape (len(t), N)."""
        return evaluate_many(self.backward, np.ravel(np.asarray(t, dtype=float)) / self.period)


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

STRESS_SCALE_LIMIT = 1e10
"""Largest stress scale max_i k_i |L_i| / min_j mu_j of a crawler (`stress_scale`). The offsets
c = [mu+ - D^T K L; mu- + D^T K L] hold the friction next to elastic forces that many times
larger, so in double precision (and under certificate tolerances of 1e-14 of |c|) the friction
is resolved only to about 1e-14 times this ratio of itself: at 1e12 the decisions of which block
slips err by a quarter of the friction, and v0 by many times its estimate (a two-block inching
gait, v0 = 0.6 - 2/k: 19x its estimate at k = 1e12; a Clarabel failure at 1e18). Up to 1e10
both integrators give the closed form to roundoff (tests/test_certificates.py)."""

STIFFNESS_CONDITION_LIMIT = 1e12
"""Largest estimated condition number (k_max / k_min) N^2 of the active-set Gram matrices
G_A = B_A K B_A^T. Beyond it an exact step cannot be certified in double precision: the
multipliers (the slips) would carry errors far above the certificates' roundoff tolerance."""


def _positive(what: str, description: str = "") -> dict:
    return {"type": "number", "exclusiveMinimum": 0, "maximum": LARGEST,
            "x-expected": f"a positive number ({what})",
            **({"description": description} if description else {})}


def _count(what: str, most: int, description: str) -> dict:
    return {"type": "integer", "minimum": 1, "maximum": most,
            "x-expected": f"an integer from 1 to {most:,} ({what})", "description": description}


def _list(most: int, what: str, items: Any) -> dict:
    # maxItems before items: a refused huge list is refused before its items are validated
    return {"type": "array", "maxItems": most, "x-expected": what, "items": items}


SIMULATION_SCHEMA: dict = {
    "type": "object",
    "x-expected": "a mapping of simulation settings",
    "additionalProperties": False,
    "properties": {
        "steps_per_period": _count("time steps per period", MAX_STEPS_PER_PERIOD,
                                   "Uniform catch-up steps per period (the breakpoints are added). "
                                   "Memory grows with it; the run estimates it before starting."),
        "max_periods": _count("the most periods to simulate", MAX_PERIODS,
                              "Give up after this many periods."),
        "tolerance": _positive("the convergence tolerance",
                               "Stop when the Poincare step is at most this, relative to |w|."),
        "integrator": {"enum": ["exact", "catch-up"],
                       "description": "exact: event-driven, v0 to roundoff (the default). "
                                      "catch-up: the paper's time discretisation, first order in "
                                      "the step."},
        "limit": {"enum": ["newton", "iterate"],
                  "description": "How the periodic limit is found: newton, the periodic-limit "
                                 "solver (the default), or iterate, plain period after period."},
        "unchecked_uniqueness": {
            "type": "boolean", "x-expected": "true or false",
            "description": "Run a crawler whose friction is beyond an exact check of the uniqueness "
                           "condition (docs/model.md §3) instead of refusing it. The condition is "
                           "still checked where it can be; the run warns and its results file "
                           "records unchecked_uniqueness = 1."},
    },
}

_FRICTION_MAPPING = {
    "type": "object",
    "x-expected": "a mapping {forward: mu+, backward: mu-}",
    "required": ["forward", "backward"],
    "additionalProperties": False,
    "properties": {"forward": SIGNAL_SCHEMA, "backward": SIGNAL_SCHEMA},
}

CRAWLER_SCHEMA: dict = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "x-expected": "a mapping (a gait document)",
    "required": ["blocks", "period", "stiffness", "links", "friction"],
    "additionalProperties": False,
    "properties": {
        "kind": {"enum": ["crawler"]},
        "name": {"type": "string"},
        "description": {"type": "string"},
        "blocks": {"type": "integer", "minimum": 2, "maximum": MAX_BLOCKS,
                   "x-expected": f"an integer from 2 to {MAX_BLOCKS:,} (the number of blocks N)",
                   "description": "N, the number of blocks."},
        "period": {**_positive("the period T of the gait"), "minimum": MIN_PERIOD,
                   "maximum": MAX_PERIOD,
                   "x-expected": f"a positive number from {MIN_PERIOD:g} to {MAX_PERIOD:g} (the period T)",
                   "description": "T, the period of the gait. The model is rate-independent, so T "
                                  "only rescales time; within [1e-9, 1e9] every time and rate of "
                                  "a run is representable to a step's resolution."},
        "stiffness": {
            "type": ["number", "array"],
            "x-expected": "a positive number or a list of N-1 positive numbers (spring stiffness k > 0)",
            "exclusiveMinimum": 0,
            "maximum": LARGEST,
            "maxItems": MAX_BLOCKS - 1,
            "items": _positive("the spring stiffness k > 0 of one link"),
            "description": "k, one value for every link or one per link. The ratio k_max / k_min "
                           "times N^2 estimates the conditioning of a step and must stay below 1e12.",
        },
        "links": _list(MAX_BLOCKS - 1, "a list of N-1 signals (actuator lengths)", SIGNAL_SCHEMA),
        "friction": {
            **_FRICTION_MAPPING,
            "type": ["object", "array"],
            "x-expected": "a mapping {forward: mu+, backward: mu-} or a list of N such mappings",
            "maxItems": MAX_BLOCKS,
            "items": _FRICTION_MAPPING,
        },
        "initial": {
            "type": "object",
            "x-expected": "a mapping {positions: [...]}",
            "required": ["positions"],
            "additionalProperties": False,
            "properties": {"positions": _list(MAX_BLOCKS, "a list of N numbers",
                                              {"type": "number", "x-expected": "a number"})},
        },
        "simulation": SIMULATION_SCHEMA,
        "units": UNITS_SCHEMA,
        "loads": LOADS_SCHEMA,
    },
}
"""JSON Schema (Draft 2020-12) of a crawler gait document."""


def load_gait(path: str | Path) -> Gait | ProcessSpec:
    """Read and validate a gait file; the name defaults to the file's stem.

    The file is read by `crawlsim.gait.yamlsafe`: at most `MAX_GAIT_BYTES`, devices refused, YAML
    depth and alias expansion bounded.
    """
    text = read_limited(path)
    return parse_gait(text, source=str(path), default_name=Path(path).stem)


def parse_gait(text: str, source: str = "<string>", default_name: str = "gait") -> Gait | ProcessSpec:
    """Parse and validate gait YAML; syntax errors are reported with line and column."""
    document = load_yaml(text, source)
    return gait_from_document(document, source, source_text=text, default_name=default_name)


def _plain(value: Any) -> Any:
    """A deep copy with numpy scalars and arrays turned into Python numbers and lists."""
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        if all(type(item) in _SCALARS for item in value):
            return list(value)  # a list of numbers (the common long list) needs no deeper copy
        return [_plain(item) for item in value]
    return copy.deepcopy(value)


_SCALARS = frozenset({float, int, str, bool, type(None)})


def _prepare(doc: Any, source: str) -> tuple[dict, dict, Callable[..., Any]]:
    """A plain copy of the document, and its kind's schema and builder."""
    if doc is None:
        raise GaitError(source, "", "the document is empty; expected a gait mapping")
    document = _plain(doc)
    if not isinstance(document, dict):
        raise GaitError(source, "", f"expected a gait mapping at the top level, got {type(document).__name__}")
    kind = document.get("kind", "crawler")
    if kind not in _KINDS:
        close = difflib.get_close_matches(str(kind), list(_KINDS), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise GaitError(source, "kind", f"expected one of {', '.join(map(repr, _KINDS))}, got {kind!r}{hint}")
    schema, build = _KINDS[kind]
    return document, schema, build


def _structure(schema: dict) -> dict:
    """The schema with every signal accepted as is: signals are validated one by one (and only
    once each) by `parse_signal`, which keeps a document of 10^5 links fast to check."""
    skeleton = _SKELETONS.get(id(schema))
    if skeleton is None:
        skeleton = _SKELETONS[id(schema)] = without_signals(schema)
    return skeleton


_SKELETONS: dict[int, dict] = {}


def gait_from_document(doc: dict, source: str, source_text: str | None = None,
                       default_name: str = "gait") -> Gait | ProcessSpec:
    """Validate a parsed document (for instance one edited by a parameter sweep) into a Gait,
    or a ProcessSpec for ``kind: sweeping-process``."""
    document, schema, build = _prepare(doc, source)
    check_finite(document, source)
    check_schema(document, _structure(schema), source)
    if source_text is None:
        source_text = yaml.safe_dump(document, sort_keys=False)
    return build(document, source, source_text, default_name, _Errors())


def validation_errors(path: str | Path) -> list[GaitError]:
    """Every error of a gait file, in document order (empty when the file is valid).

    Structure, types and bounds are all listed (jsonschema's iter_errors, and every signal
    checked on its own); the semantic checks then run as far as the structure allows, each
    check that can run on its own listing its error.
    """
    source = str(path)
    try:
        text = read_limited(path)
        document = load_yaml(text, source)
    except GaitError as error:
        return [error]
    return document_errors(document, source, text, Path(path).stem)


def document_errors(doc: Any, source: str, source_text: str | None = None,
                    default_name: str = "gait") -> list[GaitError]:
    """Every error of a parsed document (see `validation_errors`)."""
    try:
        document, schema, build = _prepare(doc, source)
    except GaitError as error:
        return [error]
    errors = finite_errors(document, source)
    reported = {e.keypath for e in errors}
    errors += [e for e in schema_errors(document, _structure(schema), source)
               if e.keypath not in reported]
    for keypath, value in _signal_slots(document):
        found = [e for e in schema_errors(value, SIGNAL_SCHEMA, source, keypath)
                 if e.keypath not in reported]
        if not found and not any(e.keypath.startswith(keypath) for e in errors):
            try:
                parse_signal(value, keypath, source)
            except GaitError as error:
                found = [error]
        errors += found
    if errors:
        return _distinct(errors)
    collected = _Errors(collect=True)
    try:
        build(document, source, source_text or yaml.safe_dump(document, sort_keys=False),
              default_name, collected)
    except GaitError as error:  # a check whose failure stops the others
        collected.found.append(error)
    return _distinct(collected.found)


def _distinct(errors: list[GaitError]) -> list[GaitError]:
    seen: set[str] = set()
    out = []
    for error in errors:
        if str(error) not in seen:
            seen.add(str(error))
            out.append(error)
    return out


def _signal_slots(document: dict):
    """(key path, value) of every place a signal goes, where the structure around it is right."""
    def items(key):
        value = document.get(key)
        return enumerate(value) if isinstance(value, list) else ()

    if document.get("kind", "crawler") == "sweeping-process":
        for i, value in items("offsets"):
            yield f"offsets[{i}]", value
        return
    for i, value in items("links"):
        yield f"links[{i}]", value
    friction = document.get("friction")
    entries = [("friction", friction)] if isinstance(friction, dict) else [
        (f"friction[{j}]", f) for j, f in items("friction")]
    for path, entry in entries:
        if isinstance(entry, dict):
            for direction in ("forward", "backward"):
                if direction in entry:
                    yield f"{path}.{direction}", entry[direction]
    loads = document.get("loads")
    if isinstance(loads, dict) and "force" in loads:
        force = loads["force"]
        if isinstance(force, list):
            for j, value in enumerate(force):
                yield f"loads.force[{j}]", value
        else:
            yield "loads.force", force


class _Errors:
    """Where a builder's checks report: by default the first error is raised; with
    ``collect=True`` each is recorded and the checks that do not depend on it go on."""

    def __init__(self, collect: bool = False):
        self.collect = collect
        self.found: list[GaitError] = []

    def add(self, error: GaitError) -> None:
        if not self.collect:
            raise error
        self.found.append(error)

    def attempt(self, check: Callable[..., Any], *args: Any) -> Any:
        """``check(*args)``, or None after reporting its GaitError."""
        try:
            return check(*args)
        except GaitError as error:
            self.add(error)
            return None


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _check_units(document: dict, source: str, errors: _Errors) -> None:
    """Each unit name of the ``units:`` block is one of `crawlsim.gait.units.UNIT_NAMES`."""
    for keypath, problem in unit_problems(document.get("units")):
        errors.add(GaitError(source, keypath, problem))


def _count_error(source: str, keypath: str, expected: int, what: str, got: int) -> GaitError:
    return GaitError(source, keypath, f"expected {expected} {what}, got {got}")


def _signals(values: list, keypath: str, source: str, errors: _Errors) -> list[Signal] | None:
    """Each value parsed as a signal at ``keypath[i]``; None if any is invalid (each reported)."""
    parsed = [errors.attempt(parse_signal, value, f"{keypath}[{i}]", source)
              for i, value in enumerate(values)]
    return None if any(p is None for p in parsed) else parsed


def _friction_signals(document: dict, n: int, source: str, errors: _Errors
                      ) -> tuple[list[Signal], list[Signal], list[str]] | None:
    """mu^+ and mu^- per block and, per block, the key path prefix to blame."""
    friction = document["friction"]
    if isinstance(friction, dict):
        shared_forward = errors.attempt(parse_signal, friction["forward"], "friction.forward", source)
        shared_backward = errors.attempt(parse_signal, friction["backward"], "friction.backward", source)
        if shared_forward is None or shared_backward is None:
            return None
        return [shared_forward] * n, [shared_backward] * n, ["friction"] * n
    if len(friction) != n:
        errors.add(_count_error(source, "friction", n, "friction mappings (one per block)", len(friction)))
        return None
    paths = [f"friction[{j}]" for j in range(n)]
    forward = [errors.attempt(parse_signal, f["forward"], f"{p}.forward", source)
               for f, p in zip(friction, paths)]
    backward = [errors.attempt(parse_signal, f["backward"], f"{p}.backward", source)
                for f, p in zip(friction, paths)]
    if any(s is None for s in forward + backward):
        return None
    return forward, backward, paths


def _check_friction_positive(signals: list[Signal], paths: list[str], direction: str,
                             period: float, source: str, errors: _Errors) -> bool:
    minima: dict[Signal, tuple[float, float]] = {}
    checked: set[tuple[Signal, str]] = set()
    ok = True
    for signal, path in zip(signals, paths):
        if (signal, path) in checked:  # shared friction: one signal, one key path
            continue
        checked.add((signal, path))
        if signal not in minima:
            minima[signal] = signal.minimum()
        value, at = minima[signal]
        if not value > 0:
            ok = False
            errors.add(GaitError(source, f"{path}.{direction}",
                                 f"friction must be positive (mu > 0: a block at rest must resist "
                                 f"sliding both ways, docs/model.md §1), but its minimum is {value:g} "
                                 f"at t = {at:g} T" + (f" = {at * period:g}" if period != 1.0 else "")))
    return ok


def stiffness_condition(stiffness: np.ndarray) -> float:
    """Estimated condition number (k_max / k_min) N^2 of the active-set Gram matrices.

    G_A = B_A K B_A^T with B = [D^T; -D^T]: its eigenvalues lie between k_min times those of
    B_A B_A^T and k_max times them, and those of D D^T (the path Laplacian of N blocks) span
    4 sin^2(pi/2N) ~ (pi/N)^2 to 4, so cond(G_A) <= (k_max / k_min) (2N/pi)^2 < (k_max/k_min) N^2.
    """
    k = np.asarray(stiffness, dtype=float)
    return float(np.max(k) / np.min(k)) * float(len(k) + 1) ** 2


def _check_stiffness(k: np.ndarray, source: str) -> None:
    estimate = stiffness_condition(k)
    if estimate > STIFFNESS_CONDITION_LIMIT:
        ratio = float(np.max(k) / np.min(k))
        raise GaitError(source, "stiffness",
                        f"the stiffness ratio k_max / k_min = {ratio:.3g} is too wide for "
                        f"N = {len(k) + 1} blocks: a step's Gram matrices would have an estimated "
                        f"condition number (k_max / k_min) N^2 = {estimate:.3g}, above the "
                        f"{STIFFNESS_CONDITION_LIMIT:g} at which a step can still be certified in "
                        "double precision (docs/model.md §3). Narrow the range of the stiffnesses "
                        "(only their ratio matters for conditioning).")


def _largest(signal: Signal) -> float:
    """A bound of max_t |s(t)| from the signal's coefficients (its mean and amplitudes, or its
    knot values)."""
    if isinstance(signal, Constant):
        return abs(signal.value)
    if isinstance(signal, Cosine):
        return abs(signal.mean) + abs(signal.amplitude)
    if isinstance(signal, Fourier):
        return abs(signal.mean) + float(np.sum(np.abs(signal.cos)) + np.sum(np.abs(signal.sin)))
    values = getattr(signal, "values", None)
    return float(np.max(np.abs(values))) if values is not None else float("inf")


def stress_scale(gait: Gait) -> float:
    """max_i k_i max(|L_i(t)|, |z_i(0)|) / min_j min_t min(mu+_j(t), mu-_j(t)): how many times
    the largest elastic force of the offsets exceeds the smallest friction (`STRESS_SCALE_LIMIT`).
    Dimensionless: a change of units leaves it alone."""
    k = np.asarray(gait.stiffness, dtype=float)
    lengths = np.array([_largest(s) for s in gait.links])
    z0 = np.abs(np.diff(np.asarray(gait.initial_positions, dtype=float)))
    force = float(np.max(k * np.maximum(lengths, z0)))
    friction = min(s.minimum()[0] for s in (*gait.forward, *gait.backward))
    return force / friction if friction > 0 else float("inf")


def _check_stress_scale(gait: Gait, source: str) -> None:
    ratio = stress_scale(gait)
    if ratio > STRESS_SCALE_LIMIT:
        k = np.asarray(gait.stiffness, dtype=float)
        raise GaitError(source, "stiffness",
                        f"the links are too stiff for this friction: the largest elastic force "
                        f"k L is {ratio:.3g} times the smallest friction, above the "
                        f"{STRESS_SCALE_LIMIT:g} that crawlsim supports. In double precision the "
                        f"friction would be resolved only to about {1e-14 * ratio:.1g} of itself, "
                        "so which blocks slip, and v0, could be wrong beyond their error "
                        "estimate. Lower the stiffness (here up to "
                        f"{float(np.max(k)) * STRESS_SCALE_LIMIT / ratio:.3g}), or raise the "
                        "friction (the ratio does not depend on the units)")


def _stiffness(document: dict, n: int, source: str) -> np.ndarray:
    stiffness = document["stiffness"]
    if isinstance(stiffness, list):
        if len(stiffness) != n - 1:
            raise _count_error(source, "stiffness", n - 1, "stiffness values (one per link)", len(stiffness))
        return np.array(stiffness, dtype=float)
    return np.full(n - 1, float(stiffness))


def _build_crawler(document: dict, source: str, source_text: str, default_name: str,
                   errors: _Errors) -> Gait | None:
    _check_units(document, source, errors)
    n = int(document["blocks"])
    period = float(document["period"])

    k = errors.attempt(_stiffness, document, n, source)
    links = None
    if len(document["links"]) != n - 1:
        errors.add(_count_error(source, "links", n - 1, "link signals (one per link, N-1)",
                                len(document["links"])))
    else:
        parsed = _signals(document["links"], "links", source, errors)
        links = None if parsed is None else tuple(parsed)

    friction = _friction_signals(document, n, source, errors)
    positive = friction is not None
    if friction is not None:
        forward, backward, paths = friction
        positive &= _check_friction_positive(forward, paths, "forward", period, source, errors)
        positive &= _check_friction_positive(backward, paths, "backward", period, source, errors)
    if k is not None:
        errors.attempt(_check_stiffness, k, source)

    simulation = Simulation(**{key: _SIMULATION_TYPES[key](value)
                               for key, value in document.get("simulation", {}).items()})

    loads = None
    if "loads" in document:
        loads = errors.attempt(parse_loads, document["loads"], n, source)
        if loads is None:
            return None

    positions = None
    if "initial" in document:
        given = np.array(document["initial"]["positions"], dtype=float)
        if given.shape != (n,):
            errors.add(_count_error(source, "initial.positions", n, "positions (one per block)", given.size))
        else:
            positions = given
    elif links is not None:
        lengths = evaluate_many(links, np.zeros(1))[0]
        positions = np.concatenate([[0.0], np.cumsum(lengths)])

    if errors.found or k is None or links is None or friction is None or positions is None:
        return None
    forward, backward, _ = friction
    gait = Gait(
        name=document.get("name", default_name),
        description=document.get("description", ""),
        source=source,
        source_text=source_text,
        document=document,
        blocks=n,
        period=period,
        stiffness=_readonly(k),
        links=links,
        forward=tuple(forward),
        backward=tuple(backward),
        initial_positions=_readonly(positions),
        simulation=simulation,
        units=Units.from_block(document.get("units")),
        loads=loads,
    )
    if loads is not None and positive:
        problem = hold_violation(gait.forward, gait.backward, loads, period)
        if problem is not None:
            errors.add(GaitError(source, "loads", problem))
            return None
        if "initial" not in document and admissibility_violation(gait, positions) is not None:
            gait = dataclasses.replace(gait, initial_positions=_readonly(_held_positions(gait)))
            positions = gait.initial_positions
    problem = admissibility_violation(gait, positions)
    if problem is not None:
        if loads is not None and positive:
            problem += (f". With these loads an admissible start is, for instance, initial: "
                        f"{{positions: [{', '.join(f'{x:.12g}' for x in _held_positions(gait))}]}} "
                        "(docs/model.md §6)")
        errors.add(GaitError(source, "initial.positions", problem))
    if not positive:
        return None
    try:
        violation = find_violation(*gait.thresholds())
    except UniquenessUndecidable as why:
        if simulation.unchecked_uniqueness:
            if not errors.found:
                errors.attempt(_check_stress_scale, gait, source)
            return None if errors.found else dataclasses.replace(gait, uniqueness_unchecked=True)
        errors.add(GaitError(source, "friction",
                             f"the uniqueness condition (docs/model.md §3) is beyond an exact check "
                             f"for this friction: {why}. To run it anyway, unchecked, add "
                             "'unchecked_uniqueness: true' under 'simulation' (the run then warns "
                             "and its results file records unchecked_uniqueness = 1)"))
        return None
    if violation is not None:
        message = violation.message(period)
        if loads is not None:
            message += (" Here mu+ and mu- are the thresholds shifted by the loads, mu cos(angle) "
                        "-+ F (docs/model.md §6): change the load or the friction.")
        errors.add(GaitError(source, "loads" if loads is not None else "friction", message))
        return None
    if not errors.found:  # stiffness and friction each valid: their ratio (`stress_scale`)
        errors.attempt(_check_stress_scale, gait, source)
    return None if errors.found else gait


def need_crawler(spec, command: str = "crawlsim velocity") -> None:
    """v0 is the velocity of a crawler: a generic sweeping process (docs/model.md §5) has none,
    and is refused with the command that does run it."""
    if not isinstance(spec, Gait):
        raise GaitError(spec.source, "kind", f"a sweeping process has no velocity v0: "
                        f"{command} needs a crawler gait (kind: crawler); `crawlsim run "
                        f"{spec.source}` finds the process's periodic limit")


@dataclass(frozen=True, eq=False)
class ProcessSpec:
    """A validated generic polyhedral sweeping process ``z' in -N_{C(t)}(z)`` (docs/model.md §5).

    ``C(t) = { z in R^n : <b_i, z> <= c_i(t) }`` with constant normals b_i (the rows of
    ``normals``) and T-periodic offsets c_i (signals of the cycle u = t / T), projected in the
    metric ``metric``. Arrays are read-only.
    """

    name: str
    description: str
    source: str
    source_text: str
    document: dict
    period: float
    normals: np.ndarray  # B (m, n)
    offsets: tuple[Signal, ...]  # c_i, m signals
    metric: np.ndarray  # M (n, n), symmetric positive definite
    initial: np.ndarray  # z(0) (n,), a point of C(0)
    allow_unbounded: bool
    simulation: Simulation
    units: Units = Units()

    def replace(self, *changes: Any) -> ProcessSpec:
        """A new validated process with values set at dotted paths (see `Gait.replace`)."""
        from crawlsim.gait.docpaths import replaced

        new = replaced(self, changes)
        assert isinstance(new, ProcessSpec)
        return new

    def breakpoints(self) -> np.ndarray:
        """Union of the offsets' breakpoints, in cycles in [0, 1): the stepping grid needs them."""
        return union_breakpoints([s.breakpoints() for s in self.offsets])

    def offset_values(self, t: np.ndarray) -> np.ndarray:
        """Offsets c(t) at times t, shape (len(t), m)."""
        return evaluate_many(self.offsets, np.ravel(np.asarray(t, dtype=float)) / self.period)


MAX_PROCESS_DIMENSION = 1000
"""Largest dimension n of a generic process (its metric alone is n^2 numbers)."""

MAX_PROCESS_FACES = 10_000
"""Most faces (rows of the normals) of a generic process."""

_MATRIX_ROW = {"type": "array", "minItems": 1, "maxItems": MAX_PROCESS_DIMENSION,
               "x-expected": "a list of numbers (one row)",
               "items": {"type": "number", "x-expected": "a number"}}

PROCESS_SCHEMA: dict = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "x-expected": "a mapping (a sweeping-process document)",
    "required": ["kind", "period", "normals", "offsets", "initial"],
    "additionalProperties": False,
    "properties": {
        "kind": {"enum": ["sweeping-process"]},
        "name": {"type": "string"},
        "description": {"type": "string"},
        "period": CRAWLER_SCHEMA["properties"]["period"],
        "normals": {"type": "array", "minItems": 1, "maxItems": MAX_PROCESS_FACES,
                    "x-expected": "a list of m rows b_i, each a list of n numbers",
                    "description": f"B: at most {MAX_PROCESS_FACES:,} rows of at most "
                                   f"{MAX_PROCESS_DIMENSION:,} numbers.",
                    "items": _MATRIX_ROW},
        "offsets": {"type": "array", "minItems": 1, "maxItems": MAX_PROCESS_FACES,
                    "x-expected": "a list of m signals c_i(t), one per row of normals",
                    "items": SIGNAL_SCHEMA},
        "metric": {"type": "array", "minItems": 1, "maxItems": MAX_PROCESS_DIMENSION,
                   "x-expected": "an n x n symmetric positive definite matrix (a list of rows)",
                   "items": _MATRIX_ROW},
        "initial": {**_MATRIX_ROW, "x-expected": "a list of n numbers (the initial point z(0))"},
        "allow_unbounded": {"type": "boolean",
                            "x-expected": "true or false (accept an unbounded C(t))"},
        "simulation": SIMULATION_SCHEMA,
        "units": UNITS_SCHEMA,
    },
}
"""JSON Schema (Draft 2020-12) of a generic polyhedral sweeping-process document (docs/model.md §5)."""


def _build_process(document: dict, source: str, source_text: str, default_name: str,
                   errors: _Errors) -> ProcessSpec:
    _check_units(document, source, errors)
    rows = document["normals"]
    n = len(rows[0])
    for i, row in enumerate(rows):
        if len(row) != n:
            raise GaitError(source, f"normals[{i}]",
                            f"expected {n} numbers (the dimension n set by normals[0]), got {len(row)}")
    B = np.array(rows, dtype=float)
    m = len(rows)
    for i in range(m):
        if not np.any(B[i]):
            raise GaitError(source, f"normals[{i}]",
                            "expected a nonzero normal b_i: a zero row does not describe a face")
    if len(document["offsets"]) != m:
        raise _count_error(source, "offsets", m, "offset signals (one per row of normals)",
                           len(document["offsets"]))
    offsets = tuple(parse_signal(s, f"offsets[{i}]", source) for i, s in enumerate(document["offsets"]))

    if "metric" in document:
        metric = np.array(_square(document["metric"], n, source), dtype=float)
        problem = _metric_violation(metric)
        if problem is not None:
            raise GaitError(source, "metric", problem)
    else:
        metric = np.eye(n)

    initial = np.array(document["initial"], dtype=float)
    if initial.shape != (n,):
        raise _count_error(source, "initial", n, "coordinates (the dimension n of the normals)",
                           initial.size)

    simulation = Simulation(**{key: _SIMULATION_TYPES[key](value)
                               for key, value in document.get("simulation", {}).items()})
    spec = ProcessSpec(
        name=document.get("name", default_name),
        description=document.get("description", ""),
        source=source,
        source_text=source_text,
        document=document,
        period=float(document["period"]),
        normals=_readonly(B),
        offsets=offsets,
        metric=_readonly(metric),
        initial=_readonly(initial),
        allow_unbounded=bool(document.get("allow_unbounded", False)),
        simulation=simulation,
        units=Units.from_block(document.get("units")),
    )
    problem = emptiness_violation(spec)
    if problem is not None:
        raise GaitError(source, "offsets", problem)
    direction = recession_direction(B)
    if direction is not None and not spec.allow_unbounded:
        raise GaitError(source, "normals",
                        "C(t) is unbounded: it contains the ray z + s d, s >= 0, for d = "
                        f"{_vector_text(direction)} (B d <= 0). The convergence theorem of the paper "
                        "needs a compact C(t); add a face that closes it, or set "
                        "'allow_unbounded: true' to run anyway")
    problem = process_admissibility_violation(spec, initial)
    if problem is not None:
        raise GaitError(source, "initial", problem)
    return spec


def _square(rows: list, n: int, source: str) -> list:
    if len(rows) != n:
        raise _count_error(source, "metric", n, "rows (an n x n matrix, n from the normals)", len(rows))
    for i, row in enumerate(rows):
        if len(row) != n:
            raise _count_error(source, f"metric[{i}]", n, "numbers (an n x n matrix)", len(row))
    return rows


def _metric_violation(metric: np.ndarray) -> str | None:
    """Why ``metric`` cannot define the projections' norm |z|_M^2 = z^T M z, or None."""
    scale = float(np.max(np.abs(metric)))
    asymmetry = float(np.max(np.abs(metric - metric.T)))
    if asymmetry > ROUNDOFF * scale:
        i, j = np.unravel_index(int(np.argmax(np.abs(metric - metric.T))), metric.shape)
        return (f"expected a symmetric matrix, but metric[{i}][{j}] = {metric[i, j]:g} and "
                f"metric[{j}][{i}] = {metric[j, i]:g}")
    eigenvalues = np.linalg.eigvalsh(metric)
    if not eigenvalues[0] > ROUNDOFF * max(scale, 1e-300):
        return (f"expected a positive definite matrix, but its smallest eigenvalue is "
                f"{eigenvalues[0]:.6g}: |z|_M^2 = z^T M z must be a norm")
    return None


def _vector_text(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _check_times(spec: ProcessSpec) -> np.ndarray:
    """Cycles at which C(t) must be checked nonempty to know it is nonempty at all grid times.

    Between breakpoints piecewise-linear and step offsets are affine in t, and the set
    {(t, z) : B z <= c(t)} is then convex, so C(t) is nonempty on a piece when it is nonempty at
    the piece's ends: the breakpoints decide it for every t, not only on a grid. Smooth offsets
    are checked on the uniform grid of ``steps_per_period`` as well (the grid the run steps on).
    """
    points = [np.zeros(1), spec.breakpoints()]
    if any(s.is_smooth and not isinstance(s, Constant) for s in spec.offsets):
        points.append(np.linspace(0.0, 1.0, spec.simulation.steps_per_period + 1)[:-1])
    return np.unique(np.concatenate(points))


def emptiness_violation(spec: ProcessSpec) -> str | None:
    """Why C(t) is empty at some time the run will step on, or None if it never is.

    One sparse LP (scipy's HiGHS) tests all check times at once: find z_k with B z_k <= c(t_k)
    for every k. Only when it is infeasible are the times tested one by one, to name the first
    empty one.
    """
    import scipy.sparse as sp  # process files only: `crawlsim validate` of gaits loads no scipy

    u = _check_times(spec)
    c = evaluate_many(spec.offsets, u)  # (k, m)
    B = spec.normals
    k, n = len(u), B.shape[1]
    A = sp.kron(sp.identity(k, format="csr"), sp.csr_matrix(B), format="csr")
    if _feasible(A, c.ravel(), k * n, spec.source):
        return None
    Bs = sp.csr_matrix(B)
    for j in range(k):
        if not _feasible(Bs, c[j], n, spec.source):
            where = f"at t = {u[j] * spec.period:.12g} (cycle {u[j]:.12g})"
            if j > 0 and all(not s.is_smooth or isinstance(s, Constant) for s in spec.offsets):
                first = _first_empty(spec, Bs, u[j - 1], u[j])
                where = (f"for t just after about {first * spec.period:.6g} (cycle {first:.6g}; "
                         f"to the LP's feasibility tolerance) and {where}")
            return (f"C(t) = {{z : B z <= c(t)}} is empty {where}: no point satisfies every "
                    "constraint there. Check the offsets' signs: C(t) = {z : <b_i, z> <= c_i(t)}")
    return None  # pragma: no cover - the joint LP and the per-time LPs agree


def _first_empty(spec: ProcessSpec, B, feasible: float, empty: float) -> float:
    """Bisect for the cycle where C(t) becomes empty between two breakpoints; the times where it
    is nonempty form an interval there (the offsets are affine on the piece). HiGHS decides
    feasibility to about 1e-7, so so is the answer."""
    n = B.shape[1]
    for _ in range(30):
        middle = (feasible + empty) / 2
        c = evaluate_many(spec.offsets, np.array([middle]))[0]
        if _feasible(B, c, n, spec.source):
            feasible = middle
        else:
            empty = middle
    return feasible


def _feasible(A, b: np.ndarray, n: int, source: str) -> bool:
    from scipy.optimize import linprog

    result = linprog(np.zeros(n), A_ub=A, b_ub=b, bounds=[(None, None)] * n, method="highs")
    if result.status == 2:
        return False
    if result.status != 0:
        raise GaitError(source, "offsets", f"cannot decide whether C(t) is empty: the LP solver "
                        f"(HiGHS) stopped with: {result.message}")
    return True


def recession_direction(normals: np.ndarray) -> np.ndarray | None:
    """A unit direction d != 0 with B d <= 0 (C(t) is then unbounded), or None if C(t) is bounded.

    The recession cone of a nonempty polyhedron {B z <= c} is {d : B d <= 0}, whatever c is, so
    one check decides every t. The cone is {0} exactly when no coordinate of d can be made
    positive or negative within the box |d_k| <= 1: 2n small LPs.
    """
    from scipy.optimize import linprog  # only process files need it: keeps imports light

    m, n = normals.shape
    for k in range(n):
        for sign in (1.0, -1.0):
            cost = np.zeros(n)
            cost[k] = -sign
            result = linprog(cost, A_ub=normals, b_ub=np.zeros(m), bounds=[(-1.0, 1.0)] * n,
                             method="highs")
            if result.status == 0 and -result.fun > 1e-9:
                d = np.asarray(result.x)
                return d / np.linalg.norm(d) + 0.0
    return None


def process_admissibility_violation(spec: ProcessSpec, point: np.ndarray, t: float = 0.0) -> str | None:
    """Why ``point`` is not in C(t), naming the most violated constraint, or None if it is."""
    c = spec.offset_values(np.array([t]))[0]
    slack = spec.normals @ np.asarray(point, dtype=float) - c
    excess = slack - ROUNDOFF * (1.0 + np.abs(c) + np.abs(spec.normals) @ np.abs(point))
    i = int(np.argmax(excess))
    if excess[i] <= 0:
        return None
    return (f"the initial point {_vector_text(point)} is outside C({t:g}): constraint {i} "
            f"(normals[{i}] . z <= offsets[{i}]) reads {slack[i] + c[i]:.12g} <= {c[i]:.12g}, "
            f"violated by {slack[i]:.6g}; the sweeping process must start in C(0)")


_SIMULATION_TYPES: dict[str, Callable[[Any], Any]] = {
    "steps_per_period": int, "max_periods": int, "tolerance": float, "integrator": str,
    "limit": str,
    "unchecked_uniqueness": bool}

_KINDS: dict[str, tuple[dict, Callable[..., Any]]] = {
    "crawler": (CRAWLER_SCHEMA, _build_crawler),
    "sweeping-process": (PROCESS_SCHEMA, _build_process),
}
"""Gait kinds: the value of the document's `kind` key -> (schema, builder)."""


def with_simulation(gait: Gait, **overrides: Any) -> Gait:
    """A copy of `gait` with simulation settings replaced, validated like the file's.

    The document's `simulation` section is updated too, so a sweep that edits the document
    and rebuilds keeps the overrides; `source_text` stays the text that was read.
    """
    settings = {**dataclasses.asdict(gait.simulation), **_plain(overrides)}
    check_schema(settings, SIMULATION_SCHEMA, gait.source, "simulation")
    simulation = Simulation(**{key: _SIMULATION_TYPES[key](value) for key, value in settings.items()})
    document = _plain(gait.document)
    document["simulation"] = {**document.get("simulation", {}), **_plain(overrides)}
    return dataclasses.replace(gait, simulation=simulation, document=document)


def _held_positions(gait: Gait) -> np.ndarray:
    """The default start under loads when the stress-free one is not admissible: every block at
    the same fraction of its shifted friction interval at t = 0 (docs/model.md §6)."""
    plus, minus = gait.thresholds()
    zero = np.zeros(1)
    return held_positions(gait.lengths(zero)[0], np.asarray(gait.stiffness, dtype=float),
                          evaluate_many(plus, zero)[0], evaluate_many(minus, zero)[0])


def admissibility_violation(gait: Gait, positions: np.ndarray, t: float = 0.0) -> str | None:
    """Why `positions` is not an admissible state at time t, or None if it is.

    Admissible means the elastic force on every block is held by static friction,
    -mu_j^-(t) <= f_j <= mu_j^+(t) with f = D^T sigma and sigma = K (L(t) - D x) (docs/model.md §1);
    the sweeping process starts from a point of C(t).
    """
    x = np.asarray(positions, dtype=float)
    if x.shape != (gait.blocks,):
        return f"expected {gait.blocks} positions (one per block), got {x.size}"
    at = np.array([t])
    lengths = gait.lengths(at)[0]
    plus, minus = gait.thresholds()
    u = at / gait.period
    mu_plus, mu_minus = evaluate_many(plus, u)[0], evaluate_many(minus, u)[0]
    sigma = gait.stiffness * (lengths - np.diff(x))
    force = np.zeros(gait.blocks)
    force[1:] += sigma
    force[:-1] -= sigma
    shifted = "; mu shifted by the loads, §6" if gait.loads is not None else ""
    over = force - mu_plus
    under = -mu_minus - force
    for j in range(gait.blocks):
        if over[j] > ROUNDOFF * (1.0 + abs(mu_plus[j])):
            return (f"block {j + 1} is not held by friction at t = {t:g}: its elastic force "
                    f"f_{j + 1} = {force[j]:.6g} exceeds the forward friction limit "
                    f"mu_{j + 1}^+ = {mu_plus[j]:.6g} by {over[j]:.6g}; an admissible initial state "
                    "needs -mu^- <= f <= mu^+ on every block (docs/model.md §1" + shifted + ")")
        if under[j] > ROUNDOFF * (1.0 + abs(mu_minus[j])):
            return (f"block {j + 1} is not held by friction at t = {t:g}: its elastic force "
                    f"f_{j + 1} = {force[j]:.6g} is below the backward friction limit "
                    f"-mu_{j + 1}^- = {-mu_minus[j]:.6g} by {under[j]:.6g}; an admissible initial "
                    "state needs -mu^- <= f <= mu^+ on every block (docs/model.md §1" + shifted + ")")
    return None


def uniqueness_violation(gait: Gait) -> str | None:
    """Why the friction violates the uniqueness condition, or None if it holds.

    For every subset J of blocks (all and none included), g_J(t) = sum_{j in J} mu_j^+(t) -
    sum_{j not in J} mu_j^-(t) must not vanish on an interval (docs/model.md §3; paper eq.
    (uniqueness)); otherwise the multipliers of the projection, which are the slips, are not
    unique. Decided exactly for any N by `crawlsim.model.uniqueness.find_violation`, which raises
    `crawlsim.model.uniqueness.UniquenessUndecidable` where the friction is beyond its bounds.
    """
    violation = find_violation(*gait.thresholds())
    return None if violation is None else violation.message(gait.period)
