"""The convergence figure: the Poincare step and W^{1,2} distance to the last period,
and the displacement of each period q (docs/model.md §4)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator, NullFormatter

from crawlsim.plotting.source import is_crawler_run, need, run_name, run_period, takes_run
from crawlsim.plotting.style import (
    REFERENCE,
    colours,
    figure_style,
    format_number,
    label,
    legend_right,
    new_figure,
    shown_series,
    title,
    units_of,
    velocity_axis,
)

#: A series of the convergence figure has a marker on each of its first `MARKED_START`
#: periods (the transient) and on `MAX_MARKERS` evenly spaced ones (`marked_periods`).
MARKED_START = 10
MAX_MARKERS = 30


def marked_periods(count: int) -> list[int]:
    """The indices of the periods whose values get a marker, out of ``count``: every one of
    the first `MARKED_START`, and `MAX_MARKERS` evenly spaced ones, the last included. The
    lines join every period; a hundred markers would merge into a band."""
    every = set(range(min(count, MARKED_START))) | set(shown_series(count, MAX_MARKERS).tolist())
    return sorted(every)


def convergence_series(results: dict) -> dict[str, np.ndarray]:
    """The per-period distances of the state panel, keyed by their legend label: the Poincare
    step of period q and the W^{1,2}(t0, t0+T) distance of period q to the last period."""
    conv = results["convergence"]
    series = {
        "Poincaré step": conv["poincare_step"],
        "$W^{1,2}$ distance to\nthe last period": conv["w12_distance"],
    }
    return {k: np.asarray(v, dtype=float) for k, v in series.items()}


def convergence_scale(results: dict) -> str:
    """ "linear" for a finite-time run (its distances drop to exactly 0, which a linear axis
    shows as 0), "log" otherwise (a geometric decay is a straight line there)."""
    positive = [v[v > 0] for v in convergence_series(results).values()]
    finite = results["attrs"].get("convergence", "") == "finite-time"
    return "linear" if finite or not any(p.size for p in positive) else "log"


@takes_run
def convergence_figure(results) -> Figure:
    """How the run reached its limit period, per period q (docs/model.md §4).

    Top panel, the state: the Poincare step and the W^{1,2}(t0, t0+T) distance of period q to
    the last period. A finite-time run is drawn on a linear axis, where its exact zeros are
    zeros, with a vertical line and the words "periodic from period q"; an asymptotic run on a
    log axis (exact zeros left out, no "0" tick), with the geometric decay r^q of the fitted
    contraction rate r through the last positive Poincare step.

    Bottom panel, crawlers only: the displacement of each period, y(t0+(q+1)T) - y(t0+qT), on a
    linear axis against v0 T (or the velocity of each period against v0, when the file gives a
    time unit), which shows the transient of the velocity even when it lasts one period.
    """
    need(results, "convergence", "convergence/period", "convergence/poincare_step", "convergence/w12_distance")
    units = units_of(results)
    conv, attrs = results["convergence"], results["attrs"]
    q = np.asarray(conv["period"], dtype=float)
    series = convergence_series(results)
    scale = convergence_scale(results)
    crawler = is_crawler_run(results)
    v0 = attrs.get("v0", np.nan)
    T = run_period(results)
    motion = crawler and v0 is not None and np.isfinite(v0) and "displacement" in conv
    verdict = str(attrs.get("convergence", ""))
    periodic_from = attrs.get("periodic_from", -1)
    finite = verdict == "finite-time" and periodic_from is not None and periodic_from >= 0
    with figure_style():
        if motion:
            fig, axs = new_figure(2, 1, height=4.8, sharex=True, gridspec_kw={"height_ratios": [1.25, 1.0]})
        else:
            fig, axs = new_figure(height=3.4)
        state = axs[0, 0]
        state.set_yscale(scale)
        markers = marked_periods(len(q))
        # The Poincare step's dots above the distance's open squares, which are larger: at the
        # last period both are 0, and the dot shows inside the square.
        for (name, value), colour, style in zip(
            series.items(),
            colours(2),
            [
                {"marker": "o", "markersize": 5, "zorder": 2.5},
                {"marker": "s", "markersize": 7.5, "markerfacecolor": "none", "markeredgewidth": 1.2},
            ],
        ):
            shown = value if scale == "linear" else np.where(value > 0, value, np.nan)
            state.plot(q, shown, color=colour, linewidth=1.0, label=name, clip_on=False, markevery=markers, **style)
        _mark_the_limit(axs[:, 0], q, series, attrs, scale, finite)
        if verdict == "not-converged":
            state.text(0.98, 0.95, "not converged", transform=state.transAxes, ha="right", va="top", color=REFERENCE)
        if scale == "log":
            state.yaxis.set_minor_formatter(NullFormatter())
        state.set_ylabel(
            label("distance", "\\Delta w" if crawler else "\\Delta z", "force" if crawler else None, units)
        )
        # Two lines, so that a long name keeps the title within the axes.
        state.set_title(f"{title(run_name(results), 'convergence to the limit period')}\n({verdict})")
        legend_right(state)

        if motion:
            _period_displacements(axs[1, 0], q, conv, v0, T, units)
        bottom = axs[-1, 0]
        bottom.xaxis.set_major_locator(MaxNLocator(integer=True))
        if len(q) <= 3:
            bottom.set_xlim(q[0] - 0.5, q[-1] + 0.5)
        bottom.set_xlabel(label("period index", "q"))
        fig.align_ylabels(axs[:, 0])
    return fig


def _mark_the_limit(axes, q, series, attrs, scale, finite) -> None:
    """A finite-time run: a vertical line at its first periodic period on every panel, named
    on the state panel. An asymptotic run on a log axis: the geometric decay r^q of the fitted
    contraction rate r through the last positive Poincare step."""
    state = axes[0]
    rate = attrs.get("contraction_rate", np.nan)
    poincare = next(iter(series.values()))
    if finite:
        periodic_from = attrs["periodic_from"]
        for ax in axes:
            ax.axvline(
                periodic_from,
                color=REFERENCE,
                linestyle="--",
                linewidth=1.0,
                label=f"periodic from period {periodic_from}" if ax is state else None,
            )
        right = periodic_from >= q[-1] - 0.5 * (q[-1] - q[0])
        state.text(
            periodic_from,
            0.97,
            f" periodic from period {periodic_from} " if right else f" periodic from period {periodic_from}",
            transform=state.get_xaxis_transform(),
            ha="right" if right else "left",
            va="top",
            color=REFERENCE,
        )
        state.set_ylim(bottom=0.0)
    elif scale == "log" and rate is not None and np.isfinite(rate) and np.any(poincare > 0):
        last = np.flatnonzero(poincare > 0)[-1]
        state.plot(
            q,
            poincare[last] * rate ** (q - q[last]),
            color=REFERENCE,
            linestyle="--",
            linewidth=1.0,
            zorder=3,
            label=f"fitted rate {rate:.3g}\nper period",
        )


def _period_displacements(ax, q, conv, v0, T, units) -> None:
    """The displacement d_q of each period against v0 T (without a time unit), or the velocity
    v_q = d_q / T of each period against v0 (with one)."""
    displacement = np.asarray(conv["displacement"], dtype=float)
    per_period, _ = velocity_axis(units)
    if per_period:
        value, target, symbol, each = displacement, v0 * T, "v_0T", "d_q"
        what = label("displacement", "d_q", "length", units)
    else:
        value, target, symbol, each = displacement / T, v0, "v_0", "v_q"
        what = label("velocity", "v_q", "velocity", units)
    ax.plot(
        q,
        value,
        color=colours(3)[2],
        marker="^",
        markersize=5,
        linewidth=1.0,
        markevery=marked_periods(len(q)),
        label=f"${each}$, period $q$",
    )
    ax.axhline(target, color=REFERENCE, linestyle=":", linewidth=1.2, label=f"${symbol}$ = {format_number(target)}")
    ax.margins(y=0.15)
    ax.set_ylabel(what)
    legend_right(ax)
