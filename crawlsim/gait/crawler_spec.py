"""Crawler gait documents (``kind: crawler``, the default): their schema, the `Gait` they
validate into, and the semantic checks (docs/model.md §1).

A gait is validated completely before anything is computed. After the schema, each semantic
check refuses something the model cannot handle, and says why: non-positive friction
(docs/model.md §1: mu > 0), stiffness ratios too wide for a certified step in double precision
(`crawlsim.gait.crawler_limits`), an initial state outside the admissible set C(0)
(docs/model.md §1), and friction coefficients that violate the uniqueness condition
(docs/model.md §3; decided exactly by `crawlsim.gait.uniqueness`), under which the model does
not determine how the crawler moves.

An optional `loads:` block (`crawlsim.gait.loads`, docs/model.md §6) puts forces on the blocks
and the crawler on a slope: the friction thresholds are shifted, the body as a whole must be
able to hold its loads, the uniqueness condition is checked on the shifted thresholds, and when
the stress-free start is not admissible a held one is chosen.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.crawler_limits import check_stiffness, check_stress_scale
from crawlsim.gait.docpaths import replacement, wave_links
from crawlsim.gait.loads import LOADS_SCHEMA, Loads, held_positions, hold_violation, parse_loads
from crawlsim.gait.schemaerrors import LARGEST
from crawlsim.gait.settings import (
    MAX_BLOCKS,
    PERIOD_SCHEMA,
    ROUNDOFF,
    SIMULATION_SCHEMA,
    Simulation,
    list_schema,
    positive_schema,
    simulation_from,
)
from crawlsim.gait.signals import MAX_PHASE, SIGNAL_SCHEMA, Signal, evaluate_many, parse_signal, union_breakpoints
from crawlsim.gait.uniqueness import UniquenessUndecidable, alike_subsets, analyse, find_violation
from crawlsim.gait.uniqueness_advice import remedy_text, smallest_change, uniqueness_message
from crawlsim.gait.units import UNITS_SCHEMA, Units
from crawlsim.gait.validation import ErrorSink, check_units, count_error, plain, readonly, validated

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
        "blocks": {
            "type": "integer",
            "minimum": 2,
            "maximum": MAX_BLOCKS,
            "x-expected": f"an integer from 2 to {MAX_BLOCKS:,} (the number of blocks N)",
            "description": "N, the number of blocks.",
        },
        "period": PERIOD_SCHEMA,
        "stiffness": {
            "type": ["number", "array"],
            "x-expected": "a positive number or a list of N-1 positive numbers (spring stiffness k > 0)",
            "exclusiveMinimum": 0,
            "maximum": LARGEST,
            "maxItems": MAX_BLOCKS - 1,
            "items": positive_schema("the spring stiffness k > 0 of one link"),
            "description": "k, one value for every link or one per link. The ratio k_max / k_min "
            "times N^2 estimates the conditioning of a step and must stay below 1e12.",
        },
        "links": {
            **list_schema(MAX_BLOCKS - 1, "a list of N-1 signals (actuator lengths)", SIGNAL_SCHEMA),
            "type": ["array", "object"],
            "x-expected": "a list of N-1 signals (actuator lengths) or a wave {wave: SIGNAL, phase_step: CYCLES}",
            "description": "L_i(t): one signal per link, or a travelling wave: every link follows the wave's "
            "signal, link i+1 phase_step cycles after link i (crawlsim.gait.docpaths.wave_links).",
            "required": ["wave"],
            "additionalProperties": False,
            "properties": {
                "wave": SIGNAL_SCHEMA,
                "phase_step": {
                    "type": "number",
                    "minimum": -MAX_PHASE,
                    "maximum": MAX_PHASE,
                    "x-expected": "a number of cycles (the phase of link i+1 minus that of link i)",
                },
            },
        },
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
            "properties": {
                "positions": list_schema(
                    MAX_BLOCKS, "a list of N numbers", {"type": "number", "x-expected": "a number"}
                )
            },
        },
        "simulation": SIMULATION_SCHEMA,
        "units": UNITS_SCHEMA,
        "loads": LOADS_SCHEMA,
    },
}
"""JSON Schema (Draft 2020-12) of a crawler gait document."""


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

    def __repr__(self) -> str:  # not the whole document and file text (2 kB for four blocks)
        return f"<Gait {self.name}: {self.blocks} blocks, period {self.period:g}, from {self.source}>"

    def replace(self, *changes: Any) -> Gait:
        """A new validated gait with values set at dotted paths, the syntax of ``--sweep``:
        ``gait.replace("links.*.amplitude", 0.2)``, several pairs
        ``gait.replace("period", 2.0, "links.1.phase", 0.25)`` or one mapping
        ``gait.replace({"period": 2.0})`` (`crawlsim.gait.docpaths`)."""
        label, document = replacement(self.source, self.document, changes)
        # a path cannot change the kind: `kind` is not a number
        return validated(
            document, CRAWLER_SCHEMA, build_crawler, label, source_text=self.source_text, default_name=self.name
        )

    def breakpoints(self) -> np.ndarray:
        """Union of all signals' breakpoints, in cycles in [0, 1): the stepping grid needs them."""
        forces = self.loads.forces if self.loads is not None else ()
        return union_breakpoints([s.breakpoints() for s in self.links + self.forward + self.backward + forces])

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


