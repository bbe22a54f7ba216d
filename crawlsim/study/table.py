"""The table of a sweep: one row per grid point, in grid order; CSV and HDF5 files of it, and
the join of the shards of one sweep (``crawlsim merge``)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from crawlsim.errors import ResultsFileError
from crawlsim.io.atomic import atomic_path
from crawlsim.io.layout import counts
from crawlsim.io.sweepfile import DERIVATIVE, read_sweep, write_sweep
from crawlsim.status import PointStatus
from crawlsim.study.grid import grid_shape, parse_shard
from crawlsim.study.points import PointResult

#: Columns of a sweep table after the swept paths (CSV header, HDF5 /results datasets).
RESULT_COLUMNS = (
    "v0",
    "v0_error_estimate",
    "displacement_per_period",
    "dissipation_per_period",
    "cost_of_transport",
    "convergence",
    "periods",
    "integrator",
    "limit",
    "newton_steps",
    "status",
    "message",
)
#: Result columns that files written before crawlsim 0.2 lack (read back as missing values).
LATER_COLUMNS = (
    "v0_error_estimate",
    "dissipation_per_period",
    "cost_of_transport",
    "integrator",
    "limit",
    "newton_steps",
)


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
    quantities: tuple[str, ...] = ()  # extra columns after `RESULT_COLUMNS` (rows' ``extra``)

    @property
    def dimensions(self) -> tuple[int, ...]:
        """The grid dimension of each swept path (linked paths share one)."""
        return tuple(range(len(self.paths))) if self.dims is None else tuple(self.dims)

    @property
    def shape(self) -> tuple[int, ...]:
        """The shape of the grid: the number of values of each dimension."""
        return grid_shape([len(a) for a in self.axes], self.dimensions)

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
        for k, name in enumerate(self.quantities):
            cols[name] = np.array(
                [np.nan if not r.extra or r.extra[k] is None else r.extra[k] for r in self.rows], float
            )
        cols.update(_derivatives(self.rows))
        return cols

    def counts(self) -> dict[str, int]:
        """The number of points of each status (``ok``, ``invalid``, ...)."""
        return {str(s): 0 for s in PointStatus} | counts([r.status for r in self.rows])

    def grid(self, column: str) -> np.ndarray:
        """A column on the grid's shape (full tables only)."""
        values = self.columns()[column]
        full = np.full(math.prod(self.shape), np.nan if values.dtype != object else "", dtype=values.dtype)
        full[self.points] = values
        return full.reshape(self.shape)

    def plot(self) -> Any:
        """The sweep figure of this table (`crawlsim.plotting.sweeps.sweep_data_figure`), a
        matplotlib figure."""
        from crawlsim.plotting.sweeps import sweep_data_figure

        return sweep_data_figure(table_payload(self))

    def to_csv(self) -> str:
        """The table as ``crawlsim velocity --sweep`` prints it: CSV, one row per point."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        derivatives = _derivatives(self.rows)
        writer.writerow(list(self.paths) + list(RESULT_COLUMNS) + list(self.quantities) + list(derivatives))
        coords = self.coordinates()
        for n, r in enumerate(self.rows):
            extra = r.extra or (None,) * len(self.quantities)
            writer.writerow(
                [_cell(c[n]) for c in coords]
                + [_cell(getattr(r, name)) for name in RESULT_COLUMNS]
                + [_cell(v) for v in extra]
                + [_cell(d[n]) for d in derivatives.values()]
            )
        return buf.getvalue()


def _derivatives(rows: Sequence[PointResult]) -> dict[str, np.ndarray]:
    """The dv0/dPATH columns of ``--sensitivity`` (`crawlsim.study.points.with_derivatives`),
    in the order the points name them, as floats: NaN where a point has no value."""
    paths = list(dict.fromkeys(path for r in rows for path in r.derivatives or {}))
    values = [[(r.derivatives or {}).get(path) for r in rows] for path in paths]
    return {
        DERIVATIVE + p: np.array([np.nan if v is None else v for v in vs], dtype=float) for p, vs in zip(paths, values)
    }


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
        write_sweep(output, **table_payload(table))
        return
    with atomic_path(output) as tmp:
        tmp.write_text(table.to_csv(), encoding="utf-8", newline="")


def is_hdf5(path) -> bool:
    return Path(path).suffix.lower() in (".h5", ".hdf5")


def table_payload(table: SweepTable) -> dict:
    """The plain data `crawlsim.io.sweepfile.write_sweep` stores."""
    return dict(
        paths=list(table.paths),
        axes=[np.asarray(a) for a in table.axes],
        points=np.asarray(table.points, dtype=np.int64),
        columns=table.columns(),
        gait_yaml=table.gait_yaml,
        source=table.source,
        shard="" if table.shard is None else f"{table.shard[0]}/{table.shard[1]}",
        steps=np.array([r.steps for r in table.rows], dtype=np.int64),
        dimensions=list(table.dimensions),
    )


def read_table(path) -> SweepTable:
    """A sweep HDF5 file (complete or a shard) back as a `SweepTable`. Files written before the
    `LATER_COLUMNS` existed read with those columns missing (NaN, ""); the dv0/dPATH columns
    of ``--sensitivity`` come back as the rows' ``derivatives``."""
    data = read_sweep(path)
    rows = [
        PointResult.from_columns(data["columns"], n, int(point), int(data["steps"][n]))
        for n, point in enumerate(data["points"])
    ]
    shard = parse_shard(data["shard"]) if data["shard"] else None
    dims = data.get("dimensions")
    return SweepTable(
        tuple(data["paths"]),
        tuple(data["axes"]),
        np.asarray(data["points"]),
        tuple(rows),
        data["gait_yaml"],
        data["source"],
        shard,
        dims=None if dims is None else tuple(int(d) for d in dims),
    )


