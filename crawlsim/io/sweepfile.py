"""Sweep files (format_version 2): /grid holds v0 and the other numbers on the Cartesian grid, one
dimension per swept path (named by `axis_name`, the path in the attribute ``path``); /results
holds one entry per computed point, as in format 1. `read_sweep` reads both formats.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from crawlsim.errors import ResultsFileError
from crawlsim.gait.settings import Simulation
from crawlsim.gait.units import Units, path_quantity
from crawlsim.io import provenance
from crawlsim.io.layout import (
    CONVERGENCE_FLAGS,
    STATUS_FLAGS,
    Scales,
    Var,
    check_version,
    describe_var,
    open_h5,
    plain,
    read_column,
    root_attrs,
    write_column,
    write_file,
    write_header,
)

_SWEEP_COMMENT = (
    "Results of a crawlsim parameter sweep. Point i of the grid is the gait document gait_yaml "
    "with the swept values of i (the paths in attribute paths, their dimensions in axis_names; "
    "C order, the last path varying fastest). /grid holds the numbers on the grid, /results one "
    "entry per computed point. Units: units_json (the gait file's units block); every dataset "
    "has units and long_name."
)


#: Prefix of a derivative column of ``--sensitivity PATH``: ``dv0/dlinks.1.phase``.
DERIVATIVE = "dv0/d"

#: /grid and /results variables of a sweep file besides the swept paths.
SWEEP_VARIABLES: dict[str, Var] = {
    "v0": Var(("point",), "asymptotic average velocity v0 (NaN where the point failed)", "velocity"),
    "displacement_per_period": Var(("point",), "barycentre displacement per period of the limit period", "length"),
    "convergence": Var(("point",), "how the point reached its periodic regime", "1", CONVERGENCE_FLAGS),
    "periods": Var(("point",), "periods simulated", "1"),
    "status": Var(("point",), "outcome of the point (message says why it failed)", "1", STATUS_FLAGS),
    "message": Var(("point",), "the reason of a failure, else empty", "1"),
    "point": Var(("point",), "grid index of the point (C order over the swept paths)", "1"),
    "steps": Var(("point",), "catch-up steps simulated (periods x steps per period)", "1"),
    "v0_error_estimate": Var(("point",), "error bound of v0", "velocity"),
    "dissipation_per_period": Var(("point",), "energy dissipated by friction in the limit period", "dissipation"),
    "cost_of_transport": Var(("point",), "dissipation per distance travelled (NaN without net motion)", "force"),
    "integrator": Var(("point",), "integrator of the point: catch-up or exact", "1"),
    "limit": Var(
        ("point",), "how the periodic limit was found: newton (periodic-limit solver) or iterate (plain periods)", "1"
    ),
    "newton_steps": Var(("point",), "Newton iterations of the periodic-limit solver (-1: the point did not run)", "1"),
}
#: Numeric columns written on the grid when a table has them (files of crawlsim 0.1 do not).
_OPTIONAL_GRID = ("v0_error_estimate", "dissipation_per_period", "cost_of_transport")


_WORDS = {
    "convergence": "finite-time, asymptotic or not-converged; empty when the point failed",
    "status": "ok, not-converged, invalid or failed",
}


def axis_name(path: str, taken: Sequence[str] = ()) -> str:
    """A netCDF- and Python-safe name for a swept path: ``links.*.amplitude`` ->
    ``links_all_amplitude``, ``links.1.phase`` -> ``links_1_phase`` (the path itself is kept in
    the attribute ``path``). Names already ``taken`` get a numeric suffix."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", path.replace("*", "all"))
    if not name or not (name[0].isalpha()):
        name = "p_" + name
    base, k = name, 2
    while name in taken or name in SWEEP_VARIABLES:
        name, k = f"{base}_{k}", k + 1
    return name


def _flag_codes(values: Any, flags: tuple[tuple[int, str], ...]) -> np.ndarray:
    """Strings (``finite-time``, ``not-converged``, "") as their CF flag codes; "" -> -1."""
    code = {m: v for v, m in flags}
    return np.array([code.get(str(s).replace("-", "_"), -1) if s else -1 for s in values], dtype=np.int8)