def _signals(values: list, keypath: str, source: str, errors: ErrorSink) -> list[Signal] | None:
    """Each value parsed as a signal at ``keypath[i]``; None if any is invalid (each reported)."""
    parsed = [errors.attempt(parse_signal, value, f"{keypath}[{i}]", source) for i, value in enumerate(values)]
    return None if any(p is None for p in parsed) else parsed


def _friction_signals(
    document: dict, n: int, source: str, errors: ErrorSink
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
        errors.add(count_error(source, "friction", n, "friction mappings (one per block)", len(friction)))
        return None
    paths = [f"friction[{j}]" for j in range(n)]
    forward = [errors.attempt(parse_signal, f["forward"], f"{p}.forward", source) for f, p in zip(friction, paths)]
    backward = [errors.attempt(parse_signal, f["backward"], f"{p}.backward", source) for f, p in zip(friction, paths)]
    if any(s is None for s in forward + backward):
        return None
    return forward, backward, paths


def _check_friction_positive(
    signals: list[Signal], paths: list[str], direction: str, period: float, source: str, errors: ErrorSink
) -> bool:
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
            errors.add(
                GaitError(
                    source,
                    f"{path}.{direction}",
                    f"friction must be positive (mu > 0: a block at rest must resist "
                    f"sliding both ways, docs/model.md §1), but its minimum is {value:g} "
                    f"at t = {at:g} T" + (f" = {at * period:g}" if period != 1.0 else ""),
                )
            )
    return ok


def _stiffness(document: dict, n: int, source: str) -> np.ndarray:
    stiffness = document["stiffness"]
    if isinstance(stiffness, list):
        if len(stiffness) != n - 1:
            raise count_error(source, "stiffness", n - 1, "stiffness values (one per link)", len(stiffness))
        return np.array(stiffness, dtype=float)
    return np.full(n - 1, float(stiffness))


def build_crawler(
    document: dict, source: str, source_text: str, default_name: str, errors: ErrorSink, unique: bool = True
) -> Gait | None:
    """The `Gait` of a schema-checked crawler document, after every semantic check (module
    docstring); None when ``errors`` collects and found some. ``unique=False`` skips the
    uniqueness condition and what follows it (`uniqueness_report` analyses it instead)."""
    check_units(document, source, errors)
    n = int(document["blocks"])
    period = float(document["period"])
    k = errors.attempt(_stiffness, document, n, source)
    links = _links(document, n, source, errors)
    friction = _friction_signals(document, n, source, errors)
    positive = friction is not None and _friction_positive(friction, period, source, errors)
    if k is not None:
        errors.attempt(check_stiffness, k, source)
    simulation = simulation_from(document.get("simulation", {}))
    loads = None
    if "loads" in document:
        loads = errors.attempt(parse_loads, document["loads"], n, source)
        if loads is None:
            return None
    positions = _positions(document, n, links, source, errors)
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
        stiffness=readonly(k),
        links=links,
        forward=tuple(forward),
        backward=tuple(backward),
        initial_positions=readonly(positions),
        simulation=simulation,
        units=Units.from_block(document.get("units")),
        loads=loads,
    )
    started = _admissible_start(gait, positive, errors)
    if started is None or not positive:
        return None
    return _unique(started, errors) if unique else started