def merge_tables(tables) -> SweepTable:
    """Join the N shards of one sweep into the table an unsharded run gives.

    All parts must come from the same sweep (gait, paths, values, links, N), and together hold
    each shard 1..N exactly once; otherwise a `ResultsFileError` says what is wrong (exit code 2).
    """
    tables = list(tables)
    if not tables:
        raise ResultsFileError("no shard files given", "merge")
    first = tables[0]
    _check_shards(tables)
    rows = sorted((r for t in tables for r in t.rows), key=lambda r: r.index)
    size = math.prod(first.shape)
    if [r.index for r in rows] != list(range(size)):
        raise ResultsFileError("the shards do not cover the grid exactly once", "merge")
    return SweepTable(
        first.paths,
        first.axes,
        np.arange(size),
        tuple(rows),
        first.gait_yaml,
        first.source,
        None,
        dims=first.dims,
        quantities=first.quantities,
    )


def _check_shards(tables: list[SweepTable]) -> None:
    """Every part is a shard of the first part's sweep, and together they hold 1..N once."""
    first = tables[0]
    for t in tables:
        if t.shard is None:
            raise ResultsFileError(
                "not a shard (no shard attribute): only files written with --shard I/N are merged", t.source
            )
        if (
            t.gait_yaml != first.gait_yaml
            or t.paths != first.paths
            or t.dimensions != first.dimensions
            or len(t.axes) != len(first.axes)
            or not all(np.array_equal(a, b) for a, b in zip(t.axes, first.axes))
        ):
            raise ResultsFileError(
                "this shard is from a different sweep (gait, paths or values differ from the first part)", t.source
            )
    shards = [t.shard for t in tables if t.shard is not None]  # all, checked above
    n = shards[0][1]
    seen = sorted(s[0] for s in shards)
    if any(s[1] != n for s in shards) or seen != list(range(1, n + 1)):
        missing = sorted(set(range(1, n + 1)) - set(seen))
        repeated = sorted({i for i in seen if seen.count(i) > 1})
        raise ResultsFileError(
            f"expected shards 1..{n} once each; missing {missing or 'none'}, repeated {repeated or 'none'}", "merge"
        )
