"""The kymograph: the strain and the stress of every link and the slip state of every block over
the body and the time, one image each, so that a wave along a body of any length is a band whose
slope is its speed (docs/model.md §1: z = D x, sigma_i = k_i (L_i - z_i))."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from crawlsim.analysis.digits import counted
from crawlsim.plotting.source import last_periods, need, run_name, run_period, step_slip, takes_run
from crawlsim.plotting.style import (
    SLIP_COLOURS,
    SLIP_NAMES,
    diverging_map,
    figure_style,
    label,
    new_figure,
    shown_series,
    time_axis,
    title,
    units_of,
)


@takes_run
def kymograph_figure(results, last: int | None = None) -> Figure:
    """Three panels sharing the time axis, the body upwards (link i, block j; block N, the head
    in the direction of +x, at the top):

    1. the strain of each link, z_i / mean(z_i) - 1 over the window: its length against its own
       mean, contraction below 0;
    2. the slip state of each block on each step (stick, forward slip, backward slip, the colours
       of the gait diagram);
    3. the stress sigma_i = k_i (L_i - z_i), compression above 0;

    strain and stress in the diverging map of `style.diverging_map`, centred on 0. The window is
    the limit period, (t - t0)/T (``/limit``), or with ``last=K`` the last K periods of the
    stored trajectory, t/T, whose slip states are the signs of the blocks' displacements over
    each stored step (`source.step_slip`). Each panel is one image, whatever N.
    """
    units = units_of(results)
    T = run_period(results)
    if last is None:
        need(results, "kymograph", "limit/t", "limit/shape", "limit/stress", "limit/slip")
        lim = results["limit"]
        t, z, slip = (np.asarray(lim[k], dtype=float) for k in ("t", "shape", "slip"))
        sigma = np.asarray(lim["stress"], dtype=float)
        factor, time_label = time_axis(units, T, symbol="t - t_0", name="time in the limit period")
    else:
        need(results, "kymograph", "trajectory/t", "trajectory/x", "trajectory/stress")
        t, x = last_periods(results, last)
        z, slip = np.diff(x, axis=1), step_slip(x)
        sigma = np.asarray(results["trajectory"]["stress"], dtype=float)[-len(t) :]
        factor, time_label = time_axis(units, T)
    s = t * factor
    mean = z.mean(axis=0)
    strain = np.divide(z, mean, out=np.full_like(z, np.nan), where=mean != 0) - 1.0
    cmap = diverging_map()
    with figure_style():
        fig, axs = new_figure(3, 1, height=6.6, sharex=True)
        panels = (
            (strain, "link $i$", label("strain", "z_i/\\bar z_i - 1")),
            (slip, "block $j$", None),
            (sigma, "link $i$", label("stress", "\\sigma_i", "force", units)),
        )
        for ax, (data, index, name) in zip(axs[:, 0], panels):
            rows = data.shape[1]
            if name is None:  # the slip states: one cell per block and step
                ax.pcolormesh(
                    s,
                    np.arange(rows + 1) + 0.5,
                    data.T,
                    cmap=ListedColormap([SLIP_COLOURS[k] for k in (-1, 0, 1)]),
                    norm=BoundaryNorm([-1.5, -0.5, 0.5, 1.5], 3),
                    shading="flat",
                    rasterized=True,
                )
                patches = [Patch(facecolor=SLIP_COLOURS[k], label=SLIP_NAMES[k]) for k in (0, 1, -1)]
                ax.legend(handles=patches, loc="lower left", bbox_to_anchor=(0, 1), ncol=3, fontsize="small")
            else:
                largest = float(np.nanmax(np.abs(data), initial=0.0)) or 1.0
                mesh = ax.pcolormesh(
                    s,
                    np.arange(1, rows + 1),
                    data.T,
                    cmap=cmap,
                    norm=Normalize(-largest, largest),
                    shading="nearest",
                    rasterized=True,
                )
                fig.colorbar(mesh, ax=ax, pad=0.01, fraction=0.04).set_label(name)
            ticks = shown_series(rows, 6) + 1
            ax.set_yticks(ticks, [str(k) for k in ticks])
            ax.set_ylim(0.5, rows + 0.5)
            ax.set_ylabel(index)
            ax.grid(False)
        axs[-1, 0].set_xlim(s[0], s[-1])
        axs[-1, 0].set_xlabel(time_label)
        window = "" if last is None else f", the last {counted(last, 'period')}"
        fig.suptitle(title(run_name(results), f"kymograph{window}"))
    return fig
