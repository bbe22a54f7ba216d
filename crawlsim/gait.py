"""Gait files: the YAML description of a crawler and its periodic actuation (MODEL.md §1).

A gait is validated completely before anything is computed. jsonschema checks structure and
types; the semantic checks that follow each refuse something the model cannot handle, and say
why: non-positive friction (MODEL.md §1: mu > 0), an initial state outside the admissible set
C(0) (MODEL.md §1), and friction coefficients that violate the uniqueness condition
(MODEL.md §3), under which the model does not determine how the crawler moves.

Documents are dispatched on their `kind` key (`_KINDS`): `crawler` (the default) builds a `Gait`,
`sweeping-process` a `ProcessSpec`, a generic polyhedral sweeping process of MODEL.md §5. A
process is refused when its dimensions do not match, when C(t) is empty at a time the run steps
on, when C(t) is unbounded (the paper's theorem needs a compact set; `allow_unbounded: true`
accepts it), when the metric is not symmetric positive definite, or when the initial point is
outside C(0).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
import yaml

from crawlsim.errors import GaitError
from crawlsim.signals import (
    JUMP_TOLERANCE,
    SIGNAL_SCHEMA,
    Constant,
    Signal,
    check_finite,
    check_schema,
    evaluate_many,
    parse_signal,
    union_breakpoints,
)
from crawlsim.units import UNITS_SCHEMA, Units

ROUNDOFF = 1e-12
"""Relative tolerance of the admissibility and uniqueness checks: roundoff, not a modelling slack."""

MAX_UNIQUENESS_BLOCKS = 20
"""Above this many blocks the 2^N subsets of the uniqueness condition are not enumerated."""

_SUBSET_CHUNK_ENTRIES = 1 << 22


@dataclass(frozen=True)
class Simulation:
    """Numerical settings of a run; none of them changes the model, only how it is stepped."""

    steps_per_period: int = 1000
    max_periods: int = 1000
    tolerance: float = 1e-12
    integrator: str = "catch-up"


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

    def replace(self, *changes: Any) -> Gait:
        """A new validated gait with values set at dotted paths, the syntax of ``--sweep``:
        ``gait.replace("links.*.amplitude", 0.2)``, several pairs
        ``gait.replace("period", 2.0, "links.1.phase", 0.25)`` or one mapping
        ``gait.replace({"period": 2.0})`` (`crawlsim.docpaths`)."""
        from crawlsim.docpaths import replaced

        new = replaced(self, changes)
        assert isinstance(new, Gait)  # a path cannot change the kind: `kind` is not a number
        return new

    def breakpoints(self) -> np.ndarray:
        """Union of all signals' breakpoints, in cycles in [0, 1): the stepping grid needs them."""
        return union_breakpoints([s.breakpoints() for s in self.links + self.forward + self.backward])

    def lengths(self, t: np.ndarray) -> np.ndarray:
        """Actuator lengths L(t) at times t, shape (len(t), N-1)."""
        return evaluate_many(self.links, np.ravel(np.asarray(t, dtype=float)) / self.period)

    def mu_plus(self, t: np.ndarray) -> np.ndarray:
        """Forward friction coefficients mu^+(t) at times t, shape (len(t), N)."""
        return evaluate_many(self.forward, np.ravel(np.asarray(t, dtype=float)) / self.period)

    def mu_minus(self, t: np.ndarray) -> np.ndarray:
        """Backward friction coefficients mu^-(t) at times t, shape (len(t), N)."""
        return evaluate_many(self.backward, np.ravel(np.asarray(t, dtype=float)) / self.period)


def _positive(what: str) -> dict:
    return {"type": "number", "exclusiveMinimum": 0, "x-expected": f"a positive number ({what})"}


def _count(what: str) -> dict:
    return {"type": "integer", "minimum": 1, "x-expected": f"an integer >= 1 ({what})"}


