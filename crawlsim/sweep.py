"""Parameter sweeps of v0: a Cartesian grid of edited gait documents, run in batches.

A sweep axis is ``PATH=SPEC``: ``PATH`` is a dotted path into the gait document (integer list
indices, ``*`` for every element: ``links.*.amplitude``, ``friction.1.backward``, ``period``);
``SPEC`` is ``START:STOP:NUM`` (inclusive linspace) or a comma list ``a,b,c``. The grid is the
Cartesian product of the axes in the order given, the last axis varying fastest (C order):
grid point i has the multi-index ``np.unravel_index(i, shape)``.

Every point's document is validated into a `Gait` (`crawlsim.gait.gait_from_document`) before
any point is simulated, so a bad path or a value that makes a gait invalid is a `GaitError`
(exit code 2) and nothing is computed or written. Points then run through the batched exact
stepper (`crawlsim.batch`), in-process, on local worker processes, or on a Dask cluster; a
point that fails while running (a certificate that cannot be met, a LICQ failure) is recorded
with status ``failed`` and its reason, and does not stop the sweep.

Nothing is lost: each finished chunk of points is appended to a journal next to the output
(``OUT.journal``, JSON lines, flushed and fsynced), read back on a rerun of the same sweep so that
finished points are not recomputed. The output file is written atomically at the end.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import io
import json
import math
import os
from concurrent.futures import FIRST_COMPLETED, wait
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .atomic import atomic_path
from .docpaths import path_keys, resolve_path, set_value
from .errors import CrawlsimError, GaitError
from .gait import Gait, gait_from_document
from .status import PointStatus

#: Columns of a sweep table after the swept paths (CSV header, HDF5 /results datasets).
RESULT_COLUMNS = ("v0", "displacement_per_period", "convergence", "periods", "status", "message")
#: Points per task handed to a worker (each task is one batch).
MAX_CHUNK = 256
MIN_CHUNK = 16
#: How long to wait for a Dask scheduler before giving up (exit code 2).
SCHEDULER_TIMEOUT = "20s"


# -- axes and the grid ------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    """One swept path and its values."""

    path: str
    values: tuple

    @property
    def keys(self) -> tuple:
        return path_keys(self.path)


def parse_axis(text: str) -> Axis:
    """``PATH=START:STOP:NUM`` or ``PATH=a,b,c`` -> `Axis`; a malformed option is a GaitError."""
    source = f"--sweep {text}"
    path, sep, spec = text.partition("=")
    path, spec = path.strip(), spec.strip()
    if not sep or not path or not spec:
        raise GaitError(source, "", "expected PATH=START:STOP:NUM or PATH=a,b,c, for example "
                                    "links.*.amplitude=0.1:0.4:7")
    if any(part == "" for part in path.split(".")):
        raise GaitError(source, path, "empty key in the dotted path")
    if ":" in spec:
        parts = spec.split(":")
        try:
            if len(parts) != 3:
                raise ValueError
            start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise GaitError(source, path, f"expected START:STOP:NUM with NUM an integer, got "
                                          f"{spec!r}") from None
        if num < 1:
            raise GaitError(source, path, f"NUM must be at least 1, got {num}")
        values = tuple(float(v) for v in np.linspace(start, stop, num))
    else:
        try:
            values = tuple(_number(v) for v in spec.split(","))
        except ValueError:
            raise GaitError(source, path, f"expected a comma list of numbers, got {spec!r}") \
                from None
    if not all(math.isfinite(v) for v in values):
        raise GaitError(source, path, f"values must be finite numbers, got {spec!r}")
    return Axis(path, values)


def _number(text: str):
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        return float(text)


@dataclass(frozen=True, eq=False)
class SweepGrid:
    """A base gait and its axes: the Cartesian grid of edited gait documents."""

    base: Gait
    axes: tuple[Axis, ...]
    targets: tuple[tuple[tuple, ...], ...]  # concrete key tuples of each axis

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.axes)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def paths(self) -> tuple[str, ...]:
        return tuple(a.path for a in self.axes)

    @property
    def gait_yaml(self) -> str:
        """The base gait document as YAML, simulation overrides included."""
        return yaml.safe_dump(self.base.document, sort_keys=False)

    def values(self, index: int) -> tuple:
        multi = np.unravel_index(index, self.shape) if self.axes else ()
        return tuple(a.values[i] for a, i in zip(self.axes, multi))

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
        """Identity of a sweep: base document, axes and shard (journals from others are refused)."""
        spec = json.dumps([self.gait_yaml, [[a.path, list(a.values)] for a in self.axes],
                           list(shard) if shard else None])
        return hashlib.sha256(spec.encode()).hexdigest()

    def indices(self, shard=None) -> np.ndarray:
        """Grid indices of the shard ``(i, n)`` (1-based i: points i-1, i-1+n, ...), or all."""
        if shard is None:
            return np.arange(self.size)
        i, n = shard
        return np.arange(i - 1, self.size, n)


def make_grid(base: Gait, axes) -> SweepGrid:
    """Check every path against the base document; overlapping or repeated paths are refused."""
    axes = tuple(axes)
    source = base.source
    targets = tuple(tuple(resolve_path(base.document, a, source)) for a in axes)
    seen: dict[tuple, str] = {}
    for axis, keys in zip(axes, targets):
        for key in keys:
            if key in seen:
                raise GaitError(source, axis.path, f"this path sets {'.'.join(map(str, key))}, "
                                                   f"which {seen[key]} sets too: sweep each "
                                                   "value once")
            seen[key] = f"--sweep {axis.path}"
    return SweepGrid(base, axes, targets)


def parse_shard(text: str) -> tuple[int, int]:
    """``I/N`` with 1 <= I <= N."""
    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise GaitError(f"--shard {text}", "", "expected I/N, for example 3/16") from None
    if not 1 <= i <= n:
        raise GaitError(f"--shard {text}", "", f"expected 1 <= I <= N, got I = {i}, N = {n}")
    return i, n


# -- running points ---------------------------------------------------------------------------
@dataclass(frozen=True)
class PointResult:
    """One row of a sweep table (without the swept values, which the grid gives)."""

    index: int
    v0: float | None
    displacement_per_period: float | None
    convergence: str
    periods: int
    status: PointStatus
    message: str = ""
    steps: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", PointStatus(self.status))

    def to_json(self) -> dict:
        return {k: getattr(self, k) for k in ("index", "v0", "displacement_per_period",
                                              "convergence", "periods", "status", "message",
                                              "steps")}


def build_gaits(grid: SweepGrid, indices) -> list[Gait]:
    """Validate the points ``indices``; the first invalid one raises its GaitError."""
    return [grid.gait(int(i)) for i in indices]


def evaluate(gaits, indices, *, capacity=None, progress=None) -> list[PointResult]:
    """v0 of validated gaits: catch-up gaits through the batched stepper, ``exact`` one by one."""
    from .analysis import simulate
    from .batch import DEFAULT_CAPACITY, simulate_batch
    from .model import compile_gait

    out: dict[int, PointResult] = {}
    batch = [(i, g) for i, g in zip(indices, gaits) if g.simulation.integrator == "catch-up"]
    if batch:
        runs = simulate_batch([compile_gait(g) for _, g in batch],
                              max_periods=[g.simulation.max_periods for _, g in batch],
                              tolerance=[g.simulation.tolerance for _, g in batch],
                              capacity=capacity or DEFAULT_CAPACITY, progress=progress)
        for (i, _), r in zip(batch, runs):
            out[int(i)] = PointResult(int(i), r.v0, r.displacement_per_period,
                                      r.convergence or "", r.periods, r.status, r.message,
                                      r.steps)
    for i, g in zip(indices, gaits):
        if int(i) in out:
            continue
        s = g.simulation
        try:
            run = simulate(compile_gait(g), max_periods=s.max_periods, tolerance=s.tolerance,
                           integrator=s.integrator)
        except CrawlsimError as exc:
            out[int(i)] = PointResult(int(i), None, None, "", 0, PointStatus.FAILED, str(exc))
        else:
            status = PointStatus.OK if run.converged else PointStatus.NOT_CONVERGED
            out[int(i)] = PointResult(int(i), run.v0, run.displacement_per_period,
                                      run.convergence, run.periods, status, "", run.steps)
        if progress is not None:
            progress(1)
    return [out[int(i)] for i in indices]


def _evaluate_task(gaits, indices):
    """A worker's task: one chunk of validated gaits, one batch."""
    return evaluate(gaits, indices)


