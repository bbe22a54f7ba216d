"""The shape-space figure: the moving polyhedron K(t) = {w : B w <= c(t)} at instants of
the limit period and the orbit of w(t) (docs/model.md §2, §5)."""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction

import numpy as np
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.patches import Polygon
from scipy.optimize import linprog
from scipy.spatial import HalfspaceIntersection

from crawlsim.plotting.source import is_crawler_run, need, run_name, run_period, takes_run
from crawlsim.plotting.style import (
    FAINT,
    REFERENCE,
    colours,
    figure_style,
    format_number,
    label,
    legend_right,
    new_figure,
    time_axis,
    title,
    units_of,
)

#: How many distinct sets K(t) the shape-space figure aims to draw over the limit period.
SHAPE_SPACE_TIMES = 6
#: Divisions of the period tried for the shape-space instants, most preferred first: the
#: instants are the grid times j T / n, so their labels are exact fractions.
NICE_DIVISIONS = (6, 8, 10, 12, 5, 4, 3, 2)


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
    res = linprog(
        c=[0.0, 0.0, -1.0],
        A_ub=np.hstack([A, norms[:, None]]),
        b_ub=b,
        bounds=[(None, None), (None, None), (0, None)],
        method="highs",
    )
    if res.status != 0 or res.x[2] <= 1e-12 * max(np.abs(b).max(), 1.0):
        raise ValueError(
            "the polygon has an empty interior"
            if res.status == 0
            else "the polygon is unbounded or empty; give a bounding box"
        )
    hs = HalfspaceIntersection(np.hstack([A, -b[:, None]]), res.x[:2])
    vertices = hs.intersections
    centre = vertices.mean(axis=0)
    order = np.argsort(np.arctan2(vertices[:, 1] - centre[1], vertices[:, 0] - centre[0]))
    vertices = vertices[order]
    distinct = np.concatenate(
        [[True], np.linalg.norm(np.diff(vertices, axis=0), axis=1) > 1e-12 * max(np.abs(vertices).max(), 1.0)]
    )
    return vertices[distinct]


def section(normals: np.ndarray, offsets: np.ndarray, point: np.ndarray, coords):
    """The slice of {w : B w <= c} through ``point`` in the plane of coordinates ``coords``:
    the 2-D halfplanes {(u, v) : B[:, i] u + B[:, j] v <= c - sum_{k != i, j} B[:, k] w_k}."""
    i, j = coords
    others = [k for k in range(normals.shape[1]) if k not in (i, j)]
    return normals[:, [i, j]], offsets - normals[:, others] @ np.asarray(point)[others]


def _fraction_text(value: Fraction) -> str:
    return "0" if value == 0 else str(value)


def shape_space_instants(
    t: np.ndarray, period: float, keys: Callable[[int], np.ndarray], target: int = SHAPE_SPACE_TIMES
) -> list[tuple[list[int], str]]:
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
    return groups(indices.tolist(), [format_number(t[k] / period) for k in indices])


@takes_run
def shape_space_figure(results, coords=(0, 1), times: int = SHAPE_SPACE_TIMES) -> Figure:
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
    need(
        results, "shape space", "trajectory/t", "trajectory/w", "limit/t", "limit/w", "limit/offsets", "process/normals"
    )
    units = units_of(results)
    B = np.asarray(results["process"]["normals"], dtype=float)
    lim = results["limit"]
    c = np.asarray(lim["offsets"], dtype=float)
    wl = np.asarray(lim["w"], dtype=float)
    tl = np.asarray(lim["t"], dtype=float)
    tt = np.asarray(results["trajectory"]["t"], dtype=float)
    wt = np.asarray(results["trajectory"]["w"], dtype=float)
    T = run_period(results)
    t0 = float(results["limit_attrs"].get("start", tt[-1] - T))
    n = wl.shape[1]
    crawler = is_crawler_run(results)
    if n == 1:
        return _shape_space_line(results, B, c, tl, wl, tt, wt, t0, crawler, units)
    coords = tuple(int(k) for k in coords)
    if len(coords) != 2 or coords[0] == coords[1] or not all(0 <= k < n for k in coords):
        raise ValueError(
            f"shape coordinates {[k + 1 for k in coords]}: need two different coordinates between 1 and {n}"
        )
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
                handles += ax.plot(
                    [],
                    [],
                    marker="o",
                    markersize=5.5,
                    color=colour,
                    linestyle="none",
                    label=f"{text} (section without interior)",
                )
            else:
                patch = Polygon(
                    vertices, closed=True, linewidth=1.3, facecolor=to_rgba(colour, 0.07), edgecolor=colour, label=text
                )
                ax.add_patch(patch)
                handles.append(patch)
            for k in members:
                ax.plot(
                    wl[k, i],
                    wl[k, j],
                    marker="o",
                    markersize=5.5,
                    color=colour,
                    markeredgecolor="white",
                    markeredgewidth=0.6,
                    linestyle="none",
                    zorder=4,
                )
        handles += _orbit(ax, wt[:, [i, j]], wl[:, [i, j]], earlier, span, state)
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        dimension = "force" if crawler else None
        ax.set_xlabel(label("shape coordinate", f"{state}_{{{i + 1}}}", dimension, units))
        ax.set_ylabel(label("shape coordinate", f"{state}_{{{j + 1}}}", dimension, units))
        ax.set_title(_title(run_name(results), n, (i, j), crawler))
        ax.legend(
            handles=handles,
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            borderaxespad=0,
            title=f"${where}$ at $(t - t_0)/T$ =",
        )
    return fig


