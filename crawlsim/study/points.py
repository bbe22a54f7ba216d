"""The evaluation of sweep points: a grid point's gait validated, compiled and run to its
periodic regime, one `PointResult` (a row of the sweep table) per point.

Points run one by one, each as its single run does (`crawlsim.analysis.run.settle` with the
gait's own settings, stopping at the verified limit: no history), so a point's row is its run's.
One point never stops the others: it is recorded ``invalid`` (an `InputError`, exit code 2 for a
single run) or ``failed``, with its reason.

Extra per-point columns (`PointQuantity`, such as the derivative of v0 with respect to a gait
parameter) are computed after a point's run, for the points that ran.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol

from crawlsim.analysis.run import settle
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.gait.document import Gait
from crawlsim.io.sweepfile import DERIVATIVE
from crawlsim.model.process import compile_gait
from crawlsim.status import PointStatus

if TYPE_CHECKING:
    from crawlsim.study.grid import SweepGrid


class PointQuantity(Protocol):
    """An extra column of a sweep table: ``name`` heads the column, and calling it on a point's
    gait and finished row gives the value (None where it has none). Called only for the rows
    whose status is ``ok``."""

    name: str

    def __call__(self, gait: Gait, row: PointResult) -> float | None: ...


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
    extra: tuple[float | None, ...] = ()  # the grid's extra columns (`PointQuantity`)
    derivatives: dict[str, float | None] | None = None  # dv0/dPATH (--sensitivity)

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", PointStatus(self.status))
        object.__setattr__(self, "extra", tuple(self.extra))

    def to_json(self) -> dict:
        row = {f: getattr(self, f) for f in _POINT_FIELDS}
        if self.extra:  # journals of sweeps without extra columns stay as they were
            row["extra"] = list(self.extra)
        if self.derivatives is not None:  # and so do those of sweeps without --sensitivity
            row["derivatives"] = self.derivatives
        return row

    @classmethod
    def from_columns(cls, columns: Mapping[str, Any], n: int, index: int, steps: int) -> PointResult:
        """Row ``n`` of a file's table (a sweep file's /results, an optimisation file's
        /evaluations): NaN is missing, and so are the columns of files written before them; the
        dv0/dPATH columns of ``--sensitivity`` are the row's ``derivatives``."""

        def number(name: str) -> float | None:
            value = float(columns[name][n]) if name in columns else math.nan
            return None if math.isnan(value) else value

        def text(name: str) -> str:
            return str(columns[name][n]) if name in columns else ""

        newton = int(columns["newton_steps"][n]) if "newton_steps" in columns else -1
        derivatives = {name[len(DERIVATIVE) :]: number(name) for name in columns if name.startswith(DERIVATIVE)}
        return cls(
            index,
            PointStatus(text("status")),
            number("v0"),
            number("v0_error_estimate"),
            number("displacement_per_period"),
            number("dissipation_per_period"),
            number("cost_of_transport"),
            convergence=text("convergence"),
            periods=int(columns["periods"][n]),
            integrator=text("integrator"),
            message=text("message"),
            steps=steps,
            limit=text("limit"),
            newton_steps=None if newton < 0 else newton,
            derivatives=derivatives or None,
        )

    @classmethod
    def from_json(cls, row: dict) -> PointResult:
        """A journal line (older journals lack the later columns: they stay missing)."""
        return cls(**{k: v for k, v in row.items() if k in (*_POINT_FIELDS, "extra", "derivatives")})


_POINT_FIELDS = (
    "index",
    "status",
    "v0",
    "v0_error_estimate",
    "displacement_per_period",
    "dissipation_per_period",
    "cost_of_transport",
    "convergence",
    "periods",
    "integrator",
    "message",
    "steps",
    "limit",
    "newton_steps",
)


def _failure(index: int, exc: BaseException) -> PointResult:
    """An invalid point (bad input: exit code 2 for a single run) or a failed one."""
    if isinstance(exc, InputError):
        return PointResult(int(index), PointStatus.INVALID, message=str(exc))
    text = str(exc) if isinstance(exc, CrawlsimError) else f"{type(exc).__name__}: {exc}"
    return PointResult(int(index), PointStatus.FAILED, message=text)


def run_points(grid: SweepGrid, indices, *, progress=None) -> list[PointResult]:
    """Validate and evaluate the grid points ``indices`` (a worker's task); a point that is not
    a valid gait is an ``invalid`` row, the others go to `evaluate` (with the grid's extra
    `quantities <PointQuantity>`), then, with ``--sensitivity``, to `with_derivatives` on the
    limit periods their runs
    found. ``progress(k)`` is called as k more points finish."""
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
        for row in evaluate(
            [g for _, g in valid],
            [i for i, _ in valid],
            progress=progress,
            quantities=grid.quantities,
            runs=runs,
        ):
            rows[row.index] = row
        if runs is not None:
            rows.update(with_derivatives(grid.sensitivity, valid, rows, runs))
    return [rows[int(i)] for i in indices]


