"""Generic polyhedral sweeping-process documents (``kind: sweeping-process``, docs/model.md §5):
their schema, the `ProcessSpec` they validate into, and their checks.

A process is refused when its dimensions do not match, when C(t) is empty at a time the run
steps on, when C(t) is unbounded (the paper's theorem needs a compact set; `allow_unbounded:
true` accepts it), when the metric is not symmetric positive definite, or when the initial point
is outside C(0).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.docpaths import replacement
from crawlsim.gait.settings import PERIOD_SCHEMA, ROUNDOFF, SIMULATION_SCHEMA, Simulation, simulation_from
from crawlsim.gait.signals import SIGNAL_SCHEMA, Constant, Signal, evaluate_many, parse_signal, union_breakpoints
from crawlsim.gait.units import UNITS_SCHEMA, Units
from crawlsim.gait.validation import ErrorSink, check_units, count_error, readonly, validated


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

    def __repr__(self) -> str:
        n, m = self.normals.shape[1], len(self.offsets)
        return f"<ProcessSpec {self.name}: {m} faces in R^{n}, period {self.period:g}, from {self.source}>"

    def replace(self, *changes: Any) -> ProcessSpec:
        """A new validated process with values set at dotted paths (see `Gait.replace`)."""
        label, document = replacement(self.source, self.document, changes)
        return validated(
            document, PROCESS_SCHEMA, build_process, label, source_text=self.source_text, default_name=self.name
        )

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

_MATRIX_ROW = {
    "type": "array",
    "minItems": 1,
    "maxItems": MAX_PROCESS_DIMENSION,
    "x-expected": "a list of numbers (one row)",
    "items": {"type": "number", "x-expected": "a number"},
}

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
        "period": PERIOD_SCHEMA,
        "normals": {
            "type": "array",
            "minItems": 1,
            "maxItems": MAX_PROCESS_FACES,
            "x-expected": "a list of m rows b_i, each a list of n numbers",
            "description": f"B: at most {MAX_PROCESS_FACES:,} rows of at most {MAX_PROCESS_DIMENSION:,} numbers.",
            "items": _MATRIX_ROW,
        },
        "offsets": {
            "type": "array",
            "minItems": 1,
            "maxItems": MAX_PROCESS_FACES,
            "x-expected": "a list of m signals c_i(t), one per row of normals",
            "items": SIGNAL_SCHEMA,
        },
        "metric": {
            "type": "array",
            "minItems": 1,
            "maxItems": MAX_PROCESS_DIMENSION,
            "x-expected": "an n x n symmetric positive definite matrix (a list of rows)",
            "items": _MATRIX_ROW,
        },
        "initial": {**_MATRIX_ROW, "x-expected": "a list of n numbers (the initial point z(0))"},
        "allow_unbounded": {"type": "boolean", "x-expected": "true or false (accept an unbounded C(t))"},
        "simulation": SIMULATION_SCHEMA,
        "units": UNITS_SCHEMA,
    },
}
"""JSON Schema (Draft 2020-12) of a generic polyhedral sweeping-process document (docs/model.md §5)."""


def build_process(document: dict, source: str, source_text: str, default_name: str, errors: ErrorSink) -> ProcessSpec:
    check_units(document, source, errors)
    rows = document["normals"]
    n = len(rows[0])
    for i, row in enumerate(rows):
        if len(row) != n:
            raise GaitError(
                source, f"normals[{i}]", f"expected {n} numbers (the dimension n set by normals[0]), got {len(row)}"
            )
    B = np.array(rows, dtype=float)
    m = len(rows)
    for i in range(m):
        if not np.any(B[i]):
            raise GaitError(
                source, f"normals[{i}]", "expected a nonzero normal b_i: a zero row does not describe a face"
            )
    if len(document["offsets"]) != m:
        raise count_error(source, "offsets", m, "offset signals (one per row of normals)", len(document["offsets"]))
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
        raise count_error(source, "initial", n, "coordinates (the dimension n of the normals)", initial.size)

    simulation = simulation_from(document.get("simulation", {}))
    spec = ProcessSpec(
        name=document.get("name", default_name),
        description=document.get("description", ""),
        source=source,
        source_text=source_text,
        document=document,
        period=float(document["period"]),
        normals=readonly(B),
        offsets=offsets,
        metric=readonly(metric),
        initial=readonly(initial),
        allow_unbounded=bool(document.get("allow_unbounded", False)),
        simulation=simulation,
        units=Units.from_block(document.get("units")),
    )
    problem = emptiness_violation(spec)
    if problem is not None:
        raise GaitError(source, "offsets", problem)
    direction = recession_direction(B)
    if direction is not None and not spec.allow_unbounded:
        raise GaitError(
            source,
            "normals",
            "C(t) is unbounded: it contains the ray z + s d, s >= 0, for d = "
            f"{_vector_text(direction)} (B d <= 0). The convergence theorem of the paper "
            "needs a compact C(t); add a face that closes it, or set "
            "'allow_unbounded: true' to run anyway",
        )
    problem = process_admissibility_violation(spec, initial)
    if problem is not None:
        raise GaitError(source, "initial", problem)
    return spec


def _square(rows: list, n: int, source: str) -> list:
    if len(rows) != n:
        raise count_error(source, "metric", n, "rows (an n x n matrix, n from the normals)", len(rows))
    for i, row in enumerate(rows):
        if len(row) != n:
            raise count_error(source, f"metric[{i}]", n, "numbers (an n x n matrix)", len(row))
    return rows


def _metric_violation(metric: np.ndarray) -> str | None:
    """Why ``metric`` cannot define the projections' norm |z|_M^2 = z^T M z, or None."""
    scale = float(np.max(np.abs(metric)))
    asymmetry = float(np.max(np.abs(metric - metric.T)))
    if asymmetry > ROUNDOFF * scale:
        i, j = np.unravel_index(int(np.argmax(np.abs(metric - metric.T))), metric.shape)
        return (
            f"expected a symmetric matrix, but metric[{i}][{j}] = {metric[i, j]:g} and "
            f"metric[{j}][{i}] = {metric[j, i]:g}"
        )
    eigenvalues = np.linalg.eigvalsh(metric)
    if not eigenvalues[0] > ROUNDOFF * max(scale, 1e-300):
        return (
            f"expected a positive definite matrix, but its smallest eigenvalue is "
            f"{eigenvalues[0]:.6g}: |z|_M^2 = z^T M z must be a norm"
        )
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
                where = (
                    f"for t just after about {first * spec.period:.6g} (cycle {first:.6g}; "
                    f"to the LP's feasibility tolerance) and {where}"
                )
            return (
                f"C(t) = {{z : B z <= c(t)}} is empty {where}: no point satisfies every "
                "constraint there. Check the offsets' signs: C(t) = {z : <b_i, z> <= c_i(t)}"
            )
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
        raise GaitError(
            source,
            "offsets",
            f"cannot decide whether C(t) is empty: the LP solver (HiGHS) stopped with: {result.message}",
        )
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
            result = linprog(cost, A_ub=normals, b_ub=np.zeros(m), bounds=[(-1.0, 1.0)] * n, method="highs")
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
    return (
        f"the initial point {_vector_text(point)} is outside C({t:g}): constraint {i} "
        f"(normals[{i}] . z <= offsets[{i}]) reads {slack[i] + c[i]:.12g} <= {c[i]:.12g}, "
        f"violated by {slack[i]:.6g}; the sweeping process must start in C(0)"
    )
