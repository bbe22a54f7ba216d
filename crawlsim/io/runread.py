"""Reading a run's results file (format_version 1 or 2): the groups as dicts of arrays
(`read_results`), what a rerun needs (`read_provenance`) and the root attributes (`read_attrs`).

Files of both versions give the same keys, format 2 adding new ones only; the time coordinates
of format 2 (/trajectory/time, ...) repeat the group's t and are left out of the dicts. The
typed reader, which gives the same `crawlsim.api.SimulationResult` as a run in memory, is
`crawlsim.api.open_run`.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from crawlsim.errors import ResultsFileError
from crawlsim.io.layout import check_version, open_h5, plain, root_attrs, variables
from crawlsim.io.runfile import TIME_DIMENSIONS


def read_results(path: Any) -> dict[str, Any]:
    """Load a results file (format_version 1 or 2) into plain dicts of arrays: ``{"attrs",
    "trajectory", "convergence", "limit"}`` and the groups' attributes as ``"<group>_attrs"``,
    plus ``"process"``, ``"events"``, ``"energy"`` and ``"rigid"`` (with ``"rigid_attrs"``) when the
    file has them. Format 2 adds
    ``"coordinates"`` (the root coordinate variables: block, link, constraint, ...) and
    ``/limit/step``; files that record the periodic-limit solver add ``"limit_solver"`` and
    ``"limit_solver_attrs"`` (``/limit/solver``). Raises `ResultsFileError` naming what is
    missing."""
    source, f = _open_run(path)
    with f:
        out: dict[str, Any] = {"attrs": root_attrs(f)}
        for group in ("trajectory", "convergence", "limit"):
            if group not in f:
                raise ResultsFileError(f"{source}: missing group /{group}")
            out[group] = _group(f, group)
            out[group + "_attrs"] = {k: plain(v) for k, v in f[group].attrs.items()}
        for group in ("process", "events", "energy", "rigid"):
            if group in f:
                out[group] = _group(f, group)
        if "rigid" in f:
            out["rigid_attrs"] = {k: plain(v) for k, v in f["rigid"].attrs.items()}
        if "solver" in f["limit"]:  # files since the periodic-limit solver
            out["limit_solver"] = variables(f["limit"]["solver"])
            out["limit_solver_attrs"] = {k: plain(v) for k, v in f["limit"]["solver"].attrs.items()}
        coordinates = variables(f)
        if coordinates:
            out["coordinates"] = coordinates
    process = out.get("process", {})
    if "stiffness" in process and "normals" not in process:
        # a crawler's B = [D^T; -D^T], (D^T v)_j = v_{j-1} - v_j, and M = K^-1 (docs/model.md §2)
        k = np.asarray(process["stiffness"], dtype=float)
        Dt = np.eye(len(k) + 1, len(k), -1) - np.eye(len(k) + 1, len(k))
        process.update(normals=np.vstack([Dt, -Dt]), metric=np.diag(1.0 / k))
    return out


def _open_run(path: Any) -> tuple[Any, h5py.File]:
    """A run's results file opened for reading (a path or a binary file object), refused with
    a `ResultsFileError` when it is a sweep or optimisation file."""
    source = path
    if isinstance(path, io.IOBase):
        f = h5py.File(path, "r")
    else:
        source = Path(path)
        f = open_h5(source, "results file")
    try:
        check_version(f, source)
        kind = plain(f.attrs.get("kind", ""))
        if kind == "sweep":
            raise ResultsFileError(
                f"{source}: a sweep file, not a run's results file: read it with crawlsim.study.sweep.read_table"
            )
        if kind == "optimization":
            raise ResultsFileError(
                f"{source}: an optimisation file, not a run's results file: "
                "read it with crawlsim.io.optfile.read_optimization"
            )
    except BaseException:
        f.close()
        raise
    return source, f


def _group(f: h5py.File, group: str) -> dict[str, Any]:
    """A group's variables, without its time coordinate (it repeats the group's t)."""
    time_dim = TIME_DIMENSIONS.get(group)
    return variables(f[group], skip=() if time_dim is None else (time_dim,))


def read_provenance(path: Any) -> dict[str, Any]:
    """What a rerun needs from a run's results file: ``kind``, ``name``, ``gait_yaml`` (the
    effective document), ``integrator_settings`` and ``save_every``.

    Only format_version 2 files record the effective document and the integrator's settings; a
    format_version 1 file, or a sweep file, is refused with a `ResultsFileError` saying so.
    """
    path = Path(path)
    with open_h5(path, "results file") as f:
        version = check_version(f, path)
        a = {k: plain(v) for k, v in f.attrs.items()}
    if a.get("kind") == "optimization":
        raise ResultsFileError(
            f"{path}: an optimisation file; --from reruns a run's results "
            "file. Write the best gait with crawlsim optimize --write-best "
            "BEST.yaml and run that (its command line was: "
            f"{a.get('command_line', 'not recorded')})"
        )
    if a.get("kind") == "sweep":
        raise ResultsFileError(
            f"{path}: a sweep file; --from reruns a run's results file (the "
            f"sweep's command line was: {a.get('command_line', 'not recorded')})"
        )
    if version < 2 or "integrator_json" not in a:
        raise ResultsFileError(
            f"{path}: format_version {version} files do not record the "
            "command-line overrides or the integrator, so the run cannot be "
            "reproduced from it; rerun from the gait file (crawlsim run "
            "GAIT.yaml with the same options)"
        )
    return {
        "kind": a["kind"],
        "name": a["name"],
        "gait_yaml": a["gait_yaml"],
        "integrator_settings": json.loads(a["integrator_json"]),
        "save_every": int(a.get("save_every", 1)) or 1,
        "format_version": version,
    }


def read_attrs(path: Any) -> dict[str, Any]:
    """The root attributes of a results or sweep file (a path or a file object)."""
    if isinstance(path, io.IOBase):
        with h5py.File(path, "r") as f:
            return {k: plain(v) for k, v in f.attrs.items()}
    with open_h5(Path(path), "results file") as f:
        return {k: plain(v) for k, v in f.attrs.items()}