def evaluate(
    gaits, indices, *, progress=None, quantities: Sequence[PointQuantity] = (), runs=None
) -> list[PointResult]:
    """v0 of validated gaits (module docstring), one row per gait, in the order given.

    A row's ``v0_error_estimate`` bounds the true error of its v0. Catch-up rows leave it
    missing: their time-step error is not measured in a sweep (a single run measures it against
    the exact integrator, which would double a sweep's cost); the exact integrator, the
    default, has none.

    A point that raises is recorded (``invalid`` for an `InputError` such as a uniqueness
    failure at a grid time, ``failed`` otherwise). ``quantities`` add their columns to the rows
    that are ``ok``. ``runs``, when given, receives what each point's run settled on, by index
    (``--sensitivity`` walks its limit period).
    """
    rows = []
    for i, gait in zip((int(i) for i in indices), gaits):
        rows.append(_with_quantities(_run_single(i, gait, runs), gait, quantities))
        if progress is not None:
            progress(1)
    return rows


def _reraise_memory(exc: BaseException) -> None:
    if isinstance(exc, MemoryError):
        raise exc


def _run_single(i: int, gait: Gait, runs: dict | None = None) -> PointResult:
    """One point through `crawlsim.analysis.run.settle` (no history); what it settled on joins
    ``runs`` (by index) when given."""
    s = gait.simulation
    try:
        settled = settle(
            compile_gait(gait),
            max_periods=s.max_periods,
            tolerance=s.tolerance,
            integrator=s.integrator,
            limit=s.limit,
            history=False,
            series=runs is not None,  # the row holds no per-period series,
            running_frame=runs is not None,  # nor the running frame
        )
    except Exception as exc:
        _reraise_memory(exc)
        return replace(_failure(i, exc), integrator=s.integrator)
    run, e = settled.result, settled.result.estimate
    assert e is not None and run.energy is not None  # a crawler: sweeps refuse generic processes
    if runs is not None:
        runs[i] = settled
    return PointResult(
        i,
        PointStatus.OK if run.converged else PointStatus.NOT_CONVERGED,
        v0=run.v0,
        v0_error_estimate=e.error_estimate if run.integrator == "exact" else None,
        displacement_per_period=e.displacement,
        dissipation_per_period=run.energy.dissipation,
        cost_of_transport=run.energy.cost_of_transport,
        convergence=str(run.convergence),
        periods=run.periods + run.solver.periods,
        integrator=run.integrator,
        steps=run.effort.steps,
        limit=run.solver.method,
        newton_steps=run.solver.newton_steps,
    )


def with_derivatives(
    paths: Sequence[str], gaits: Iterable[tuple[int, Gait]], rows: Mapping[int, PointResult], runs: Mapping[int, Any]
) -> dict[int, PointResult]:
    """The rows of the converged points among ``gaits`` ((index, Gait) pairs) with their
    ``derivatives`` (``--sweep ... --sensitivity PATH``): {concrete path: dv0/dpath, None where
    the point's limit is not smooth in that number (no one-sided differences in a sweep)}, of
    the point's own integrator (the ``integrator`` column says which). ``runs``: what each
    point's run settled on, by index, whose limit period is walked: no point is stepped again
    (a point without one has its limit searched). A point whose derivatives fail keeps its row,
    with the failure in its message."""
    from crawlsim.analysis.sensitivity import sensitivity  # start-up: the tangent kernels only when asked

    out: dict[int, PointResult] = {}
    for i, gait in gaits:
        row = rows[i]
        if row.status != PointStatus.OK:
            continue
        try:
            result = sensitivity(gait, list(paths), one_sided=False, run=runs.get(i))
        except CrawlsimError as exc:
            message = f"{row.message}; " if row.message else ""
            out[i] = replace(row, message=f"{message}no derivatives: {exc}")
            continue
        out[i] = replace(row, derivatives={p.path: (p.v0.value if p.smooth else None) for p in result.parameters})
    return out


def _with_quantities(row: PointResult, gait: Gait, quantities: Sequence[PointQuantity]) -> PointResult:
    """The row with its extra columns (missing where the point did not run, or where a quantity
    raises: the reason joins the row's message)."""
    if not quantities:
        return row
    values: list[float | None] = []
    notes: list[str] = []
    for q in quantities:
        value = None
        if row.status == PointStatus.OK:
            try:
                value = q(gait, row)
            except CrawlsimError as exc:
                notes.append(f"{q.name}: {exc}")
        values.append(value)
    message = "; ".join([row.message, *notes]) if notes and row.message else "; ".join(notes)
    return replace(row, extra=tuple(values), message=message or row.message)