SIMULATION_SCHEMA: dict = {
    "type": "object",
    "x-expected": "a mapping of simulation settings",
    "additionalProperties": False,
    "properties": {
        "steps_per_period": _count("time steps per period"),
        "max_periods": _count("the most periods to simulate"),
        "tolerance": _positive("the convergence tolerance"),
        "integrator": {"enum": ["catch-up", "exact"]},
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
        "blocks": {"type": "integer", "minimum": 2, "x-expected": "an integer >= 2 (the number of blocks N)"},
        "period": _positive("the period T of the gait"),
        "stiffness": {
            "type": ["number", "array"],
            "x-expected": "a positive number or a list of N-1 positive numbers (spring stiffness k > 0)",
            "exclusiveMinimum": 0,
            "items": _positive("the spring stiffness k > 0 of one link"),
        },
        "links": {"type": "array", "x-expected": "a list of N-1 signals (actuator lengths)",
                  "items": SIGNAL_SCHEMA},
        "friction": {
            **_FRICTION_MAPPING,
            "type": ["object", "array"],
            "x-expected": "a mapping {forward: mu+, backward: mu-} or a list of N such mappings",
            "items": _FRICTION_MAPPING,
        },
        "initial": {
            "type": "object",
            "x-expected": "a mapping {positions: [...]}",
            "required": ["positions"],
            "additionalProperties": False,
            "properties": {"positions": {"type": "array", "x-expected": "a list of N numbers",
                                         "items": {"type": "number", "x-expected": "a number"}}},
        },
        "simulation": SIMULATION_SCHEMA,
        "units": UNITS_SCHEMA,
    },
}
"""JSON Schema (Draft 2020-12) of a crawler gait document."""


class _Loader(yaml.SafeLoader):
    """Safe YAML that also reads 1e-3 as a float (YAML 1.2) and refuses duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_Loader.yaml_implicit_resolvers = {k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_gait(path: str | Path) -> Gait | ProcessSpec:
    """Read and validate a gait file; the name defaults to the file's stem."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise GaitError(source, "", "no such gait file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise GaitError(source, "", f"cannot read the gait file: {error}") from None
    return parse_gait(text, source=source, default_name=Path(path).stem)


def parse_gait(text: str, source: str = "<string>", default_name: str = "gait") -> Gait | ProcessSpec:
    """Parse and validate gait YAML; syntax errors are reported with line and column."""
    try:
        document = yaml.load(text, Loader=_Loader)
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise GaitError(source, "", f"YAML syntax error{where}: {error.problem}") from None
    except yaml.YAMLError as error:
        raise GaitError(source, "", f"YAML syntax error: {error}") from None
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
        return [_plain(item) for item in value]
    return copy.deepcopy(value)


def gait_from_document(doc: dict, source: str, source_text: str | None = None,
                       default_name: str = "gait") -> Gait | ProcessSpec:
    """Validate a parsed document (for instance one edited by a parameter sweep) into a Gait,
    or a ProcessSpec for ``kind: sweeping-process``."""
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
    check_schema(document, schema, source)
    check_finite(document, source)
    if source_text is None:
        source_text = yaml.safe_dump(document, sort_keys=False)
    return build(document, source, source_text, default_name)


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _count_error(source: str, keypath: str, expected: int, what: str, got: int) -> GaitError:
    return GaitError(source, keypath, f"expected {expected} {what}, got {got}")


def _friction_signals(document: dict, n: int, source: str) -> tuple[list[Signal], list[Signal], list[str]]:
    """mu^+ and mu^- per block and, per block, the key path prefix to blame."""
    friction = document["friction"]
    if isinstance(friction, dict):
        shared_forward = parse_signal(friction["forward"], "friction.forward", source)
        shared_backward = parse_signal(friction["backward"], "friction.backward", source)
        return [shared_forward] * n, [shared_backward] * n, ["friction"] * n
    if len(friction) != n:
        raise _count_error(source, "friction", n, "friction mappings (one per block)", len(friction))
    paths = [f"friction[{j}]" for j in range(n)]
    forward = [parse_signal(f["forward"], f"{p}.forward", source) for f, p in zip(friction, paths)]
    backward = [parse_signal(f["backward"], f"{p}.backward", source) for f, p in zip(friction, paths)]
    return forward, backward, paths


def _check_friction_positive(signals: list[Signal], paths: list[str], direction: str,
                             period: float, source: str) -> None:
    for signal, path in zip(signals, paths):
        value, at = signal.minimum()
        if not value > 0:
            raise GaitError(source, f"{path}.{direction}",
                            f"friction must be positive (mu > 0: a block at rest must resist sliding "
                            f"both ways, MODEL.md §1), but its minimum is {value:g} at t = {at:g} T"
                            + (f" = {at * period:g}" if period != 1.0 else ""))


