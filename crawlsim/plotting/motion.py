"""The motion figure: block positions x_j(t), the barycentre y = mean(x) and the line
y(t0) + v0 (t - t0) of the average velocity (docs/model.md §4)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from crawlsim.analysis.digits import counted
from crawlsim.plotting.source import last_periods, need, run_name, run_period, takes_run
from crawlsim.plotting.style import (
    FAINT,
    REFERENCE,
    colours,
    figure_style,
    format_number,
    label,
    legend_right,
    new_figure,
    shown_series,
    shown_title,
    time_axis,
    title,
    units_of,
    velocity_axis,
)

#: The motion figure draws at most this many blocks (evenly spaced, first and last included).
MAX_MOTION_BLOCKS = 32
#: Beyond `MAX_MOTION_BLOCKS` blocks the motion figure follows the crawler over this many last
#: periods by default.
FOLLOW_PERIODS = 3


@takes_run
def motion_figure(results, last: int | None = None) -> Figure:
    """Block positions x_j(t) over the simulated time, the barycentre y(t) and the line of slope
    v0 through y at the start of the limit period, y(t0) + v0 (t - t0), with the limit period
    shaded (after the trajectory when the periodic-limit solver found it). Line order: blocks
    1..N, barycentre, v0 line. Times are t/T, or t in the file's time unit
    (`style.time_axis`); positions are the file's. Beyond `MAX_MOTION_BLOCKS` blocks, that
    many evenly spaced blocks are drawn (`shown_series`), which the legend title says.

    ``last=K`` zooms on the last K periods of the run in a frame that follows the crawler: each
    block's position from where it stood at the start of the window, x_j(t) - x_j(t_a), with
    the barycentre's y(t) - y(t_a) and the line v0 (t - t_a), so that the steps of every block
    and the net motion show whatever the length of the body (a 100-block crawler spans 100
    lengths and moves 0.07 of one a period), eight of them at most. Beyond `MAX_MOTION_BLOCKS`
    blocks that is the default, over `FOLLOW_PERIODS` periods."""
    need(results, "motion", "trajectory/t", "trajectory/x")
    units = units_of(results)
    t = np.asarray(results["trajectory"]["t"], dtype=float)
    x = np.asarray(results["trajectory"]["x"], dtype=float)
    v0 = float(results["attrs"]["v0"])
    t0 = float(results["limit_attrs"].get("start", t[0]))
    T = run_period(results)
    factor, time_label = time_axis(units, T)
    N = x.shape[1]
    if last is None and N > MAX_MOTION_BLOCKS:
        last = FOLLOW_PERIODS
    if last is not None:
        t, x = last_periods(results, last)
        x, t0 = x - x[0], t[0]
    y = x.mean(axis=1)
    per_period, _ = velocity_axis(units)
    if per_period:
        speed = (
            f"$v_0T$ = {format_number(v0 * T)} {units.length}"
            if units.length
            else f"$v_0T/\\ell$ = {format_number(v0 * T)}"
        )
    else:
        length = units.length or r"$\ell$"
        speed = f"$v_0$ = {format_number(v0)} {length}/{units.time}"
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        drawn = shown_series(N, MAX_MOTION_BLOCKS if last is None else 8)  # steps that cross: fewer
        for j, colour in zip(drawn, colours(len(drawn))):
            shown = len(drawn) <= 8 or j in (0, N - 1)
            ax.plot(t * factor, x[:, j], color=colour, label=f"block {j + 1}" if shown else None)
        ax.plot(t * factor, y, color=REFERENCE, linestyle="--", linewidth=1.2, label="barycentre $y$", zorder=3)
        # The v0 line meets the barycentre at every period start of the limit, so a thin line
        # would hide under it: it is a wide translucent band beneath the blocks instead. A limit
        # found by the solver is the period after the history (`analysis.following`).
        ends = np.array([t[0], max(t[-1], t0 + T)])
        ax.plot(
            ends * factor,
            np.interp(t0, t, y) + v0 * (ends - t0),
            color=REFERENCE,
            alpha=0.22,
            linewidth=6.0,
            solid_capstyle="butt",
            zorder=1,
            label=f"slope {speed}",
        )
        span = ax.axvspan(t0 * factor, (t0 + T) * factor, color=FAINT, alpha=0.15, linewidth=0, label="limit period")
        ax.set_xlim(ends[0] * factor, ends[1] * factor)
        if units.time is None and (ends[1] - ends[0]) / T <= 12:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(time_label)
        if last is None:
            ax.set_ylabel(label("position", "x_j", "length", units))
            ax.set_title(title(run_name(results), "block positions"))
        else:
            span.remove()
            ax.set_ylabel(label("displacement", "\\Delta x_j", "length", units))  # x_j(t) - x_j(t_a)
            ax.set_title(title(run_name(results), f"the last {counted(last, 'period')}"))
        # The legend lists the lines from top to bottom as they end at the right of the axes
        # (the front block first), then the shaded limit period.
        lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
        lines.sort(key=lambda line: -float(np.asarray(line.get_ydata())[-1]))
        legend_right(ax, handles=[*lines] + ([span] if last is None else []), title=shown_title(drawn, N, "blocks"))
    return fig