def write_sweep(
    path: Any,
    *,
    paths: Sequence[str],
    axes: Sequence[Any],
    points: Any,
    columns: Mapping[str, Any],
    gait_yaml: str,
    source: str,
    shard: str,
    steps: Any,
    dimensions: Sequence[int] | None = None,
) -> None:
    """Write a sweep table atomically (`crawlsim.io.atomic`); ``path`` may be a binary file
    object (an in-memory image). ``dimensions`` gives the grid dimension of each swept path
    (linked paths share one; default: each path its own)."""
    dims = list(range(len(paths))) if dimensions is None else [int(d) for d in dimensions]
    layout = _SweepLayout.of(paths, axes, points, dims, gait_yaml)
    write_file(path, lambda f: _write_sweep(f, layout, columns, gait_yaml, source, shard, steps))


@dataclass(frozen=True)
class _SweepLayout:
    """The grid of a sweep file: the swept paths, their names, the grid dimensions (one per
    distinct entry of ``dims``, named after its first path; linked paths are auxiliary
    coordinates along it), the points computed, and the document's kind and units."""

    paths: Sequence[str]
    names: list[str]
    axes: Sequence[Any]
    dims: Sequence[int]
    first: dict[int, int]
    order: list[int]
    points: np.ndarray
    kind: str
    units: Units
    document: Mapping[str, Any]

    @classmethod
    def of(
        cls, paths: Sequence[str], axes: Sequence[Any], points: Any, dims: Sequence[int], gait_yaml: str
    ) -> _SweepLayout:
        import yaml

        document = yaml.safe_load(gait_yaml) or {}
        names: list[str] = []
        for p in paths:
            names.append(axis_name(p, names))
        first = {d: i for i, d in reversed(list(enumerate(dims)))}
        order = sorted(first, key=lambda d: first[d])
        return cls(
            paths,
            names,
            axes,
            dims,
            first,
            order,
            np.asarray(points, dtype=np.int64),
            document.get("kind", "crawler"),
            Units.from_block(document.get("units")),
            document,
        )

    @property
    def dim_names(self) -> list[str]:
        return [self.names[self.first[d]] for d in self.order]

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(self.axes[self.first[d]]) for d in self.order)

    def axis_var(self, path: str) -> Var:
        quantity = path_quantity(self.kind, tuple(int(k) if k.isdigit() else k for k in path.split(".")))
        return Var((), f"swept value of {path}", quantity)

    def integrator(self, columns: Mapping[str, Any]) -> str:
        """The integrator the rows ran (a shard or a grid of invalid points has none: the
        document's, with the default of `crawlsim.gait.settings.Simulation`); several,
        comma-separated, if they differ."""
        used = sorted({str(s) for s in columns.get("integrator", ())} - {""})
        simulation = self.document.get("simulation")
        if not isinstance(simulation, dict):
            simulation = {}
        return ",".join(used) if used else str(simulation.get("integrator", Simulation.integrator))


def _write_sweep(
    f: h5py.File, layout: _SweepLayout, columns: Mapping[str, Any], gait_yaml: str, source: str, shard: str, steps: Any
) -> None:
    paths, names = layout.paths, layout.names
    write_header(f, title="crawlsim parameter sweep", comment=_SWEEP_COMMENT, kind="sweep")
    a = f.attrs
    a["gait_yaml"] = gait_yaml
    a["source"] = str(source)
    a["paths"] = json.dumps(list(paths))
    a["axis_names"] = json.dumps(names)
    a["shape"] = np.array(layout.shape, dtype=np.int64)
    a["shard"] = shard
    a["dimensions"] = json.dumps([layout.order.index(d) for d in layout.dims])
    a["units_json"] = json.dumps(layout.units.to_json())
    a["integrator"] = layout.integrator(columns)
    a["sweep_json"] = json.dumps(
        [{"path": p, "name": n, "values": np.asarray(v).tolist()} for p, n, v in zip(paths, names, layout.axes)]
    )
    for key, value in provenance.session_attrs().items():
        a[key] = value
    scales = Scales()
    _write_grid(f, scales, layout, columns, steps)
    _write_results(f, scales, layout, columns, steps)
    _write_derivatives(f, scales, layout, columns)


