"""Draw the figures of a results file and write them next to it (``crawlsim plot``, ``--plot``).

Every figure is drawn before any is written, and each file is written to a temporary name and
renamed into place, so a figure that cannot be drawn leaves no file behind.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from crawlsim import __version__
from crawlsim.errors import ResultsFileError
from crawlsim.io.atomic import atomic_path
from crawlsim.io.optfile import read_optimization
from crawlsim.io.runread import read_attrs, read_results
from crawlsim.io.sweepfile import read_sweep
from crawlsim.plotting import (
    CRAWLER_FIGURES,
    FIGURE_NAMES,
    FORMATS,
    LAST_FIGURES,
    OPTIMIZATION_FIGURES,
    RIGID_FIGURE,
    SWEEP_FIGURE,
)
from crawlsim.plotting.convergence import convergence_figure
from crawlsim.plotting.gait_diagram import gait_figure
from crawlsim.plotting.kymograph import kymograph_figure
from crawlsim.plotting.motion import motion_figure
from crawlsim.plotting.optimization import OPTIMIZATION_FIGURE_FUNCTIONS
from crawlsim.plotting.rigid import rigid_figure
from crawlsim.plotting.shape_space import shape_space_figure
from crawlsim.plotting.style import DPI, NARROW, FigureOptions, figure_style, legends_below, user_style
from crawlsim.plotting.sweeps import sweep_data_figure

#: The figures of one run, by the names of `crawlsim.plotting.FIGURE_NAMES`: each takes the run
#: (`crawlsim.plotting.source.run_data`) and returns a matplotlib Figure in the style of
#: `crawlsim.plotting.style`; a figure that needs data the run lacks raises `ResultsFileError`
#: naming the missing dataset.
FIGURES: dict[str, Callable[..., Any]] = {
    "motion": motion_figure,
    "gait-diagram": gait_figure,
    "kymograph": kymograph_figure,
    "convergence": convergence_figure,
    "shape-space": shape_space_figure,
    "rigid": rigid_figure,
}


def available_figures(results: dict) -> list[str]:
    """The figures a file supports: all of them for crawler runs, the shape-space and
    convergence figures for a generic sweeping process (no blocks, no velocity); and the rigid
    limit's when the file has one."""
    crawler = results["attrs"].get("kind", "crawler") == "crawler"
    rigid = [RIGID_FIGURE] if "rigid" in results else []
    return [n for n in FIGURE_NAMES if crawler or n not in CRAWLER_FIGURES] + rigid


def draw_figure(results: Any, name: str, *, coords=(0, 1), last: int | None = None):
    """The figure ``name`` (one of `FIGURE_NAMES`) of ``results`` (a results dict, file or result
    object: `source.run_data`); ``last``: the last periods the figures of `LAST_FIGURES` zoom on."""
    if name not in FIGURES:
        raise ValueError(f"unknown figure {name!r}; choose one of {', '.join(FIGURE_NAMES)}")
    if name == "shape-space":
        return FIGURES[name](results, coords=coords)
    return FIGURES[name](results, last=last) if name in LAST_FIGURES else FIGURES[name](results)


def read_plottable(path: Path) -> tuple[str, dict]:
    """("run", `read_results` dict), ("sweep", `read_sweep` dict) or ("optimization",
    `read_optimization` dict) for a results, sweep or optimisation file.

    A file that is none of them raises the results reader's error, which says what is missing.
    """
    try:
        kind = read_attrs(path).get("kind")
    except ResultsFileError:
        kind = None
    if kind == "optimization":
        return "optimization", read_optimization(path)
    try:
        return "run", read_results(path)
    except ResultsFileError as exc:
        try:
            return "sweep", read_sweep(path)
        except ResultsFileError:
            raise exc from None


