"""The one module that reads and writes HDF5 results files.

Layout (format_version 1; the README documents it):

    /                       attrs: crawlsim_version, format_version, name, kind, v0, convergence,
                                   periodic_from (-1 = null), contraction_rate (NaN = null),
                                   v0_error_estimate, displacement_per_period,
                                   dissipation_per_period, cost_of_transport, period,
                                   steps_per_period, periods, save_every, gait_yaml, summary_json,
                                   unchecked_uniqueness (1: the gait opted out of an exact
                                   uniqueness check it was beyond; 0 otherwise)
    /trajectory/t           (n,)        time of each saved grid point (a dimension scale)
    /trajectory/w           (n, d)      state of the sweeping process
    /trajectory/x           (n, N)      block positions                      [crawlers]
    /trajectory/stress      (n, N-1)    link stresses, compression positive  [crawlers]
    /trajectory/shape       (n, N-1)    z = D x                              [crawlers]
    /trajectory/reaction    (n, m)      constraint reactions: the multipliers of the steps since
                                        the previous saved point (0 at t = 0)  [generic processes]
    /convergence/*          (P,)        period, displacement, velocity, poincare_step,
                                        w12_distance, sup_distance, slip_l2_distance, dissipation
    /limit/*                            t, w, multipliers, x, shape, stress, slip, slip_rate
    /limit/offsets          (G+1, m)    c(t) on the limit period's grid: K(t) = {w : B w <= c(t)}
    /limit/lengths          (G+1, N-1)  actuator lengths L(t) on that grid       [crawlers]
    /limit/friction         (G+1, 2N)   [mu^+, mu^-] on that grid               [crawlers]
    /process/normals        (m, d)      B, the constant normals of K(t)
    /process/metric         (d, d)      M, the metric of the projections (K^{-1} for crawlers)
    /events/t               (E,)        event times of the exact integrator, every period, never
                                        thinned by save_every (a dimension scale) [--integrator exact]
    /events/w               (E, d)      state after each event (a closed form in between)
    /events/x               (E, N)      block positions at the events        [exact, crawlers]

Writes are atomic: everything goes to a temporary file in the destination's folder, renamed over
the destination only when complete. A failed run leaves no file behind.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from . import __version__
from .atomic import atomic_path, discard, publish, temporary_beside
from .errors import ResultsFileError

FORMAT_VERSION = 1


class ResultsWriter:
    """Streams a run's trajectory into a temporary HDF5 file; `finish` renames it into place.

    Use as a context manager: leaving the block with an exception deletes the temporary file.
    Only every ``save_every``-th grid point is written, and nothing is kept in memory.
    """

    def __init__(self, path, process, *, save_every: int = 1):
        self.path = Path(path)
        self.process = process
        self.save_every = int(save_every)
        self._count = 0  # global grid index of the next row to consider
        self._tmp = temporary_beside(self.path)
        self.file = h5py.File(self._tmp, "w")
        self._traj = self.file.create_group("trajectory")
        self._sets: dict[str, h5py.Dataset] = {}
        self._columns = ["w"] + (["x", "stress", "shape"] if process.is_crawler else [])
        self._reaction_carry = np.zeros(process.normals.shape[0])

    def _append(self, name, rows):
        rows = np.asarray(rows)
        ds = self._sets.get(name)
        if ds is None:
            ds = self._traj.create_dataset(
                name, shape=(0,) + rows.shape[1:], maxshape=(None,) + rows.shape[1:],
                dtype=rows.dtype, chunks=(min(4096, max(len(rows), 1) * 4),) + rows.shape[1:])
            self._sets[name] = ds
        n = ds.shape[0]
        ds.resize(n + len(rows), axis=0)
        ds[n:] = rows

    def add_period(self, record):
        """Append the saved grid points of one period (its first point only for period 0)."""
        p = self.process
        if getattr(record, "events", None) is not None:
            self._append_events(record.events)
        first = 0 if record.index == 0 else 1
        local = np.arange(first, p.steps + 1)
        global_index = record.index * p.steps + local
        sel = local[global_index % self.save_every == 0]
        reaction = None if p.is_crawler else self._reaction_rows(record.multipliers, sel)
        if sel.size == 0:
            return
        self._append("t", record.start + p.times[sel])
        self._append("w", record.w[sel])
        if p.is_crawler:
            self._append("x", record.x[sel])
            self._append("stress", record.w[sel] + p.stress_offset[sel])
            self._append("shape", record.w[sel] * -np.diag(p.metric))
        if reaction is not None:
            self._append("reaction", reaction)

    def _append_events(self, events):
        """Append one period's event trajectory ``(t, w, x)`` to /events (exact integrator)."""
        group = self.file.require_group("events")
        for name, rows in zip(("t", "w", "x"), events):
            if rows is None:
                continue
            rows = np.asarray(rows, dtype=float)
            if name not in group:
                ds = group.create_dataset(name, shape=(0,) + rows.shape[1:],
                                          maxshape=(None,) + rows.shape[1:], dtype=float,
                                          chunks=(256,) + rows.shape[1:])
                if name == "t":
                    ds.make_scale("t")
                else:
                    ds.dims[0].attach_scale(group["t"])
            ds = group[name]
            n = ds.shape[0]
            ds.resize(n + len(rows), axis=0)
            ds[n:] = rows

    def _reaction_rows(self, multipliers, sel):
        """Reactions of the m constraints at the saved grid points ``sel`` of one period.

        The multipliers of catch-up steps are the constraints' reaction impulses (MODEL.md §3).
        Row s sums the multipliers of the steps since the previous saved point, so with
        ``save_every = 1`` it is the multiplier of the step ending at t_s, and a larger
        ``save_every`` loses nothing of the total.
        """
        rows = np.zeros((len(sel), multipliers.shape[1]))
        ends = sel[sel > 0]  # grid point s ends step s - 1
        if ends.size == 0:
            self._reaction_carry = self._reaction_carry + multipliers.sum(axis=0)
            return rows
        starts = np.concatenate([[0], ends[:-1]])
        sums = np.add.reduceat(multipliers, starts, axis=0)
        sums[-1] = multipliers[starts[-1]:ends[-1]].sum(axis=0)
        sums[0] += self._reaction_carry
        rows[len(sel) - len(ends):] = sums
        self._reaction_carry = multipliers[ends[-1]:].sum(axis=0)
        return rows

    def finish(self, result, gait_yaml: str, kind: str = "crawler", unchecked_uniqueness: bool = False):
        """Write the analysis, close, and atomically rename into place.

        ``unchecked_uniqueness`` records (as the root attribute of that name, 0 or 1) that the
        gait opted out of an exact check of the uniqueness condition it was beyond."""
        f = self.file
        if "t" in self._sets:
            t = self._sets["t"]
            t.make_scale("t")
            for name, ds in self._sets.items():
                if name != "t":
                    ds.dims[0].attach_scale(t)
        conv = f.create_group("convergence")
        h = result.history
        for name in ("period", "displacement", "velocity", "poincare_step", "w12_distance",
                     "sup_distance", "slip_l2_distance", "dissipation"):
            conv.create_dataset(name, data=getattr(h, name))
        lim = f.create_group("limit")
        lim.attrs["start"] = result.limit.start
        for name in ("t", "w", "multipliers", "x", "shape", "stress", "slip", "slip_rate"):
            value = getattr(result.limit, name)
            if value is not None:
                lim.create_dataset(name, data=value)
        p = self.process
        lim.create_dataset("offsets", data=p.offsets)
        if p.is_crawler:
            lim.create_dataset("lengths", data=p.lengths)
            lim.create_dataset("friction", data=p.friction)
        proc = f.create_group("process")
        proc.create_dataset("normals", data=p.normals)
        proc.create_dataset("metric", data=p.metric)
        a = f.attrs
        a["crawlsim_version"] = __version__
        a["format_version"] = FORMAT_VERSION
        a["kind"] = kind
        a["name"] = result.name
        a["convergence"] = str(result.convergence)
        a["periodic_from"] = -1 if result.periodic_from is None else int(result.periodic_from)
        for key in ("v0", "contraction_rate", "v0_error_estimate", "displacement_per_period",
                    "dissipation_per_period", "cost_of_transport"):
            value = getattr(result, key)
            a[key] = np.nan if value is None else float(value)
        a["period"] = result.period
        a["steps_per_period"] = result.steps_per_period
        a["periods"] = result.periods
        a["save_every"] = self.save_every
        a["gait_yaml"] = gait_yaml
        a["summary_json"] = json.dumps(result.summary())
        a["unchecked_uniqueness"] = int(bool(unchecked_uniqueness))
        f.close()
        publish(self._tmp, self.path)

    def abort(self):
        try:
            self.file.close()
        finally:
            discard(self._tmp)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None or self._tmp.exists():
            self.abort()
        return False