# -- the journal --------------------------------------------------------------------------------
class Journal:
    """JSON lines next to the output: a header, then one line per finished point.

    Appended and fsynced after every finished chunk, so an interrupted sweep (Ctrl-C, a killed
    job) keeps every finished point; a torn last line (a kill mid-write) is ignored.
    """

    def __init__(self, path: Path, fingerprint: str):
        self.path = Path(path)
        self.fingerprint = fingerprint
        self._file = None

    def load(self) -> dict[int, PointResult]:
        """Finished points of an earlier run of the same sweep ({} when there is none)."""
        if not self.path.exists():
            return {}
        done = {}
        with open(self.path, encoding="utf-8") as f:
            lines = f.read().split("\n")
        try:
            header = json.loads(lines[0])
        except (json.JSONDecodeError, IndexError):
            header = {}
        if header.get("fingerprint") != self.fingerprint:
            raise GaitError(str(self.path), "", "this journal belongs to a different sweep (other "
                                                "gait, paths, values or shard); delete it to start "
                                                "afresh, or rerun the sweep that wrote it")
        for line in lines[1:]:
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            done[int(row["index"])] = PointResult(**row)
        return done

    def append(self, results):
        if self._file is None:
            new = not self.path.exists() or self.path.stat().st_size == 0
            self._file = open(self.path, "a", encoding="utf-8")
            if new:
                self._file.write(json.dumps({"fingerprint": self.fingerprint}) + "\n")
        self._file.write("".join(json.dumps(r.to_json()) + "\n" for r in results))
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self):
        if self._file is not None:
            self._file.close()
            self._file = None

    def remove(self):
        self.close()
        self.path.unlink(missing_ok=True)