def _links(document: dict, n: int, source: str, errors: ErrorSink) -> tuple[Signal, ...] | None:
    """The N-1 actuator lengths L_i(t) (those of a wave, `wave_links`, once its signal is
    valid), or None after reporting why not."""
    links = document["links"]
    if isinstance(links, dict):
        if errors.attempt(parse_signal, links["wave"], "links.wave", source) is None:
            return None
        links = wave_links(links, n - 1)
    elif len(links) != n - 1:
        errors.add(count_error(source, "links", n - 1, "link signals (one per link, N-1)", len(links)))
        return None
    parsed = _signals(links, "links", source, errors)
    return None if parsed is None else tuple(parsed)


def _friction_positive(
    friction: tuple[list[Signal], list[Signal], list[str]], period: float, source: str, errors: ErrorSink
) -> bool:
    """mu^+ > 0 and mu^- > 0 on every block at every time, each direction's failures reported."""
    forward, backward, paths = friction
    ok_forward = _check_friction_positive(forward, paths, "forward", period, source, errors)
    ok_backward = _check_friction_positive(backward, paths, "backward", period, source, errors)
    return ok_forward and ok_backward


def _positions(
    document: dict, n: int, links: tuple[Signal, ...] | None, source: str, errors: ErrorSink
) -> np.ndarray | None:
    """x(0): the file's ``initial.positions``, else the stress-free start z(0) = L(0)."""
    if "initial" in document:
        given = np.array(document["initial"]["positions"], dtype=float)
        if given.shape != (n,):
            errors.add(count_error(source, "initial.positions", n, "positions (one per block)", given.size))
            return None
        return given
    if links is None:
        return None
    lengths = evaluate_many(links, np.zeros(1))[0]
    return np.concatenate([[0.0], np.cumsum(lengths)])


def _admissible_start(gait: Gait, positive: bool, errors: ErrorSink) -> Gait | None:
    """The gait with an admissible start (docs/model.md §1): under loads that the body can hold,
    a held start replaces an inadmissible stress-free one (§6). An inadmissible start is
    reported; None when the loads cannot be held at all."""
    source, loads = gait.source, gait.loads
    if loads is not None and positive:
        problem = hold_violation(gait.forward, gait.backward, loads, gait.period)
        if problem is not None:
            errors.add(GaitError(source, "loads", problem))
            return None
        if "initial" not in gait.document and admissibility_violation(gait, gait.initial_positions) is not None:
            gait = dataclasses.replace(gait, initial_positions=readonly(_held_positions(gait)))
    problem = admissibility_violation(gait, gait.initial_positions)
    if problem is not None:
        if loads is not None and positive:
            problem += (
                f". With these loads an admissible start is, for instance, initial: "
                f"{{positions: [{', '.join(f'{x:.12g}' for x in _held_positions(gait))}]}} "
                "(docs/model.md §6)"
            )
        errors.add(GaitError(source, "initial.positions", problem))
    return gait


