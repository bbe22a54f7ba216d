"""The evaluation of sweep points: a grid point's gait validated, compiled and run to its
periodic regime, one `PointResult` (a row of the sweep table) per point.

Exact points run one by one through the periodic-limit solver (no history); catch-up points go
through the batched stepper (`crawlsim.study.batch`), for at most `BATCH_PLAIN_PERIODS`
periods when the gait's limit method is ``newton`` (the periodic-limit solver then finishes
those that have not converged, one by one). One point never stops the others: it is recorded
``invalid`` (an `InputError`, exit code 2 for a single run) or ``failed``, with its reason.

Extra per-point columns (`PointQuantity`, such as the derivative of v0 with respect to a gait
parameter) are computed after a point's run, for the points that ran.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol

from crawlsim.analysis.run import Settled, settle
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.gait.document import Gait
from crawlsim.model.process import compile_gait
from crawlsim.status import PointStatus
from crawlsim.study.batch import DEFAULT_CAPACITY, simulate_batch

if TYPE_CHECKING:
    from crawlsim.study.grid import SweepGrid

#: Periods a catch-up point is iterated in the vectorised batch before the periodic-limit
#: solver takes over (finite-time crawlers and fast contractions finish within them).
BATCH_PLAIN_PERIODS = 2


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


def run_points(grid: SweepGrid, indices, *, capacity=None, progress=None) -> list[PointResult]:
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
            capacity=capacity,
            progress=progress,
            quantities=grid.quantities,
            runs=runs,
        ):
            rows[row.index] = row
        if runs is not None:
            rows.update(with_derivatives(grid.sensitivity, valid, rows, runs))
    return [rows[int(i)] for i in indices]


_Member = tuple[int, Any, Gait]  # grid index, compiled process, gait


def evaluate(
    gaits, indices, *, capacity=None, progress=None, quantities: Sequence[PointQuantity] = (), runs=None
) -> list[PointResult]:
    """v0 of validated gaits (module docstring), one row per gait, in the order given.

    A row's ``v0_error_estimate`` bounds the true error of its v0. Catch-up rows leave it
    missing: their time-step error is not measured in a sweep (a single run measures it against
    the exact integrator, which would double a sweep's cost); the exact integrator, the
    default, has none.

    A gait that cannot be compiled, or a batch that raises, is retried point by point, and each
    point that still raises is recorded (``invalid`` for an `InputError` such as a uniqueness
    failure at a grid time, ``failed`` otherwise). ``quantities`` add their columns to the rows
    that are ``ok``. ``runs``, when given, receives the run of each point run one by one, by
    index (``--sensitivity`` walks its limit period).
    """
    tick: Callable[[int], None] = progress if progress is not None else (lambda k: None)
    out: dict[int, PointResult] = {}
    batch, single = _compile(gaits, indices, out, tick)
    if batch:
        _run_batch_safely(batch, single, out, capacity, tick, runs)
    for member in single:
        out[member[0]] = _run_single(member, runs)
        tick(1)
    by_index = {int(i): g for i, g in zip(indices, gaits)}
    return [_with_quantities(out[int(i)], by_index[int(i)], quantities) for i in indices]


def _compile(gaits, indices, out: dict[int, PointResult], tick) -> tuple[list[_Member], list[_Member]]:
    """The compiled processes, catch-up ones (for the batch) apart from exact ones; a gait
    that cannot be compiled is its row at once."""
    batch: list[_Member] = []
    single: list[_Member] = []
    for i, g in zip((int(i) for i in indices), gaits):
        try:
            process = compile_gait(g)
        except Exception as exc:  # recorded in the row: the sweep goes on
            _reraise_memory(exc)
            out[i] = _failure(i, exc)
            tick(1)
            continue
        (batch if g.simulation.integrator == "catch-up" else single).append((i, process, g))
    return batch, single


def _reraise_memory(exc: BaseException) -> None:
    if isinstance(exc, MemoryError):
        raise exc


def _run_batch_safely(
    batch: list[_Member], single: list[_Member], out: dict[int, PointResult], capacity, tick, runs: dict | None = None
) -> None:
    """`_run_batch`; when the batch raises, each point again alone (one bad point must not sink
    its batch)."""
    try:
        _run_batch(batch, single, out, capacity, tick, runs)
    except Exception as exc:
        _reraise_memory(exc)
        done = set(out) | {i for i, _, _ in single}
        for member in batch:
            if member[0] in done:
                continue
            try:
                _run_batch([member], single, out, capacity, tick, runs)
            except Exception as one:
                _reraise_memory(one)
                out[member[0]] = _failure(member[0], one)
                tick(1)


def _run_batch(
    members: list[_Member], single: list[_Member], out: dict[int, PointResult], capacity, tick, kept: dict | None = None
) -> None:
    """Catch-up points through the batched stepper; a ``newton`` point not converged within
    `BATCH_PLAIN_PERIODS` goes to ``single`` (the periodic-limit solver finishes it). What the
    others settled on joins ``kept`` when given (--sensitivity)."""
    newton = [g.simulation.limit == "newton" for _, _, g in members]
    runs = simulate_batch(
        [p for _, p, _ in members],
        max_periods=[
            min(g.simulation.max_periods, BATCH_PLAIN_PERIODS) if n else g.simulation.max_periods
            for (_, _, g), n in zip(members, newton)
        ],
        tolerance=[g.simulation.tolerance for _, _, g in members],
        capacity=capacity or DEFAULT_CAPACITY,
        progress=None,
        keep_limit=kept is not None,
    )
    for (i, p, g), r, n in zip(members, runs, newton):
        if n and r.status == PointStatus.NOT_CONVERGED and g.simulation.max_periods > BATCH_PLAIN_PERIODS:
            single.append((i, p, g))
            continue
        if kept is not None and r.record is not None:
            kept[i] = Settled(r, r.record, p)
        out[i] = PointResult(
            i,
            r.status,
            v0=r.v0,
            v0_error_estimate=None,  # time-step error unmeasured
            displacement_per_period=r.displacement_per_period,
            dissipation_per_period=r.dissipation_per_period,
            cost_of_transport=r.cost_of_transport,
            convergence=str(r.convergence or ""),
            periods=r.periods,
            integrator="catch-up",
            message=r.message,
            steps=r.steps,
            **_limit_of(r.v0),
        )
        tick(1)


def _limit_of(v0: float | None) -> dict[str, Any]:
    """A batched catch-up row's limit columns: plain iteration, no Newton step (none when the
    point has no v0)."""
    return {"limit": "iterate", "newton_steps": 0} if v0 is not None else {}


def _run_single(member: _Member, runs: dict | None = None) -> PointResult:
    """One point through `crawlsim.analysis.run.settle` (no history); what it settled on joins
    ``runs`` (by index) when given."""
    i, process, g = member
    s = g.simulation
    try:
        settled = settle(
            process,
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
        return _failure(i, exc)
    run, e = settled.result, settled.result.estimate
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
