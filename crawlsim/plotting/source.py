"""What a run's figures are drawn from, whichever way the run is given.

Every figure of a run (and the animation) reads one thing: the dict of
`crawlsim.io.runread.read_results`, the groups and attributes of the results file. A study in a
notebook holds a result object instead (`crawlsim.simulate`, `crawlsim.api.run`), and a command
holds a path. `run_data` turns any of the three into that dict, and `takes_run` makes a figure
function call it on its first argument: the conversion is made here and nowhere else, so
``motion_figure(crawlsim.simulate(gait))`` draws what ``crawlsim plot`` draws from the file the
same run writes.

A result object has what the file holds except the sampled signals of the gait on the period's
grid (the offsets c(t), actuator lengths L(t) and friction coefficients of ``/limit``, and the
normals B of ``/process``): those come from the process its provenance records (the effective
gait document), compiled again, which is how the results writer gets them too.
"""

from __future__ import annotations

import functools
import json
import math
import os
from collections.abc import Callable
from typing import Any, TypeVar

from crawlsim.errors import ResultsFileError
from crawlsim.gait.document import parse_gait
from crawlsim.io.runread import read_results
from crawlsim.model.process import compile

#: The per-period series of ``/convergence`` the figures read, by their names on
#: `crawlsim.analysis.run.ConvergenceHistory`.
CONVERGENCE_SERIES = ("period", "poincare_step", "w12_distance", "displacement")
#: The datasets of ``/trajectory`` and ``/limit`` a result object carries, by their names on
#: `crawlsim.api.Trajectory` and `crawlsim.analysis.run.LimitPeriod`.
TRAJECTORY_SERIES = ("t", "w", "x", "stress", "shape", "reaction")
LIMIT_SERIES = ("t", "w", "multipliers", "x", "shape", "stress", "slip", "slip_rate")
#: Datasets of the gait's signals on the period's grid: from the compiled process.
PROCESS_SERIES = ("offsets", "lengths", "friction")

F = TypeVar("F", bound=Callable[..., Any])


def run_data(source: Any) -> dict[str, Any]:
    """The dict of `crawlsim.io.runread.read_results` for ``source``: that dict itself, a results
    file's path (read), or a run's result object (`crawlsim.api.SimulationResult`,
    `crawlsim.analysis.run.RunResult`: `from_result`; the results file it names as ``output``,
    when it wrote one). TypeError for anything else."""
    if isinstance(source, dict):
        return source
    if isinstance(source, (str, os.PathLike)):
        return read_results(source)
    if hasattr(source, "limit") and hasattr(source, "history"):
        written = getattr(source, "output", None)
        if written is not None and os.path.isfile(written):
            # `crawlsim.api.run(gait, output=...)`: its file holds the trajectory the result
            # object does not keep.
            return read_results(written)
        return from_result(source)
    raise TypeError(
        f"a figure of a run takes a results file, the dict of "
        f"crawlsim.io.runread.read_results or the result of crawlsim.simulate; got "
        f"{type(source).__name__}"
    )


def takes_run(function: F) -> F:
    """``function(source, ...)`` called with ``run_data(source)``: a figure function of the
    read_results dict that takes files and result objects too."""

    @functools.wraps(function)
    def wrapper(source: Any, *args: Any, **kwargs: Any) -> Any:
        return function(run_data(source), *args, **kwargs)

    return wrapper  # type: ignore[return-value]


