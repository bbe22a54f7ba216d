"""One function per figure: each takes the dict of `crawlsim.h5io.read_results` and returns a
matplotlib `Figure` in the style of `crawlsim.plotting.style`.

A figure that needs data the file lacks raises `ResultsFileError` naming the missing dataset
(the command line turns it into exit code 2).

Quantities and their equations (MODEL.md):

* motion: block positions x_j(t), barycentre y = mean(x), and y(t0) + v0 (t - t0);
* gait diagram: slip state of each block on each step of the limit period (``/limit/slip``), the
  actuator lengths L_i(t) against the link lengths z_i = x_{i+1} - x_i, the link stresses
  sigma_i = k_i (L_i - z_i) against their friction bounds, and the elastic force on each block
  f = D^T sigma (f_j = sigma_{j-1} - sigma_j) against its friction limits [-mu_j^-, mu_j^+];
* convergence: Poincare step, W^{1,2} distance to the limit period and |v_q - v0| per period q;
* shape space: the moving polyhedron K(t) = {w : B w <= c(t)} and the orbit of w(t).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from matplotlib.colors import CenteredNorm, to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon
from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullLocator
from scipy.optimize import linprog
from scipy.spatial import HalfspaceIntersection

from ..errors import ResultsFileError
from .style import (
    FAINT,
    REFERENCE,
    SLIP_COLOURS,
    SLIP_NAMES,
    colours,
    figure_style,
    label,
    new_figure,
    title,
)

#: How many instants of the limit period the shape-space figure draws K(t) at.
SHAPE_SPACE_TIMES = 6


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


# --------------------------------------------------------------------------------------------
# 1. Motion


def motion_figure(results: dict) -> Figure:
    """Block positions x_j(t) over the simulated time, the barycentre y(t) and the line of slope
    v0 through y at the start of the limit period, y(t0) + v0 (t - t0), with the limit period
    shaded. Line order: blocks 1..N, barycentre, v0 line."""
    _need(results, "motion", "trajectory/t", "trajectory/x")
    t = np.asarray(results["trajectory"]["t"], dtype=float)
    x = np.asarray(results["trajectory"]["x"], dtype=float)
    v0 = float(results["attrs"]["v0"])
    t0 = float(results["limit_attrs"].get("start", t[0]))
    T = _period(results)
    N = x.shape[1]
    y = x.mean(axis=1)
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        for j, colour in enumerate(colours(N)):
            shown = N <= 8 or j in (0, N - 1)
            ax.plot(t, x[:, j], color=colour, label=f"block {j + 1}" if shown else None)
        ax.plot(t, y, color=REFERENCE, linestyle="--", linewidth=1.2, label="barycentre $y$")
        ends = np.array([t[0], t[-1]])
        ax.plot(ends, np.interp(t0, t, y) + v0 * (ends - t0), color=REFERENCE, linestyle=":",
                linewidth=1.2, label=f"slope $v_0$ = {v0:.4g}")
        ax.axvspan(t0, t0 + T, color=FAINT, alpha=0.15, linewidth=0, label="limit period")
        ax.set_xlim(t[0], t[-1])
        ax.set_xlabel(label("time", "t"))
        ax.set_ylabel(label("position", "x_j"))
        ax.set_title(title(_name(results), "block positions"))
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
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
    """Net elastic force on each block, f = D^T sigma: f_j = sigma_{j-1} - sigma_j (MODEL.md §1),
    with sigma_0 = sigma_N = 0. Shape (G+1, N)."""
    stress = np.asarray(stress, dtype=float)
    padded = np.pad(stress, ((0, 0), (1, 1)))
    return padded[:, :-1] - padded[:, 1:]


def gait_figure(results: dict) -> Figure:
    """The gait diagram of the limit period, four panels sharing the time axis t - t0:

    1. one band per block: stick, forward slip, backward slip on each step (``/limit/slip``);
    2. actuator lengths L_i(t) (solid) and link lengths z_i(t) = x_{i+1} - x_i (dashed);
    3. link stresses sigma_i(t) (solid) with their friction bounds (dotted, `stress_bounds`);
    4. elastic force on each block f_j(t) = sigma_{j-1} - sigma_j (solid) with the friction
       limits mu_j^+(t) and -mu_j^-(t) (dotted). This is the exact admissibility picture: block j
       sticks while -mu_j^- < f_j < mu_j^+ and slips forward (backward) only on the upper (lower)
       limit, which is where the bands of panel 1 change colour. Blocks sharing the same limits
       get one black pair of dotted lines.
    """
    _need(results, "gait diagram", "limit/t", "limit/slip", "limit/shape", "limit/stress",
          "limit/lengths", "limit/friction")
    lim = results["limit"]
    t = np.asarray(lim["t"], dtype=float)
    slip = np.asarray(lim["slip"])
    L = np.asarray(lim["lengths"], dtype=float)
    z = np.asarray(lim["shape"], dtype=float)
    sigma = np.asarray(lim["stress"], dtype=float)
    friction = np.asarray(lim["friction"], dtype=float)
    N = slip.shape[1]
    block_colours, link_colours = colours(N), colours(N - 1)
    with figure_style():
        fig, axs = new_figure(4, 1, height=1.0 + 0.3 * N + 5.4, sharex=True,
                              gridspec_kw={"height_ratios": [0.2 * N + 0.1, 1.0, 1.0, 1.0]})
        bands, lengths, stresses, forces = axs[:, 0]

        for j in range(N):
            for state, a, b in slip_runs(slip[:, j], t):
                bands.barh(j, b - a, left=a, height=0.72, color=SLIP_COLOURS[state],
                           linewidth=0)
        bands.set_yticks(range(N), [f"block {j + 1}" for j in range(N)])
        bands.set_ylim(-0.6, N - 0.4)
        bands.grid(False)
        bands.tick_params(axis="y", length=0)
        bands.spines["left"].set_visible(False)
        bands.legend(handles=[Patch(color=SLIP_COLOURS[s], label=SLIP_NAMES[s])
                              for s in (0, 1, -1)],
                     loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3, borderaxespad=0.2)

        for i, colour in enumerate(link_colours):
            lengths.plot(t, L[:, i], color=colour, label=f"$L_{{{i + 1}}}$ actuator")
        for i, colour in enumerate(link_colours):
            lengths.plot(t, z[:, i], color=colour, linestyle="--",
                         label=f"$z_{{{i + 1}}}$ link")
        lengths.set_ylabel(label("length"))
        _legend_right(lengths, ncol=2)

        low, high = stress_bounds(friction)
        for i, colour in enumerate(link_colours):
            stresses.plot(t, sigma[:, i], color=colour, label=f"$\\sigma_{{{i + 1}}}$")
            stresses.plot(t, high[:, i], color=colour, linestyle=":", linewidth=1.0)
            stresses.plot(t, low[:, i], color=colour, linestyle=":", linewidth=1.0)
        handles, names = stresses.get_legend_handles_labels()
        handles.append(Line2D([], [], color=FAINT, linestyle=":", linewidth=1.0))
        names.append("friction bounds")
        stresses.axhline(0.0, color=REFERENCE, linewidth=0.6)
        stresses.set_ylabel(label("stress", "\\sigma_i"))
        _legend_right(stresses, handles=handles, labels=names)

        f = block_forces(sigma)
        plus, minus = friction[:, :N], friction[:, N:]
        shared = all(np.array_equal(plus[:, j], plus[:, 0]) and
                     np.array_equal(minus[:, j], minus[:, 0]) for j in range(N))
        for j, colour in enumerate(block_colours):
            forces.plot(t, f[:, j], color=colour, label=f"$f_{{{j + 1}}}$")
        for j, colour in enumerate([REFERENCE] if shared else block_colours):
            forces.plot(t, plus[:, j], color=colour, linestyle=":", linewidth=1.0)
            forces.plot(t, -minus[:, j], color=colour, linestyle=":", linewidth=1.0)
        handles, names = forces.get_legend_handles_labels()
        handles.append(Line2D([], [], color=REFERENCE if shared else FAINT, linestyle=":",
                              linewidth=1.0))
        names.append("$\\mu^+$, $-\\mu^-$")
        forces.set_ylabel(label("force", "f_j"))
        _legend_right(forces, handles=handles, labels=names)

        forces.set_xlim(t[0], t[-1])
        forces.set_xlabel(label("time in the limit period", "t - t_0"))
        fig.suptitle(title(_name(results), "gait diagram over the limit period"))
        fig.align_ylabels(axs[:, 0])
    return fig


def _legend_right(ax, **kwargs):
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0, **kwargs)


# --------------------------------------------------------------------------------------------
# 3. Convergence


def convergence_series(results: dict) -> dict[str, np.ndarray]:
    """The per-period distances drawn on the log axis, keyed by their legend label.

    |v_q - v0| is left out for processes without a velocity (NaN in the file).
    """
    conv = results["convergence"]
    series = {
        "Poincaré step $|w(t_0{+}(q{+}1)T) - w(t_0{+}qT)|$": conv["poincare_step"],
        "$W^{1,2}$ distance to the limit period": conv["w12_distance"],
    }
    v0 = results["attrs"].get("v0", np.nan)
    velocity = np.asarray(conv.get("velocity", []), dtype=float)
    if velocity.size and np.isfinite(v0) and np.all(np.isfinite(velocity)):
        series["$|v_q - v_0|$"] = np.abs(velocity - v0)
    return {k: np.asarray(v, dtype=float) for k, v in series.items()}


def zero_floor(values) -> float:
    """Where exact zeros are drawn on the log axis: a decade below the smallest positive value
    (1e-16 when there is none), rounded down to a power of ten."""
    positive = np.concatenate([np.ravel(v) for v in values])
    positive = positive[np.isfinite(positive) & (positive > 0)]
    if positive.size == 0:
        return 1e-16
    return 10.0 ** (np.floor(np.log10(positive.min())) - 1)


def convergence_figure(results: dict) -> Figure:
    """Per period q, on a log axis: the Poincare step, the W^{1,2}(t0, t0+T) distance of period
    q to the limit period, and |v_q - v0| (MODEL.md §4).

    A log axis cannot show zero, and zeros are the point of finite-time convergence: values that
    are exactly 0 are drawn as open markers on the bottom of the axis, a decade below the smallest
    positive value, whose tick is labelled 0 (`zero_floor`). Finite-time convergence is marked by a
    vertical line at ``periodic_from``;
    asymptotic convergence by the geometric decay ``r^q`` of the fitted contraction rate r
    through the last positive Poincare step.
    """
    _need(results, "convergence", "convergence/period", "convergence/poincare_step",
          "convergence/w12_distance")
    conv, attrs = results["convergence"], results["attrs"]
    q = np.asarray(conv["period"], dtype=float)
    series = convergence_series(results)
    floor = zero_floor(series.values())
    markers = ["o", "s", "^"]
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        ax.set_yscale("log")
        for (name, value), colour, marker in zip(series.items(), colours(len(series)), markers):
            ax.plot(q, np.where(value > 0, value, np.nan), color=colour, marker=marker,
                    markersize=4, label=name)
            zero = value == 0
            if np.any(zero):
                ax.plot(q[zero], np.full(np.count_nonzero(zero), floor), linestyle="none",
                        marker=marker, markersize=6, markerfacecolor="white",
                        markeredgecolor=colour, clip_on=False)
        _zero_floor_axis(ax, floor, series.values())

        verdict = attrs.get("convergence", "")
        periodic_from = attrs.get("periodic_from", -1)
        rate = attrs.get("contraction_rate", np.nan)
        poincare = next(iter(series.values()))
        if verdict == "finite-time" and periodic_from is not None and periodic_from >= 0:
            ax.axvline(periodic_from, color=REFERENCE, linestyle="--", linewidth=1.0,
                       label=f"periodic from period {periodic_from} (finite time)")
        elif rate is not None and np.isfinite(rate) and np.any(poincare > 0):
            last = np.flatnonzero(poincare > 0)[-1]
            ax.plot(q, poincare[last] * rate ** (q - q[last]), color=REFERENCE, linestyle="--",
                    linewidth=1.0, label=f"fitted contraction rate {rate:.3g} per period")
        if verdict == "not-converged":
            ax.text(0.98, 0.95, "not converged", transform=ax.transAxes, ha="right", va="top",
                    color=REFERENCE)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(label("period index", "q"))
        ax.set_ylabel(label("distance"))
        ax.set_title(title(_name(results), f"convergence to the limit period ({verdict})"))
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=2, borderaxespad=0)
    return fig


def _zero_floor_axis(ax, floor: float, values) -> None:
    """Log axis from the zero floor up, one tick per decade (or every few decades), the floor's
    tick labelled 0: the bottom spine is the line on which exact zeros sit."""
    positive = np.concatenate([np.ravel(v) for v in values])
    positive = positive[np.isfinite(positive) & (positive > 0)]
    lo = int(round(np.log10(floor)))
    hi = int(np.ceil(np.log10(positive.max()))) if positive.size else lo + 2
    hi = max(hi, lo + 1)
    step = max(1, int(np.ceil((hi - lo) / 7)))
    hi = lo + step * int(np.ceil((hi - lo) / step))
    ax.set_ylim(10.0 ** lo, 10.0 ** hi)
    ax.yaxis.set_major_locator(FixedLocator((10.0 ** np.arange(lo, hi + 1, step)).tolist()))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(
        lambda y, _: "0" if abs(np.log10(y) - lo) < 1e-6 else f"$10^{{{round(np.log10(y))}}}$"))


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


def shape_space_figure(results: dict, coords=(0, 1), times: int = SHAPE_SPACE_TIMES) -> Figure:
    """The moving set K(t) = {w : B w <= c(t)} at ``times`` equally spaced instants of the limit
    period, and the orbit of w(t): the periods before the limit faint, the limit cycle bold
    (the style of the paper's Section 5 figures).

    * n = 2 (three blocks): K(t) is a polygon in the plane, drawn whole.
    * n > 2: the figure is drawn in the plane of the shape coordinates ``coords`` (0-based pair;
      ``crawlsim plot --coords`` takes them 1-based): each polygon is the *section* of K(t)
      through w(t) parallel to that plane, which contains w(t) and shows the constraints active
      in those two directions; the orbit is projected onto the plane.
    * n = 1 (two blocks): K(t) is an interval, drawn as a band over the limit period with w(t)
      inside it, and the earlier periods folded onto it.

    For crawlers w = -K z (stiffness times shortening of the links), so K(t) is the set of
    admissible stresses C(t) shifted by K L(t) (MODEL.md §2). Artists: one polygon patch and one
    marker of w(t_k) per instant; lines for the earlier periods (when there are any), the limit
    cycle and the start w(0).
    """
    _need(results, "shape space", "trajectory/t", "trajectory/w", "limit/t", "limit/w",
          "limit/offsets", "process/normals")
    B = np.asarray(results["process"]["normals"], dtype=float)
    lim = results["limit"]
    c = np.asarray(lim["offsets"], dtype=float)
    wl = np.asarray(lim["w"], dtype=float)
    tl = np.asarray(lim["t"], dtype=float)
    tt = np.asarray(results["trajectory"]["t"], dtype=float)
    wt = np.asarray(results["trajectory"]["w"], dtype=float)
    t0 = float(results["limit_attrs"].get("start", tt[-1] - _period(results)))
    n = wl.shape[1]
    crawler = results["attrs"].get("kind", "crawler") == "crawler"
    if n == 1:
        return _shape_space_line(results, B, c, tl, wl, tt, wt, t0, crawler)
    coords = tuple(int(k) for k in coords)
    if len(coords) != 2 or coords[0] == coords[1] or not all(0 <= k < n for k in coords):
        raise ValueError(f"shape coordinates {[k + 1 for k in coords]}: need two different "
                         f"coordinates between 1 and {n}")
    i, j = coords
    G = len(tl) - 1
    instants = np.unique(np.round(np.linspace(0, G, times + 1)[:-1]).astype(int))
    span = np.ptp(np.vstack([wt[:, [i, j]], wl[:, [i, j]]]), axis=0).max()
    box = None
    if not crawler:
        middle = wl[:, [i, j]].mean(axis=0)
        half = 5 * max(span, 1.0)
        box = (middle - half, middle + half)
    earlier = tt <= t0 + 1e-12 * max(abs(t0), 1.0)
    with figure_style():
        fig, axs = new_figure(height=4.6)
        ax = axs[0, 0]
        for k, colour in zip(instants, colours(len(instants))):
            A, b = section(B, c[k], wl[k], coords) if n > 2 else (B, c[k])
            ax.add_patch(Polygon(polygon(A, b, box), closed=True, linewidth=1.2,
                                 facecolor=to_rgba(colour, 0.07), edgecolor=colour))
            ax.plot(wl[k, i], wl[k, j], marker="o", markersize=6, color=colour,
                    linestyle="none", label=f"$t - t_0$ = {tl[k]:.3g}")
        if np.count_nonzero(earlier) > 1:
            ax.plot(wt[earlier, i], wt[earlier, j], color=FAINT, linewidth=0.8, alpha=0.8,
                    label="earlier periods")
        ax.plot(wl[:, i], wl[:, j], color=REFERENCE, linewidth=2.2, label="limit cycle")
        ax.plot(wt[0, i], wt[0, j], marker="x", markersize=7, color=REFERENCE,
                linestyle="none", label="start $w(0)$")
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        symbol = "w_{%d} = -k_{%d} z_{%d}" if crawler else "w_{%d}"
        ax.set_xlabel(label("shape coordinate", symbol.replace("%d", str(i + 1))))
        ax.set_ylabel(label("shape coordinate", symbol.replace("%d", str(j + 1))))
        what = "$K(t)$ and the orbit of $w(t)$" if n == 2 else \
            f"sections of $K(t)$ through $w(t)$, coordinates ({i + 1}, {j + 1}) of {n}"
        ax.set_title(title(_name(results), f"shape space: {what}"))
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
                  title="$K(t)$ and $w(t)$ at")
    return fig


def interval(normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K(t) = {w in R : b_r w <= c_r} as [low(t), high(t)] for a one-dimensional process."""
    b = np.asarray(normals, dtype=float)[:, 0]
    c = np.asarray(offsets, dtype=float)
    with np.errstate(divide="ignore"):
        high = np.min(np.where(b > 0, c / np.where(b > 0, b, 1), np.inf), axis=-1)
        low = np.max(np.where(b < 0, c / np.where(b < 0, b, 1), -np.inf), axis=-1)
    return low, high


def _shape_space_line(results, B, c, tl, wl, tt, wt, t0, crawler):
    low, high = interval(B, c)
    T = _period(results)
    earlier = tt <= t0 + 1e-12 * max(abs(t0), 1.0)
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        ax.fill_between(tl, low, high, color=colours(1)[0], alpha=0.15, linewidth=0,
                        label="$K(t)$")
        ax.plot(tl, high, color=colours(1)[0], linewidth=1.0)
        ax.plot(tl, low, color=colours(1)[0], linewidth=1.0)
        if np.count_nonzero(earlier) > 1:
            phase = tt[earlier] - np.floor((tt[earlier] - tt[0]) / T + 1e-9) * T - tt[0]
            folded = np.where(np.diff(phase, prepend=phase[0]) < 0, np.nan, wt[earlier, 0])
            ax.plot(phase, folded, color=FAINT, linewidth=0.8, label="earlier periods")
        ax.plot(tl, wl[:, 0], color=REFERENCE, linewidth=2.2, label="limit cycle")
        ax.set_xlim(tl[0], tl[-1])
        ax.set_xlabel(label("time in the period", "t - t_0"))
        ax.set_ylabel(label("shape coordinate", "w_1 = -k_1 z_1" if crawler else "w_1"))
        ax.set_title(title(_name(results), "shape space: the interval $K(t)$ and $w(t)$"))
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    return fig


# --------------------------------------------------------------------------------------------
# 5. Sweeps


def sweep_figure(axes: dict, v0: np.ndarray, failed: np.ndarray, title: str) -> Figure:
    """v0 over a sweep of one or two gait parameters, named by their dotted paths.

    ``axes`` maps each swept dotted path (``"friction.backward"``) to its values, in the order of
    the dimensions of ``v0`` and ``failed`` (both of the grid's shape; ``failed`` is True where
    the point did not give a v0).

    * one parameter: v0 against it, failed points as crosses on the parameter axis;
    * two parameters: a heat map of v0 (first parameter across, second up) with a colour bar,
      failed cells crossed. The colour map is cividis when v0 has one sign, and the diverging,
      colourblind-safe PuOr centred on 0 when it changes sign.
    """
    names = list(axes)
    values = [np.asarray(axes[k], dtype=float) for k in names]
    v0 = np.asarray(v0, dtype=float)
    failed = np.asarray(failed, dtype=bool)
    grid = tuple(len(v) for v in values)
    if len(names) not in (1, 2):
        raise ValueError(f"sweep_figure draws one or two swept parameters, got {len(names)}: "
                         f"{', '.join(names)}")
    if v0.shape != grid or failed.shape != grid:
        raise ValueError(f"v0 {v0.shape} and failed {failed.shape} must have the grid's shape "
                         f"{grid}")
    good = ~failed & np.isfinite(v0)
    with figure_style():
        fig, axs = new_figure(height=3.6 if len(names) == 1 else 4.2)
        ax = axs[0, 0]
        if len(names) == 1:
            x = values[0]
            ax.plot(x[good], v0[good], color=colours(1)[0], marker="o", markersize=4,
                    label="$v_0$")
            if np.any(~good):
                ax.plot(x[~good], np.zeros(np.count_nonzero(~good)), linestyle="none",
                        marker="x", markersize=7, color=SLIP_COLOURS[-1], clip_on=False,
                        transform=ax.get_xaxis_transform(), label="failed")
            ax.axhline(0.0, color=REFERENCE, linewidth=0.6)
            ax.set_xlabel(label(names[0]))
            ax.set_ylabel(label("average velocity", "v_0"))
            ax.legend(loc="best")
        else:
            x, y = values
            data = np.where(good, v0, np.nan).T
            finite = data[np.isfinite(data)]
            if finite.size and finite.min() < 0 < finite.max():
                cmap, norm = "PuOr_r", CenteredNorm(0.0)
            else:
                cmap, norm = "cividis", None
            mesh = ax.pcolormesh(x, y, data, cmap=cmap, norm=norm, shading="nearest")
            bar = fig.colorbar(mesh, ax=ax)
            bar.set_label(label("average velocity", "v_0"))
            xi, yi = np.nonzero(~good)
            if xi.size:
                ax.plot(x[xi], y[yi], linestyle="none", marker="x", markersize=7,
                        color=REFERENCE, label="failed")
                ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), borderaxespad=0)
            ax.set_xlabel(label(names[0]))
            ax.set_ylabel(label(names[1]))
            ax.grid(False)
        ax.set_title(title)
    return fig


#: The figures of one run, by the names of `crawlsim.plotting.FIGURE_NAMES`.
FIGURES: dict[str, Callable[..., Figure]] = {
    "motion": motion_figure,
    "gait-diagram": gait_figure,
    "convergence": convergence_figure,
    "shape-space": shape_space_figure,
}