def _open(path: Path, what: str) -> h5py.File:
    """Open an HDF5 file for reading, or raise `ResultsFileError` saying why it can't be."""
    if not path.exists():
        raise ResultsFileError(f"{path}: no such {what}")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise ResultsFileError(f"{path}: not an HDF5 file ({exc})") from None


def read_results(path) -> dict:
    """Load a results file into plain dicts of arrays: ``{"attrs", "trajectory", "convergence",
    "limit"}``, plus ``"process"`` when the file has it. Raises `ResultsFileError` naming what is
    missing."""
    path = Path(path)
    with _open(path, "results file") as f:
        if "format_version" not in f.attrs:
            raise ResultsFileError(f"{path}: not a crawlsim results file (no format_version "
                                   "attribute)")
        out = {"attrs": {k: _plain(v) for k, v in f.attrs.items()}}
        for group in ("trajectory", "convergence", "limit"):
            if group not in f:
                raise ResultsFileError(f"{path}: missing group /{group}")
            out[group] = {k: f[group][k][()] for k in f[group]}
            out[group + "_attrs"] = {k: _plain(v) for k, v in f[group].attrs.items()}
        if "process" in f:
            out["process"] = {k: f["process"][k][()] for k in f["process"]}
        if "events" in f:
            out["events"] = {k: f["events"][k][()] for k in f["events"]}
    return out