def journal_path(output) -> Path:
    return Path(str(output) + ".journal")


# -- the table --------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SweepTable:
    """The results of a sweep (or of one shard): one row per grid point, in grid order."""

    paths: tuple[str, ...]
    axes: tuple[np.ndarray, ...]  # values of each swept path
    points: np.ndarray  # grid index of each row
    rows: tuple[PointResult, ...]
    gait_yaml: str
    source: str
    shard: tuple[int, int] | None = None
    computed: int = 0  # points simulated by this run (the others came from the journal)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a) for a in self.axes)

    def coordinates(self) -> list[np.ndarray]:
        """Swept value of each row, per path."""
        if not self.paths:
            return []
        multi = np.unravel_index(self.points, self.shape)
        return [np.asarray(a)[m] for a, m in zip(self.axes, multi)]

    def columns(self) -> dict[str, np.ndarray]:
        """Every column of the table (swept paths first), as arrays."""
        cols = dict(zip(self.paths, self.coordinates()))
        cols["v0"] = np.array([np.nan if r.v0 is None else r.v0 for r in self.rows], float)
        cols["displacement_per_period"] = np.array(
            [np.nan if r.displacement_per_period is None else r.displacement_per_period
             for r in self.rows], float)
        cols["convergence"] = np.array([r.convergence for r in self.rows], dtype=object)
        cols["periods"] = np.array([r.periods for r in self.rows], dtype=np.int64)
        cols["status"] = np.array([r.status for r in self.rows], dtype=object)
        cols["message"] = np.array([r.message for r in self.rows], dtype=object)
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
        writer.writerow(list(self.paths) + list(RESULT_COLUMNS))
        coords = self.coordinates()
        for n, r in enumerate(self.rows):
            writer.writerow([_cell(c[n]) for c in coords] + [
                _cell(r.v0), _cell(r.displacement_per_period), r.convergence, r.periods,
                r.status, r.message])
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
        from . import h5io

        h5io.write_sweep(output, **table_payload(table))
        return
    with atomic_path(output) as tmp:
        tmp.write_text(table.to_csv(), encoding="utf-8", newline="")


def is_hdf5(path) -> bool:
    return Path(path).suffix.lower() in (".h5", ".hdf5")


def table_payload(table: SweepTable) -> dict:
    """The plain data `crawlsim.h5io.write_sweep` stores."""
    return dict(paths=list(table.paths), axes=[np.asarray(a) for a in table.axes],
                points=np.asarray(table.points, dtype=np.int64), columns=table.columns(),
                gait_yaml=table.gait_yaml, source=table.source,
                shard="" if table.shard is None else f"{table.shard[0]}/{table.shard[1]}",
                steps=np.array([r.steps for r in table.rows], dtype=np.int64))


