"""The ``dv0/dPATH`` columns of ``crawlsim velocity --sweep ... --sensitivity PATH`` (issue 22):
the derivative of each grid point's v0 in each number PATH names, computed where the point runs
(`crawlsim.study.points.run_points`, on the limit period the point's run found, so workers and
shards share the work), kept in the journal
with the row, and written to the CSV table, the sweep file's /grid and /results groups and the
xarray Dataset of `crawlsim.sweep` with the units of v0 over those of PATH.

A cell holds the derivative where the point's limit is smooth in that number (the exact
integrator's, or the catch-up scheme's own discrete map for a catch-up point: the ``integrator``
column says which); it is missing (NaN, an empty CSV cell) where the point did not converge, sits
on a kink (no one-sided differences in a sweep: `crawlsim velocity GAIT --sensitivity PATH` at
that point gives them), or the number is not differentiated.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from fractions import Fraction
from typing import Any

import numpy as np

#: Prefix of a derivative column: ``dv0/dlinks.1.phase``.
PREFIX = "dv0/d"


def check_paths(gait: Any, paths: Sequence[str]) -> tuple[str, ...]:
    """The ``--sensitivity`` paths, checked against the base gait (a `GaitError` naming the path
    when one names nothing or no continuous parameter, such as ``blocks``: exit code 2 before
    any point runs)."""
    from crawlsim.analysis.sensitivity_terms import STRUCTURAL
    from crawlsim.errors import GaitError
    from crawlsim.gait.docpaths import resolve_path

    for path in paths:
        resolve_path(gait.document, path, gait.source)
        if path.split(".")[0] in STRUCTURAL:
            raise GaitError(gait.source, path, "not a continuous parameter of the gait: v0 has no derivative in it")
    return tuple(paths)


def with_derivatives(
    paths: Sequence[str], gaits: Iterable[tuple[int, Any]], rows: Mapping[int, Any], runs: Mapping[int, Any]
) -> dict[int, Any]:
    """The rows of the converged points among ``gaits`` ((index, Gait) pairs) with their
    ``derivatives``: {concrete path: dv0/dpath, None where not smooth}; a point whose
    derivatives fail keeps its row, with the failure in its message. ``runs``: the points' own
    runs by index (`crawlsim.analysis.run.RunResult`, or `crawlsim.study.batch.BatchRun` for
    catch-up points of the batch), whose limit periods are walked: no point is stepped again
    (a point without one has its limit searched)."""
    import dataclasses

    from crawlsim.analysis.sensitivity import sensitivity
    from crawlsim.errors import CrawlsimError
    from crawlsim.status import PointStatus

    out: dict[int, Any] = {}
    for i, gait in gaits:
        row = rows[i]
        if row.status != PointStatus.OK:
            continue
        try:
            result = sensitivity(gait, list(paths), one_sided=False, run=runs.get(i))
        except CrawlsimError as exc:
            message = f"{row.message}; " if row.message else ""
            out[i] = dataclasses.replace(row, message=f"{message}no derivatives: {exc}")
            continue
        out[i] = dataclasses.replace(
            row, derivatives={p.path: (p.v0.value if p.smooth else None) for p in result.parameters}
        )
    return out


def column_names(rows: Iterable[Any]) -> list[str]:
    """The derivative columns of a table, ``dv0/dPATH``, in the order the points name them."""
    names: dict[str, None] = {}
    for r in rows:
        for path in getattr(r, "derivatives", None) or {}:
            names.setdefault(PREFIX + path, None)
    return list(names)


def columns(rows: Sequence[Any]) -> dict[str, np.ndarray]:
    """Each derivative column as floats, NaN where a point has no value."""
    out = {}
    for name in column_names(rows):
        path = name[len(PREFIX) :]
        values = [(getattr(r, "derivatives", None) or {}).get(path) for r in rows]
        out[name] = np.array([np.nan if v is None else v for v in values], dtype=float)
    return out


def row_derivatives(cols: Mapping[str, Any], n: int) -> dict[str, float | None] | None:
    """Row n's derivatives read back from a table's columns (a sweep file), or None."""
    out: dict[str, float | None] = {}
    for name, values in cols.items():
        if name.startswith(PREFIX):
            value = float(values[n])
            out[name[len(PREFIX) :]] = None if np.isnan(value) else value
    return out or None


def unit(units: Any, kind: str, path: str) -> str:
    """The units of dv0/dPATH: those of v0 over those of PATH (``mm/s`` over ``N``:
    ``mm/(N s)``, composed from the base exponents; per degree for a slope's angle)."""
    from crawlsim.gait.units import QUANTITIES, path_quantity

    keys = tuple(int(k) if k.isdigit() else k for k in path.split("."))
    quantity = path_quantity(kind, keys)
    velocity = QUANTITIES["velocity"]
    if quantity == "angle":
        return f"{units.of('velocity')}/degree" if units.of("velocity") != "1" else "1/degree"
    below = QUANTITIES[quantity]
    exponents = {b: Fraction(velocity.get(b, 0)) - Fraction(below.get(b, 0)) for b in set(velocity) | set(below)}
    return str(units.compose(exponents))
