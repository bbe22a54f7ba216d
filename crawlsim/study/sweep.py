"""Parameter sweeps of v0: a grid of edited gait documents, run in batches.

A sweep axis is ``PATH=SPEC``. ``PATH`` is a dotted path into the gait document (integer list
indices, ``*`` for every element: ``links.*.amplitude``, ``friction.1.backward``, ``period``).
``SPEC`` is one of

* ``START:STOP:NUM``: NUM evenly spaced values, both ends included;
* ``log:LO:HI:NUM``: NUM log-spaced (geometric) values, LO and HI > 0, both ends included;
* ``[a,b,c]`` or ``a,b,c``: these values.

Axes are grouped into grid dimensions. A dimension is one axis, or several **linked** axes with
the same number of values that vary together (the command line's ``--link PATH=SPEC`` joins the
``--sweep`` before it): value k of every linked path belongs to index k of the dimension. The
grid is the Cartesian product of the dimensions in the order given, the last varying fastest (C
order): grid point i has the multi-index ``np.unravel_index(i, shape)``.

Every path is resolved against the base document before anything runs, so a bad path is an
`InputError` (exit code 2) and nothing is computed or written; so is a grid in which no point is
a valid gait (no point could run). A point whose edited document is not a valid gait (a friction
value that breaks the uniqueness condition, a non-positive length) is recorded with status
``invalid`` and the reason, and the others run. Points run through the batched exact stepper
(`crawlsim.integrate.batch`), in-process, on local worker processes, or on a Dask cluster; a point that
fails while running is recorded with status ``failed`` and its reason.

Nothing finished is lost: finished points go to a journal next to the output (``OUT.journal``,
JSON lines), flushed and fsynced every `JOURNAL_SECONDS` seconds, at the end and on an
interrupt, and read back on a rerun of the same sweep so that finished points are not
recomputed. The output file is written atomically at the end.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import io
import json
import math
import os
import stat
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from crawlsim.errors import CrawlsimError, GaitError, InputError, OutputError, SweepSpecError
from crawlsim.gait.docpaths import path_keys, resolve_path, set_value
from crawlsim.gait.document import Gait, gait_from_document, need_crawler
from crawlsim.io.atomic import DISK_ERRORS, atomic_path, disk_error
from crawlsim.status import PointStatus

#: Columns of a sweep table after the swept paths (CSV header, HDF5 /results datasets).
RESULT_COLUMNS = ("v0", "v0_error_estimate", "displacement_per_period",
                  "dissipation_per_period", "cost_of_transport", "convergence", "periods",
                  "integrator", "limit", "newton_steps", "status", "message")
#: Result columns that files written before crawlsim 0.2 lack (read back as missing values).
LATER_COLUMNS = ("v0_error_estimate", "dissipation_per_period", "cost_of_transport",
                 "integrator", "limit", "newton_steps")
#: Periods a catch-up point is iterated in the vectorised batch before the periodic-limit
#: solver takes over (finite-time crawlers and fast contractions finish within them).
BATCH_PLAIN_PERIODS = 2
#: Points per task handed to a worker: a task is one batch. Small tasks keep progress and the
#: journal moving; large ones fill the vectorised batch (throughput about doubles from 16 to
#: 256 points). Task sizes adapt between the two to take about `TASK_SECONDS` each.
MIN_CHUNK = 8
MAX_CHUNK = 256
TASK_SECONDS = 2.0
#: Seconds between two flushes of the journal (and at the end, and on an interrupt).
JOURNAL_SECONDS = 3.0
#: How long to wait for a Dask scheduler before giving up (exit code 2).
SCHEDULER_TIMEOUT = "20s"
#: Most values of one axis (START:STOP:NUM, log:LO:HI:NUM), and most points of a grid. At the
#: fastest, some 10^3 points a second, a million points take hours; the values are made before
#: anything is checked, so a mistyped NUM must not allocate gigabytes.
MAX_AXIS_POINTS = 1_000_000


# -- axes and the grid ------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    """One swept path and its values."""

    path: str
    values: tuple

    @property
    def keys(self) -> tuple:
        return path_keys(self.path)


_SPECS = ("START:STOP:NUM, log:LO:HI:NUM, [a,b,c] or a,b,c")


def parse_axis(text: str, option: str = "--sweep") -> Axis:
    """``PATH=SPEC`` -> `Axis` (the specs of the module docstring); a malformed option is a
    `SweepSpecError` naming ``option``."""
    source = f"{option} {text}"
    path, sep, spec = text.partition("=")
    path, spec = path.strip(), spec.strip()
    if not sep or not path or not spec:
        raise SweepSpecError(source, "", f"expected PATH=SPEC with SPEC one of {_SPECS}, for "
                                         "example links.*.amplitude=0.1:0.4:7")
    if any(part == "" for part in path.split(".")):
        raise SweepSpecError(source, path, "empty key in the dotted path")
    if spec.startswith("[") or spec.endswith("]"):
        if not (spec.startswith("[") and spec.endswith("]")) or not spec[1:-1].strip():
            raise SweepSpecError(source, path, f"expected a list [a,b,c] of numbers, got {spec!r}")
        values = _list(spec[1:-1], source, path)
    elif spec.lower().startswith("log:"):
        lo, hi, num = _range(spec[4:], source, path, "log:LO:HI:NUM")
        if not (lo > 0 and hi > 0):
            raise SweepSpecError(source, path, f"log-spaced values need LO > 0 and HI > 0, got "
                                               f"{spec!r}")
        values = tuple(float(v) for v in np.geomspace(lo, hi, num))
        values = (lo, *values[1:-1], hi) if num > 1 else (lo,)  # both ends exactly as given
    elif ":" in spec:
        start, stop, num = _range(spec, source, path, "START:STOP:NUM")
        values = tuple(float(v) for v in np.linspace(start, stop, num))
    else:
        values = _list(spec, source, path)
    if not all(math.isfinite(v) for v in values):
        raise SweepSpecError(source, path, f"values must be finite numbers, got {spec!r}")
    return Axis(path, values)


def _range(spec: str, source: str, path: str, form: str) -> tuple[float, float, int]:
    parts = spec.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise SweepSpecError(source, path, f"expected {form} with NUM an integer, got "
                                           f"{spec!r}") from None
    if num < 1:
        raise SweepSpecError(source, path, f"NUM must be at least 1, got {num}")
    if num > MAX_AXIS_POINTS:
        raise SweepSpecError(source, path, f"NUM must be at most {MAX_AXIS_POINTS:,}, got {num:,}; "
                                           "a sweep that large would not finish: sweep fewer points")
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise SweepSpecError(source, path, f"values must be finite numbers, got {spec!r}")
    return start, stop, num


def _list(text: str, source: str, path: str) -> tuple:
    try:
        return tuple(_number(v) for v in text.split(","))
    except ValueError:
        raise SweepSpecError(source, path, f"expected a comma list of numbers, got {text!r}") \
            from None


def _number(text: str):
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        return float(text)


@dataclass(frozen=True, eq=False)
class SweepGrid:
    """A base gait and its axes: the grid of edited gait documents.

    ``dims[a]`` is the grid dimension of axis a; linked axes share one (`make_grid`).
    """

    base: Gait
    axes: tuple[Axis, ...]
    targets: tuple[tuple[tuple, ...], ...]  # concrete key tuples of each axis
    dims: tuple[int, ...] = ()
    sensitivity: tuple[str, ...] = ()  # --sensitivity paths: a dv0/dPATH column each

    def __post_init__(self) -> None:
        if not self.dims:
            object.__setattr__(self, "dims", tuple(range(len(self.axes))))
        if self.size > MAX_AXIS_POINTS:
            raise SweepSpecError("--sweep", "", f"the grid has {self.size:,} points (the product of "
                                                f"its axes), more than {MAX_AXIS_POINTS:,}; a sweep "
                                                "that large would not finish: sweep fewer points")

    @property
    def shape(self) -> tuple[int, ...]:
        return _shape([len(a.values) for a in self.axes], self.dims)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def paths(self) -> tuple[str, ...]:
        return tuple(a.path for a in self.axes)

    @property
    def linked(self) -> bool:
        return len(set(self.dims)) < len(self.dims)

    @property
    def gait_yaml(self) -> str:
        """The base gait document as YAML, simulation overrides included."""
        return yaml.safe_dump(self.base.document, sort_keys=False)

    def values(self, index: int) -> tuple:
        """The value of every axis at grid point ``index``."""
        multi = np.unravel_index(index, self.shape) if self.axes else ()
        return tuple(a.values[multi[d]] for a, d in zip(self.axes, self.dims))

    def document(self, index: int) -> dict:
        doc = copy.deepcopy(self.base.document)
        for targets, value in zip(self.targets, self.values(index)):
            for keys in targets:
                set_value(doc, keys, value)
        return doc

    def label(self, index: int) -> str:
        """The point in words, for error messages: ``file with path=value, ...``."""
        pairs = ", ".join(f"{a.path}={v!r}" for a, v in zip(self.axes, self.values(index)))
        return f"{self.base.source} with {pairs}" if pairs else self.base.source

    def gait(self, index: int) -> Gait:
        """Grid point ``index`` validated into a Gait (a GaitError names the point)."""
        gait = gait_from_document(self.document(index), self.label(index),
                                  source_text=self.base.source_text,
                                  default_name=self.base.name)
        assert isinstance(gait, Gait)  # the base is a crawler, and sweeps keep the kind
        return gait

    def fingerprint(self, shard) -> str:
        """Identity of a sweep: base document, axes, links and shard (journals from others are
        refused). Unlinked grids hash as before links existed, so their journals resume."""
        axes: list = [[a.path, list(a.values)] for a in self.axes]
        if self.linked:
            axes = [axes, list(self.dims)]
        spec = json.dumps([self.gait_yaml, axes, list(shard) if shard else None]
                          + ([list(self.sensitivity)] if self.sensitivity else []))
        return hashlib.sha256(spec.encode()).hexdigest()

    def indices(self, shard=None) -> np.ndarray:
        """Grid indices of the shard ``(i, n)`` (1-based i: points i-1, i-1+n, ...), or all."""
        if shard is None:
            return np.arange(self.size)
        i, n = shard
        return np.arange(i - 1, self.size, n)


def _shape(lengths, dims) -> tuple[int, ...]:
    """Values per grid dimension: the length of the first axis of each dimension."""
    first: dict[int, int] = {}
    for length, d in zip(lengths, dims):
        first.setdefault(d, int(length))
    return tuple(first[d] for d in sorted(first))


def _group(item) -> tuple[Axis, ...]:
    """One grid dimension: an `Axis` or ``PATH=SPEC``, or a sequence of them (linked paths)."""
    if isinstance(item, (Axis, str)):
        items: Sequence = [item]
    else:
        items = list(item)
        if not items:
            raise SweepSpecError("--sweep", "", "an empty group of linked paths")
    return tuple(a if isinstance(a, Axis) else parse_axis(a, "--sweep" if k == 0 else "--link")
                 for k, a in enumerate(items))


def make_grid(base: Gait, axes, sensitivity: Sequence[str] = ()) -> SweepGrid:
    """The grid of ``base`` over ``axes``: each item is one dimension, an `Axis` (or its
    ``PATH=SPEC`` text) or a sequence of them that vary together (linked paths, the same
    number of values each). Every path is checked against the base document; overlapping or
    repeated paths are refused, and so is a base that is not a crawler (`crawlsim.gait.document.need_crawler`)."""
    need_crawler(base, "a sweep of v0")
    groups = [_group(item) for item in axes]
    flat: list[Axis] = []
    dims: list[int] = []
    for d, group in enumerate(groups):
        for axis in group[1:]:
            if len(axis.values) != len(group[0].values):
                raise SweepSpecError(f"--link {axis.path}", axis.path,
                                     f"has {len(axis.values)} values, but the path it is linked "
                                     f"to ({group[0].path}) has {len(group[0].values)}: linked "
                                     "paths vary together and need the same number of values")
        flat.extend(group)
        dims.extend([d] * len(group))
    source = base.source
    targets = tuple(tuple(resolve_path(base.document, a, source)) for a in flat)
    seen: dict[tuple, str] = {}
    for k, (axis, keys) in enumerate(zip(flat, targets)):
        option = "--link" if k and dims[k] == dims[k - 1] else "--sweep"
        for key in keys:
            if key in seen:
                raise GaitError(source, axis.path, f"this path sets {'.'.join(map(str, key))}, "
                                                   f"which {seen[key]} sets too: sweep each "
                                                   "value once")
            seen[key] = f"{option} {axis.path}"
    from crawlsim.analysis.sensitivity_sweep import check_paths

    return SweepGrid(base, tuple(flat), targets, tuple(dims), check_paths(base, sensitivity))


def parse_shard(text: str) -> tuple[int, int]:
    """``I/N`` with 1 <= I <= N."""
    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise SweepSpecError(f"--shard {text}", "", "expected I/N, for example 3/16") from None
    if not 1 <= i <= n:
        raise SweepSpecError(f"--shard {text}", "", f"expected 1 <= I <= N, got I = {i}, "
                                                    f"N = {n}")
    return i, n


def check_some_point_runs(grid: SweepGrid) -> None:
    """Refuse a grid in which no point is a valid gait: nothing could run (a misspelt optional
    key, say, or a value that every point shares). Scans in grid order and stops at the first
    valid point, so a usual grid costs one validation."""
    first: InputError | None = None
    for index in range(grid.size):
        try:
            grid.gait(index)
        except InputError as exc:
            first = first or exc
        else:
            return
    if first is not None:
        raise SweepSpecError(first.source, first.keypath,
                             f"{first.message} (no point of the grid is a valid gait: "
                             f"all {grid.size} are refused, this is the first)")


# -- running points ---------------------------------------------------------------------------
@dataclass(frozen=True)
class PointResult:
    """One row of a sweep table (without the swept values, which the grid gives)."""

    index: int
    status: PointStatus
    v0: float | None = None
    v0_error_estimate: float | None = None
    displacement_per_period: float | None = None
    dissipation_per_period: float | None = None
    cost_of_transport: float | None = None
    convergence: str = ""
    periods: int = 0
    integrator: str = ""
    message: str = ""
    steps: int = 0
    limit: str = ""
    newton_steps: int | None = None  # None: not computed (a failed point, an older file)
    derivatives: dict[str, float | None] | None = None  # dv0/dPATH (--sensitivity)

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", PointStatus(self.status))

    def to_json(self) -> dict:
        return {f: getattr(self, f) for f in _POINT_FIELDS}

    @classmethod
    def from_json(cls, row: dict) -> PointResult:
        """A journal line (older journals lack the later columns: they stay missing)."""
        return cls(**{k: v for k, v in row.items() if k in _POINT_FIELDS})


_POINT_FIELDS = ("index", "status", "v0", "v0_error_estimate", "displacement_per_period",
                 "dissipation_per_period", "cost_of_transport", "convergence", "periods",
                 "integrator", "message", "steps", "limit", "newton_steps", "derivatives")


def _failure(index: int, exc: BaseException) -> PointResult:
    """An invalid point (bad input: exit code 2 for a single run) or a failed one."""
    if isinstance(exc, InputError):
        return PointResult(int(index), PointStatus.INVALID, message=str(exc))
    text = str(exc) if isinstance(exc, CrawlsimError) else f"{type(exc).__name__}: {exc}"
    return PointResult(int(index), PointStatus.FAILED, message=text)


def run_points(grid: SweepGrid, indices, *, capacity=None, progress=None) -> list[PointResult]:
    """Validate and evaluate the grid points ``indices`` (a worker's task); a point that is not
    a valid gait is an ``invalid`` row, the others go to `evaluate`. ``progress(k)`` is called
    as k more points finish."""
    rows: dict[int, PointResult] = {}
    valid: list[tuple[int, Gait]] = []
    for i in (int(i) for i in indices):
        try:
            valid.append((i, grid.gait(i)))
        except InputError as exc:
            rows[i] = _failure(i, exc)
            if progress is not None:
                progress(1)
    if valid:
        runs: dict | None = {} if grid.sensitivity else None  # their limits, for derivatives
        for row in evaluate([g for _, g in valid], [i for i, _ in valid], capacity=capacity,
                            progress=progress, runs=runs):
            rows[row.index] = row
        if runs is not None:
            from crawlsim.analysis.sensitivity_sweep import with_derivatives

            rows.update(with_derivatives(grid.sensitivity, valid, rows, runs))
    return [rows[int(i)] for i in indices]


def evaluate(gaits, indices, *, capacity=None, progress=None, runs=None) -> list[PointResult]:
    """v0 of validated gaits: ``exact`` ones one by one (periodic-limit solver, no history),
    catch-up ones through the batched stepper, for at most `BATCH_PLAIN_PERIODS` periods when
    the gait's limit method is ``newton`` (the periodic-limit solver then finishes those that
    have not converged, one by one).

    A row's ``v0_error_estimate`` bounds the true error of its v0. Catch-up rows leave it
    missing: their time-step error is not measured in a sweep (a single run measures it against
    the exact integrator, which would double a sweep's cost); the exact integrator, the
    default, has none.

    One point never stops the others: a gait that cannot be compiled, or a batch that raises,
    is retried point by point, and each point that still raises is recorded (``invalid`` for an
    `InputError` such as a uniqueness failure at a grid time, ``failed`` otherwise).
    """
    from crawlsim.analysis.run import simulate
    from crawlsim.integrate.batch import DEFAULT_CAPACITY, simulate_batch
    from crawlsim.model.process import compile_gait

    out: dict[int, PointResult] = {}
    batch: list[tuple[int, Any, Gait]] = []
    single: list[tuple[int, Any, Gait]] = []
    for i, g in zip((int(i) for i in indices), gaits):
        try:
            process = compile_gait(g)
        except Exception as exc:  # recorded in the row: the sweep goes on
            if isinstance(exc, MemoryError):
                raise
            out[i] = _failure(i, exc)
            if progress is not None:
                progress(1)
            continue
        (batch if g.simulation.integrator == "catch-up" else single).append((i, process, g))

    def batched(members, progress):
        newton = [g.simulation.limit == "newton" for _, _, g in members]
        runs = simulate_batch(
            [p for _, p, _ in members],
            max_periods=[min(g.simulation.max_periods, BATCH_PLAIN_PERIODS) if n
                         else g.simulation.max_periods for (_, _, g), n in zip(members, newton)],
            tolerance=[g.simulation.tolerance for _, _, g in members],
            capacity=capacity or DEFAULT_CAPACITY, progress=None)
        for (i, p, g), r, n in zip(members, runs, newton):
            if n and r.status == PointStatus.NOT_CONVERGED \
                    and g.simulation.max_periods > BATCH_PLAIN_PERIODS:
                single.append((i, p, g))  # the periodic-limit solver finishes it
                continue
            out[i] = PointResult(
                i, r.status, v0=r.v0, v0_error_estimate=None,  # time-step error unmeasured
                displacement_per_period=r.displacement_per_period,
                dissipation_per_period=r.dissipation_per_period,
                cost_of_transport=r.cost_of_transport, convergence=str(r.convergence or ""),
                periods=r.periods, integrator="catch-up", message=r.message, steps=r.steps,
                **({"limit": "iterate", "newton_steps": 0} if r.v0 is not None else {}))
            if progress is not None:
                progress(1)

    if batch:
        try:
            batched(batch, progress)
        except Exception as exc:  # one bad point must not sink its batch
            if isinstance(exc, MemoryError):
                raise
            done = set(out) | {i for i, _, _ in single}
            for member in batch:
                if member[0] in done:
                    continue
                try:
                    batched([member], progress)
                except Exception as one:
                    if isinstance(one, MemoryError):
                        raise
                    out[member[0]] = _failure(member[0], one)
                    if progress is not None:
                        progress(1)
    for i, process, g in single:
        s = g.simulation
        try:
            run = simulate(process, max_periods=s.max_periods, tolerance=s.tolerance,
                           integrator=s.integrator, limit=s.limit, history=False)
        except Exception as exc:
            if isinstance(exc, MemoryError):
                raise
            out[i] = _failure(i, exc)
        else:
            status = PointStatus.OK if run.converged else PointStatus.NOT_CONVERGED
            out[i] = PointResult(
                i, status, v0=run.v0,
                v0_error_estimate=run.v0_error_estimate if run.integrator == "exact" else None,
                displacement_per_period=run.displacement_per_period,
                dissipation_per_period=run.dissipation_per_period,
                cost_of_transport=run.cost_of_transport, convergence=str(run.convergence),
                periods=run.periods + run.limit_periods, integrator=run.integrator,
                steps=run.steps, limit=run.limit_method, newton_steps=run.limit_newton_steps)
            if runs is not None:  # ``runs``: each point run here, by index (``--sensitivity``)
                runs[i] = run
        if progress is not None:
            progress(1)
    return [out[int(i)] for i in indices]


# -- the journal --------------------------------------------------------------------------------
class Journal:
    """JSON lines next to the output: a header, then one line per finished point.

    The first rows are written at once (the journal shows up with the first finished points);
    later rows are buffered and written, flushed and fsynced every ``interval`` seconds, on
    `flush` and on `close` (which the sweep calls at the end and on an interrupt), so an
    interrupted sweep keeps every finished point and a killed one loses at most the last
    ``interval`` seconds. A torn last line (a kill mid-write) is ignored on reading.
    """

    def __init__(self, path: Path, fingerprint: str, *, interval: float | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.path = Path(path)
        self.fingerprint = fingerprint
        self.interval = JOURNAL_SECONDS if interval is None else float(interval)
        self.clock = clock
        self._file: io.TextIOWrapper | None = None
        self._buffer: list[PointResult] = []
        self._last: float | None = None  # time of the last flush

    def _check_regular(self) -> None:
        """Refuse a journal path that is not a regular file (a FIFO would block the sweep
        forever, a device swallow its points): `OutputError`, exit code 2."""
        try:
            mode = os.stat(self.path).st_mode
        except FileNotFoundError:
            return
        except OSError as error:
            raise OutputError(str(self.path), "", f"cannot inspect the journal: {error.strerror}") from None
        if not stat.S_ISREG(mode):
            from crawlsim.io.outputs import special_kind

            raise OutputError(str(self.path), "", f"is {special_kind(mode)}, not a regular file: "
                                                  "the journal of a sweep must be a regular file; "
                                                  "remove it, or choose another output name")

    def load(self) -> dict[int, PointResult]:
        """Finished points of an earlier run of the same sweep ({} when there is none)."""
        self._check_regular()
        if not self.path.exists():
            return {}
        done = {}
        with open(self.path, encoding="utf-8") as f:
            lines = f.read().split("\n")
        try:
            header = json.loads(lines[0])
        except (json.JSONDecodeError, IndexError):
            header = {}
        if not isinstance(header, dict) or header.get("fingerprint") != self.fingerprint:
            raise GaitError(str(self.path), "", "this journal belongs to a different sweep (other "
                                                "gait, paths, values or shard); delete it to start "
                                                "afresh, or rerun the sweep that wrote it")
        for line in lines[1:]:
            try:
                row = PointResult.from_json(json.loads(line))
            except (json.JSONDecodeError, TypeError, ValueError):
                continue
            done[row.index] = row
        return done

    def append(self, results) -> None:
        self._buffer.extend(results)
        if self._last is None or self.clock() - self._last >= self.interval:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows, flush and fsync."""
        if not self._buffer:
            return
        self._last = self.clock()
        rows, self._buffer = self._buffer, []
        try:
            if self._file is None:
                self._check_regular()
                new = not self.path.exists() or self.path.stat().st_size == 0
                self._file = open(self.path, "a", encoding="utf-8")
                if new:
                    self._file.write(json.dumps({"fingerprint": self.fingerprint}) + "\n")
            self._file.write("".join(json.dumps(r.to_json()) + "\n" for r in rows))
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as error:
            self._abandon()
            if error.errno in DISK_ERRORS:
                raise disk_error(self.path, error, "the sweep stopped; the journal keeps the "
                                                   "points written before") from None
            raise

    def _abandon(self) -> None:
        """Forget the file after a failed write (its buffered text cannot be written either; a
        torn last line is ignored on reading)."""
        self._buffer = []
        if self._file is not None:
            try:
                self._file.close()
            except OSError:
                pass
            self._file = None

    def close(self) -> None:
        try:
            self.flush()
        finally:
            if self._file is not None:
                self._file.close()
                self._file = None

    def remove(self) -> None:
        self._buffer = []
        self.close()
        self.path.unlink(missing_ok=True)


def journal_path(output) -> Path:
    return Path(str(output) + ".journal")


# -- the table --------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SweepTable:
    """The results of a sweep (or of one shard): one row per grid point, in grid order.

    ``dims[a]`` is the grid dimension of path a (linked paths share one); None: each its own.
    """

    paths: tuple[str, ...]
    axes: tuple[np.ndarray, ...]  # values of each swept path
    points: np.ndarray  # grid index of each row
    rows: tuple[PointResult, ...]
    gait_yaml: str
    source: str
    shard: tuple[int, int] | None = None
    computed: int = 0  # points simulated by this run (the others came from the journal)
    dims: tuple[int, ...] | None = field(default=None)

    @property
    def dimensions(self) -> tuple[int, ...]:
        return tuple(range(len(self.paths))) if self.dims is None else tuple(self.dims)

    @property
    def shape(self) -> tuple[int, ...]:
        return _shape([len(a) for a in self.axes], self.dimensions)

    def dimension_paths(self) -> list[list[str]]:
        """The swept paths of each grid dimension (linked paths together), in grid order."""
        out: dict[int, list[str]] = {}
        for path, d in zip(self.paths, self.dimensions):
            out.setdefault(d, []).append(path)
        return [out[d] for d in sorted(out)]

    def coordinates(self) -> list[np.ndarray]:
        """Swept value of each row, per path."""
        if not self.paths:
            return []
        multi = np.unravel_index(self.points, self.shape)
        return [np.asarray(a)[multi[d]] for a, d in zip(self.axes, self.dimensions)]

    def columns(self) -> dict[str, np.ndarray]:
        """Every column of the table (swept paths first), as arrays."""
        cols = dict(zip(self.paths, self.coordinates()))
        for name in RESULT_COLUMNS:
            values = [getattr(r, name) for r in self.rows]
            if name == "periods":
                cols[name] = np.array(values, dtype=np.int64)
            elif name == "newton_steps":  # -1: not computed
                cols[name] = np.array([-1 if v is None else v for v in values], dtype=np.int64)
            elif name in ("convergence", "integrator", "limit", "status", "message"):
                cols[name] = np.array([str(v) for v in values], dtype=object)
            else:
                cols[name] = np.array([np.nan if v is None else v for v in values], float)
        from crawlsim.analysis import sensitivity_sweep

        cols.update(sensitivity_sweep.columns(self.rows))
        return cols

    def counts(self) -> dict[str, int]:
        out = {str(s): 0 for s in PointStatus}
        for r in self.rows:
            out[r.status] = out.get(r.status, 0) + 1
        return out

    def grid(self, column: str) -> np.ndarray:
        """A column on the grid's shape (full tables only)."""
        values = self.columns()[column]
        full = np.full(math.prod(self.shape), np.nan if values.dtype != object else "",
                       dtype=values.dtype)
        full[self.points] = values
        return full.reshape(self.shape)

    def to_csv(self) -> str:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        from crawlsim.analysis.sensitivity_sweep import columns

        derivatives = columns(self.rows)
        writer.writerow(list(self.paths) + list(RESULT_COLUMNS) + list(derivatives))
        coords = self.coordinates()
        for n, r in enumerate(self.rows):
            writer.writerow([_cell(c[n]) for c in coords]
                            + [_cell(getattr(r, name)) for name in RESULT_COLUMNS]
                            + [_cell(d[n]) for d in derivatives.values()])
        return buf.getvalue()


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return "" if not math.isfinite(value) else repr(float(value))
    if isinstance(value, np.integer):
        return str(int(value))
    return str(value)


def write_table(table: SweepTable, output) -> None:
    """CSV (``.csv`` or any other suffix) or HDF5 (``.h5``/``.hdf5``), written atomically."""
    output = Path(output)
    if is_hdf5(output):
        from crawlsim.io import hdf5 as h5io

        h5io.write_sweep(output, **table_payload(table))
        return
    with atomic_path(output) as tmp:
        tmp.write_text(table.to_csv(), encoding="utf-8", newline="")


def is_hdf5(path) -> bool:
    return Path(path).suffix.lower() in (".h5", ".hdf5")


def table_payload(table: SweepTable) -> dict:
    """The plain data `crawlsim.io.hdf5.write_sweep` stores."""
    return dict(paths=list(table.paths), axes=[np.asarray(a) for a in table.axes],
                points=np.asarray(table.points, dtype=np.int64), columns=table.columns(),
                gait_yaml=table.gait_yaml, source=table.source,
                shard="" if table.shard is None else f"{table.shard[0]}/{table.shard[1]}",
                steps=np.array([r.steps for r in table.rows], dtype=np.int64),
                dimensions=list(table.dimensions))


def read_table(path) -> SweepTable:
    """A sweep HDF5 file (complete or a shard) back as a `SweepTable`. Files written before the
    `LATER_COLUMNS` existed read with those columns missing (NaN, "")."""
    from crawlsim.analysis.sensitivity_sweep import row_derivatives
    from crawlsim.io import hdf5 as h5io

    data = h5io.read_sweep(path)
    cols = data["columns"]

    def number(name, n):
        if name not in cols:
            return None
        value = float(cols[name][n])
        return None if math.isnan(value) else value

    rows: list[PointResult] = []
    for n, point in enumerate(data["points"]):
        rows.append(PointResult(
            int(point), PointStatus(str(cols["status"][n])), v0=number("v0", n),
            v0_error_estimate=number("v0_error_estimate", n),
            displacement_per_period=number("displacement_per_period", n),
            dissipation_per_period=number("dissipation_per_period", n),
            cost_of_transport=number("cost_of_transport", n),
            convergence=str(cols["convergence"][n]), periods=int(cols["periods"][n]),
            integrator=str(cols["integrator"][n]) if "integrator" in cols else "",
            message=str(cols["message"][n]), steps=int(data["steps"][n]),
            limit=str(cols["limit"][n]) if "limit" in cols else "",
            newton_steps=(int(cols["newton_steps"][n])
                          if "newton_steps" in cols and cols["newton_steps"][n] >= 0 else None),
            derivatives=row_derivatives(cols, n)))
    shard = parse_shard(data["shard"]) if data["shard"] else None
    dims = data.get("dimensions")
    return SweepTable(tuple(data["paths"]), tuple(data["axes"]), np.asarray(data["points"]),
                      tuple(rows), data["gait_yaml"], data["source"], shard,
                      dims=None if dims is None else tuple(int(d) for d in dims))


def merge_tables(tables) -> SweepTable:
    """Join the N shards of one sweep into the table an unsharded run gives.

    All parts must come from the same sweep (gait, paths, values, links, N), and together hold
    each shard 1..N exactly once; otherwise a `ResultsFileError` says what is wrong (exit code 2).
    """
    from crawlsim.errors import ResultsFileError

    tables = list(tables)
    if not tables:
        raise ResultsFileError("no shard files given", "merge")
    first = tables[0]
    for t in tables:
        if t.shard is None:
            raise ResultsFileError("not a shard (no shard attribute): only files written "
                                   "with --shard I/N are merged", t.source)
        if (t.gait_yaml != first.gait_yaml or t.paths != first.paths
                or t.dimensions != first.dimensions or len(t.axes) != len(first.axes)
                or not all(np.array_equal(a, b) for a, b in zip(t.axes, first.axes))):
            raise ResultsFileError("this shard is from a different sweep (gait, paths or "
                                   "values differ from the first part)", t.source)
    n = first.shard[1]
    seen = sorted(t.shard[0] for t in tables)
    if any(t.shard[1] != n for t in tables) or seen != list(range(1, n + 1)):
        missing = sorted(set(range(1, n + 1)) - set(seen))
        repeated = sorted({i for i in seen if seen.count(i) > 1})
        raise ResultsFileError(f"expected shards 1..{n} once each; missing "
                               f"{missing or 'none'}, repeated {repeated or 'none'}", "merge")
    rows = sorted((r for t in tables for r in t.rows), key=lambda r: r.index)
    size = math.prod(first.shape)
    if [r.index for r in rows] != list(range(size)):
        raise ResultsFileError("the shards do not cover the grid exactly once", "merge")
    return SweepTable(first.paths, first.axes, np.arange(size), tuple(rows), first.gait_yaml,
                      first.source, None, dims=first.dims)


# -- executors ----------------------------------------------------------------------------------
class _Chunker:
    """Hands out the points still to do as tasks sized to take about `TASK_SECONDS` on one
    worker, at the rate measured so far (`MIN_CHUNK` until the first task is back); the last
    tasks shrink so that the workers finish together."""

    def __init__(self, todo: np.ndarray, workers: int):
        self.todo = np.asarray(todo, dtype=np.int64)
        self.workers = max(1, int(workers))
        self.pos = 0
        self.points = 0
        self.seconds = 0.0

    def record(self, points: int, seconds: float) -> None:
        self.points += points
        self.seconds += seconds

    def take(self) -> np.ndarray | None:
        left = len(self.todo) - self.pos
        if left <= 0:
            return None
        size = MIN_CHUNK
        if self.seconds > 0:
            size = round(self.points / self.seconds * TASK_SECONDS)
        size = max(MIN_CHUNK, min(MAX_CHUNK, size, math.ceil(left / self.workers)))
        chunk = self.todo[self.pos:self.pos + size]
        self.pos += len(chunk)
        return chunk


def _run_here(grid, todo, collect, progress) -> None:
    chunker = _Chunker(todo, 1)
    while (chunk := chunker.take()) is not None:
        began = time.perf_counter()
        rows = run_points(grid, chunk, progress=progress)
        chunker.record(len(chunk), time.perf_counter() - began)
        collect(rows)


_WORKER: dict[str, Any] = {}


def _init_worker(grid, queue) -> None:
    """A local worker keeps the grid for all its tasks; Ctrl-C is the parent's to handle (it
    stops the pool), so a worker ignores SIGINT rather than dying with a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _WORKER["grid"], _WORKER["queue"] = grid, queue


def _pool_task(indices):
    """A local worker's task: rows of ``indices`` and the seconds they took. Each finished
    point is reported on the progress queue at once."""
    queue = _WORKER["queue"]
    began = time.perf_counter()
    rows = run_points(_WORKER["grid"], indices, progress=None if queue is None else queue.put)
    return rows, time.perf_counter() - began


def _dask_task(grid, indices):
    """A Dask worker's task (``grid`` is scattered once to every worker)."""
    began = time.perf_counter()
    rows = run_points(grid, indices)
    return rows, time.perf_counter() - began


def _relay(queue, progress) -> None:
    """Progress counts from the workers' queue, until the None that ends the pool."""
    while (k := queue.get()) is not None:
        progress(k)


def _run_pool(grid, todo, jobs, collect, progress) -> None:
    """A pool of ``jobs`` local processes, two tasks in flight per worker."""
    import multiprocessing
    import threading
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    context = multiprocessing.get_context("forkserver" if os.name == "posix" else "spawn")
    if os.name == "posix":
        context.set_forkserver_preload(["crawlsim.study.sweep", "crawlsim.integrate.batch"])
    queue = context.SimpleQueue() if progress is not None else None
    if queue is not None:
        threading.Thread(target=_relay, args=(queue, progress), name="crawlsim-relay",
                         daemon=True).start()
    chunker = _Chunker(todo, jobs)
    ex = ProcessPoolExecutor(jobs, mp_context=context, initializer=_init_worker,
                             initargs=(grid, queue))
    pending: dict = {}
    try:
        for _ in range(2 * jobs):
            chunk = chunker.take()
            if chunk is None:
                break
            pending[ex.submit(_pool_task, chunk)] = chunk
        while pending:
            ready, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for fut in ready:
                chunk = pending.pop(fut)
                rows, seconds = fut.result()
                chunker.record(len(chunk), seconds)
                collect(rows)
                nxt = chunker.take()
                if nxt is not None:
                    pending[ex.submit(_pool_task, nxt)] = nxt
    except BaseException:
        _stop_pool(ex, pending)
        raise
    ex.shutdown(wait=True)
    if queue is not None:
        queue.put(None)  # after every worker's last report: the relay drains them all


def _pool_grid_task(grid, indices):
    """A task of a `WorkerPool`, which serves several grids: the grid comes with the task."""
    queue = _WORKER["queue"]
    began = time.perf_counter()
    rows = run_points(grid, indices, progress=None if queue is None else queue.put)
    return rows, time.perf_counter() - began


class WorkerPool:
    """``jobs`` local worker processes kept for several sweeps, for a caller that runs many
    small ones (an optimisation runs one per generation of its search: starting a pool for each,
    about a second, would cost more than the workers save). Use as a context manager and pass
    it to `run_sweep` as ``pool``; each task carries its grid. Progress reports from the workers
    go to the ``progress`` of the sweep that is running."""

    def __init__(self, jobs: int):
        import multiprocessing
        import threading
        from concurrent.futures import ProcessPoolExecutor

        self.jobs = int(jobs)
        context = multiprocessing.get_context("forkserver" if os.name == "posix" else "spawn")
        if os.name == "posix":
            context.set_forkserver_preload(["crawlsim.study.sweep", "crawlsim.integrate.batch"])
        self.progress: Callable[[int], None] | None = None
        self._queue = context.SimpleQueue()
        self._relay = threading.Thread(target=_relay, args=(self._queue, self._report),
                                       name="crawlsim-relay", daemon=True)
        self._relay.start()
        self.executor = ProcessPoolExecutor(self.jobs, mp_context=context,
                                            initializer=_init_worker,
                                            initargs=(None, self._queue))

    def _report(self, k: int) -> None:
        if self.progress is not None:
            self.progress(k)

    def stop(self) -> None:
        """End the workers now (an interrupt, a failure)."""
        _stop_pool(self.executor, {})
        self._queue.put(None)

    def close(self) -> None:
        self.executor.shutdown(wait=True)
        self._queue.put(None)
        self._relay.join(5)

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.stop()
        else:
            self.close()


def _run_shared_pool(grid, todo, pool: WorkerPool, collect, progress) -> None:
    """`_run_pool` on a `WorkerPool` that outlives this sweep."""
    from concurrent.futures import FIRST_COMPLETED, wait

    chunker = _Chunker(todo, pool.jobs)
    pool.progress = progress
    pending: dict = {}
    try:
        for _ in range(2 * pool.jobs):
            chunk = chunker.take()
            if chunk is None:
                break
            pending[pool.executor.submit(_pool_grid_task, grid, chunk)] = chunk
        while pending:
            ready, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for fut in ready:
                chunk = pending.pop(fut)
                rows, seconds = fut.result()
                chunker.record(len(chunk), seconds)
                collect(rows)
                nxt = chunker.take()
                if nxt is not None:
                    pending[pool.executor.submit(_pool_grid_task, grid, nxt)] = nxt
    except BaseException:
        for fut in pending:
            fut.cancel()
        pool.stop()
        raise


def _stop_pool(ex, pending) -> None:
    """Cancel what has not started and end the workers now (an interrupt, a failure)."""
    for fut in pending:
        fut.cancel()
    processes = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(5)


def check_scheduler(address: str) -> None:
    """Refuse (`SweepSpecError`, exit code 2), before anything is computed, a ``--scheduler``
    that is not the address of a Dask scheduler (SCHEME://HOST:PORT or HOST:PORT) or when Dask
    is not installed."""
    source = f"--scheduler {address}"
    try:
        from distributed.comm.addressing import get_address_host_port
    except ImportError:
        raise SweepSpecError(source, "", "Dask is not installed: pip install 'crawlsim[dask]'") from None
    try:
        host, port = get_address_host_port(address)
        valid = bool(host) and 0 < int(port) < 65536
    except (ValueError, TypeError):
        valid = False
    if not valid:
        raise SweepSpecError(source, "", "expected the address of a Dask scheduler, "
                                         "SCHEME://HOST:PORT such as tcp://127.0.0.1:8786")


def _run_dask(grid, todo, scheduler, collect, progress) -> None:
    """Tasks on a Dask cluster, two in flight per worker thread, collected as each finishes
    (`distributed.as_completed`): progress and the journal move with every task."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise SweepSpecError("--scheduler", "", "Dask is not installed: pip install "
                                                "'crawlsim[dask]'") from None
    check_scheduler(scheduler)
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
    except OSError as exc:
        raise SweepSpecError(f"--scheduler {scheduler}", "", f"cannot reach the Dask scheduler "
                                                             f"({exc})") from None
    pending: dict = {}
    try:
        workers = _workers(client)
        chunker = _Chunker(todo, workers)
        shared = client.scatter(grid, broadcast=True)

        def submit():
            chunk = chunker.take()
            if chunk is None:
                return None
            fut = client.submit(_dask_task, shared, chunk, pure=False)
            pending[fut] = chunk
            return fut

        first = [f for f in (submit() for _ in range(2 * workers)) if f is not None]
        done = as_completed(first)
        for fut in done:
            chunk = pending.pop(fut)
            rows, seconds = fut.result()
            chunker.record(len(chunk), seconds)
            collect(rows)
            if progress is not None:
                progress(len(rows))
            nxt = submit()
            if nxt is not None:
                done.add(nxt)
    except BaseException:
        if pending:
            client.cancel(list(pending))
        raise
    finally:
        client.close()


def _workers(client) -> int:
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:
        return 1


# -- the sweep ----------------------------------------------------------------------------------
class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (or SIGTERM): ``done`` of ``total`` points are finished and
    kept in ``journal`` (None when the sweep has no output, and so no journal)."""

    def __init__(self, done: int, total: int, journal: Path | None):
        super().__init__(f"interrupted after {done} of {total} points")
        self.done, self.total, self.journal = done, total, journal


def run_sweep(grid: SweepGrid, *, jobs: int = 1, shard=None, scheduler: str | None = None,
              journal: Journal | None = None, progress=None, on_rows=None,
              pool: WorkerPool | None = None) -> SweepTable:
    """Evaluate the grid (or one shard of it) and return its table, in grid order.

    ``journal`` (see `Journal`) keeps finished points across interruptions and skips them on a
    rerun. ``progress(k)`` is called as k more points finish (from a helper thread with local
    workers); ``on_rows(rows, resumed)`` receives the rows read from the journal
    (``resumed=True``) and then every batch of finished rows. An interrupt (KeyboardInterrupt)
    becomes `SweepInterrupted` once the journal holds every finished point. ``pool`` (a
    `WorkerPool`, instead of ``jobs``) runs the points on workers that outlive this sweep.
    """
    done = journal.load() if journal is not None else {}  # refuses a FIFO before any work
    check_some_point_runs(grid)
    indices = grid.indices(shard)
    todo = np.array([i for i in indices if int(i) not in done], dtype=np.int64)
    finished = dict(done)
    if done and on_rows is not None:
        on_rows([done[i] for i in sorted(done)], True)

    def collect(rows):
        for r in rows:
            finished[r.index] = r
        if journal is not None:
            journal.append(rows)
        if on_rows is not None:
            on_rows(rows, False)

    try:
        if scheduler:
            _run_dask(grid, todo, scheduler, collect, progress)
        elif pool is not None and len(todo) > MIN_CHUNK:
            _run_shared_pool(grid, todo, pool, collect, progress)
        elif jobs > 1 and len(todo) > MIN_CHUNK:
            _run_pool(grid, todo, jobs, collect, progress)
        else:
            _run_here(grid, todo, collect, progress)
    except KeyboardInterrupt:
        raise SweepInterrupted(len(finished), len(indices),
                               None if journal is None else journal.path) from None
    finally:
        if journal is not None:
            journal.close()
    return SweepTable(grid.paths, tuple(np.asarray(a.values) for a in grid.axes),
                      np.asarray(indices), tuple(finished[int(i)] for i in indices),
                      grid.gait_yaml, grid.base.source, shard, computed=len(todo),
                      dims=grid.dims)


def sweep(gait: Gait, axes, *, output=None, jobs: int = 1, shard=None,
          scheduler: str | None = None, progress=None, on_rows=None,
          sensitivity: Sequence[str] = ()) -> SweepTable:
    """The library entry point behind ``crawlsim velocity --sweep``.

    ``axes`` as `make_grid` takes them (``PATH=SPEC`` texts or `Axis`, a sequence of them for
    linked paths). Checks the paths, runs the points, keeps a journal next to ``output`` while
    running, and writes ``output`` (CSV or HDF5) atomically at the end, removing the journal.
    Without ``output`` nothing is written. ``progress`` and ``on_rows`` as in `run_sweep`.
    ``sensitivity``: paths whose ``dv0/dPATH`` columns are added (`crawlsim.analysis.sensitivity_sweep`).
    """
    grid = make_grid(gait, axes, sensitivity)
    if shard is not None and (output is None or not is_hdf5(output)):
        raise SweepSpecError("--shard", "", "a shard must be written to an HDF5 file "
                                            "(-o part-I.h5) so that `crawlsim merge` can join "
                                            "the parts")
    journal = Journal(journal_path(output), grid.fingerprint(shard)) if output else None
    table = run_sweep(grid, jobs=jobs, shard=shard, scheduler=scheduler, journal=journal,
                      progress=progress, on_rows=on_rows)
    if output is not None and journal is not None:
        write_table(table, output)
        journal.remove()
    return table


def sweep_figure_data(table: SweepTable) -> tuple[dict, np.ndarray, np.ndarray]:
    """What `crawlsim.plotting.sweep_figure` draws: the values of each grid dimension (named by
    its first path), v0 on the grid, and the points without a v0 (failed or invalid)."""
    dims = table.dimension_paths()
    if len(dims) not in (1, 2):
        raise SweepSpecError("--plot", "", f"a sweep figure shows one or two swept dimensions, "
                                           f"this sweep has {len(dims)}")
    first = dict(zip(table.paths, table.axes))
    axes = {paths[0]: np.asarray(first[paths[0]], dtype=float) for paths in dims}
    status = table.grid("status")
    missing = (status == PointStatus.FAILED) | (status == PointStatus.INVALID)
    return axes, table.grid("v0"), missing


def plot_table(table: SweepTable, path, title: str | None = None,
               figure_options: dict | None = None) -> None:
    """v0 against one swept dimension, or a heat map over two, with the points that have no v0
    (failed or invalid) marked; written atomically."""
    from crawlsim.plotting import save_figure, sweep_figure
    from crawlsim.plotting.style import units_of

    axes, v0, _ = sweep_figure_data(table)
    if title is None:
        document = yaml.safe_load(table.gait_yaml) if table.gait_yaml else None
        name = document.get("name") if isinstance(document, dict) else None
        title = f"{name or Path(table.source).stem}: average velocity over a sweep"
    marks = None
    if len(axes) == 1 and table.gait_yaml:
        from crawlsim.analysis.stall import curve_marks

        name = next(iter(axes))
        marks = curve_marks(table.gait_yaml, name, axes[name], v0)
    # The statuses themselves, not a failed/ok mask: an invalid gait and a failed run are
    # different answers and are marked differently (docs/figures.md).
    status = table.grid("status")
    figure = sweep_figure(axes, v0, status, title, units=units_of({"gait_yaml": table.gait_yaml}),
                          displacement=table.grid("displacement_per_period"), marks=marks)
    save_figure(figure, path, **(figure_options or {}))