def _unique(gait: Gait, errors: ErrorSink) -> Gait | None:
    """The gait when its friction satisfies the uniqueness condition (docs/model.md §3) and its
    links are not too stiff for it; where the condition is beyond an exact check, the gait
    marked unchecked if the file opted in."""
    source = gait.source
    try:
        problem = uniqueness_violation(gait)
    except UniquenessUndecidable as why:
        if not gait.simulation.unchecked_uniqueness:
            errors.add(
                GaitError(
                    source,
                    "friction",
                    f"the uniqueness condition (docs/model.md §3) is beyond an exact "
                    f"check for this friction: {why}. To run it anyway, unchecked, "
                    "add 'unchecked_uniqueness: true' under 'simulation' (the run "
                    "then warns and its results file records "
                    "unchecked_uniqueness = 1)",
                )
            )
            return None
        gait = dataclasses.replace(gait, uniqueness_unchecked=True)
    else:
        if problem is not None:
            errors.add(GaitError(source, "loads" if gait.loads is not None else "friction", problem))
            return None
    if not errors.found:  # stiffness and friction each valid: their ratio (`stress_scale`)
        errors.attempt(
            check_stress_scale, gait.stiffness, gait.links, gait.initial_positions, gait.forward + gait.backward, source
        )
    return None if errors.found else gait


def need_crawler(spec, command: str = "crawlsim velocity") -> None:
    """v0 is the velocity of a crawler: a generic sweeping process (docs/model.md §5) has none,
    and is refused with the command that does run it."""
    if not isinstance(spec, Gait):
        raise GaitError(
            spec.source,
            "kind",
            f"a sweeping process has no velocity v0: "
            f"{command} needs a crawler gait (kind: crawler); `crawlsim run "
            f"{spec.source}` finds the process's periodic limit",
        )


def _held_positions(gait: Gait) -> np.ndarray:
    """The default start under loads when the stress-free one is not admissible: every block at
    the same fraction of its shifted friction interval at t = 0 (docs/model.md §6)."""
    plus, minus = gait.thresholds()
    zero = np.zeros(1)
    return held_positions(
        gait.lengths(zero)[0],
        np.asarray(gait.stiffness, dtype=float),
        evaluate_many(plus, zero)[0],
        evaluate_many(minus, zero)[0],
    )


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
            return (
                f"block {j + 1} is not held by friction at t = {t:g}: its elastic force "
                f"f_{j + 1} = {force[j]:.6g} exceeds the forward friction limit "
                f"mu_{j + 1}^+ = {mu_plus[j]:.6g} by {over[j]:.6g}; an admissible initial state "
                "needs -mu^- <= f <= mu^+ on every block (docs/model.md §1" + shifted + ")"
            )
        if under[j] > ROUNDOFF * (1.0 + abs(mu_minus[j])):
            return (
                f"block {j + 1} is not held by friction at t = {t:g}: its elastic force "
                f"f_{j + 1} = {force[j]:.6g} is below the backward friction limit "
                f"-mu_{j + 1}^- = {-mu_minus[j]:.6g} by {under[j]:.6g}; an admissible initial "
                "state needs -mu^- <= f <= mu^+ on every block (docs/model.md §1" + shifted + ")"
            )
    return None


def negative_length(gait: Gait) -> str | None:
    """Where the first actuator length L_i(t) that goes negative does, in words, or None.

    Not an error of the model: adding a constant to L translates K(t) = C(t) - K L(t) rigidly
    and leaves the slips alone (docs/model.md §2), so v0 does not depend on the links' mean
    lengths. But a negative rest length lets blocks i and i+1 pass through each other, which the
    positions and the figures then show: `crawlsim.gait.document.load_gait` warns.
    """
    lowest: dict[Signal, float] = {}  # by the shape of the signal: its phase moves no minimum
    for i, link in enumerate(gait.links):
        shape = dataclasses.replace(link, phase=0.0) if hasattr(link, "phase") else link  # type: ignore[call-arg]
        if shape not in lowest:
            lowest[shape] = shape.minimum()[0]
        if lowest[shape] < 0:
            value, at = link.minimum()
            when = f"t = {at:g} T" + (f" = {at * gait.period:g}" if gait.period != 1.0 else "")
            return (
                f"{gait.source}: links[{i}]: the actuator length goes negative ({value:.3g} at {when}), so blocks "
                f"{i + 1} and {i + 2} can pass through each other; v0 does not depend on the links' mean lengths "
                f"(docs/model.md §2), but the positions and figures do: add {-value:.3g} or more to this length"
            )
    return None


