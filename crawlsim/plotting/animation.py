"""The crawler in motion: an animation of a run's blocks and links (``crawlsim animate``).

Each frame shows, at one instant,

* the crawler: each block a rectangle at its position x_j(t), filled in the colour of its slip
  state on the step that follows (stick, forward slip, backward slip: `style.SLIP_COLOURS`, the
  colours of the gait diagram), and each link a line between its two blocks, coloured by its
  stress sigma_i(t) = k_i (L_i - z_i) in a diverging map of two Okabe-Ito colours (tension
  sigma < 0 blue, compression sigma > 0 vermilion, through light grey), never a slip colour,
  with a colour bar;
* the link lengths z_i(t) = x_{i+1} - x_i (grey bars; beyond 12 blocks a grey curve) against
  the actuator lengths L_i(t) (black markers) when the file has them, by link i;
* the link stresses sigma_i(t), by link i, in the colours of the links above.

The lower panels are drawn against the link index, so a 100-block crawler stays readable: its
body is a thin strip whose slip colours show the wave, and its lengths and stresses are a curve
along the body. Up to `MAX_LABELLED_LINKS` links, each link's length and stress are also
written over it.

Frames are taken at evenly spaced instants of the limit period (``/limit``) or, for a range of
periods, of the stored trajectory (``/trajectory``), at the nearest stored time; the slip state
there is ``/limit/slip``, or the sign of the block's displacement over the next stored step.
The last periods (``last=K``) are drawn in a frame that follows the crawler: positions from its
barycentre, over at most `FOLLOW_LINKS` links of the body around it, the ground's marks passing
by and the barycentre's trace since the first frame growing behind it: the net motion shows at
any N.
GIFs are written by matplotlib's Pillow writer, MP4s by its FFmpeg writer (when ffmpeg is on the
PATH), both to a temporary file renamed into place (`crawlsim.io.atomic`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from crawlsim import interrupts
from crawlsim.errors import ResultsFileError
from crawlsim.io.atomic import atomic_path
from crawlsim.plotting.source import need, run_name, run_period, step_slip, takes_run
from crawlsim.plotting.style import (
    FAINT,
    REFERENCE,
    SLIP_COLOURS,
    SLIP_NAMES,
    diverging_map,
    figure_style,
    label,
    title,
    units_of,
)

#: Formats `write_animation` writes, by extension, and the matplotlib writer of each.
ANIMATION_FORMATS = {"gif": "pillow", "mp4": "ffmpeg"}
#: Frames per period and frames per second by default: two seconds a period.
FRAMES_PER_PERIOD = 40
FPS = 20
#: At most this many frames in one animation (frames per period are lowered to fit).
MAX_FRAMES = 1200
#: Up to this many links, each link's length and stress are written over it.
MAX_LABELLED_LINKS = 8
#: The frame that follows the crawler shows at most this many links' lengths of its body.
FOLLOW_LINKS = 12
#: Resolution of the animation frames (dots per inch) and their size in inches.
ANIMATION_DPI = 80
ANIMATION_SIZE = (8.0, 5.6)


@dataclass(frozen=True)
class Frames:
    """What the frames show, one row per frame: times t (absolute), block positions x (F, N),
    link stresses (F, N-1), actuator lengths (F, N-1) or None, slip states (F, N), in -1, 0, 1."""

    t: np.ndarray
    x: np.ndarray
    stress: np.ndarray
    lengths: np.ndarray | None
    slip: np.ndarray
    period: float
    start: float  # t0 of the limit period (the frames' clock is (t - t0)/T on the limit)
    limit: bool


def parse_periods(text: str) -> tuple[int, int]:
    """``"A:B"`` -> (A, B): the periods A, A+1, ..., B-1, from t = A T to t = B T (integers,
    0 <= A < B); ValueError otherwise."""
    parts = text.split(":")
    try:
        a, b = (int(p) for p in parts)
    except ValueError:
        raise ValueError(
            f"--periods {text}: expected A:B, two whole numbers of periods with "
            "0 <= A < B, such as 0:3 (from t = 0 to t = 3T)"
        ) from None
    if not 0 <= a < b:
        raise ValueError(f"--periods {text}: need 0 <= A < B (from t = A T to t = B T)")
    return a, b


def animation_frames(
    results: dict, periods: tuple[int, int] | None = None, frames_per_period: int = FRAMES_PER_PERIOD
) -> Frames:
    """The instants of the animation and what each shows: the limit period, or the periods
    ``(A, B)`` of the stored trajectory (`parse_periods`). ValueError for periods the file
    does not hold."""
    need(results, "animation", "limit/t", "limit/x", "limit/stress", "limit/slip")
    T = run_period(results)
    start = float(results["limit_attrs"].get("start", 0.0))
    if periods is None:
        lim = results["limit"]
        t = np.asarray(lim["t"], dtype=float)
        x = limit_positions(results)
        stress = np.asarray(lim["stress"], dtype=float)
        lengths = lim.get("lengths")
        slip = np.asarray(lim["slip"])
        count = max(int(frames_per_period), 2)
        wanted = t[0] + (t[-1] - t[0]) * np.arange(count) / count
        t_abs = t + start
    else:
        need(results, "animation", "trajectory/t", "trajectory/x", "trajectory/stress")
        tr = results["trajectory"]
        t_abs = np.asarray(tr["t"], dtype=float)
        a, b = periods
        end = (t_abs[-1] - t_abs[0]) / T
        if b > round(end, 9) + 1e-9:
            raise ValueError(
                f"--periods {a}:{b}: the run holds {end:.4g} periods (t from "
                f"{t_abs[0]:.4g} to {t_abs[-1]:.4g}), so B is at most "
                f"{int(np.floor(end + 1e-9))}"
            )
        x = np.asarray(tr["x"], dtype=float)
        stress = np.asarray(tr["stress"], dtype=float)
        lengths = None
        per = max(min(int(frames_per_period), MAX_FRAMES // (b - a)), 2)
        count = per * (b - a)
        wanted = t_abs[0] + a * T + (b - a) * T * np.arange(count) / count
        slip = step_slip(x)
        t = t_abs
    index = np.clip(np.searchsorted(t, wanted, side="left"), 0, len(t) - 1)
    # The nearest stored time to each wanted instant.
    before = np.clip(index - 1, 0, len(t) - 1)
    index = np.where(np.abs(t[before] - wanted) <= np.abs(t[index] - wanted), before, index)
    step = np.clip(index, 0, len(slip) - 1)
    return Frames(
        t=t_abs[index] if periods is None else t[index],
        x=x[index],
        stress=stress[index],
        lengths=None if lengths is None else np.asarray(lengths, float)[index],
        slip=np.asarray(slip)[step],
        period=T,
        start=start,
        limit=periods is None,
    )


def limit_positions(results: dict) -> np.ndarray:
    """Absolute block positions over the limit period, (G+1, N).

    The body comes from the link lengths, x_j - x_1 = z_1 + ... + z_{j-1} (z = D x), and its
    barycentre from the running frame of ``/limit/x``: y(t) = y(t0) + v0 (t - t0) + mean_j
    ``/limit/x``(t), which holds whether ``/limit/x`` is measured from the barycentre at t0 or
    from each block's own position at t0 (the two differ by a constant per block, whose mean
    the barycentre of the frame absorbs). y(t0) is the barycentre of the stored trajectory at
    t0 (0 when the file has none).
    """
    lim = results["limit"]
    t = np.asarray(lim["t"], dtype=float)
    running = np.asarray(lim["x"], dtype=float)
    z = np.asarray(lim["shape"], dtype=float) if "shape" in lim else np.diff(running, axis=1)
    body = np.concatenate([np.zeros((len(t), 1)), np.cumsum(z, axis=1)], axis=1)
    body -= body.mean(axis=1, keepdims=True)
    start = float(results["limit_attrs"].get("start", 0.0))
    v0 = float(results["attrs"].get("v0", 0.0))
    y0 = 0.0
    tr = results.get("trajectory") or {}
    if "x" in tr and "t" in tr and len(tr["t"]):
        y0 = float(np.interp(start, np.asarray(tr["t"], float), np.asarray(tr["x"], float).mean(axis=1)))
    y = y0 + v0 * t + running.mean(axis=1)
    return body + y[:, None]


def _block_boxes(x: np.ndarray, width: float, height: float) -> np.ndarray:
    """The corners of one rectangle per block, centred on x_j, (N, 4, 2)."""
    left, right = x - width / 2, x + width / 2
    low, high = np.full_like(x, -height / 2), np.full_like(x, height / 2)
    return np.stack(
        [
            np.stack([left, low], -1),
            np.stack([right, low], -1),
            np.stack([right, high], -1),
            np.stack([left, high], -1),
        ],
        axis=1,
    )


def _lengths_panel(ax, frames: Frames, links: np.ndarray, units):
    """The link lengths z_i of the first frame against the actuators' L_i: bars from 0 for a
    few links; beyond 12 a curve along the body, on an axis fitted to the lengths, where the
    wave of a long crawler shows. Returns the artists a frame updates: the bars (or the curve)
    and the actuator markers (None when the file has no actuator lengths)."""
    x_all = frames.x
    N = x_all.shape[1]
    # Grey, not a series colour: blue and vermilion are the stress map's tension and compression.
    if N <= 12:
        bars = ax.bar(links, np.diff(x_all[0]), color=FAINT, width=0.7, label="link $z_i$")
        z_artists, handles = list(bars), [bars]  # the container carries the legend label
    else:
        (z_line,) = ax.plot(links, np.diff(x_all[0]), color=FAINT, linewidth=1.6, label="link $z_i$")
        z_artists, handles = [z_line], [z_line]
    actuator = None
    if frames.lengths is not None:
        (actuator,) = ax.plot(
            links,
            frames.lengths[0],
            linestyle="none",
            marker="_" if N > 12 else "o",
            markersize=8,
            color=REFERENCE,
            label="actuator $L_i$",
        )
        handles.append(actuator)
    z_all = np.diff(x_all, axis=1)
    given = frames.lengths if frames.lengths is not None else z_all
    top = max(float(z_all.max()), float(np.max(frames.lengths)) if frames.lengths is not None else 0.0)
    if N > 12:
        low = min(float(z_all.min()), float(np.min(given)))
        pad = 0.08 * max(top - low, 1e-12 * max(abs(top), 1.0))
        ax.set_ylim(low - pad, top + pad)
    else:
        bottom = min(float(z_all.min()), float(np.min(given)), 0.0)
        ax.set_ylim(bottom, top * 1.08 if top > 0 else 1.0)
    ax.set_ylabel(label("length", "z_i", "length", units))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    return z_artists, actuator


def animation_figure(results: dict, frames: Frames, follow: bool = False):
    """The figure of the animation and the function that draws frame k on it (for
    `matplotlib.animation.FuncAnimation`); ``follow``: in the frame of the barycentre (module
    docstring)."""
    units = units_of(results)
    N = frames.x.shape[1]
    origin = frames.x.mean(axis=1) if follow else np.zeros(len(frames.t))
    x_all = frames.x - origin[:, None]
    spacing = float(np.median(np.abs(np.diff(x_all[0])))) if N > 1 else 1.0
    narrow = N > 12 and not follow
    width = min(0.35 * spacing, 0.02 * max(float(np.ptp(x_all)), spacing)) if narrow else 0.35 * spacing
    height = 1.0
    # Stresses in a diverging map of two series colours through light grey (tension blue,
    # compression vermilion): a link never takes a slip colour, and the sign reads at a glance.
    cmap = diverging_map()
    s_max = float(np.max(np.abs(frames.stress), initial=0.0)) or 1.0
    norm = Normalize(-s_max, s_max)
    links = np.arange(1, N)
    labelled = N - 1 <= MAX_LABELLED_LINKS
    with figure_style():
        fig = Figure(figsize=ANIMATION_SIZE, layout="constrained")
        body, lengths_ax, stress_ax = fig.subplots(3, 1, gridspec_kw={"height_ratios": [1.1, 1.0, 1.0]})
        # The crawler: links under blocks.
        segments = list(
            np.stack(
                [np.stack([x_all[0, :-1], np.zeros(N - 1)], -1), np.stack([x_all[0, 1:], np.zeros(N - 1)], -1)], axis=1
            )
        )
        link_lines = LineCollection(segments, cmap=cmap, norm=norm, linewidths=4.0 if N <= 12 else 2.0, zorder=1)
        link_lines.set_array(frames.stress[0])
        body.add_collection(link_lines)
        boxes = PolyCollection(
            list(_block_boxes(x_all[0], width, height)),
            edgecolors=REFERENCE if N <= 12 else "none",
            linewidths=0.8,
            zorder=2,
        )
        body.add_collection(boxes)
        margin = max(0.6 * spacing, 0.02 * float(np.ptp(x_all)))
        body.set_xlim(float(x_all.min()) - margin, float(x_all.max()) + margin)
        if follow:  # the ground's marks, one a link length apart, and the barycentre's trace
            half = min(0.5 * float(np.ptp(x_all[0])), 0.5 * FOLLOW_LINKS * spacing) + margin
            body.set_xlim(-half, half)
            marks = spacing * np.arange(np.floor((origin.min() - half) / spacing), (origin.max() + half) / spacing + 1)
            ground = LineCollection([], colors=FAINT, linewidths=1.0)
            body.add_collection(ground)
            (trace,) = body.plot([], [], color=REFERENCE, linewidth=3.0, solid_capstyle="butt")
            moved = body.text(0.02 * half, -1.4 * height, "", ha="left", va="center", fontsize=8)
            body.axhline(-1.25 * height, color=FAINT, linewidth=0.6)
        body.set_ylim(-1.6 * height, 1.6 * height)
        body.set_yticks([])
        body.grid(False)
        body.spines["left"].set_visible(False)
        if follow:
            body.set_xlabel(label("position from the barycentre", "x_j - y", "length", units))
        else:
            body.set_xlabel(label("position", "x_j", "length", units))
        bar = fig.colorbar(link_lines, ax=body, pad=0.01, fraction=0.04)
        bar.set_label(label("stress", "\\sigma_i", "force", units))
        handles = [
            Patch(facecolor=SLIP_COLOURS[k], edgecolor=REFERENCE, linewidth=0.6, label=SLIP_NAMES[k])
            for k in (0, 1, -1)
        ]
        if follow:
            trace.set_label("barycentre's trace")
            handles.append(trace)
        body.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=len(handles), borderaxespad=0.2)
        texts = []
        if labelled:
            texts = [body.text(0, 0.75 * height, "", ha="center", va="bottom", fontsize=8) for _ in links]
        clock = body.set_title("", loc="right")
        fig.suptitle(title(run_name(results), "the crawler in motion"))

        z_bars, actuator = _lengths_panel(lengths_ax, frames, links, units)

        s_bars = stress_ax.bar(links, frames.stress[0], width=0.7, color=cmap(norm(frames.stress[0])))
        stress_ax.axhline(0.0, color=REFERENCE, linewidth=0.6)
        stress_ax.set_ylim(-1.08 * s_max, 1.08 * s_max)
        stress_ax.set_ylabel(label("stress", "\\sigma_i", "force", units))
        stress_ax.set_xlabel("link $i$")
        for ax in (lengths_ax, stress_ax):
            ax.set_xlim(0.4, N - 0.4)
            if N <= 12:
                ax.set_xticks(links)

    animated = [boxes, link_lines, *z_bars, *s_bars, *texts, clock]
    if actuator is not None:
        animated.append(actuator)
    if follow:
        animated += [ground, trace, moved]
    for artist in animated:
        artist.set_animated(True)

    def draw(k: int):
        x = x_all[k]
        sigma = frames.stress[k]
        if follow:  # the ground passes by; the trace is the way the barycentre came
            ground.set_segments([[(g, -1.25 * height), (g, -1.05 * height)] for g in marks - origin[k]])
            trace.set_data([origin[0] - origin[k], 0.0], [-1.4 * height] * 2)
        boxes.set_verts(list(_block_boxes(x, width, height)))
        boxes.set_facecolor([SLIP_COLOURS[int(v)] for v in frames.slip[k]])
        link_lines.set_segments(
            list(np.stack([np.stack([x[:-1], np.zeros(N - 1)], -1), np.stack([x[1:], np.zeros(N - 1)], -1)], axis=1))
        )
        link_lines.set_array(sigma)
        z = np.diff(x)
        if N <= 12:
            for rect, value in zip(z_bars, z):
                rect.set_height(value)
        else:
            z_bars[0].set_ydata(z)
        for rect, value in zip(s_bars, sigma):
            rect.set_height(value)
            rect.set_facecolor(cmap(norm(value)))
        if actuator is not None and frames.lengths is not None:
            actuator.set_ydata(frames.lengths[k])
        for text, left, right, zi, si in zip(texts, x[:-1], x[1:], z, sigma):
            text.set_position(((left + right) / 2, 0.75 * height))
            text.set_text(f"z={zi:.3g}\nσ={si:.3g}")
        if frames.limit:
            # Plain text: a mathtext clock would be parsed anew for every frame.
            clock.set_text(f"(t − t₀)/T = {(frames.t[k] - frames.start) / frames.period:.3f}")
        else:
            clock.set_text(f"t/T = {frames.t[k] / frames.period:.3f}")
        if follow:
            moved.set_text(f"{origin[k] - origin[0]:+.3g}")
        return animated

    draw(0)
    # Lay the figure out once, for the first frame, and keep that layout: the frames then line
    # up, and each costs a redraw only (constrained layout per frame costs several times more).
    fig.draw_without_rendering()
    fig.set_layout_engine("none")
    return fig, draw


def _blitting_pillow_writer():
    from matplotlib import animation
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    class BlittingPillowWriter(animation.PillowWriter):
        """matplotlib's Pillow writer, drawing the still parts of the figure (axes, ticks,
        labels, legends) once: each frame restores them and draws only the artists marked
        animated, which is most of the cost of a frame saved whole."""

        def setup(self, fig, outfile, dpi=None):
            super().setup(fig, outfile, dpi=dpi)
            fig.set_dpi(self.dpi)
            self._canvas = FigureCanvasAgg(fig)
            self._canvas.draw()  # animated artists are left out
            self._background = self._canvas.copy_from_bbox(fig.bbox)
            self._animated = [a for a in fig.findobj() if a.get_animated()]

        def grab_frame(self, **savefig_kwargs):
            canvas = self._canvas
            canvas.restore_region(self._background)
            for artist in self._animated:
                self.fig.draw_artist(artist)
            width, height = canvas.get_width_height()
            frame = Image.frombuffer("RGBA", (width, height), bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1)
            cast(Any, self)._frames.append(frame)  # PillowWriter's own list of frames

    return BlittingPillowWriter


def _BlittingPillowWriter(fps: float):
    return _blitting_pillow_writer()(fps=fps)


@takes_run
def write_animation(
    results: dict,
    target,
    *,
    periods: tuple[int, int] | None = None,
    frames_per_period: int = FRAMES_PER_PERIOD,
    fps: float = FPS,
    dpi: float = ANIMATION_DPI,
    last: int | None = None,
) -> tuple[Path, int]:
    """Write the animation of ``results`` to ``target`` (.gif, or .mp4 where ffmpeg is on the
    PATH), atomically: an error leaves no file. Returns (path, number of frames). ``last=K``:
    the last K periods of the stored trajectory, in the frame that follows the crawler."""
    from matplotlib import animation

    target = Path(target)
    fmt = target.suffix.lower().lstrip(".")
    if fmt not in ANIMATION_FORMATS:
        raise ValueError(f"{target}: an animation is written as .gif or .mp4")
    if fmt == "mp4" and not animation.writers.is_available("ffmpeg"):
        raise ValueError(f"{target}: writing MP4 needs ffmpeg on the PATH, which is not there; write a .gif instead")
    if last is not None:
        need(results, "animation", "trajectory/t")
        t = np.asarray(results["trajectory"]["t"], dtype=float)
        stored = int(np.floor((t[-1] - t[0]) / run_period(results) + 1e-9))
        periods = (max(stored - last, 0), stored)
    frames = animation_frames(results, periods, frames_per_period)
    count = len(frames.t)
    fig, draw = animation_figure(results, frames, follow=last is not None)
    writer = _BlittingPillowWriter(fps=fps) if fmt == "gif" else animation.FFMpegWriter(fps=round(fps))
    with figure_style(), atomic_path(target) as tmp:
        # The writers choose the container by the file's name: the temporary keeps the suffix.
        named = tmp.with_name(tmp.name + f".{fmt}")
        try:
            # The writer's own loop (`FuncAnimation.save` would draw every frame twice).
            with writer.saving(fig, str(named), dpi):
                for k in range(count):
                    interrupts.check()  # noted in matplotlib's or Pillow's code: stop here
                    draw(k)
                    writer.grab_frame()
            named.replace(tmp)
        finally:
            named.unlink(missing_ok=True)
    return target, count


__all__ = [
    "ANIMATION_FORMATS",
    "Frames",
    "ResultsFileError",
    "animation_figure",
    "animation_frames",
    "parse_periods",
    "write_animation",
]
