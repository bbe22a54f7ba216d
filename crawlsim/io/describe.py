"""A summary of any crawlsim HDF5 file, without reading its trajectories (`crawlsim info`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from crawlsim.errors import GaitError, ResultsFileError
from crawlsim.io.layout import counts, number, open_h5, plain, read_column, root_attrs

#: Root attributes that `describe` reports under their own names (the others, provenance
#: included, are listed under "attributes" when they are short).
_DESCRIBED = {
    "crawlsim_version",
    "format_version",
    "kind",
    "name",
    "convergence",
    "periodic_from",
    "v0",
    "contraction_rate",
    "v0_error_estimate",
    "displacement_per_period",
    "dissipation_per_period",
    "cost_of_transport",
    "period",
    "steps_per_period",
    "periods",
    "save_every",
    "gait_yaml",
    "summary_json",
    "source",
    "paths",
    "shape",
    "shard",
    "dimensions",
    "integrator",
}


#: Root attributes of an optimisation file that `describe` reports under its own keys (or that
#: repeat them).
_OPTIMIZATION_DESCRIBED = {
    "objective",
    "constraints_json",
    "free_json",
    "seed",
    "evaluations",
    "max_evaluations",
    "best_json",
    "best_feasible",
    "best_value",
    "best_v0",
    "best_cost_of_transport",
    "axis_names",
    "title",
    "objective_quantity",
    "objective_sense",
    "gait_file",
}


def describe(path: Any) -> dict[str, Any]:
    """What a results file holds, without reading its trajectories: ``file_kind`` (``run`` or
    ``sweep``), the identity and outcome of the run or the grid and the counts of statuses of the
    sweep, and the other short root attributes (provenance). Raises `ResultsFileError` for a file
    that is not a crawlsim results file."""
    path = Path(path)
    with open_h5(path, "results file") as f:
        attrs = root_attrs(f)
        if "format_version" not in attrs:
            raise ResultsFileError(f"{path}: not a crawlsim results file (no format_version attribute)")
        described = _DESCRIBED | (_OPTIMIZATION_DESCRIBED if attrs.get("kind") == "optimization" else set())
        other = {
            k: v
            for k, v in attrs.items()
            if k not in described and (not isinstance(v, str) or len(v) <= 200) and np.ndim(v) == 0
        }
        if "provenance" in f:
            other.update({k: plain(v) for k, v in f["provenance"].attrs.items()})
        out = {
            "file": str(path),
            "crawlsim_version": attrs.get("crawlsim_version"),
            "format_version": attrs.get("format_version"),
            "attributes": other,
        }
        if attrs.get("kind") == "sweep":
            out.update(_describe_sweep(path, f, attrs))
        elif attrs.get("kind") == "optimization":
            out.update(_describe_optimization(path, f, attrs))
        else:
            out.update(_describe_run(path, f, attrs))
    return out


def _describe_run(path: Path, f: h5py.File, attrs: dict[str, Any]) -> dict[str, Any]:
    try:
        summary = json.loads(attrs.get("summary_json", "{}"))
    except json.JSONDecodeError:
        summary = {}
    periodic_from = attrs.get("periodic_from", -1)
    solver = (
        {k: plain(v) for k, v in f["limit"]["solver"].attrs.items()} if "limit" in f and "solver" in f["limit"] else {}
    )
    return {
        "file_kind": "run",
        "kind": attrs.get("kind", "crawler"),
        "name": attrs.get("name"),
        "integrator": attrs.get("integrator", summary.get("integrator")),
        "v0": number(attrs.get("v0")),
        "v0_error_estimate": number(attrs.get("v0_error_estimate")),
        "convergence": attrs.get("convergence"),
        "periodic_from": None if periodic_from is None or periodic_from < 0 else periodic_from,
        "contraction_rate": number(attrs.get("contraction_rate")),
        "periods": attrs.get("periods"),
        "steps_per_period": attrs.get("steps_per_period"),
        "period": attrs.get("period"),
        "displacement_per_period": number(attrs.get("displacement_per_period")),
        "dissipation_per_period": number(attrs.get("dissipation_per_period")),
        "dissipation_error_estimate": summary.get("dissipation_error_estimate"),
        "cost_of_transport": number(attrs.get("cost_of_transport")),
        "final_poincare_step": summary.get("final_poincare_step"),
        "limit_method": solver.get("method", summary.get("limit_method")),
        "limit_newton_steps": solver.get("newton_steps", summary.get("limit_newton_steps")),
        "limit_periods": solver.get("periods", summary.get("limit_periods")),
        "jacobian_rate": number(solver.get("jacobian_rate", summary.get("jacobian_rate"))),
        "contraction_rate_error": summary.get("contraction_rate_error"),
        "contraction_rate_periods": summary.get("contraction_rate_periods"),
        "status": summary.get("status"),
        "message": summary.get("message"),
        "grid_note": summary.get("grid_note"),
        "rigid_v0": number(f["rigid"].attrs["v0"]) if "rigid" in f else None,
        "rigid_v0_error_estimate": number(f["rigid"].attrs["v0_error_estimate"]) if "rigid" in f else None,
        "uniqueness_margin": _margin(attrs),
    }


def _margin(attrs: dict[str, Any]) -> dict[str, Any] | None:
    """The margin to the uniqueness condition of the run's gait (`crawlsim.gait.apriori`), from
    its effective document; None for a generic process or a file that records none."""
    from crawlsim.gait.apriori import margin
    from crawlsim.gait.document import Gait, parse_gait

    try:
        gait = parse_gait(attrs["gait_yaml"], source="gait_yaml")
    except (KeyError, GaitError):
        return None
    if not isinstance(gait, Gait):
        return None
    found = margin(gait)
    return {**found.summary(), "text": found.text()}


def _describe_sweep(path: Path, f: h5py.File, attrs: dict[str, Any]) -> dict[str, Any]:
    if "results" not in f or "status" not in f["results"]:
        raise ResultsFileError(f"{path}: missing /results/status")
    results = f["results"]
    status = [str(s) for s in read_column(results["status"])]
    v0 = results["v0"][()] if "v0" in results else np.array([])
    ok = np.array([s == "ok" for s in status], dtype=bool)
    good = v0[ok & np.isfinite(v0)] if v0.size == ok.size else np.array([])
    integrators = sorted({str(s) for s in read_column(results["integrator"])} - {""}) if "integrator" in results else []
    return {
        "file_kind": "sweep",
        "kind": "sweep",
        "name": _sweep_name(attrs) or Path(str(attrs.get("source", path))).stem,
        "source": attrs.get("source"),
        "shard": attrs.get("shard") or None,
        "grid": _sweep_grid(f, attrs),
        "points": len(status),
        "statuses": counts(status),
        "integrator": ", ".join(integrators) or None,
        "v0_min": float(good.min()) if good.size else None,
        "v0_max": float(good.max()) if good.size else None,
    }


def _sweep_grid(f: h5py.File, attrs: dict[str, Any]) -> list[dict[str, Any]]:
    """Each grid dimension: its paths (linked paths share one), its number of values and their
    range."""
    paths = json.loads(attrs.get("paths", "[]"))
    dims = json.loads(attrs["dimensions"]) if "dimensions" in attrs else list(range(len(paths)))
    grouped: dict[int, list[str]] = {}
    for p, d in zip(paths, dims):
        grouped.setdefault(int(d), []).append(p)
    if "axis_names" in attrs:  # format 2: the values are the coordinates of /grid
        names = json.loads(attrs["axis_names"])
        values = {p: f["grid"][n][()] for p, n in zip(paths, names) if "grid" in f and n in f["grid"]}
    else:
        values = {p: f["axes"][p][()] for p in paths if "axes" in f and p in f["axes"]}

    def extent(first: str) -> dict[str, Any]:
        if first not in values:
            return {"values": 0, "min": None, "max": None}
        v = values[first]
        if v.dtype.kind in "OSU":  # gait files: no range
            return {"values": len(v), "min": None, "max": None}
        return {"values": len(v), "min": number(float(np.min(v))), "max": number(float(np.max(v)))}

    return [{"paths": grouped[d], **extent(grouped[d][0])} for d in sorted(grouped)]


def _sweep_name(attrs: dict[str, Any]) -> str | None:
    """The gait's name, from the sweep's document."""
    import yaml

    try:
        document = yaml.safe_load(attrs.get("gait_yaml", "")) or {}
    except yaml.YAMLError:
        document = {}
    return document.get("name") if isinstance(document, dict) else None


def _describe_optimization(path: Path, f: h5py.File, attrs: dict[str, Any]) -> dict[str, Any]:
    if "evaluations" not in f or "status" not in f["evaluations"]:
        raise ResultsFileError(f"{path}: missing /evaluations/status")
    status = [str(s) for s in read_column(f["evaluations"]["status"])]
    return {
        "file_kind": "optimization",
        "kind": "optimization",
        "name": attrs.get("name"),
        "source": attrs.get("source"),
        "objective": attrs.get("objective"),
        "constraints": json.loads(attrs.get("constraints_json", "[]")),
        "free": json.loads(attrs.get("free_json", "[]")),
        "integrator": attrs.get("integrator"),
        "seed": attrs.get("seed"),
        "evaluations": len(status),
        "max_evaluations": attrs.get("max_evaluations"),
        "statuses": counts(status),
        "best": json.loads(attrs.get("best_json", "{}")),
        "best_feasible": bool(attrs.get("best_feasible", 0)),
        "best_value": number(attrs.get("best_value")),
        "v0": number(attrs.get("best_v0")),
        "cost_of_transport": number(attrs.get("best_cost_of_transport")),
        "front_points": int(f["front"]["front_point"].shape[0]) if "front" in f else None,
    }