def _plain(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


# --------------------------------------------------------------------------------------------
# Sweep files (`crawlsim velocity --sweep ... -o OUT.h5`, `crawlsim merge`). Layout:
#
#     /                     attrs: crawlsim_version, format_version, kind = "sweep", gait_yaml
#                                  (the base gait document), source, paths (JSON list of the
#                                  swept paths, in grid order), shape, shard ("" or "I/N")
#     /axes/<path>          (n_k,)  values of each swept path
#     /results/<column>     (P,)    one entry per point, in grid order: each swept path, v0,
#                                   displacement_per_period, convergence, periods, status,
#                                   message; point (grid index), steps (catch-up steps simulated)

def write_sweep(path, *, paths, axes, points, columns, gait_yaml, source, shard, steps) -> None:
    """Write a sweep table atomically (`crawlsim.atomic`)."""
    text = h5py.string_dtype()
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        a = f.attrs
        a["crawlsim_version"] = __version__
        a["format_version"] = FORMAT_VERSION
        a["kind"] = "sweep"
        a["gait_yaml"] = gait_yaml
        a["source"] = str(source)
        a["paths"] = json.dumps(list(paths))
        a["shape"] = np.array([len(v) for v in axes], dtype=np.int64)
        a["shard"] = shard
        g = f.create_group("axes")
        for name, values in zip(paths, axes):
            g.create_dataset(name, data=np.asarray(values))
        r = f.create_group("results")
        r.create_dataset("point", data=np.asarray(points, dtype=np.int64))
        r.create_dataset("steps", data=np.asarray(steps, dtype=np.int64))
        for name, values in columns.items():
            values = np.asarray(values)
            if values.dtype == object:
                r.create_dataset(name, data=values.astype(str).tolist(), dtype=text,
                                 shape=values.shape)
            else:
                r.create_dataset(name, data=values)


def read_sweep(path) -> dict:
    """A sweep file as ``{paths, axes, points, steps, columns, gait_yaml, source, shard}``.

    Raises `ResultsFileError` naming what is missing when the file is not a sweep file.
    """
    path = Path(path)
    with _open(path, "sweep file") as f:
        if _plain(f.attrs.get("kind", "")) != "sweep":
            raise ResultsFileError(f"{path}: not a crawlsim sweep file (attribute kind is not "
                                   "'sweep')")
        for group in ("axes", "results"):
            if group not in f:
                raise ResultsFileError(f"{path}: missing group /{group}")
        paths = json.loads(_plain(f.attrs["paths"]))
        missing = [p for p in paths if p not in f["axes"]]
        if missing:
            raise ResultsFileError(f"{path}: missing /axes/{missing[0]}")
        results = f["results"]
        columns = {}
        for name in list(paths) + ["v0", "displacement_per_period", "convergence", "periods",
                                   "status", "message", "point", "steps"]:
            if name not in results:
                raise ResultsFileError(f"{path}: missing /results/{name}")
            ds = results[name]
            columns[name] = (np.array(ds.asstr()[()], dtype=object)
                             if h5py.check_string_dtype(ds.dtype) else ds[()])
        return dict(paths=paths, axes=[f["axes"][p][()] for p in paths],
                    points=columns.pop("point"), steps=columns.pop("steps"), columns=columns,
                    gait_yaml=_plain(f.attrs["gait_yaml"]), source=_plain(f.attrs["source"]),
                    shard=_plain(f.attrs["shard"]))