def from_result(result: Any) -> dict[str, Any]:
    """The read_results dict of a run's result object, from its attributes: ``name``,
    ``period``, ``steps_per_period``, ``periods``, ``convergence``, ``periodic_from``,
    ``contraction_rate``, ``v0``, ``history`` (`CONVERGENCE_SERIES`), ``limit``
    (`LIMIT_SERIES` and ``start``), and where the result has them ``trajectory``
    (`TRAJECTORY_SERIES`), ``units`` and ``provenance`` (its ``gait_yaml`` gives the process,
    `PROCESS_SERIES` and the normals). A missing part leaves its datasets out, and a figure that
    needs one says so (`need`)."""
    provenance = getattr(result, "provenance", None)
    process = None
    if provenance is not None and getattr(provenance, "gait_yaml", None):
        spec = parse_gait(provenance.gait_yaml, source=f"{result.name} (provenance)", default_name=str(result.name))
        process = compile(spec)
    limit, history = result.limit, result.history
    kind = "crawler" if getattr(limit, "x", None) is not None else "sweeping-process"
    units = getattr(result, "units", None)
    attrs = {
        "name": str(result.name),
        "kind": kind,
        "period": float(result.period),
        "steps_per_period": int(result.steps_per_period),
        "periods": int(result.periods),
        "convergence": str(result.convergence),
        "periodic_from": -1 if result.periodic_from is None else int(result.periodic_from),
        "v0": math.nan if result.v0 is None else float(result.v0),
        "contraction_rate": math.nan if result.rate is None else result.rate.rate,
        "units_json": json.dumps(units.to_json() if units is not None else {}),
        "source": "result",
    }
    trajectory = getattr(result, "trajectory", None)
    out: dict[str, Any] = {
        "attrs": attrs,
        "trajectory": _present(trajectory, TRAJECTORY_SERIES),
        "convergence": _present(history, CONVERGENCE_SERIES),
        "limit": _present(limit, LIMIT_SERIES),
        "limit_attrs": {"start": float(limit.start)},
        "process": {},
    }
    if process is not None:
        out["limit"]["offsets"] = process.offsets
        out["limit"].update(_present(process.crawler, PROCESS_SERIES[1:]))
        out["process"]["normals"] = process.normals
    return out


def _present(holder: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """The attributes ``names`` of ``holder`` that are not None (none of a None holder)."""
    if holder is None:
        return {}
    found = {name: getattr(holder, name, None) for name in names}
    return {name: value for name, value in found.items() if value is not None}


def need(results: dict, figure: str, *paths: str) -> None:
    """Raise `ResultsFileError` naming the first dataset in ``paths`` the results lack, and
    what to do about it (rerun, or keep the trajectory of a result object)."""
    from_object = results.get("attrs", {}).get("source") == "result"
    for path in paths:
        group, name = path.split("/")
        if name in (results.get(group) or {}):
            continue
        hint = ""
        if group in ("trajectory", "limit") and name in ("x", "stress", "shape", "slip"):
            hint = " (only crawler runs have it)"
        elif from_object and group == "trajectory":
            hint = " (this result keeps no trajectory: use crawlsim.simulate(gait), which keeps it by default)"
        elif from_object and (group == "process" or name in PROCESS_SERIES):
            hint = " (this result records no provenance, whose gait document gives it)"
        elif group == "rigid":
            hint = " (crawlsim run --rigid writes it)"
        elif path in ("limit/lengths", "limit/friction", "limit/offsets", "process/normals"):
            hint = " (files written before crawlsim stored it lack it; rerun `crawlsim run`)"
        raise ResultsFileError(f"the {figure} figure needs /{path}, which is missing{hint}")


def last_periods(results: dict, last: int) -> tuple[Any, Any]:
    """The times and block positions of the last ``last`` periods of the stored trajectory (all
    of it when it holds fewer): the window the figures zoom on (``--last``)."""
    import numpy as np

    t = np.asarray(results["trajectory"]["t"], dtype=float)
    keep = t >= t[-1] - last * run_period(results) * (1 + 1e-12)
    return t[keep], np.asarray(results["trajectory"]["x"], dtype=float)[keep]


def step_slip(x: Any) -> Any:
    """The slip state of each block on each stored step, (G, N) in -1, 0, 1: the sign of its
    displacement over the step, a displacement below roundoff of the crawler's size counted as
    stick."""
    import numpy as np

    dx = np.diff(x, axis=0)
    tol = 1e-9 * max(float(np.max(np.abs(x))), 1.0)
    return np.where(dx > tol, 1, np.where(dx < -tol, -1, 0)).astype(np.int8)


def run_name(results: dict) -> str:
    return str(results["attrs"].get("name", "crawlsim run"))


def run_period(results: dict) -> float:
    return float(results["attrs"]["period"])


def is_crawler_run(results: dict) -> bool:
    return bool(results["attrs"].get("kind", "crawler") == "crawler")