def _write_grid(f: h5py.File, scales: Scales, layout: _SweepLayout, columns: Mapping[str, Any], steps: Any) -> None:
    """/grid: the swept values as coordinates, and the numbers on the grid (NaN, or the flag
    not_computed, where another shard computed the point)."""
    units, dim_names, shape = layout.units, layout.dim_names, layout.shape
    grid = f.create_group("grid", track_order=True)
    grid.attrs["comment"] = (
        "the sweep's numbers on the grid; points not computed (another shard's) are NaN, status not_computed"
    )
    for p, n, values, d in zip(layout.paths, layout.names, layout.axes, layout.dims):
        if n in dim_names:
            ds = scales.coordinate(grid, n, np.asarray(values))
        else:  # a path linked to another: a coordinate along that path's dimension
            ds = grid.create_dataset(n, data=np.asarray(values), track_order=True)
            scales.attach(ds, (layout.names[layout.first[d]],))
        describe_var(ds, layout.axis_var(p), units.of(layout.axis_var(p).quantity))
        ds.attrs["path"] = p
    size = math.prod(shape)
    gridded = ["v0", "displacement_per_period", "convergence", "status", "periods", "steps"]
    gridded += [c for c in _OPTIONAL_GRID if c in columns]
    for name in gridded:
        data = _on_grid(steps if name == "steps" else columns[name], SWEEP_VARIABLES[name], name, size, layout.points)
        ds = grid.create_dataset(name, data=data.reshape(shape), track_order=True)
        scales.attach(ds, dim_names)
        describe_var(ds, SWEEP_VARIABLES[name], units.of(SWEEP_VARIABLES[name].quantity))
    messages = np.full(size, "", dtype=object)
    messages[layout.points] = np.asarray(columns["message"], dtype=object).astype(str)
    ds = grid.create_dataset(
        "message", data=messages.reshape(shape).tolist(), dtype=h5py.string_dtype(), shape=shape, track_order=True
    )
    scales.attach(ds, dim_names)
    describe_var(ds, SWEEP_VARIABLES["message"], "1")


def _on_grid(values: Any, var: Var, name: str, size: int, points: np.ndarray) -> np.ndarray:
    """A column spread on the flattened grid: flags (-1 where not computed), counts (0) or
    numbers (NaN)."""
    if var.flags:
        data = np.full(size, -1, dtype=np.int8)
        data[points] = _flag_codes(values, var.flags)
    elif name in ("periods", "steps"):
        data = np.zeros(size, dtype=np.int64)
        data[points] = np.asarray(values, dtype=np.int64)
    else:
        data = np.full(size, np.nan)
        data[points] = np.asarray(values, dtype=float)
    return data


def _write_results(f: h5py.File, scales: Scales, layout: _SweepLayout, columns: Mapping[str, Any], steps: Any) -> None:
    """/results: one entry per computed point, the table's words kept (as in the CSV table;
    /grid has the CF flags)."""
    units = layout.units
    results = f.create_group("results", track_order=True)
    results.attrs["comment"] = "one entry per computed point, in grid order"
    ds = scales.coordinate(results, "point", layout.points)
    describe_var(ds, SWEEP_VARIABLES["point"], "1")
    for p, n in zip(layout.paths, layout.names):
        ds = write_column(results, n, columns[p])
        scales.attach(ds, ("point",))
        describe_var(ds, layout.axis_var(p), units.of(layout.axis_var(p).quantity))
        ds.attrs["path"] = p
    table = ["v0", "displacement_per_period", "convergence", "periods", "status", "message"]
    table += [c for c in (*_OPTIONAL_GRID, "integrator", "limit", "newton_steps") if c in columns]
    for name, values in [(k, columns[k]) for k in table] + [("steps", steps)]:
        ds = write_column(results, name, values)
        var = SWEEP_VARIABLES[name]
        scales.attach(ds, ("point",))
        describe_var(ds, worded(var, name), units.of(var.quantity))