def plot_results(
    path,
    out_dir=None,
    fmt: str = "png",
    only: str | None = None,
    *,
    coords=(0, 1),
    options: FigureOptions | None = None,
    target=None,
    last: int | None = None,
) -> list[Path]:
    """Draw the figures of the results file ``path`` into ``out_dir`` (default: its folder) as
    ``<stem>-<figure>.<fmt>``; return the paths written.

    ``only`` draws one figure; otherwise every figure the file supports (`available_figures`).
    ``coords`` is the 0-based pair of shape coordinates of the shape-space figure when the shape
    space has more than two dimensions. A sweep file (``crawlsim velocity --sweep ... -o
    OUT.h5``) gets its one figure, ``<stem>-sweep.<fmt>`` (`crawlsim.plotting.sweeps.sweep_data_figure`); an
    optimisation file (``crawlsim optimize``) ``<stem>-objective.<fmt>`` and, with --pareto,
    ``<stem>-pareto-front.<fmt>`` (`crawlsim.plotting.optimization`). A
    missing dataset raises `ResultsFileError` naming the file and the dataset; nothing is
    written then.

    ``options`` (`style.FigureOptions`) sets the dpi, the size in inches and a matplotlib style
    sheet. ``target``, a file name, writes the one figure drawn there instead (its extension
    gives the format; ValueError when more than one figure would be drawn). ``last=K``: the
    motion figure and the kymograph zoom on the last K periods (`motion.motion_figure`).
    """
    options = options or FigureOptions()
    path = Path(path)
    if fmt not in FORMATS:
        raise ValueError(f"format {fmt!r}: choose one of {', '.join(FORMATS)}")
    kind, results = read_plottable(path)
    choices = {
        "run": (*FIGURE_NAMES, RIGID_FIGURE),
        "sweep": (SWEEP_FIGURE,),
        "optimization": optimization_figures(results),
    }[kind]
    if only is not None and only not in choices:
        article = "an" if kind[0] in "aeiou" else "a"
        raise ValueError(f"unknown figure {only!r} for {article} {kind} file; choose one of {', '.join(choices)}")
    if target is not None:
        count = (
            1
            if (only is not None or kind == "sweep")
            else len(optimization_figures(results) if kind == "optimization" else available_figures(results))
        )
        if count != 1:
            raise ValueError(
                f"{target} names one figure, and this {kind} file has {count}; choose one with --only, or give a folder"
            )
    try:
        with user_style(options.style):
            drawn = _draw(results, kind, choices, only, coords, last)
    except ResultsFileError as exc:
        raise ResultsFileError(f"{path}: {exc}") from None
    if target is not None:
        (fig,) = drawn.values()
        Path(target).parent.mkdir(parents=True, exist_ok=True)
        with user_style(options.style):
            save_figure(fig, target, dpi=options.dpi, figsize=options.figsize)
        return [Path(target)]
    folder = Path(out_dir) if out_dir is not None else path.resolve().parent
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    with user_style(options.style):
        for name, fig in drawn.items():
            out = folder / f"{path.stem}-{name}.{fmt}"
            save_figure(fig, out, fmt, dpi=options.dpi, figsize=options.figsize)
            written.append(out)
    return written


def _draw(results, kind, choices, only, coords, last) -> dict:
    """The figures of a file of ``kind``, by name, drawn (not yet written)."""
    if kind == "sweep":
        return {SWEEP_FIGURE: sweep_data_figure(results)}
    if kind == "optimization":
        return {
            name: OPTIMIZATION_FIGURE_FUNCTIONS[name](results) for name in ([only] if only is not None else choices)
        }
    names = [only] if only is not None else available_figures(results)
    return {name: draw_figure(results, name, coords=coords, last=last) for name in names}


def optimization_figures(data: dict) -> tuple[str, ...]:
    """The figures an optimisation file supports: the objective's convergence, and the front
    when it was written with --pareto."""
    return OPTIMIZATION_FIGURES if "front" in data else OPTIMIZATION_FIGURES[:1]


def save_figure(
    fig, target, fmt: str | None = None, *, dpi: float | None = None, figsize: tuple[float, float] | None = None
) -> Path:
    """Save ``fig`` atomically in the shared style (`crawlsim.io.atomic`) and close it.

    ``dpi`` (default `style.DPI`) is the resolution of a PNG. Without ``figsize`` the file is
    cropped to the figure's content; with it (width, height in inches) the figure is laid out
    again at that size and written whole, so a PNG is exactly width x dpi by height x dpi pixels
    (rounded), and a PDF or SVG page exactly that size.
    """
    import matplotlib
    import matplotlib.pyplot as plt

    target = Path(target)
    fmt = fmt or target.suffix.lstrip(".").lower() or "png"
    try:
        if figsize is not None:
            fig.set_size_inches(*figsize)
            if figsize[0] < NARROW:
                legends_below(fig)
        # The whole figure, not its tight bounding box, when a size is asked for (an
        # bbox_inches of None would fall back to the style's "tight").
        whole: dict = {"savefig.bbox": "standard"} if figsize is not None else {}
        with atomic_path(target) as tmp, figure_style(), matplotlib.rc_context(whole):
            fig.savefig(
                tmp,
                format=fmt,
                dpi=dpi or DPI,
                bbox_inches=None if figsize is not None else "tight",
                metadata=_metadata(fmt),
            )
    finally:
        plt.close(fig)
    return target


def _metadata(fmt: str) -> dict:
    """Reproducible files: no creation date in PDF and SVG, and crawlsim named as creator."""
    creator = f"crawlsim {__version__}"
    if fmt == "pdf":
        return {"Creator": creator, "CreationDate": None}
    if fmt == "svg":
        return {"Creator": creator, "Date": None}
    return {"Software": creator}