def _build_crawler(document: dict, source: str, source_text: str, default_name: str) -> Gait:
    n = int(document["blocks"])
    period = float(document["period"])

    stiffness = document["stiffness"]
    if isinstance(stiffness, list):
        if len(stiffness) != n - 1:
            raise _count_error(source, "stiffness", n - 1, "stiffness values (one per link)", len(stiffness))
        k = np.array(stiffness, dtype=float)
    else:
        k = np.full(n - 1, float(stiffness))

    if len(document["links"]) != n - 1:
        raise _count_error(source, "links", n - 1, "link signals (one per link, N-1)", len(document["links"]))
    links = tuple(parse_signal(s, f"links[{i}]", source) for i, s in enumerate(document["links"]))

    forward, backward, paths = _friction_signals(document, n, source)
    _check_friction_positive(forward, paths, "forward", period, source)
    _check_friction_positive(backward, paths, "backward", period, source)

    simulation = Simulation(**{key: _SIMULATION_TYPES[key](value)
                               for key, value in document.get("simulation", {}).items()})

    if "initial" in document:
        positions = np.array(document["initial"]["positions"], dtype=float)
        if positions.shape != (n,):
            raise _count_error(source, "initial.positions", n, "positions (one per block)", positions.size)
    else:
        lengths = evaluate_many(links, np.zeros(1))[0]
        positions = np.concatenate([[0.0], np.cumsum(lengths)])

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
    )
    problem = admissibility_violation(gait, positions)
    if problem is not None:
        raise GaitError(source, "initial.positions", problem)
    problem = uniqueness_violation(gait)
    if problem is not None:
        raise GaitError(source, "friction", problem)
    return gait


@dataclass(frozen=True, eq=False)
class ProcessSpec:
    """A validated generic polyhedral sweeping process ``z' in -N_{C(t)}(z)`` (MODEL.md §5).

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
        from crawlsim.docpaths import replaced

        new = replaced(self, changes)
        assert isinstance(new, ProcessSpec)
        return new

    def breakpoints(self) -> np.ndarray:
        """Union of the offsets' breakpoints, in cycles in [0, 1): the stepping grid needs them."""
        return union_breakpoints([s.breakpoints() for s in self.offsets])

    def offset_values(self, t: np.ndarray) -> np.ndarray:
        """Offsets c(t) at times t, shape (len(t), m)."""
        return evaluate_many(self.offsets, np.ravel(np.asarray(t, dtype=float)) / self.period)


_MATRIX_ROW = {"type": "array", "minItems": 1, "x-expected": "a list of numbers (one row)",
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
        "period": _positive("the period T of the offsets"),
        "normals": {"type": "array", "minItems": 1,
                    "x-expected": "a list of m rows b_i, each a list of n numbers",
                    "items": _MATRIX_ROW},
        "offsets": {"type": "array", "minItems": 1,
                    "x-expected": "a list of m signals c_i(t), one per row of normals",
                    "items": SIGNAL_SCHEMA},
        "metric": {"type": "array", "minItems": 1,
                   "x-expected": "an n x n symmetric positive definite matrix (a list of rows)",
                   "items": _MATRIX_ROW},
        "initial": {**_MATRIX_ROW, "x-expected": "a list of n numbers (the initial point z(0))"},
        "allow_unbounded": {"type": "boolean",
                            "x-expected": "true or false (accept an unbounded C(t))"},
        "simulation": SIMULATION_SCHEMA,
        "units": UNITS_SCHEMA,
    },
}
"""JSON Schema (Draft 2020-12) of a generic polyhedral sweeping-process document (MODEL.md §5)."""


def _build_process(document: dict, source: str, source_text: str, default_name: str) -> ProcessSpec:
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
    "steps_per_period": int, "max_periods": int, "tolerance": float, "integrator": str}