def _write_derivatives(f: h5py.File, scales: Scales, layout: _SweepLayout, columns: Mapping[str, Any]) -> None:
    """The dv0/dPATH columns of ``--sensitivity`` (`DERIVATIVE`), on the grid and in the table,
    with the units of v0 over PATH; the column in ``column``."""
    shape, dim_names = layout.shape, layout.dim_names
    for column, name, unit, long_name in _derivative_variables(
        columns, layout.units, layout.kind, [*layout.names, *SWEEP_VARIABLES]
    ):
        values = np.asarray(columns[column], dtype=float)
        data = np.full(math.prod(shape), np.nan)
        data[layout.points] = values
        for group, array, dims in ((f["grid"], data.reshape(shape), dim_names), (f["results"], values, ("point",))):
            ds = group.create_dataset(name, data=array, track_order=True)
            scales.attach(ds, dims)
            describe_var(ds, Var(tuple(dims), long_name, "1"), unit)
            ds.attrs["column"] = column


def _derivative_variables(
    cols: Mapping[str, Any], units: Units, kind: str, taken: Sequence[str]
) -> list[tuple[str, str, str, str]]:
    """(column, dataset name, units, long_name) of each derivative column of a sweep file: the
    name netCDF-safe (``dv0_dlinks_1_phase``), the column itself in the attribute ``column``."""
    out = []
    names = list(taken)
    for column in cols:
        if not column.startswith(DERIVATIVE):
            continue
        path = column[len(DERIVATIVE) :]
        name = axis_name("dv0_d" + path.replace(".", "_"), names)
        names.append(name)
        long_name = f"derivative of v0 with respect to {path} (NaN where not smooth or not computed)"
        out.append((column, name, units.derivative(kind, path), long_name))
    return out


def worded(var: Var, name: str) -> Var:
    """A status column kept as words: its flags dropped, the words it takes as its comment."""
    return Var(var.dims, var.long_name, var.quantity, comment=_WORDS.get(name, ""))


#: The columns every sweep file's /results has, besides the swept paths.
_REQUIRED = ("v0", "displacement_per_period", "convergence", "periods", "status", "message", "point", "steps")


def read_sweep(path: Any) -> dict[str, Any]:
    """A sweep file (format_version 1 or 2) as ``{paths, axes, points, steps, columns,
    gait_yaml, source, shard}``; format 2 adds ``attrs`` (every root attribute).

    Raises `ResultsFileError` naming what is missing when the file is not a sweep file.
    """
    path = Path(path)
    with open_h5(path, "sweep file") as f:
        if plain(f.attrs.get("kind", "")) != "sweep":
            raise ResultsFileError(f"{path}: not a crawlsim sweep file (attribute kind is not 'sweep')")
        version = check_version(f, path)
        paths = json.loads(plain(f.attrs["paths"]))
        if version == 1:
            names, axes_group = list(paths), "axes"
        else:
            names, axes_group = json.loads(plain(f.attrs["axis_names"])), "grid"
        for group in (axes_group, "results"):
            if group not in f:
                raise ResultsFileError(f"{path}: missing group /{group}")
        missing = [n for n in names if n not in f[axes_group]]
        if missing:
            raise ResultsFileError(f"{path}: missing /{axes_group}/{missing[0]}")
        columns = _read_columns(path, f["results"], names, paths)
        dimensions = json.loads(plain(f.attrs["dimensions"])) if "dimensions" in f.attrs else None
        out = dict(
            paths=paths,
            axes=[f[axes_group][n][()] for n in names],
            points=columns.pop("point"),
            steps=columns.pop("steps"),
            columns=columns,
            gait_yaml=plain(f.attrs["gait_yaml"]),
            source=plain(f.attrs["source"]),
            shard=plain(f.attrs["shard"]),
            dimensions=dimensions,
        )
        if version >= 2:
            out["attrs"] = root_attrs(f)
        return out


def _read_columns(path: Path, results: h5py.Group, names: Sequence[str], paths: Sequence[str]) -> dict[str, Any]:
    """The /results columns by key (the swept paths by their path), the required ones first,
    then the later ones (v0_error_estimate, ...) when the file has them."""
    columns = {}
    for name, key in [*zip(names, paths)] + [(c, c) for c in _REQUIRED]:
        if name not in results:
            raise ResultsFileError(f"{path}: missing /results/{name}")
        columns[key] = read_column(results[name])
    for name in results:  # a dv0/dPATH dataset is keyed by its column (`_write_derivatives`)
        if name not in columns and name not in names:
            columns[plain(results[name].attrs.get("column", name))] = read_column(results[name])
    return columns