def _orbit(ax, trajectory, limit, earlier, span, state) -> list:
    """The orbit in the drawn plane (``trajectory`` and ``limit`` (rows, 2)): the earlier periods
    faint (when they have any extent), the limit cycle bold (a circle when the limit is a
    constant state), the start w(0) a cross. Returns the legend handles."""
    handles = []
    if np.count_nonzero(earlier) > 1 and np.ptp(trajectory[earlier], axis=0).max() > 0:
        handles += ax.plot(
            trajectory[earlier, 0],
            trajectory[earlier, 1],
            color=FAINT,
            linewidth=0.8,
            alpha=0.9,
            label="earlier periods",
        )
    if np.ptp(limit, axis=0).max() <= 1e-9 * span:
        handles += ax.plot(
            limit[0, 0],
            limit[0, 1],
            marker="o",
            markersize=8,
            color=REFERENCE,
            markerfacecolor="none",
            markeredgewidth=1.6,
            linestyle="none",
            label="limit (a constant state)",
        )
    else:
        handles += ax.plot(limit[:, 0], limit[:, 1], color=REFERENCE, linewidth=2.2, label="limit cycle")
    handles += ax.plot(
        trajectory[0, 0],
        trajectory[0, 1],
        marker="x",
        markersize=7,
        color=REFERENCE,
        linestyle="none",
        label=f"start ${state}(0)$",
    )
    return handles


def _title(name: str, n: int, coords: tuple[int, int], crawler: bool) -> str:
    """The title in short lines, so that it stays within the axes (square, by the equal
    aspect) however long the gait's name: name, what is drawn, and where."""
    state, where = ("w", "K(t)") if crawler else ("z", "C(t)")
    i, j = coords
    if n == 2:
        what = f"${where}$ and the orbit of ${state}(t)$" + (", $w = -Kz$" if crawler else "")
    else:
        what = f"sections of ${where}$ through ${state}(t)$\ncoordinates ({i + 1}, {j + 1}) of {n}" + (
            ", $w = -Kz$" if crawler else ""
        )
    return f"{title(name, 'shape space')}\n{what}"


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
    T = run_period(results)
    factor, time_label = time_axis(units, T, symbol="t - t_0", name="time in the limit period")
    earlier = tt <= t0 + 1e-12 * max(abs(t0), 1.0)
    state, where = ("w", "K(t)") if crawler else ("z", "C(t)")
    band = colours(1)[0]
    with figure_style():
        fig, axs = new_figure(height=3.4)
        ax = axs[0, 0]
        ax.fill_between(tl * factor, low, high, color=band, alpha=0.15, linewidth=0, label=f"${where}$")
        ax.plot(tl * factor, high, color=band, linewidth=1.0)
        ax.plot(tl * factor, low, color=band, linewidth=1.0)
        if np.count_nonzero(earlier) > 1:
            phase = tt[earlier] - np.floor((tt[earlier] - tt[0]) / T + 1e-9) * T - tt[0]
            folded = np.where(np.diff(phase, prepend=phase[0]) < 0, np.nan, wt[earlier, 0])
            ax.plot(phase * factor, folded, color=FAINT, linewidth=0.8, label="earlier periods")
        ax.plot(tl * factor, wl[:, 0], color=REFERENCE, linewidth=2.2, label="limit cycle")
        ax.set_xlim(tl[0] * factor, tl[-1] * factor)
        ax.set_xlabel(time_label)
        ax.set_ylabel(label("shape coordinate", f"{state}_1", "force" if crawler else None, units))
        what = f"the interval ${where}$ and ${state}(t)$" + (", $w = -kz$" if crawler else "")
        ax.set_title(f"{title(run_name(results), 'shape space')}\n{what}")
        legend_right(ax)
    return fig
