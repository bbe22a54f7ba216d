"""The gait diagram of the limit period: slip state of each block on each step
(``/limit/slip``), the actuator lengths L_i(t) against the link lengths z_i = x_{i+1} - x_i, the
link stresses sigma_i = k_i (L_i - z_i) against their friction bounds, and the elastic force on
each block f = D^T sigma (f_j = sigma_{j-1} - sigma_j) against its friction limits
[-mu_j^-, mu_j^+] (docs/model.md §1)."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FixedLocator, FuncFormatter

from crawlsim.model.crawler import block_forces, stress_bounds
from crawlsim.plotting.source import need, run_name, run_period, takes_run
from crawlsim.plotting.style import (
    REFERENCE,
    SLIP_COLOURS,
    SLIP_NAMES,
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
)

#: The line panels of the gait diagram draw at most this many links (blocks), evenly spaced,
#: first and last included: beyond it lines are no longer told apart, and a thousand-block
#: crawler would cost minutes and a gigabyte to draw (`shown_series`).
MAX_SERIES = 8
#: Up to this many blocks, the slip bands of the gait diagram are labelled "block j" one by one
#: and grow with N; beyond it the panel keeps this height and gets thinned block numbers.
MAX_BAND_LABELS = 12
#: The force panel of the gait diagram is one small panel per block, at most this many (evenly
#: spaced, first and last included), each this tall (inches).
MAX_FORCE_ROWS = 6
FORCE_ROW_HEIGHT = 0.62
#: The gait diagram draws the stresses over their bounds when the largest bound is more than this
#: many times the largest stress (`stress_mode`).
RELATIVE_STRESS_RATIO = 5.0


def slip_runs(slip: np.ndarray, t: np.ndarray) -> list[tuple[int, float, float]]:
    """Maximal runs of one slip state of one block: ``(state, start, end)`` in time.

    ``slip[k]`` is the state on step k, the interval [t_k, t_{k+1}], so the runs tile
    [t_0, t_G] exactly.
    """
    slip = np.asarray(slip)
    cuts = np.flatnonzero(np.diff(slip)) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [len(slip)]])
    return [(int(slip[a]), float(t[a]), float(t[b])) for a, b in zip(starts, ends)]


def relative_stress(sigma: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Each link stress over its bound on the side of its sign, sigma_i / high_i where sigma_i >= 0
    and sigma_i / |low_i| where sigma_i < 0 (`stress_bounds`): a number in [-1, 1], +-1 exactly
    where the link's stress is as large as a group of blocks can resist. A bound of 0 (no
    friction on one side) holds a stress of 0, drawn as 0."""
    sigma = np.asarray(sigma, dtype=float)
    bound = np.where(sigma >= 0, high, -np.asarray(low, dtype=float))
    return np.divide(sigma, bound, out=np.zeros_like(sigma), where=bound > 0)


def stress_mode(sigma: np.ndarray, low: np.ndarray, high: np.ndarray) -> str:
    """ "relative" when the friction bounds dwarf the stresses (the largest bound more than
    `RELATIVE_STRESS_RATIO` times the largest stress: a long crawler, whose bounds grow with the
    number of blocks behind and ahead of a link, while its stresses do not), else "absolute"."""
    largest = float(np.max(np.abs(sigma), initial=0.0))
    bound = float(max(np.max(np.abs(low), initial=0.0), np.max(np.abs(high), initial=0.0)))
    return "relative" if bound > RELATIVE_STRESS_RATIO * largest else "absolute"