def uniqueness_violation(gait: Gait) -> str | None:
    """Why the friction violates the uniqueness condition, or None if it holds.

    For every subset J of blocks (all and none included), g_J(t) = sum_{j in J} mu_j^+(t) -
    sum_{j not in J} mu_j^-(t) must not vanish on an interval (docs/model.md §3; paper eq.
    (uniqueness)); otherwise the multipliers of the projection, which are the slips, are not
    unique. Decided exactly for any N by `crawlsim.gait.uniqueness`, which raises
    `crawlsim.gait.uniqueness.UniquenessUndecidable` where the friction is beyond its bounds.
    The message lists every violating subset and the smallest change of one friction
    coefficient that restores the condition (`crawlsim.gait.uniqueness_advice`).
    """
    analysis = analyse(*gait.thresholds())
    if analysis is None:
        return None
    return uniqueness_message(
        gait.document,
        gait.forward,
        gait.backward,
        analysis,
        gait.period,
        lambda f, b: _valid_friction(gait, f, b),
        loaded=gait.loads is not None,
        source=gait.source,
    )


def uniqueness_report(document: dict, source: str) -> list[str]:
    """The whole uniqueness analysis of a crawler document (``crawlsim validate --explain``):
    what was checked, every violating subset J (those alike written out) with the intervals on
    which g_J vanishes, and the smallest change of one coefficient that restores the condition.
    A document that fails a check that comes before gets one line saying so."""
    try:
        gait = validated(plain(document), CRAWLER_SCHEMA, functools.partial(build_crawler, unique=False), source)
    except GaitError:
        return ["uniqueness condition (docs/model.md §3): not analysed until the errors above are fixed"]
    plus, minus = gait.thresholds()
    lines = [
        f"uniqueness condition (docs/model.md §3): g_J(t) = sum of mu+ over J - sum of mu- "
        f"over the rest, for each of the 2^{gait.blocks} subsets J of blocks, must not "
        "vanish on an interval" + (" (mu shifted by the loads, §6)" if gait.loads else "")
    ]
    try:
        analysis = analyse(plus, minus)
    except UniquenessUndecidable as why:
        return lines + [f"  beyond an exact check: {why}"]
    if analysis is None:
        return lines + ["  holds: no g_J vanishes on an interval (decided exactly)"]
    subsets = [(s, v) for v in analysis.violations for s in alike_subsets(v, plus, minus)]
    lines.append(
        f"  violated by {sum(v.alike for v in analysis.violations):,} subsets"
        + ("" if analysis.complete else " at least")
        + ":"
    )
    for subset, violation in subsets:
        inside = ", ".join(str(j + 1) for j in np.flatnonzero(subset))
        lines.append(f"    J = {{{inside}}}: g_J = 0 for t in {violation.where(gait.period)}")
    if len(subsets) < sum(v.alike for v in analysis.violations):
        lines.append("    ... and the other subsets alike (blocks of the same friction exchanged)")
    change = smallest_change(
        gait.document, (gait.forward, gait.backward), analysis, lambda f, b: _valid_friction(gait, f, b), source
    )
    return lines + ["  " + remedy_text(change)]


def _valid_friction(gait: Gait, forward: tuple[Signal, ...], backward: tuple[Signal, ...]) -> bool:
    """Whether ``gait`` with this friction starts admissibly and satisfies the uniqueness
    condition: the test of a suggested change."""
    changed = dataclasses.replace(gait, forward=forward, backward=backward)
    if admissibility_violation(changed, changed.initial_positions) is not None:
        return False
    try:
        return find_violation(*changed.thresholds()) is None
    except UniquenessUndecidable:
        return False
