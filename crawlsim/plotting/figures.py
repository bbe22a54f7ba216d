"""One function per figure: each takes the dict of `crawlsim.io.hdf5.read_results` and returns a
matplotlib `Figure` in the style of `crawlsim.plotting.style`.

A figure that needs data the file lacks raises `ResultsFileError` naming the missing dataset
(the command line turns it into exit code 2).

Quantities and their equations (docs/model.md):

* motion: block positions x_j(t), barycentre y = mean(x), and y(t0) + v0 (t - t0) (§4);
* gait diagram: slip state of each block on each step of the limit period (``/limit/slip``), the
  actuator lengths L_i(t) against the link lengths z_i = x_{i+1} - x_i, the link stresses
  sigma_i = k_i (L_i - z_i) against their friction bounds, and the elastic force on each block
  f = D^T sigma (f_j = sigma_{j-1} - sigma_j) against its friction limits [-mu_j^-, mu_j^+] (§1);
* convergence: Poincare step and W^{1,2} distance to the last period, and the displacement of
  each period q (§4);
* shape space: the moving polyhedron K(t) = {w : B w <= c(t)} and the orbit of w(t) (§2, §5);
* sweeps: v0 over one or two swept gait parameters.

Times are drawn as t/T (in periods) unless the file gives a time unit, and every label comes
from `crawlsim.plotting.style.label`, with the file's units when it has them.
"""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap, to_rgba
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon, Rectangle
from matplotlib.ticker import (
    FixedLocator,
    FuncFormatter,
    MaxNLocator,
    NullFormatter,
    NullLocator,
)
from scipy.optimize import linprog
from scipy.spatial import HalfspaceIntersection

from crawlsim.errors import ResultsFileError
from crawlsim.plotting.style import (
    FAINT,
    REFERENCE,
    SLIP_COLOURS,
    SLIP_NAMES,
    STATUS_MARKERS,
    Units,
    colour_map,
    colours,
    figure_style,
    label,
    new_figure,
    path_label,
    time_axis,
    title,
    units_of,
    velocity_axis,
)

#: How many distinct sets K(t) the shape-space figure aims to draw over the limit period.
SHAPE_SPACE_TIMES = 6
#: Divisions of the period tried for the shape-space instants, most preferred first: the
#: instants are the grid times j T / n, so their labels are exact fractions.
NICE_DIVISIONS = (6, 8, 10, 12, 5, 4, 3, 2)
#: A swept axis with more values than this gets a tick label on every k-th value only.
MAX_TICK_LABELS = 9
#: A sweep interval is a jump of v0 when its change is more than this many times what the
#: neighbouring slopes predict, and more than this fraction of the range of v0 (`jumps`).
JUMP_RATIO = 2.5
JUMP_FLOOR = 0.1
#: The line panels of the gait diagram draw at most this many links (blocks), evenly spaced,
#: first and last included: beyond it lines are no longer told apart, and a thousand-block
#: crawler would cost minutes and a gigabyte to draw (`shown_series`).
MAX_SERIES = 8
#: The motion figure draws at most this many blocks (evenly spaced, first and last included).
MAX_MOTION_BLOCKS = 32
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


def _need(results: dict, figure: str, *paths: str) -> None:
    """Raise `ResultsFileError` naming the first dataset in ``paths`` the results lack."""
    for path in paths:
        group, name = path.split("/")
        if name not in (results.get(group) or {}):
            hint = ""
            if group in ("trajectory", "limit") and name in ("x", "stress", "shape", "slip"):
                hint = " (only crawler runs have it)"
            elif path in ("limit/lengths", "limit/friction", "limit/offsets", "process/normals"):
                hint = " (files written before crawlsim stored it lack it; rerun `crawlsim run`)"
            raise ResultsFileError(f"the {figure} figure needs /{path}, which is missing{hint}")


def _name(results: dict) -> str:
    return str(results["attrs"].get("name", "crawlsim run"))


def _period(results: dict) -> float:
    return float(results["attrs"]["period"])


def _crawler(results: dict) -> bool:
    return results["attrs"].get("kind", "crawler") == "crawler"


def _legend_right(ax, **kwargs):
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0, **kwargs)


def _number(value: float) -> str:
    """A value for a legend or a tick: four significant digits, no trailing zeros."""
    return f"{value:.4g}"


def shown_series(count: int, limit: int) -> np.ndarray:
    """The 0-based indices of the series drawn out of ``count``: all of them up to ``limit``,
    else ``limit`` evenly spaced ones, the first and the last included."""
    if count <= limit:
        return np.arange(count)
    return np.unique(np.round(np.linspace(0, count - 1, limit)).astype(int))


def _shown_title(shown: np.ndarray, count: int, what: str) -> str | None:
    """The legend title of a thinned panel ("8 of 999 links"), None when all are drawn."""
    return None if len(shown) == count else f"{len(shown)} of {count} {what}"


# --------------------------------------------------------------------------------------------
# 1. Motion


