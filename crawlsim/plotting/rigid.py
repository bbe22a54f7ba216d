"""The rigid-limit figure: which block rests when as the links stiffen without bound
(docs/model.md §7), from a run's /rigid group (``crawlsim run --rigid``)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from crawlsim.analysis.digits import with_error
from crawlsim.plotting.source import need, run_name, run_period, takes_run
from crawlsim.plotting.style import REFERENCE, SLIP_COLOURS, figure_style, new_figure, time_axis, title, units_of


@takes_run
def rigid_figure(results) -> Figure:
    """One row per block over one period: a bar where the block rests in the rigid limit (every
    other block moves with it, rigidly), a tick where a jump of the links is made with it at
    rest; the title gives v0 in that limit with its estimate."""
    need(results, "rigid", "rigid/start", "rigid/end", "rigid/resting_block")
    rigid, attrs = results["rigid"], results.get("rigid_attrs", {})
    start, end = np.asarray(rigid["start"], dtype=float), np.asarray(rigid["end"], dtype=float)
    block = np.asarray(rigid["resting_block"], dtype=int)
    blocks = len(results.get("coordinates", {}).get("block", [])) or int(block.max())
    factor, time_label = time_axis(units_of(results), run_period(results))
    with figure_style():
        fig, axs = new_figure(height=min(1.6 + 0.3 * blocks, 6.0))
        ax = axs[0, 0]
        for j in np.unique(block):
            rows = block == j
            bars = [(a * factor, (b - a) * factor) for a, b in zip(start[rows], end[rows]) if b > a]
            ax.broken_barh(bars, (j - 0.4, 0.8), color=SLIP_COLOURS[1])
            jumps = start[rows & (end == start)] * factor
            ax.plot(jumps, np.full(len(jumps), j), linestyle="", marker="|", markersize=14, color=REFERENCE)
        ax.set_xlim(start[0] * factor, end[-1] * factor)
        ax.set_ylim(blocks + 0.6, 0.4)
        if blocks <= 12:
            ax.set_yticks(range(1, blocks + 1))
        else:
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(time_label)
        ax.set_ylabel("resting block $j$")
        v0 = with_error(attrs.get("v0", np.nan), attrs.get("v0_error_estimate"))
        ax.set_title(title(run_name(results), f"resting block as $k \\to \\infty$, $v_0$ = {v0}"))
    return fig