def read_table(path) -> SweepTable:
    """A sweep HDF5 file (complete or a shard) back as a `SweepTable`."""
    from . import h5io

    data = h5io.read_sweep(path)
    cols = data["columns"]
    rows: list[PointResult] = []
    for n, point in enumerate(data["points"]):
        v0 = float(cols["v0"][n])
        d = float(cols["displacement_per_period"][n])
        rows.append(PointResult(int(point), None if math.isnan(v0) else v0,
                                None if math.isnan(d) else d, str(cols["convergence"][n]),
                                int(cols["periods"][n]), PointStatus(str(cols["status"][n])),
                                str(cols["message"][n]), int(data["steps"][n])))
    shard = parse_shard(data["shard"]) if data["shard"] else None
    return SweepTable(tuple(data["paths"]), tuple(data["axes"]), np.asarray(data["points"]),
                      tuple(rows), data["gait_yaml"], data["source"], shard)


def merge_tables(tables) -> SweepTable:
    """Join the N shards of one sweep into the table an unsharded run gives.

    All parts must come from the same sweep (gait, paths, values, N), and together hold each
    shard 1..N exactly once; otherwise a `GaitError` says what is wrong (exit code 2).
    """
    tables = list(tables)
    if not tables:
        raise GaitError("merge", "", "no shard files given")
    first = tables[0]
    for t in tables:
        if t.shard is None:
            raise GaitError(t.source, "", "not a shard (no shard attribute): only files written "
                                          "with --shard I/N are merged")
        if (t.gait_yaml != first.gait_yaml or t.paths != first.paths
                or len(t.axes) != len(first.axes)
                or not all(np.array_equal(a, b) for a, b in zip(t.axes, first.axes))):
            raise GaitError(t.source, "", "this shard is from a different sweep (gait, paths or "
                                          "values differ from the first part)")
    n = first.shard[1]
    seen = sorted(t.shard[0] for t in tables)
    if any(t.shard[1] != n for t in tables) or seen != list(range(1, n + 1)):
        missing = sorted(set(range(1, n + 1)) - set(seen))
        repeated = sorted({i for i in seen if seen.count(i) > 1})
        raise GaitError("merge", "", f"expected shards 1..{n} once each; missing {missing or 'none'}"
                                     f", repeated {repeated or 'none'}")
    rows = sorted((r for t in tables for r in t.rows), key=lambda r: r.index)
    size = math.prod(first.shape)
    if [r.index for r in rows] != list(range(size)):
        raise GaitError("merge", "", "the shards do not cover the grid exactly once")
    return SweepTable(first.paths, first.axes, np.arange(size), tuple(rows), first.gait_yaml,
                      first.source, None)


# -- executors ----------------------------------------------------------------------------------
@contextmanager
def _executor(jobs: int, scheduler: str | None):
    """None (in-process), a process pool, or a Dask client's executor."""
    if scheduler:
        try:
            from distributed import Client
        except ImportError:
            raise GaitError("--scheduler", "", "Dask is not installed: pip install "
                                               "'crawlsim[dask]'") from None
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
        except OSError as exc:
            raise GaitError(f"--scheduler {scheduler}", "", f"cannot reach the Dask scheduler "
                                                            f"({exc})") from None
        try:
            with client.get_executor() as ex:
                yield ex, _workers(client)
        finally:
            client.close()
    elif jobs > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        context = multiprocessing.get_context("forkserver" if os.name == "posix" else "spawn")
        if os.name == "posix":
            context.set_forkserver_preload(["crawlsim.sweep", "crawlsim.batch"])
        with ProcessPoolExecutor(jobs, mp_context=context) as ex:
            yield ex, jobs
    else:
        yield None, 1


def _workers(client) -> int:
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:
        return 1


def _chunks(indices: np.ndarray, workers: int) -> list[np.ndarray]:
    size = len(indices)
    if size == 0:
        return []
    per = max(MIN_CHUNK, min(MAX_CHUNK, math.ceil(size / (2 * workers))))
    return [indices[k:k + per] for k in range(0, size, per)]