def motion_figure(results: dict) -> Figure:
    """Block positions x_j(t) over the simulated time, the barycentre y(t) and the line of slope
    v0 through y at the start of the limit period, y(t0) + v0 (t - t0), with the limit period
    shaded (after the trajectory when the periodic-limit solver found it). Line order: blocks
    1..N, barycentre, v0 line. Times are t/T, or t in the file's time unit
    (`style.time_axis`); positions are the file's. Beyond `MAX_MOTION_BLOCKS` blocks, that
    many evenly spaced blocks are drawn (`shown_series`), which the legend title says."""
    _need(results, "motion", "trajectory/t", "trajectory/x")
    units = units_of(results)
    t = np.asarray(results["trajectory"]["t"], dtype=float)
    x = np.asarray(results["trajectory"]["x"], dtype=float)
    v0 = float(results["attrs"]["v0"])
    t0 = float(results["limit_attrs"].get("start", t[0]))
    T = _period(results)
    factor, time_label = time_axis(units, T)
    N = x.shape[1]
    y = x.mean(axis=1)
    per_period, _ = velocity_axis(units)
    if per_period:
        speed = (f"$v_0T$ = {_number(v0 * T)} {units.length}" if units.length
                 else f"$v_0T/\\ell$ = {_number(v0 * T)}")
    else:
        length = units.length or r"$\ell$"
        speed = f"$v_0$ = {_number(v0)} {length}/{units.time}"
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        drawn = shown_series(N, MAX_MOTION_BLOCKS)
        for j, colour in zip(drawn, colours(len(drawn))):
            shown = N <= 8 or j in (0, N - 1)
            ax.plot(t * factor, x[:, j], color=colour, label=f"block {j + 1}" if shown else None)
        ax.plot(t * factor, y, color=REFERENCE, linestyle="--", linewidth=1.2,
                label="barycentre $y$", zorder=3)
        # The v0 line meets the barycentre at every period start of the limit, so a thin line
        # would hide under it: it is a wide translucent band beneath the blocks instead. A limit
        # found by the solver is the period after the history (`analysis.following`).
        ends = np.array([t[0], max(t[-1], t0 + T)])
        ax.plot(ends * factor, np.interp(t0, t, y) + v0 * (ends - t0), color=REFERENCE,
                alpha=0.22, linewidth=6.0, solid_capstyle="butt", zorder=1,
                label=f"slope {speed}")
        span = ax.axvspan(t0 * factor, (t0 + T) * factor, color=FAINT, alpha=0.15, linewidth=0,
                          label="limit period")
        ax.set_xlim(ends[0] * factor, ends[1] * factor)
        if units.time is None and (ends[1] - ends[0]) / T <= 12:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(time_label)
        ax.set_ylabel(label("position", "x_j", "length", units))
        ax.set_title(title(_name(results), "block positions"))
        # The legend lists the lines from top to bottom as they end at the right of the axes
        # (the front block first), then the shaded limit period.
        lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
        lines.sort(key=lambda line: -float(np.asarray(line.get_ydata())[-1]))
        _legend_right(ax, handles=[*lines, span], title=_shown_title(drawn, N, "blocks"))
    return fig


# --------------------------------------------------------------------------------------------
# 2. Gait diagram


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


