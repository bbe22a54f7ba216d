"""The figure of a velocity sweep: v0 over one or two swept gait parameters, its jumps
drawn as jumps (docs/model.md §3), points without a value marked by their status."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle
from matplotlib.ticker import FixedLocator, NullFormatter, NullLocator

from crawlsim.analysis.stall import curve_marks
from crawlsim.plotting.style import (
    FAINT,
    REFERENCE,
    STATUS_MARKERS,
    Units,
    colour_map,
    colours,
    figure_style,
    format_number,
    label,
    new_figure,
    path_label,
    units_of,
    velocity_axis,
)

#: A swept axis with more values than this gets a tick label on every k-th value only.
MAX_TICK_LABELS = 9
#: A sweep interval is a jump of v0 when its change is more than this many times what the
#: neighbouring slopes predict, and more than this fraction of the range of v0 (`jumps`).
JUMP_RATIO = 2.5
JUMP_FLOOR = 0.1


def is_geometric(values) -> bool:
    """True for three or more positive values with a constant ratio other than 1 (a log-spaced
    axis, ``PATH=log:LO:HI:NUM``): drawn on a log axis, cells centred in log space."""
    v = np.asarray(values, dtype=float)
    if v.size < 3 or np.any(v <= 0):
        return False
    ratios = v[1:] / v[:-1]
    steps = np.diff(v)
    uniform = np.allclose(steps, steps[0], rtol=1e-6, atol=0)
    return bool(np.allclose(ratios, ratios[0], rtol=1e-6) and not uniform)


def cell_edges(values, log: bool = False) -> np.ndarray:
    """Edges of the heat-map cells of a swept axis: halfway between neighbouring values
    (geometric means on a log axis), the outer cells as wide as their neighbours. Uniform
    (or log-uniform) values sit at the centres of their cells."""
    v = np.asarray(values, dtype=float)
    if log:
        return np.exp(cell_edges(np.log(v)))
    if v.size == 1:
        half = 0.5 * max(abs(v[0]), 1.0)
        return np.array([v[0] - half, v[0] + half])
    middle = (v[1:] + v[:-1]) / 2
    return np.concatenate([[2 * v[0] - middle[0]], middle, [2 * v[-1] - middle[-1]]])


def swept_ticks(values) -> tuple[np.ndarray, np.ndarray]:
    """(major, minor) tick positions of a swept axis: every value is a tick; when there are
    more than `MAX_TICK_LABELS`, only every k-th one (from the first, and the last too when a k
    allows it) carries a label, and the others are minor ticks (up to 60; beyond that none)."""
    v = np.asarray(values, dtype=float)
    if v.size <= MAX_TICK_LABELS:
        return v, np.array([])
    k = int(np.ceil(v.size / MAX_TICK_LABELS))
    ends = [m for m in range(k, 2 * k + 1) if (v.size - 1) % m == 0]
    k = ends[0] if ends else k
    major = v[::k]
    minor = np.setdiff1d(v, major) if v.size <= 60 else np.array([])
    return major, minor


def _set_swept_ticks(axis, values, log: bool) -> None:
    major, minor = swept_ticks(values)
    axis.set_major_locator(FixedLocator(major.tolist()))
    axis.set_minor_locator(FixedLocator(minor.tolist()) if minor.size else NullLocator())
    axis.set_ticklabels([format_number(v) for v in major])
    axis.set_minor_formatter(NullFormatter())


def _status_grid(status, shape) -> np.ndarray:
    """Status strings on the grid: a bool array means True = failed, False = ok."""
    status = np.asarray(status)
    if status.dtype == bool:
        status = np.where(status, "failed", "ok")
    return np.asarray(status, dtype=object).reshape(shape).astype(str)


def sweep_figure(
    axes: dict, v0, status, title: str, *, units: Units | None = None, displacement=None, marks=None
) -> Figure:
    """v0 over a sweep of one or two gait parameters, named by their dotted paths.

    ``axes`` maps each swept dotted path (``"friction.backward"``) to its values, in the order of
    the dimensions of ``v0`` (the grid's shape). ``status`` has the grid's shape too: the
    statuses of the points (``ok``, ``not-converged``, ``failed``, ``invalid``; empty for points
    a shard did not hold), or a bool array, True where the point failed. ``units`` labels the
    axes (`style.path_label`). Without a time unit the figure draws the displacement per period
    v0 T (``displacement``, of the grid's shape) when it is given, and v0 otherwise.

    * one parameter: the values at the swept points (markers, joined by a line that breaks at
      points without a value); failed and invalid points marked on the parameter axis,
      not-converged points circled; a tick at every swept value (thinned on long axes,
      `swept_ticks`);
    * two parameters: a heat map in the one colour map, each cell centred on its swept values
      (first parameter across, second up), ticks at the swept values, a colour bar, the contour
      v0 = 0 when v0 changes sign, and cells without a value hatched and marked by status.

    A log-spaced axis (constant ratio, `is_geometric`) is drawn on a log scale. ``marks`` (a
    `crawlsim.analysis.stall.CurveMarks`, sweeps of one load or friction number) break the line
    where v0 jumps (dotted verticals) instead of joining across them, and mark the stall load;
    for a sweep of the stiffness they hold the rigid limit, drawn as the asymptote it is (dashed).
    """
    units = units or Units()
    names = list(axes)
    values = [np.asarray(axes[k], dtype=float) for k in names]
    grid = tuple(len(v) for v in values)
    if len(names) not in (1, 2):
        raise ValueError(f"sweep_figure draws one or two swept parameters, got {len(names)}: {', '.join(names)}")
    v0 = np.asarray(v0, dtype=float)
    statuses = np.asarray(status)
    if v0.shape != grid or statuses.shape != grid:
        raise ValueError(f"v0 {v0.shape} and status {statuses.shape} must have the grid's shape {grid}")
    statuses = _status_grid(statuses, grid)
    per_period, value_label = velocity_axis(units)
    if per_period and displacement is not None:
        data = np.asarray(displacement, dtype=float).reshape(grid)
    else:
        data = v0
        if per_period:
            value_label = label("average velocity", "v_0")
    data = np.where(np.isin(statuses, ["ok", "not-converged"]) & np.isfinite(data), data, np.nan)
    logs = [is_geometric(v) for v in values]
    with figure_style():
        fig, axs = new_figure(height=3.6 if len(names) == 1 else 4.4)
        ax = axs[0, 0]
        if len(names) == 1:
            if marks is not None and marks.rigid is not None:
                limit = (
                    marks.rigid.displacement_per_period if per_period and displacement is not None else marks.rigid.v0
                )
                text = f"rigid limit $k \\to \\infty$: {format_number(limit)}"
                ax.axhline(limit, color=REFERENCE, linestyle="--", linewidth=1.0, zorder=3, label=text)
            _sweep_line(ax, values[0], data, statuses, logs[0], marks)
            ax.set_xlabel(path_label(names[0], units))
            ax.set_ylabel(value_label)
        else:
            _sweep_map(fig, ax, values, data, statuses, logs, value_label)
            ax.set_xlabel(path_label(names[0], units))
            ax.set_ylabel(path_label(names[1], units))
        ax.set_title(title)
    return fig


def _status_handles(ax, statuses, where) -> list:
    """Mark the points whose status is in `STATUS_MARKERS` at ``where(mask)`` -> (x, y, kwargs);
    return the legend handles."""
    handles = []
    for status, (marker, name) in STATUS_MARKERS.items():
        mask = statuses == status
        if not np.any(mask):
            continue
        x, y, extra = where(mask)
        style: dict[str, object] = dict(linestyle="none", marker=marker, color=REFERENCE, label=name)
        if marker == "o":
            style.update(markerfacecolor="none", markersize=9, markeredgewidth=1.2)
        else:
            style.update(markersize=8, markeredgewidth=1.6)
        handles += ax.plot(x, y, **style, **extra)
    return handles


def jumps(values, data, log: bool = False) -> np.ndarray:
    """Where a sampled v0 jumps between neighbouring swept values: a bool array, one entry per
    interval [values[k], values[k+1]] (the last axis of ``data``).

    v0 of this model is piecewise smooth in the gait's parameters and jumps where the set of
    slipping blocks changes discontinuously (a friction coefficient crossing an equality of the
    uniqueness condition, docs/model.md §3). On a sampled axis a jump is an interval whose
    change of v0 is more than `JUMP_RATIO` times what the slopes of the intervals on either side
    predict over it, and more than `JUMP_FLOOR` of the range of v0. On a monotone convex or
    concave stretch, and across a kink, the change over an interval lies between its neighbours'
    (ratio at most 1); a jump does not shrink with the step. A smooth transition sharper than the
    grid resolves (a tanh of width w sampled at h >= 1.3 w gives a ratio above 2.5) is drawn as
    a jump too: the grid cannot tell the two apart. Only an interval with a known slope on both
    sides can be a jump: not the first or last of an axis (a saturating curve changes more over
    its first interval than over the next, by any ratio), nor one beside a missing value, nor
    any interval of an axis of fewer than four values. On a log axis slopes are taken in log
    space.
    """
    v = np.log(np.asarray(values, dtype=float)) if log else np.asarray(values, dtype=float)
    d = np.asarray(data, dtype=float)
    h = np.diff(v)
    change = np.diff(d, axis=-1)
    out = np.zeros(change.shape, dtype=bool)
    if change.shape[-1] < 3:
        return out  # fewer than four values: too few to tell a jump from a steep slope
    slope = np.abs(change) / h
    finite = np.where(np.isfinite(slope), slope, -np.inf)
    before = np.concatenate([np.full(finite.shape[:-1] + (1,), -np.inf), finite[..., :-1]], axis=-1)
    after = np.concatenate([finite[..., 1:], np.full(finite.shape[:-1] + (1,), -np.inf)], axis=-1)
    # Both neighbours are needed: at an end of the axis a saturating curve changes more over its
    # first interval than over the next, by any ratio, without a jump.
    local = np.where(np.isfinite(before) & np.isfinite(after), np.maximum(before, after), np.nan)
    scale = np.nanmax(np.abs(d)) if np.any(np.isfinite(d)) else 0.0
    span = (np.nanmax(d) - np.nanmin(d)) if np.any(np.isfinite(d)) else 0.0
    with np.errstate(invalid="ignore"):
        out = (
            np.isfinite(change)
            & np.isfinite(local)
            & (np.abs(change) > JUMP_RATIO * local * h)
            & (np.abs(change) > JUMP_FLOOR * max(span, 1e-12 * scale))
        )
    return out


def _break_at_jumps(x, data, jump):
    """x and data with a NaN inserted inside every jump interval, so the line breaks there."""
    cut = np.flatnonzero(jump) + 1
    return np.insert(x.astype(float), cut, np.nan), np.insert(data, cut, np.nan)


def _sweep_line(ax, x, data, statuses, log, marks=None):
    """v0 over one swept value, broken at its jumps. ``marks`` (`crawlsim.analysis.stall.curve_marks`, for a
    swept load) gives the jumps where the uniqueness condition fails, located exactly, and the
    stall; without them the jumps are found from the samples (`jumps`)."""
    exact = marks is not None and bool(marks.jumps)
    if exact:
        jump = np.array(
            [any(min(a, b) <= s <= max(a, b) for s in marks.jumps) for a, b in zip(x[:-1], x[1:])], dtype=bool
        )
    else:
        jump = jumps(x, data, log)
    xs, ys = _break_at_jumps(x, data, jump)
    ax.plot(xs, ys, color=colours(1)[0], marker="o", markersize=4.5, label="$v_0$")
    if marks is not None:
        _draw_marks(ax, marks)
    if not exact:
        _draw_sampled_jumps(ax, x, data, jump, log)
    if log:
        ax.set_xscale("log")
    ax.axhline(0.0, color=REFERENCE, linewidth=0.6)
    handles = _status_handles(
        ax,
        statuses,
        lambda mask: (
            (x[mask], data[mask], {})
            if np.all(np.isfinite(data[mask]))
            else (x[mask], np.zeros(np.count_nonzero(mask)), {"transform": ax.get_xaxis_transform(), "clip_on": False})
        ),
    )
    _set_swept_ticks(ax.xaxis, x, log)
    pad = 0.04 * (np.log(x[-1] / x[0]) if log else x[-1] - x[0]) if x.size > 1 else 0.5
    if log:
        ax.set_xlim(x[0] * np.exp(-pad), x[-1] * np.exp(pad))
    else:
        ax.set_xlim(x[0] - pad, x[-1] + pad)
    if handles or (marks is not None and (marks.jumps or marks.stall is not None or marks.rigid is not None)):
        ax.legend(loc="best")


def _draw_marks(ax, marks) -> None:
    """The stall load (dashed) and the exact jumps of a swept load (dotted verticals)."""
    if marks.stall is not None:
        ax.axvline(
            marks.stall,
            color=REFERENCE,
            linestyle="--",
            linewidth=1.2,
            label=f"{marks.label} {marks.stall:.6g} ({marks.cause})",
        )
    for k, s in enumerate(marks.jumps or ()):
        ax.axvline(s, color=FAINT, linestyle=":", linewidth=1.0, label=marks.jump_label if k == 0 else None)


def _draw_sampled_jumps(ax, x, data, jump, log) -> None:
    """Each jump found from the samples: a faint vertical at the middle of its interval,
    between the two values, where no value of v0 was sampled."""
    sampled = np.flatnonzero(jump)
    for k in sampled:
        middle = np.sqrt(x[k] * x[k + 1]) if log else (x[k] + x[k + 1]) / 2
        ax.plot(
            [middle, middle],
            [data[k], data[k + 1]],
            color=FAINT,
            linestyle=":",
            linewidth=1.0,
            label="jump of $v_0$" if k == sampled[0] else None,
        )


def _sweep_map(fig, ax, values, data, statuses, logs, value_label):
    x, y = values
    cmap = colour_map().with_extremes(bad="white")
    mesh = ax.pcolormesh(cell_edges(x, logs[0]), cell_edges(y, logs[1]), data.T, cmap=cmap, shading="flat")
    bar = fig.colorbar(mesh, ax=ax)
    bar.set_label(value_label)
    if logs[0]:
        ax.set_xscale("log")
    if logs[1]:
        ax.set_yscale("log")
    handles: list = []
    empty = ~np.isfinite(data)
    if np.any(empty):
        xe, ye = cell_edges(x, logs[0]), cell_edges(y, logs[1])
        for a, b in zip(*np.nonzero(empty)):
            ax.add_patch(
                Rectangle(
                    (xe[a], ye[b]),
                    xe[a + 1] - xe[a],
                    ye[b + 1] - ye[b],
                    facecolor="white",
                    edgecolor=FAINT,
                    hatch="////",
                    linewidth=0.0,
                    label="_no value",
                )
            )
        handles.append(Patch(facecolor="white", edgecolor=FAINT, hatch="////", label="no value"))
    finite = data[np.isfinite(data)]
    jump_x, jump_y = jumps(x, data.T, logs[0]).T, jumps(y, data, logs[1])
    if finite.size and finite.min() < 0 < finite.max() and min(data.shape) >= 2:
        segments = zero_contour(x, y, data, jump_x, jump_y, logs)
        if segments:
            ax.add_collection(LineCollection(segments, colors=REFERENCE, linewidths=1.2))
            handles.append(Line2D([], [], color=REFERENCE, linewidth=1.2, label="$v_0$ = 0"))
            bar.ax.axhline(0.0, color=REFERENCE, linewidth=1.2)
    walls = jump_walls(x, y, jump_x, jump_y, logs)
    if walls:
        ax.add_collection(LineCollection(walls, colors=REFERENCE, linewidths=2.4, linestyles="solid"))
        handles.append(Line2D([], [], color=REFERENCE, linewidth=2.4, label="jump of $v_0$"))
    handles += _status_handles(ax, statuses, lambda mask: (x[np.nonzero(mask)[0]], y[np.nonzero(mask)[1]], {}))
    _set_swept_ticks(ax.xaxis, x, logs[0])
    _set_swept_ticks(ax.yaxis, y, logs[1])
    ax.grid(False)
    if handles:
        ax.legend(
            handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=min(len(handles), 3), borderaxespad=0
        )


def zero_contour(x, y, data, jump_x, jump_y, logs=(False, False)) -> list[np.ndarray]:
    """The level set v0 = 0 of a heat map as line segments, by marching squares on the grid of
    swept points, never across a jump.

    ``data[a, b]`` is v0 at (x[a], y[b]); ``jump_x[a, b]`` says whether v0 jumps between
    (x[a], y[b]) and (x[a+1], y[b]), ``jump_y[a, b]`` between (x[a], y[b]) and (x[a], y[b+1])
    (`jumps`). A crossing of 0 is interpolated linearly along an edge of the grid only where v0
    is continuous there; a square with a jump on any edge, or a missing value at a corner, has
    no contour: its sign change is the jump itself (`jump_walls`), which is what the model
    does, not a smooth zero. Interpolation is in log space on a log axis. A square whose four
    edges all cross (a saddle) is resolved by the sign of its mean.
    """
    d = np.asarray(data, dtype=float)
    u = np.log(np.asarray(x, dtype=float)) if logs[0] else np.asarray(x, dtype=float)
    w = np.log(np.asarray(y, dtype=float)) if logs[1] else np.asarray(y, dtype=float)

    def back(p):
        return (np.exp(p[0]) if logs[0] else p[0], np.exp(p[1]) if logs[1] else p[1])

    def cross(p, q, dp, dq):
        r = dp / (dp - dq)
        return back((p[0] + r * (q[0] - p[0]), p[1] + r * (q[1] - p[1])))

    segments = []
    for a in range(d.shape[0] - 1):
        for b in range(d.shape[1] - 1):
            corners = [(a, b), (a + 1, b), (a + 1, b + 1), (a, b + 1)]
            values = [d[c] for c in corners]
            if not np.all(np.isfinite(values)):
                continue
            if jump_x[a, b] or jump_x[a, b + 1] or jump_y[a, b] or jump_y[a + 1, b]:
                continue
            points = []
            for k in range(4):
                (i0, j0), (i1, j1) = corners[k], corners[(k + 1) % 4]
                v_0, v_1 = values[k], values[(k + 1) % 4]
                if (v_0 < 0) != (v_1 < 0):
                    points.append(cross((u[i0], w[j0]), (u[i1], w[j1]), v_0, v_1))
            if len(points) == 2:
                segments.append(np.array(points))
            elif len(points) == 4:
                # Saddle: pair the crossings around the corners whose sign differs from the
                # square's mean.
                first = (values[0] < 0) != (np.mean(values) < 0)
                pairs = [(0, 1), (2, 3)] if first else [(3, 0), (1, 2)]
                segments += [np.array([points[i], points[j]]) for i, j in pairs]
    return segments


def jump_walls(x, y, jump_x, jump_y, logs=(False, False)) -> list[np.ndarray]:
    """The jumps of a heat map as segments on the cell boundaries between the two points v0
    jumps between (`jumps`, `cell_edges`): a wall, where the map changes colour abruptly."""
    xe, ye = cell_edges(x, logs[0]), cell_edges(y, logs[1])
    walls = [np.array([[xe[a + 1], ye[b]], [xe[a + 1], ye[b + 1]]]) for a, b in zip(*np.nonzero(jump_x))]
    walls += [np.array([[xe[a], ye[b + 1]], [xe[a + 1], ye[b + 1]]]) for a, b in zip(*np.nonzero(jump_y))]
    return walls


def sweep_data_figure(data: Any, title: str | None = None) -> Figure:
    """The sweep figure of a sweep file (`crawlsim.io.sweepfile.read_sweep`), of a table
    (`crawlsim.study.sweep.table_payload`) or of the `xarray.Dataset` of `crawlsim.sweep`
    (``grid.crawlsim.plot()``): the columns are put back on the grid (points a shard did not hold
    have no value and no status), the units come from the file (`style.units_of`)."""
    if not isinstance(data, dict):  # a Dataset, its dimensions named by the paths
        flags = dict(zip(data.status.attrs["flag_values"].tolist(), data.status.attrs["flag_meanings"].split()))
        columns = {name: data[name].values.ravel() for name in ("v0", "displacement_per_period")}
        columns["status"] = np.array([flags[int(s)].replace("_", "-") for s in data.status.values.ravel()])
        data = {**data.attrs, "paths": data.v0.dims, "axes": [data[d].values for d in data.v0.dims]}
        data.update(points=np.arange(columns["v0"].size), columns=columns, dimensions=None)
    dims = data.get("dimensions") or range(len(data["paths"]))
    first = [list(dims).index(d) for d in sorted(set(dims))]  # a dimension's first path: linked ones once
    paths, values = [data["paths"][k] for k in first], [data["axes"][k] for k in first]
    shape = tuple(len(a) for a in values)
    points = np.asarray(data["points"], dtype=int)
    columns = data["columns"]

    def on_grid(name, fill, dtype):
        full = np.full(int(np.prod(shape)), fill, dtype=dtype)
        full[points] = np.asarray(columns[name]).astype(dtype)
        return full.reshape(shape)

    v0 = on_grid("v0", np.nan, float)
    displacement = on_grid("displacement_per_period", np.nan, float)
    status = on_grid("status", "", object)
    if title is None:
        title = f"{_sweep_name(data)}: average velocity over a sweep"
    marks = None
    if len(paths) == 1 and data.get("gait_yaml"):
        marks = curve_marks(data["gait_yaml"], paths[0], values[0], v0)
    return sweep_figure(
        dict(zip(paths, values)), v0, status, title, units=units_of(data), displacement=displacement, marks=marks
    )


def _sweep_name(data: dict) -> str:
    import yaml

    try:
        document = yaml.safe_load(data.get("gait_yaml") or "")
    except yaml.YAMLError:
        document = None
    if isinstance(document, dict) and isinstance(document.get("name"), str):
        return document["name"]
    from pathlib import Path

    return Path(str(data.get("source", "sweep"))).stem