# -- the sweep ----------------------------------------------------------------------------------
def run_sweep(grid: SweepGrid, *, jobs: int = 1, shard=None, scheduler: str | None = None,
              journal: Journal | None = None, progress=None, fail_after=None) -> SweepTable:
    """Evaluate the grid (or one shard of it) and return its table, in grid order.

    ``journal`` (see `Journal`) keeps finished points across interruptions and skips them on a
    rerun. ``progress(k)`` is called as k more points finish. ``fail_after`` is a test hook:
    raise KeyboardInterrupt once that many chunks have been journaled.
    """
    indices = grid.indices(shard)
    done = journal.load() if journal is not None else {}
    todo = np.array([i for i in indices if int(i) not in done], dtype=np.int64)
    if progress is not None and done:
        progress(len(indices) - len(todo))
    finished = dict(done)
    with _executor(jobs, scheduler) as (ex, workers):
        chunks = _chunks(todo, workers)
        if ex is None:
            gaits = [build_gaits(grid, c) for c in chunks]
        else:
            gaits = _map(ex, build_gaits, [(grid, c) for c in chunks])
        try:
            if ex is None:
                for k, (chunk, gs) in enumerate(zip(chunks, gaits)):
                    rows = evaluate(gs, chunk, progress=progress)
                    _finish(rows, finished, journal, k, fail_after)
            else:
                pending = {ex.submit(_evaluate_task, gs, c) for gs, c in zip(gaits, chunks)}
                k = 0
                while pending:
                    ready, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in ready:
                        rows = fut.result()
                        if progress is not None:
                            progress(len(rows))
                        _finish(rows, finished, journal, k, fail_after)
                        k += 1
        except BaseException:
            if ex is not None:
                for fut in list(locals().get("pending", ())):
                    fut.cancel()
            raise
        finally:
            if journal is not None:
                journal.close()
    return SweepTable(grid.paths, tuple(np.asarray(a.values) for a in grid.axes),
                      np.asarray(indices), tuple(finished[int(i)] for i in indices), grid.gait_yaml, grid.base.source,
                      shard, computed=len(todo))


def _finish(rows, finished, journal, k, fail_after):
    for r in rows:
        finished[r.index] = r
    if journal is not None:
        journal.append(rows)
    if fail_after is not None and k + 1 >= fail_after:
        raise KeyboardInterrupt(f"test hook: stopped after {k + 1} chunks")


def _map(ex, fn, arglist):
    """Run ``fn(*args)`` for every args on ``ex``; the first exception cancels the rest."""
    futures = [ex.submit(fn, *args) for args in arglist]
    try:
        return [f.result() for f in futures]
    except BaseException:
        for f in futures:
            f.cancel()
        raise


def sweep(gait: Gait, axes, *, output=None, jobs: int = 1, shard=None,
          scheduler: str | None = None, progress=None) -> SweepTable:
    """The library entry point behind ``crawlsim velocity --sweep``.

    Validates the paths and every point of the grid (or of the shard), runs the points, keeps a
    journal next to ``output`` while running, and writes ``output`` (CSV or HDF5) atomically at
    the end, removing the journal. Without ``output`` nothing is written.
    """
    grid = make_grid(gait, [parse_axis(a) if isinstance(a, str) else a for a in axes])
    if shard is not None and (output is None or not is_hdf5(output)):
        raise GaitError("--shard", "", "a shard must be written to an HDF5 file (-o part-I.h5) "
                                       "so that `crawlsim merge` can join the parts")
    journal = Journal(journal_path(output), grid.fingerprint(shard)) if output else None
    table = run_sweep(grid, jobs=jobs, shard=shard, scheduler=scheduler, journal=journal,
                      progress=progress)
    if output is not None and journal is not None:
        write_table(table, output)
        journal.remove()
    return table


def plot_table(table: SweepTable, path, title: str | None = None) -> None:
    """v0 against one swept path, or a heat map over two, failed points marked (atomic PNG)."""
    from .plotting import save_figure, sweep_figure

    if len(table.paths) not in (1, 2):
        raise GaitError("--plot", "", f"a plot needs one or two swept paths, got "
                                      f"{len(table.paths)}")
    axes = {p: np.asarray(a, dtype=float) for p, a in zip(table.paths, table.axes)}
    failed = table.grid("status") == "failed"
    title = title or f"v0 of {Path(table.source).name}"
    fig = sweep_figure(axes, table.grid("v0"), failed, title)
    save_figure(fig, path)