def stress_bounds(friction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The range of each link stress sigma_i over the admissible set C(t), (G+1, N-1) each.

    With f = D^T sigma we have sigma_i = -(f_1 + ... + f_i) = f_{i+1} + ... + f_N (the forces sum
    to zero), and the f_j range independently over [-mu_j^-, mu_j^+]. So sigma_i ranges exactly
    over

        [ -min(sum_{j<=i} mu_j^+, sum_{j>i} mu_j^-),  min(sum_{j<=i} mu_j^-, sum_{j>i} mu_j^+) ]:

    a link in compression sigma_i > 0 pushes the blocks behind it backward and those ahead
    forward, and it reaches its bound when one of the two groups slips as a whole. These are
    necessary limits for a stress; the exact ones are the block limits of `gait_figure`.
    """
    friction = np.asarray(friction, dtype=float)
    N = friction.shape[1] // 2
    plus, minus = friction[:, :N], friction[:, N:]
    behind_plus, behind_minus = np.cumsum(plus, axis=1)[:, :-1], np.cumsum(minus, axis=1)[:, :-1]
    ahead_plus = plus.sum(axis=1, keepdims=True) - behind_plus
    ahead_minus = minus.sum(axis=1, keepdims=True) - behind_minus
    return -np.minimum(behind_plus, ahead_minus), np.minimum(behind_minus, ahead_plus)


def block_forces(stress: np.ndarray) -> np.ndarray:
    """Net elastic force on each block, f = D^T sigma: f_j = sigma_{j-1} - sigma_j (docs/model.md §1),
    with sigma_0 = sigma_N = 0. Shape (G+1, N)."""
    stress = np.asarray(stress, dtype=float)
    padded = np.pad(stress, ((0, 0), (1, 1)))
    return padded[:, :-1] - padded[:, 1:]


def relative_stress(sigma: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Each link stress over its bound on the side of its sign, sigma_i / high_i where sigma_i >= 0
    and sigma_i / |low_i| where sigma_i < 0 (`stress_bounds`): a number in [-1, 1], +-1 exactly
    where the link's stress is as large as a group of blocks can resist. A bound of 0 (no
    friction on one side) holds a stress of 0, drawn as 0."""
    sigma = np.asarray(sigma, dtype=float)
    bound = np.where(sigma >= 0, high, -np.asarray(low, dtype=float))
    return np.divide(sigma, bound, out=np.zeros_like(sigma), where=bound > 0)


def stress_mode(sigma: np.ndarray, low: np.ndarray, high: np.ndarray) -> str:
    """"relative" when the friction bounds dwarf the stresses (the largest bound more than
    `RELATIVE_STRESS_RATIO` times the largest stress: a long crawler, whose bounds grow with the
    number of blocks behind and ahead of a link, while its stresses do not), else "absolute"."""
    largest = float(np.max(np.abs(sigma), initial=0.0))
    bound = float(max(np.max(np.abs(low), initial=0.0), np.max(np.abs(high), initial=0.0)))
    return "relative" if bound > RELATIVE_STRESS_RATIO * largest else "absolute"


def gait_figure(results: dict, stress: str = "auto") -> Figure:
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
    _need(results, "gait diagram", "limit/t", "limit/slip", "limit/shape", "limit/stress",
          "limit/lengths", "limit/friction")
    units = units_of(results)
    lim = results["limit"]
    t = np.asarray(lim["t"], dtype=float)
    factor, time_label = time_axis(units, _period(results), symbol="t - t_0",
                                   name="time in the limit period")
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
        fig, axs = new_figure(3 + nb, 1, height=1.0 + 0.3 * rows + 3.9 + FORCE_ROW_HEIGHT * nb,
                              sharex=True,
                              gridspec_kw={"height_ratios": [0.2 * rows + 0.1, 1.0, 1.0]
                                           + [FORCE_ROW_HEIGHT / 1.65] * nb})
        bands, lengths, stresses = axs[:3, 0]
        force_rows = list(axs[3:, 0])

        # One cell per block and step, coloured by its slip state: an image (rasterized in
        # vector formats), so its cost is that of G x N pixels, not of G x N patches.
        states = (-1, 0, 1)
        bands.pcolormesh(s, np.arange(N + 1) - 0.5, slip.T.astype(float),
                         cmap=ListedColormap([SLIP_COLOURS[k] for k in states]),
                         norm=BoundaryNorm([-1.5, -0.5, 0.5, 1.5], len(states)), shading="flat",
                         rasterized=True)
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
        bands.legend(handles=[Patch(facecolor=SLIP_COLOURS[s_], edgecolor="none",
                                    label=SLIP_NAMES[s_]) for s_ in (0, 1, -1)],
                     loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3, borderaxespad=0.2)

        links_title = _shown_title(links, N - 1, "links")
        for i, colour in zip(links, link_colours):
            lengths.plot(s, L[:, i], color=colour, label=f"$L_{{{i + 1}}}$ actuator")
        for i, colour in zip(links, link_colours):
            lengths.plot(s, z[:, i], color=colour, linestyle="--",
                         label=f"$z_{{{i + 1}}}$ link")
        lengths.set_ylabel(label("length", "L_i, z_i", "length", units))
        _legend_right(lengths, ncol=2, title=links_title)

        if stress == "relative":
            ratio = relative_stress(sigma, low, high)
            for i, colour in zip(links, link_colours):
                stresses.plot(s, ratio[:, i], color=colour, label=f"$\\sigma_{{{i + 1}}}$")
            bound_lines = [stresses.axhline(v, color=REFERENCE, linestyle=":", linewidth=1.0)
                           for v in (1.0, -1.0)]
            handles, names = stresses.get_legend_handles_labels()
            handles.append(bound_lines[0])
            names.append("friction bounds")
            stresses.set_ylim(-1.1, 1.1)
            stresses.set_ylabel("stress over its bound\n$\\sigma_i/\\bar\\sigma_i$")
        else:
            bound_handles = []
            for i, colour in zip(links, link_colours):
                stresses.plot(s, sigma[:, i], color=colour, label=f"$\\sigma_{{{i + 1}}}$")
                bound_handles += stresses.plot(s, high[:, i], color=colour, linestyle=":",
                                               linewidth=1.0)
                stresses.plot(s, low[:, i], color=colour, linestyle=":", linewidth=1.0)
            handles, names = stresses.get_legend_handles_labels()
            # One entry for the bounds, drawn in the colours of the links they bound.
            handles.append(tuple(Line2D([], [], color=h.get_color(), linestyle=":",
                                        linewidth=1.0) for h in bound_handles))
            names.append("friction bounds")
            stresses.set_ylabel(label("stress", "\\sigma_i", "force", units))
        stresses.axhline(0.0, color=REFERENCE, linewidth=0.6)
        _legend_right(stresses, handles=handles, labels=names, title=links_title,
                      handlelength=3.2, handler_map={tuple: HandlerTuple(ndivide=None, pad=0.0)})

        f = block_forces(sigma)
        plus, minus = friction[:, :N], friction[:, N:]
        for ax in force_rows[1:]:
            ax.sharey(force_rows[0])
        for ax, j, colour in zip(force_rows, blocks, block_colours):
            for state, start, stop in slip_runs(slip[:, j], s):
                if state != 0:
                    ax.axvspan(start, stop, color=SLIP_COLOURS[state], alpha=0.35,
                               linewidth=0)
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
        force_rows[0].yaxis.set_major_formatter(FuncFormatter(lambda v, _: _number(v)))
        first = force_rows[0]
        first.legend(handles=[Line2D([], [], color=REFERENCE, linestyle=":", linewidth=1.0)],
                     labels=["$\\mu_j^+$, $-\\mu_j^-$"], loc="upper left",
                     bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
                     title=_shown_title(blocks, N, "blocks"))
        middle = force_rows[(nb - 1) // 2]
        middle.text(1.02, 0.5 if nb % 2 else 0.0,
                    label("elastic force on\neach block", "f_j", "force", units),
                    transform=middle.transAxes, rotation=0, ha="left", va="center")
        force_rows[-1].set_xlim(s[0], s[-1])
        force_rows[-1].set_xlabel(time_label)
        fig.suptitle(title(_name(results), "gait diagram over the limit period"))
        fig.align_ylabels(axs[:3, 0])
    return fig


# --------------------------------------------------------------------------------------------
# 3. Convergence


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
    """"linear" for a finite-time run (its distances drop to exactly 0, which a linear axis
    shows as 0), "log" otherwise (a geometric decay is a straight line there)."""
    positive = [v[v > 0] for v in convergence_series(results).values()]
    finite = results["attrs"].get("convergence", "") == "finite-time"
    return "linear" if finite or not any(p.size for p in positive) else "log"


def convergence_figure(results: dict) -> Figure:
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
    _need(results, "convergence", "convergence/period", "convergence/poincare_step",
          "convergence/w12_distance")
    units = units_of(results)
    conv, attrs = results["convergence"], results["attrs"]
    q = np.asarray(conv["period"], dtype=float)
    series = convergence_series(results)
    scale = convergence_scale(results)
    crawler = _crawler(results)
    v0 = attrs.get("v0", np.nan)
    T = _period(results)
    motion = crawler and v0 is not None and np.isfinite(v0) and "displacement" in conv
    verdict = str(attrs.get("convergence", ""))
    periodic_from = attrs.get("periodic_from", -1)
    finite = verdict == "finite-time" and periodic_from is not None and periodic_from >= 0
    with figure_style():
        if motion:
            fig, axs = new_figure(2, 1, height=4.8, sharex=True,
                                  gridspec_kw={"height_ratios": [1.25, 1.0]})
        else:
            fig, axs = new_figure(height=3.4)
        state = axs[0, 0]
        state.set_yscale(scale)
        for (name, value), colour, marker in zip(series.items(), colours(2), ["o", "s"]):
            shown = value if scale == "linear" else np.where(value > 0, value, np.nan)
            state.plot(q, shown, color=colour, marker=marker, markersize=5, linewidth=1.0,
                       label=name, clip_on=False)
        rate = attrs.get("contraction_rate", np.nan)
        poincare = next(iter(series.values()))
        if finite:
            for ax in axs[:, 0]:
                ax.axvline(periodic_from, color=REFERENCE, linestyle="--", linewidth=1.0,
                           label=f"periodic from period {periodic_from}" if ax is state
                           else None)
            right = periodic_from >= q[-1] - 0.5 * (q[-1] - q[0])
            state.text(periodic_from, 0.97, f" periodic from period {periodic_from} "
                       if right else f" periodic from period {periodic_from}",
                       transform=state.get_xaxis_transform(), ha="right" if right else "left",
                       va="top", color=REFERENCE)
            state.set_ylim(bottom=0.0)
        elif (scale == "log" and rate is not None and np.isfinite(rate)
              and np.any(poincare > 0)):
            last = np.flatnonzero(poincare > 0)[-1]
            state.plot(q, poincare[last] * rate ** (q - q[last]), color=REFERENCE,
                       linestyle="--", linewidth=1.0,
                       label=f"fitted rate {rate:.3g}\nper period")
        if verdict == "not-converged":
            state.text(0.98, 0.95, "not converged", transform=state.transAxes, ha="right",
                       va="top", color=REFERENCE)
        if scale == "log":
            state.yaxis.set_minor_formatter(NullFormatter())
        state.set_ylabel(label("distance", "\\Delta w" if crawler else "\\Delta z",
                               "force" if crawler else None, units))
        # Two lines, so that a long name keeps the title within the axes.
        state.set_title(f"{title(_name(results), 'convergence to the limit period')}\n"
                        f"({verdict})")
        _legend_right(state)

        if motion:
            ax = axs[1, 0]
            displacement = np.asarray(conv["displacement"], dtype=float)
            per_period, what = velocity_axis(units)
            if per_period:
                value, target, symbol, each = displacement, v0 * T, "v_0T", "d_q"
                what = label("displacement", "d_q", "length", units)
            else:
                value, target, symbol, each = displacement / T, v0, "v_0", "v_q"
                what = label("velocity", "v_q", "velocity", units)
            ax.plot(q, value, color=colours(3)[2], marker="^", markersize=5, linewidth=1.0,
                    label=f"${each}$, period $q$")
            ax.axhline(target, color=REFERENCE, linestyle=":", linewidth=1.2,
                       label=f"${symbol}$ = {_number(target)}")
            ax.margins(y=0.15)
            ax.set_ylabel(what)
            _legend_right(ax)
        bottom = axs[-1, 0]
        bottom.xaxis.set_major_locator(MaxNLocator(integer=True))
        if len(q) <= 3:
            bottom.set_xlim(q[0] - 0.5, q[-1] + 0.5)
        bottom.set_xlabel(label("period index", "q"))
        fig.align_ylabels(axs[:, 0])
    return fig


# --------------------------------------------------------------------------------------------
# 4. Shape space


def polygon(normals: np.ndarray, offsets: np.ndarray, box=None) -> np.ndarray:
    """Vertices, counter-clockwise, of the 2-D polygon {p : A p <= b}; ``box`` = (lo, hi) corners
    of a bounding box added to keep an unbounded region finite.

    scipy's `HalfspaceIntersection` (Qhull) needs a strictly interior point: the Chebyshev centre,
    the centre of the largest inscribed disc, from a small linear program (scipy `linprog`).
    """
    A = np.asarray(normals, dtype=float)
    b = np.asarray(offsets, dtype=float)
    norms = np.linalg.norm(A, axis=1)
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    A, b, norms = A[keep], b[keep], norms[keep]
    if box is not None:
        lo, hi = np.asarray(box[0], float), np.asarray(box[1], float)
        A = np.vstack([A, np.eye(2), -np.eye(2)])
        b = np.concatenate([b, hi, -lo])
        norms = np.concatenate([norms, np.ones(4)])
    res = linprog(c=[0.0, 0.0, -1.0], A_ub=np.hstack([A, norms[:, None]]), b_ub=b,
                  bounds=[(None, None), (None, None), (0, None)], method="highs")
    if res.status != 0 or res.x[2] <= 1e-12 * max(np.abs(b).max(), 1.0):
        raise ValueError("the polygon has an empty interior" if res.status == 0 else
                         "the polygon is unbounded or empty; give a bounding box")
    hs = HalfspaceIntersection(np.hstack([A, -b[:, None]]), res.x[:2])
    vertices = hs.intersections
    centre = vertices.mean(axis=0)
    order = np.argsort(np.arctan2(vertices[:, 1] - centre[1], vertices[:, 0] - centre[0]))
    vertices = vertices[order]
    distinct = np.concatenate([[True], np.linalg.norm(np.diff(vertices, axis=0), axis=1) >
                               1e-12 * max(np.abs(vertices).max(), 1.0)])
    return vertices[distinct]


def section(normals: np.ndarray, offsets: np.ndarray, point: np.ndarray, coords):
    """The slice of {w : B w <= c} through ``point`` in the plane of coordinates ``coords``:
    the 2-D halfplanes {(u, v) : B[:, i] u + B[:, j] v <= c - sum_{k != i, j} B[:, k] w_k}."""
    i, j = coords
    others = [k for k in range(normals.shape[1]) if k not in (i, j)]
    return normals[:, [i, j]], offsets - normals[:, others] @ np.asarray(point)[others]


def _fraction_text(value: Fraction) -> str:
    return "0" if value == 0 else str(value)


def shape_space_instants(t: np.ndarray, period: float, keys: Callable[[int], np.ndarray],
                         target: int = SHAPE_SPACE_TIMES) -> list[tuple[list[int], str]]:
    """The instants of the limit period at which the shape-space figure draws its sets.

    Instants are grid times j T / n for a division n of `NICE_DIVISIONS` that the grid holds
    exactly, so their labels are fractions (1/6, not 0.172). Instants whose drawn set is the same
    (``keys(k)``, the offsets of the drawn half-planes, equal to roundoff) are merged into one
    entry, labelled with all their times: a set that slides back and forth (the paper's acute
    angle) is drawn once per position, never twice on top of itself. The division whose number of
    distinct sets is nearest ``target`` without exceeding it wins (ties: the earlier in
    `NICE_DIVISIONS`); more than ``target`` sets only when no division gives fewer. A grid
    holding none of them (a prime steps_per_period, say) falls back to ``target`` grid times
    spread over the period, labelled with their values.

    Returns ``[(grid indices, label), ...]`` in time order.
    """
    t = np.asarray(t, dtype=float)
    G = len(t) - 1
    tol = 1e-9 * period

    def groups(indices, labels):
        out: list[tuple[list[int], list[str], np.ndarray]] = []
        for k, text in zip(indices, labels):
            key = np.asarray(keys(k), dtype=float)
            scale = max(float(np.max(np.abs(key), initial=0.0)), 1.0)
            for members, texts, ref in out:
                if ref.shape == key.shape and np.max(np.abs(ref - key), initial=0.0) <= 1e-9 * scale:
                    members.append(k)
                    texts.append(text)
                    break
            else:
                out.append(([k], [text], key))
        return [(members, ", ".join(texts)) for members, texts, _ in out]

    best = None
    for n in NICE_DIVISIONS:
        wanted = np.arange(n) * period / n
        nearest = np.abs(t[None, :] - wanted[:, None]).argmin(axis=1)
        if np.any(np.abs(t[nearest] - wanted) > tol) or len(set(nearest.tolist())) < n:
            continue
        found = groups(nearest.tolist(), [_fraction_text(Fraction(j, n)) for j in range(n)])
        score = (len(found) > target, abs(len(found) - target))
        if best is None or score < best[0]:
            best = (score, found)
    if best is not None:
        return best[1]
    indices = np.unique(np.round(np.linspace(0, G, target + 1)[:-1]).astype(int))
    return groups(indices.tolist(), [_number(t[k] / period) for k in indices])


def shape_space_figure(results: dict, coords=(0, 1), times: int = SHAPE_SPACE_TIMES) -> Figure:
    """The moving set K(t) = {w : B w <= c(t)} at instants of the limit period
    (`shape_space_instants`: about ``times`` distinct sets, at fractions of the period), and
    the orbit of w(t): the periods before the limit faint, the limit cycle bold (the style of
    the paper's Section 5 figures).

    * n = 2 (three blocks): K(t) is a polygon in the plane, drawn whole.
    * n > 2: the figure is drawn in the plane of the shape coordinates ``coords`` (0-based pair;
      ``crawlsim plot --coords`` takes them 1-based): each polygon is the *section* of K(t)
      through w(t) parallel to that plane, which contains w(t) and shows the constraints active
      in those two directions; the orbit is projected onto the plane. A section without interior
      (w(t) on a vertex or an edge of K(t) extreme in the other coordinates) is drawn as its
      marker alone, its legend entry saying so.
    * n = 1 (two blocks): K(t) is an interval, drawn as a band over the limit period with w(t)
      inside it, and the earlier periods folded onto it.

    For crawlers w = -K z (stiffness times shortening of the links), so K(t) is the set of
    admissible stresses C(t) shifted by K L(t) (docs/model.md §2); w has the unit of a force.
    A generic process is drawn in the paper's notation, C(t) and z. Artists: one polygon patch
    (in the legend, with its times) and one marker of w(t_k) per instant; lines for the earlier
    periods (when they have any extent), the limit cycle (a marker when the limit is a constant
    state) and the start w(0).
    """
    _need(results, "shape space", "trajectory/t", "trajectory/w", "limit/t", "limit/w",
          "limit/offsets", "process/normals")
    units = units_of(results)
    B = np.asarray(results["process"]["normals"], dtype=float)
    lim = results["limit"]
    c = np.asarray(lim["offsets"], dtype=float)
    wl = np.asarray(lim["w"], dtype=float)
    tl = np.asarray(lim["t"], dtype=float)
    tt = np.asarray(results["trajectory"]["t"], dtype=float)
    wt = np.asarray(results["trajectory"]["w"], dtype=float)
    T = _period(results)
    t0 = float(results["limit_attrs"].get("start", tt[-1] - T))
    n = wl.shape[1]
    crawler = _crawler(results)
    if n == 1:
        return _shape_space_line(results, B, c, tl, wl, tt, wt, t0, crawler, units)
    coords = tuple(int(k) for k in coords)
    if len(coords) != 2 or coords[0] == coords[1] or not all(0 <= k < n for k in coords):
        raise ValueError(f"shape coordinates {[k + 1 for k in coords]}: need two different "
                         f"coordinates between 1 and {n}")
    i, j = coords

    def drawn(k):
        return section(B, c[k], wl[k], coords) if n > 2 else (B, c[k])

    instants = shape_space_instants(tl, T, lambda k: drawn(k)[1], times)
    span = max(float(np.ptp(np.vstack([wt[:, [i, j]], wl[:, [i, j]]]), axis=0).max()), 1e-300)
    box = None
    if not crawler:
        middle = wl[:, [i, j]].mean(axis=0)
        half = 5 * max(span, 1.0)
        box = (middle - half, middle + half)
    earlier = tt <= t0 + 1e-12 * max(abs(t0), 1.0)
    state, where = ("w", "K(t)") if crawler else ("z", "C(t)")
    with figure_style():
        fig, axs = new_figure(height=4.6)
        ax = axs[0, 0]
        handles = []
        for (members, text), colour in zip(instants, colours(len(instants))):
            A, b = drawn(members[0])
            try:
                vertices = polygon(A, b, box)
            except ValueError:
                if n == 2:
                    raise
                # w(t) on a face of K(t) that is extreme in the other coordinates (a vertex or
                # an edge, common for long crawlers with many blocks at their friction limits):
                # the section through it is a segment or a point, with no polygon to draw.
                handles += ax.plot([], [], marker="o", markersize=5.5, color=colour,
                                   linestyle="none", label=f"{text} (section without interior)")
            else:
                patch = Polygon(vertices, closed=True, linewidth=1.3,
                                facecolor=to_rgba(colour, 0.07), edgecolor=colour, label=text)
                ax.add_patch(patch)
                handles.append(patch)
            for k in members:
                ax.plot(wl[k, i], wl[k, j], marker="o", markersize=5.5, color=colour,
                        markeredgecolor="white", markeredgewidth=0.6, linestyle="none",
                        zorder=4)
        if np.count_nonzero(earlier) > 1 and np.ptp(wt[earlier][:, [i, j]], axis=0).max() > 0:
            handles += ax.plot(wt[earlier, i], wt[earlier, j], color=FAINT, linewidth=0.8,
                               alpha=0.9, label="earlier periods")
        if np.ptp(wl[:, [i, j]], axis=0).max() <= 1e-9 * span:
            handles += ax.plot(wl[0, i], wl[0, j], marker="o", markersize=8, color=REFERENCE,
                               markerfacecolor="none", markeredgewidth=1.6, linestyle="none",
                               label="limit (a constant state)")
        else:
            handles += ax.plot(wl[:, i], wl[:, j], color=REFERENCE, linewidth=2.2,
                               label="limit cycle")
        handles += ax.plot(wt[0, i], wt[0, j], marker="x", markersize=7, color=REFERENCE,
                           linestyle="none", label=f"start ${state}(0)$")
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        dimension = "force" if crawler else None
        ax.set_xlabel(label("shape coordinate", f"{state}_{{{i + 1}}}", dimension, units))
        ax.set_ylabel(label("shape coordinate", f"{state}_{{{j + 1}}}", dimension, units))
        # The title in short lines, so that it stays within the axes (square, by the equal
        # aspect) however long the gait's name: name, what is drawn, and where.
        if n == 2:
            what = f"${where}$ and the orbit of ${state}(t)$" + (", $w = -Kz$" if crawler else "")
        else:
            what = (f"sections of ${where}$ through ${state}(t)$\ncoordinates ({i + 1}, {j + 1}) "
                    f"of {n}" + (", $w = -Kz$" if crawler else ""))
        ax.set_title(f"{title(_name(results), 'shape space')}\n{what}")
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                  borderaxespad=0, title=f"${where}$ at $(t - t_0)/T$ =")
    return fig


def interval(normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K(t) = {w in R : b_r w <= c_r} as [low(t), high(t)] for a one-dimensional process."""
    b = np.asarray(normals, dtype=float)[:, 0]
    c = np.asarray(offsets, dtype=float)
    with np.errstate(divide="ignore"):
        high = np.min(np.where(b > 0, c / np.where(b > 0, b, 1), np.inf), axis=-1)
        low = np.max(np.where(b < 0, c / np.where(b < 0, b, 1), -np.inf), axis=-1)
    return low, high



def _shape_space_line(results, B, c, tl, wl, tt, wt, t0, crawler, units):
    low, high = interval(B, c)
    T = _period(results)
    factor, time_label = time_axis(units, T, symbol="t - t_0", name="time in the limit period")
    earlier = tt <= t0 + 1e-12 * max(abs(t0), 1.0)
    state, where = ("w", "K(t)") if crawler else ("z", "C(t)")
    band = colours(1)[0]
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        ax.fill_between(tl * factor, low, high, color=band, alpha=0.15, linewidth=0,
                        label=f"${where}$")
        ax.plot(tl * factor, high, color=band, linewidth=1.0)
        ax.plot(tl * factor, low, color=band, linewidth=1.0)
        if np.count_nonzero(earlier) > 1:
            phase = tt[earlier] - np.floor((tt[earlier] - tt[0]) / T + 1e-9) * T - tt[0]
            folded = np.where(np.diff(phase, prepend=phase[0]) < 0, np.nan, wt[earlier, 0])
            ax.plot(phase * factor, folded, color=FAINT, linewidth=0.8, label="earlier periods")
        ax.plot(tl * factor, wl[:, 0], color=REFERENCE, linewidth=2.2, label="limit cycle")
        ax.set_xlim(tl[0] * factor, tl[-1] * factor)
        ax.set_xlabel(time_label)
        ax.set_ylabel(label("shape coordinate", f"{state}_1", "force" if crawler else None,
                            units))
        what = f"the interval ${where}$ and ${state}(t)$" + (", $w = -kz$" if crawler else "")
        ax.set_title(f"{title(_name(results), 'shape space')}\n{what}")
        _legend_right(ax)
    return fig


# --------------------------------------------------------------------------------------------
# 5. Sweeps


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
    axis.set_ticklabels([_number(v) for v in major])
    axis.set_minor_formatter(NullFormatter())


def _status_grid(status, shape) -> np.ndarray:
    """Status strings on the grid: a bool array means True = failed, False = ok."""
    status = np.asarray(status)
    if status.dtype == bool:
        status = np.where(status, "failed", "ok")
    return np.asarray(status, dtype=object).reshape(shape).astype(str)


def sweep_figure(axes: dict, v0, status, title: str, *, units: Units | None = None,
                 displacement=None, marks=None) -> Figure:
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
    `crawlsim.analysis.stall.CurveMarks`, sweeps of one load) break the line at the loads where v0 jumps
    (dotted verticals) instead of joining across them, and mark the stall load.
    """
    units = units or Units()
    names = list(axes)
    values = [np.asarray(axes[k], dtype=float) for k in names]
    grid = tuple(len(v) for v in values)
    if len(names) not in (1, 2):
        raise ValueError(f"sweep_figure draws one or two swept parameters, got {len(names)}: "
                         f"{', '.join(names)}")
    v0 = np.asarray(v0, dtype=float)
    statuses = np.asarray(status)
    if v0.shape != grid or statuses.shape != grid:
        raise ValueError(f"v0 {v0.shape} and status {statuses.shape} must have the grid's shape "
                         f"{grid}")
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
        style: dict[str, object] = dict(linestyle="none", marker=marker, color=REFERENCE,
                                        label=name)
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
    before = np.concatenate([np.full(finite.shape[:-1] + (1,), -np.inf), finite[..., :-1]],
                            axis=-1)
    after = np.concatenate([finite[..., 1:], np.full(finite.shape[:-1] + (1,), -np.inf)],
                           axis=-1)
    # Both neighbours are needed: at an end of the axis a saturating curve changes more over its
    # first interval than over the next, by any ratio, without a jump.
    local = np.where(np.isfinite(before) & np.isfinite(after), np.maximum(before, after), np.nan)
    scale = np.nanmax(np.abs(d)) if np.any(np.isfinite(d)) else 0.0
    span = (np.nanmax(d) - np.nanmin(d)) if np.any(np.isfinite(d)) else 0.0
    with np.errstate(invalid="ignore"):
        out = (np.isfinite(change) & np.isfinite(local)
               & (np.abs(change) > JUMP_RATIO * local * h)
               & (np.abs(change) > JUMP_FLOOR * max(span, 1e-12 * scale)))
    return out


def _break_at_jumps(x, data, jump):
    """x and data with a NaN inserted inside every jump interval, so the line breaks there."""
    cut = np.flatnonzero(jump) + 1
    return np.insert(x.astype(float), cut, np.nan), np.insert(data, cut, np.nan)


def _sweep_line(ax, x, data, statuses, log, marks=None):
    """v0 over one swept value, broken at its jumps. ``marks`` (`crawlsim.analysis.stall.curve_marks`, for a
    swept load) gives the jumps where the uniqueness condition fails, located exactly, and the
    stall; without them the jumps are found from the samples (`jumps`)."""
    if marks is not None and marks.jumps:
        jump = np.array([any(min(a, b) <= s <= max(a, b) for s in marks.jumps)
                         for a, b in zip(x[:-1], x[1:])], dtype=bool)
    else:
        jump = jumps(x, data, log)
    xs, ys = _break_at_jumps(x, data, jump)
    ax.plot(xs, ys, color=colours(1)[0], marker="o", markersize=4.5, label="$v_0$")
    if marks is not None and marks.stall is not None:
        ax.axvline(marks.stall, color=REFERENCE, linestyle="--", linewidth=1.2,
                   label=f"{marks.label} {marks.stall:.6g} ({marks.cause})")
    if marks is not None and marks.jumps:
        for k, s in enumerate(marks.jumps):
            ax.axvline(s, color=FAINT, linestyle=":", linewidth=1.0,
                       label="jump of $v_0$" if k == 0 else None)
    sampled = np.flatnonzero(jump) if marks is None or not marks.jumps else []
    for k in sampled:
        # The jump itself: a faint vertical at the middle of the interval, between the two
        # values, where no value of v0 was sampled.
        middle = np.sqrt(x[k] * x[k + 1]) if log else (x[k] + x[k + 1]) / 2
        ax.plot([middle, middle], [data[k], data[k + 1]], color=FAINT, linestyle=":",
                linewidth=1.0, label="jump of $v_0$" if k == sampled[0] else None)
    if log:
        ax.set_xscale("log")
    ax.axhline(0.0, color=REFERENCE, linewidth=0.6)
    handles = _status_handles(
        ax, statuses,
        lambda mask: (x[mask], data[mask], {}) if np.all(np.isfinite(data[mask])) else
        (x[mask], np.zeros(np.count_nonzero(mask)),
         {"transform": ax.get_xaxis_transform(), "clip_on": False}))
    _set_swept_ticks(ax.xaxis, x, log)
    pad = 0.04 * (np.log(x[-1] / x[0]) if log else x[-1] - x[0]) if x.size > 1 else 0.5
    if log:
        ax.set_xlim(x[0] * np.exp(-pad), x[-1] * np.exp(pad))
    else:
        ax.set_xlim(x[0] - pad, x[-1] + pad)
    if handles or (marks is not None and (marks.jumps or marks.stall is not None)):
        ax.legend(loc="best")


def _sweep_map(fig, ax, values, data, statuses, logs, value_label):
    x, y = values
    cmap = colour_map().with_extremes(bad="white")
    mesh = ax.pcolormesh(cell_edges(x, logs[0]), cell_edges(y, logs[1]), data.T, cmap=cmap,
                         shading="flat")
    bar = fig.colorbar(mesh, ax=ax)
    bar.set_label(value_label)
    if logs[0]:
        ax.set_xscale("log")
    if logs[1]:
        ax.set_yscale("log")
    handles = []
    empty = ~np.isfinite(data)
    if np.any(empty):
        xe, ye = cell_edges(x, logs[0]), cell_edges(y, logs[1])
        for a, b in zip(*np.nonzero(empty)):
            ax.add_patch(Rectangle((xe[a], ye[b]), xe[a + 1] - xe[a], ye[b + 1] - ye[b],
                                   facecolor="white", edgecolor=FAINT, hatch="////",
                                   linewidth=0.0, label="_no value"))
        handles.append(Patch(facecolor="white", edgecolor=FAINT, hatch="////",
                             label="no value"))
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
        ax.add_collection(LineCollection(walls, colors=REFERENCE, linewidths=2.4,
                                         linestyles="solid"))
        handles.append(Line2D([], [], color=REFERENCE, linewidth=2.4, label="jump of $v_0$"))
    handles += _status_handles(ax, statuses, lambda mask: (
        x[np.nonzero(mask)[0]], y[np.nonzero(mask)[1]], {}))
    _set_swept_ticks(ax.xaxis, x, logs[0])
    _set_swept_ticks(ax.yaxis, y, logs[1])
    ax.grid(False)
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.16),
                  ncol=min(len(handles), 3), borderaxespad=0)


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
    walls = [np.array([[xe[a + 1], ye[b]], [xe[a + 1], ye[b + 1]]])
             for a, b in zip(*np.nonzero(jump_x))]
    walls += [np.array([[xe[a], ye[b + 1]], [xe[a + 1], ye[b + 1]]])
              for a, b in zip(*np.nonzero(jump_y))]
    return walls


def sweep_data_figure(data: dict, title: str | None = None) -> Figure:
    """The sweep figure of a sweep file (`crawlsim.io.hdf5.read_sweep`) or of a table
    (`crawlsim.study.sweep.table_payload`): the columns are put back on the grid (points a shard did
    not hold have no value and no status), the units come from the file (`style.units_of`)."""
    paths = list(data["paths"])
    shape = tuple(len(a) for a in data["axes"])
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
        from crawlsim.analysis.stall import curve_marks

        marks = curve_marks(data["gait_yaml"], paths[0], data["axes"][0], v0)
    return sweep_figure(dict(zip(paths, data["axes"])), v0, status, title,
                        units=units_of(data), displacement=displacement, marks=marks)


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


#: The figures of one run, by the names of `crawlsim.plotting.FIGURE_NAMES`.
FIGURES: dict[str, Callable[..., Figure]] = {
    "motion": motion_figure,
    "gait-diagram": gait_figure,
    "convergence": convergence_figure,
    "shape-space": shape_space_figure,
}