_KINDS: dict[str, tuple[dict, Callable[[dict, str, str, str], Any]]] = {
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


def admissibility_violation(gait: Gait, positions: np.ndarray, t: float = 0.0) -> str | None:
    """Why `positions` is not an admissible state at time t, or None if it is.

    Admissible means the elastic force on every block is held by static friction,
    -mu_j^-(t) <= f_j <= mu_j^+(t) with f = D^T sigma and sigma = K (L(t) - D x) (MODEL.md §1);
    the sweeping process starts from a point of C(t).
    """
    x = np.asarray(positions, dtype=float)
    if x.shape != (gait.blocks,):
        return f"expected {gait.blocks} positions (one per block), got {x.size}"
    at = np.array([t])
    lengths, mu_plus, mu_minus = gait.lengths(at)[0], gait.mu_plus(at)[0], gait.mu_minus(at)[0]
    sigma = gait.stiffness * (lengths - np.diff(x))
    force = np.zeros(gait.blocks)
    force[1:] += sigma
    force[:-1] -= sigma
    over = force - mu_plus
    under = -mu_minus - force
    for j in range(gait.blocks):
        if over[j] > ROUNDOFF * (1.0 + abs(mu_plus[j])):
            return (f"block {j + 1} is not held by friction at t = {t:g}: its elastic force "
                    f"f_{j + 1} = {force[j]:.6g} exceeds the forward friction limit "
                    f"mu_{j + 1}^+ = {mu_plus[j]:.6g} by {over[j]:.6g}; an admissible initial state "
                    "needs -mu^- <= f <= mu^+ on every block (MODEL.md §1)")
        if under[j] > ROUNDOFF * (1.0 + abs(mu_minus[j])):
            return (f"block {j + 1} is not held by friction at t = {t:g}: its elastic force "
                    f"f_{j + 1} = {force[j]:.6g} is below the backward friction limit "
                    f"-mu_{j + 1}^- = {-mu_minus[j]:.6g} by {under[j]:.6g}; an admissible initial "
                    "state needs -mu^- <= f <= mu^+ on every block (MODEL.md §1)")
    return None


def _blocks_text(blocks: np.ndarray) -> str:
    return "{" + ", ".join(str(int(j) + 1) for j in blocks) + "}"


def uniqueness_violation(gait: Gait) -> str | None:
    """Why the friction violates the uniqueness condition, or None if it holds.

    For every subset J of blocks, g_J(t) = sum_{j in J} mu_j^+(t) - sum_{j not in J} mu_j^-(t)
    must not vanish on an interval (MODEL.md §3; paper eq. (uniqueness)); otherwise the
    multipliers of the projection, which are the slips, are not unique. Between the friction
    breakpoints every coefficient is a trig polynomial of degree <= H plus a linear part, which
    has at most 2H + 1 zeros on a piece unless it vanishes identically, so sampling 2H + 7
    interior points per piece decides whether g_J vanishes on a sub-interval.

    All 2^N subsets are enumerated for N <= MAX_UNIQUENESS_BLOCKS, vectorised in chunks as a
    0/1 matrix times the sampled coefficients; larger crawlers are not checked (None).
    """
    n = gait.blocks
    if n > MAX_UNIQUENESS_BLOCKS:
        return None
    friction = gait.forward + gait.backward
    edges = union_breakpoints([s.breakpoints() for s in friction] + [np.zeros(1)])
    edges = np.append(edges, 1.0)
    degree = max(s.harmonics for s in friction)
    per_piece = 2 * degree + 7
    fractions = (np.arange(per_piece) + 1.0) / (per_piece + 1.0)
    fractions = fractions + 0.3 * np.sin(7.0 * fractions) / (per_piece + 1.0)
    pieces = len(edges) - 1
    u = (edges[:-1, None] + np.diff(edges)[:, None] * fractions).ravel()

    mu_plus = evaluate_many(gait.forward, u).T
    mu_minus = evaluate_many(gait.backward, u).T
    both = mu_plus + mu_minus
    rest_total = mu_minus.sum(axis=0)
    tolerance = ROUNDOFF * both.sum(axis=0)

    bits = np.arange(n)
    first = np.arange(pieces) * per_piece
    chunk = max(1, _SUBSET_CHUNK_ENTRIES // (n + pieces))
    for start in range(1, 2**n - 1, chunk):
        codes = np.arange(start, min(start + chunk, 2**n - 1))
        subsets = ((codes[:, None] >> bits) & 1).astype(float)
        at_first = np.abs(subsets @ both[:, first] - rest_total[first]) <= tolerance[first]
        for row, piece in zip(*np.nonzero(at_first)):
            columns = slice(piece * per_piece, (piece + 1) * per_piece)
            g = subsets[row] @ both[:, columns] - rest_total[columns]
            if np.all(np.abs(g) <= tolerance[columns]):
                return _uniqueness_message(gait, subsets[row], both, rest_total, tolerance,
                                           edges, per_piece)
    return None


def _uniqueness_message(gait: Gait, subset: np.ndarray, both: np.ndarray, rest_total: np.ndarray,
                        tolerance: np.ndarray, edges: np.ndarray, per_piece: int) -> str:
    g = (subset @ both - rest_total).reshape(-1, per_piece)
    vanishing = np.all(np.abs(g) <= tolerance.reshape(-1, per_piece), axis=1)
    intervals: list[list[float]] = []
    for piece in np.nonzero(vanishing)[0]:
        lo, hi = edges[piece], edges[piece + 1]
        if intervals and abs(intervals[-1][1] - lo) <= JUMP_TOLERANCE:
            intervals[-1][1] = hi
        else:
            intervals.append([lo, hi])
    where = " and ".join(f"[{lo * gait.period:g}, {hi * gait.period:g}]" for lo, hi in intervals)
    inside = np.nonzero(subset)[0]
    outside = np.nonzero(subset == 0)[0]
    return (f"uniqueness condition violated: for J = {_blocks_text(inside)} (forward) and the rest "
            f"{_blocks_text(outside)} (backward), sum mu+ over J - sum mu- over the rest = 0 for t in "
            f"{where} (a whole interval): the model does not determine how the crawler moves "
            "(MODEL.md §3, paper eq. (uniqueness)). Make the friction anisotropic or change a coefficient.")