@takes_run
def gait_figure(results, stress: str = "auto") -> Figure:
    """The gait diagram of the limit period, panels sharing the time axis (t - t0)/T
    (or t - t0 in the file's time unit):

    1. one band per block: stick, forward slip, backward slip on each step (``/limit/slip``), in
       the slip colours, which no line of the figure uses;
    2. actuator lengths L_i(t) (solid) and link lengths z_i(t) = x_{i+1} - x_i (dashed);
    3. link stresses sigma_i(t) (solid) with their friction bounds (dotted, in the colour of
       their link, `stress_bounds`). ``stress="relative"`` draws sigma_i over its bound instead
       (`relative_stress`), the bounds then being the lines +-1; ``"auto"`` (the default) does so
       where the bounds dwarf the stresses (`stress_mode`: a 100-block crawler has bounds of
       +-70 and stresses of order 1, which a shared axis flattens);
    4. the elastic force on each block f_j(t) = sigma_{j-1} - sigma_j, one small panel per block
       (small multiples sharing one force axis: several blocks sit on the same limit at once,
       which one panel would draw as one line), with its friction limits mu_j^+(t) and
       -mu_j^-(t) (dotted) and its slipping steps shaded in the slip colours. This is the exact
       admissibility picture: block j sticks while -mu_j^- < f_j < mu_j^+ and slips forward
       (backward) only on the upper (lower) limit, which is where the bands of panel 1 change
       colour.

    Panel 1 is one image of N x G cells, whatever N. Beyond `MAX_SERIES` links, panels 2-3 draw
    that many evenly spaced ones (`shown_series`), and beyond `MAX_FORCE_ROWS` blocks panel 4
    draws that many; their legends (the first force row's) say how many of how many are drawn.
    Beyond `MAX_BAND_LABELS` blocks, panel 1 stops growing and numbers its blocks on a thinned
    axis.
    """
    if stress not in ("auto", "absolute", "relative"):
        raise ValueError(f"stress={stress!r}: choose auto, absolute or relative")
    need(
        results,
        "gait diagram",
        "limit/t",
        "limit/slip",
        "limit/shape",
        "limit/stress",
        "limit/lengths",
        "limit/friction",
    )
    units = units_of(results)
    lim = results["limit"]
    t = np.asarray(lim["t"], dtype=float)
    factor, time_label = time_axis(units, run_period(results), symbol="t - t_0", name="time in the limit period")
    s = t * factor
    slip = np.asarray(lim["slip"])
    L = np.asarray(lim["lengths"], dtype=float)
    z = np.asarray(lim["shape"], dtype=float)
    sigma = np.asarray(lim["stress"], dtype=float)
    friction = np.asarray(lim["friction"], dtype=float)
    N = slip.shape[1]
    links, blocks = shown_series(N - 1, MAX_SERIES), shown_series(N, MAX_FORCE_ROWS)
    link_colours, block_colours = colours(len(links)), colours(len(blocks))
    rows = min(N, MAX_BAND_LABELS)
    low, high = stress_bounds(friction)
    if stress == "auto":
        stress = stress_mode(sigma[:, links], low[:, links], high[:, links])
    nb = len(blocks)
    with figure_style():
        fig, axs = new_figure(
            3 + nb,
            1,
            height=1.0 + 0.3 * rows + 3.9 + FORCE_ROW_HEIGHT * nb,
            sharex=True,
            gridspec_kw={"height_ratios": [0.2 * rows + 0.1, 1.0, 1.0] + [FORCE_ROW_HEIGHT / 1.65] * nb},
        )
        bands, lengths, stresses = axs[:3, 0]
        force_rows = list(axs[3:, 0])

        # One cell per block and step, coloured by its slip state: an image (rasterized in
        # vector formats), so its cost is that of G x N pixels, not of G x N patches.
        states = (-1, 0, 1)
        bands.pcolormesh(
            s,
            np.arange(N + 1) - 0.5,
            slip.T.astype(float),
            cmap=ListedColormap([SLIP_COLOURS[k] for k in states]),
            norm=BoundaryNorm([-1.5, -0.5, 0.5, 1.5], len(states)),
            shading="flat",
            rasterized=True,
        )
        if N <= MAX_BAND_LABELS:
            bands.set_yticks(range(N), [f"block {j + 1}" for j in range(N)])
        else:
            ticks = shown_series(N, 6)
            bands.set_yticks(ticks, [str(j + 1) for j in ticks])
            bands.set_ylabel("block $j$")
        bands.set_ylim(-0.5, N - 0.5)
        bands.grid(False)
        bands.tick_params(axis="y", length=0)
        bands.spines["left"].set_visible(False)
        bands.legend(
            handles=[Patch(facecolor=SLIP_COLOURS[s_], edgecolor="none", label=SLIP_NAMES[s_]) for s_ in (0, 1, -1)],
            loc="lower left",
            bbox_to_anchor=(0.0, 1.0),
            ncol=3,
            borderaxespad=0.2,
        )

        links_title = shown_title(links, N - 1, "links")
        for i, colour in zip(links, link_colours):
            lengths.plot(s, L[:, i], color=colour, label=f"$L_{{{i + 1}}}$ actuator")
        for i, colour in zip(links, link_colours):
            lengths.plot(s, z[:, i], color=colour, linestyle="--", label=f"$z_{{{i + 1}}}$ link")
        lengths.set_ylabel(label("length", "L_i, z_i", "length", units))
        legend_right(lengths, ncol=2, title=links_title)

        if stress == "relative":
            ratio = relative_stress(sigma, low, high)
            for i, colour in zip(links, link_colours):
                stresses.plot(s, ratio[:, i], color=colour, label=f"$\\sigma_{{{i + 1}}}$")
            bound_lines = [stresses.axhline(v, color=REFERENCE, linestyle=":", linewidth=1.0) for v in (1.0, -1.0)]
            handles, names = stresses.get_legend_handles_labels()
            handles.append(bound_lines[0])
            names.append("friction bounds")
            stresses.set_ylim(-1.1, 1.1)
            stresses.set_ylabel("stress over its bound\n$\\sigma_i/\\bar\\sigma_i$")
        else:
            bound_handles = []
            for i, colour in zip(links, link_colours):
                stresses.plot(s, sigma[:, i], color=colour, label=f"$\\sigma_{{{i + 1}}}$")
                bound_handles += stresses.plot(s, high[:, i], color=colour, linestyle=":", linewidth=1.0)
                stresses.plot(s, low[:, i], color=colour, linestyle=":", linewidth=1.0)
            handles, names = stresses.get_legend_handles_labels()
            # One entry for the bounds, drawn in the colours of the links they bound.
            handles.append(
                tuple(Line2D([], [], color=h.get_color(), linestyle=":", linewidth=1.0) for h in bound_handles)
            )
            names.append("friction bounds")
            stresses.set_ylabel(label("stress", "\\sigma_i", "force", units))
        stresses.axhline(0.0, color=REFERENCE, linewidth=0.6)
        legend_right(
            stresses,
            handles=handles,
            labels=names,
            title=links_title,
            handlelength=3.2,
            handler_map={tuple: HandlerTuple(ndivide=None, pad=0.0)},
        )

        f = block_forces(sigma)
        plus, minus = friction[:, :N], friction[:, N:]
        for ax in force_rows[1:]:
            ax.sharey(force_rows[0])
        for ax, j, colour in zip(force_rows, blocks, block_colours):
            for state, start, stop in slip_runs(slip[:, j], s):
                if state != 0:
                    ax.axvspan(start, stop, color=SLIP_COLOURS[state], alpha=0.35, linewidth=0)
            ax.plot(s, f[:, j], color=colour, label=f"$f_{{{j + 1}}}$")
            ax.plot(s, plus[:, j], color=REFERENCE, linestyle=":", linewidth=1.0)
            ax.plot(s, -minus[:, j], color=REFERENCE, linestyle=":", linewidth=1.0)
            ax.set_ylabel(f"$f_{{{j + 1}}}$", rotation=0, ha="right", va="center")
        # Ticks at the extreme limits and 0, a margin so that a force on its limit is not drawn
        # on the frame.
        top, bottom = float(np.max(plus[:, blocks])), float(-np.max(minus[:, blocks]))
        pad = 0.12 * max(top - bottom, 1e-300)
        force_rows[0].set_ylim(bottom - pad, top + pad)
        force_rows[0].yaxis.set_major_locator(FixedLocator(sorted({bottom, 0.0, top})))
        force_rows[0].yaxis.set_major_formatter(FuncFormatter(lambda v, _: format_number(v)))
        first = force_rows[0]
        first.legend(
            handles=[Line2D([], [], color=REFERENCE, linestyle=":", linewidth=1.0)],
            labels=["$\\mu_j^+$, $-\\mu_j^-$"],
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            borderaxespad=0,
            title=shown_title(blocks, N, "blocks"),
        )
        middle = force_rows[(nb - 1) // 2]
        middle.text(
            1.02,
            0.5 if nb % 2 else 0.0,
            label("elastic force on\neach block", "f_j", "force", units),
            transform=middle.transAxes,
            rotation=0,
            ha="left",
            va="center",
        )
        force_rows[-1].set_xlim(s[0], s[-1])
        force_rows[-1].set_xlabel(time_label)
        fig.suptitle(title(run_name(results), "gait diagram over the limit period"))
        fig.align_ylabels(axs[:3, 0])
    return fig
