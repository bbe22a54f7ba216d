"""Figures: every figure of every example gait is drawn, and its content is checked against the
results file and against closed forms of the crawler model (docs/model.md §1-2, §5).

Runs use 200 steps a period: the figures' content is compared with the file they are drawn from,
so the step size does not matter, and the closed forms below hold on any grid.
"""

from __future__ import annotations

import copy
import json
import shutil
from fractions import Fraction
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.collections import PolyCollection, QuadMesh
from matplotlib.colors import to_hex
from matplotlib.patches import Polygon, Rectangle
from matplotlib.text import Text
from scipy.optimize import linprog

from crawlsim import api
from crawlsim.cli import main
from crawlsim.errors import ResultsFileError
from crawlsim.gait.document import gait_from_document, load_gait, with_simulation
from crawlsim.gait.units import Units as GaitUnits
from crawlsim.io.runread import read_results
from crawlsim.model import crawler as crawler_module
from crawlsim.model.process import compile_gait
from crawlsim.plotting import (
    FIGURE_NAMES,
    available_figures,
    convergence_figure,
    gait_diagram,
    gait_figure,
    kymograph_figure,
    motion_figure,
    plot_results,
    run_data,
    shape_space_figure,
    sweep_figure,
)
from crawlsim.plotting.convergence import MAX_MARKERS, marked_periods
from crawlsim.plotting.gait_diagram import (
    MAX_BAND_LABELS,
    MAX_FORCE_ROWS,
    MAX_SERIES,
    block_forces,
    relative_stress,
    slip_runs,
    stress_bounds,
    stress_mode,
)
from crawlsim.plotting.motion import FOLLOW_PERIODS, MAX_MOTION_BLOCKS
from crawlsim.plotting.shape_space import polygon, section, shape_space_instants
from crawlsim.plotting.style import (
    COLOUR_MAP,
    PALETTE,
    SLIP_COLOURS,
    Units,
    colours,
    label,
    path_dimension,
    path_label,
    shown_series,
    units_of,
)
from crawlsim.plotting.sweeps import cell_edges, is_geometric, jumps, swept_ticks, zero_contour

from .conftest import SOLVER_GAITS

GAITS = Path(__file__).resolve().parents[1] / "gaits"
GAIT_FILES = sorted(p for p in GAITS.rglob("*.yaml") if p.stem not in SOLVER_GAITS)
STEPS = 200


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """Path of a 200-step run of a gait file, computed once per gait."""
    folder = tmp_path_factory.mktemp("runs")
    cache = {}

    def get(name: str, integrator: str | None = None) -> Path:
        """``integrator`` None: the gait file's (by default exact)."""
        if (name, integrator) not in cache:
            stem = Path(name).name if integrator is None else f"{Path(name).name}-{integrator}"
            out = folder / f"{stem}.h5"
            gait = with_simulation(load_gait(GAITS / f"{name}.yaml"), steps_per_period=STEPS)
            if integrator is not None:
                gait = with_simulation(gait, integrator=integrator)
            api.run(gait, output=out)
            cache[name, integrator] = out
        return cache[name, integrator]

    return get


def results_of(run_file, name):
    return read_results(run_file(name))


def _all_texts(fig):
    """Every piece of text a figure shows: axis labels, titles, legend entries, tick labels."""
    for text in fig.findobj(Text):
        if text.get_visible() and text.get_text():
            yield text.get_text()


def _all_labels(fig):
    for ax in fig.axes:
        yield ax.get_xlabel()
        yield ax.get_ylabel()


def _check_labels(fig, units=None):
    """No "(dimensionless)" anywhere; every time axis is t/T (or in the unit given), every
    position x/ℓ (or in the length unit)."""
    texts = list(_all_texts(fig))
    assert not any("dimensionless" in s for s in texts), texts
    labels = [s for s in _all_labels(fig) if s]
    assert labels
    for s in labels:
        if s.startswith("time"):
            assert (f"({units.time})" in s) if units and units.time else s.endswith("/T$"), s
        if s.startswith("position"):
            assert (f"({units.length})" in s) if units and units.length else "/\\ell" in s, s


# --------------------------------------------------------------------------------------------
# Every figure of every gait file


#: The default run draws a crawler, a crawler on terrain and a generic process; the other
#: example gaits are drawn in the slow run.
FIGURES_BY_DEFAULT = ("peristalsis-4", "patch-4", "triangle")


@pytest.mark.parametrize(
    "gait_file",
    [pytest.param(p, id=p.stem, marks=() if p.stem in FIGURES_BY_DEFAULT else pytest.mark.slow) for p in GAIT_FILES],
)
def test_every_figure_of_every_gait(run_file, gait_file, tmp_path):
    """Every figure a file supports is written for each example gait (all five for crawlers,
    convergence and shape space for the paper's generic sweeping processes), titled with the
    gait's name, every axis labelled with its unit, as small PNG files."""
    path = run_file(str(gait_file.relative_to(GAITS).with_suffix("")))
    results = read_results(path)
    crawler = results["attrs"]["kind"] == "crawler"
    names = FIGURE_NAMES if crawler else ("convergence", "shape-space")
    assert available_figures(results) == list(names)
    written = plot_results(path, tmp_path)
    assert [p.name for p in written] == [f"{gait_file.stem}-{n}.png" for n in names]
    for p in written:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert p.stat().st_size < 400_000
    draws = {
        "motion": motion_figure,
        "gait-diagram": gait_figure,
        "kymograph": kymograph_figure,
        "convergence": convergence_figure,
        "shape-space": shape_space_figure,
    }
    for name in names:
        fig = draws[name](results)
        titles = [ax.get_title() for ax in fig.axes] + [fig._suptitle.get_text() if fig._suptitle else ""]
        assert any(gait_file.stem in s for s in titles)
        _check_labels(fig)
        for ax in fig.axes:
            if ax.get_legend() is not None and name == "shape-space":
                _legend_handles_visible(ax)
    assert not list(tmp_path.glob(".*.tmp"))


# --------------------------------------------------------------------------------------------
# Style: labels, units, palettes


def test_labels_without_and_with_units():
    """Without units a quantity is written over its scale (ℓ, F, and T for times, which are then
    plotted in periods); with units, in them; indices and phases carry no unit."""
    none = Units()
    assert label("time", "t", "time", none) == "time $t/T$"
    assert label("time in the limit period", "t - t_0", "time") == "time in the limit period $(t - t_0)/T$"
    assert label("position", "x_j", "length", none) == "position $x_j/\\ell$"
    assert label("stress", "\\sigma_i", "force") == "stress $\\sigma_i/F$"
    assert label("stiffness", "k", "stiffness") == "stiffness $k\\ell/F$"
    assert label("period index", "q") == "period index $q$"
    assert label("phase", None, "cycles") == "phase (cycles)"
    si = Units(length="m", time="s", force="N")
    assert label("time", "t", "time", si) == "time $t$ (s)"
    assert label("position", "x_j", "length", si) == "position $x_j$ (m)"
    assert label("stiffness", "k", "stiffness", si) == "stiffness $k$ (N/m)"
    assert label("average velocity", "v_0", "velocity", si) == "average velocity $v_0$ (m/s)"
    # Some units given: the missing ones as scales.
    assert label("stiffness", "k", "stiffness", Units(force="N")) == "stiffness $k$ (N/$\\ell$)"
    assert path_dimension("links.*.amplitude") == "length"
    assert path_dimension("friction.0.backward") == "force"
    assert path_dimension("links.1.phase") == "cycles"
    assert path_dimension("simulation.steps_per_period") is None
    assert path_label("friction.backward", si) == "friction.backward (N)"
    assert path_label("period", Units()) == "period"


def test_units_from_results():
    """``units_json`` first, else the ``units:`` block of the stored gait, else none; malformed
    units never stop a figure."""
    assert units_of({"attrs": {"units_json": '{"length": "mm", "time": "s"}'}}) == Units(length="mm", time="s")
    assert units_of({"attrs": {"gait_yaml": "units: {force: N}\nblocks: 2\n"}}) == Units(force="N")
    assert units_of({"gait_yaml": "units: {length: cm}\n"}) == Units(length="cm")
    assert units_of({"attrs": {"units_json": "not json"}}) == Units()
    assert units_of({"attrs": {"gait_yaml": "blocks: 2\n"}}) == Units()
    assert Units.parse({"length": 3, "time": " "}) == Units()
    # The one Units class: the gait's (crawlsim.gait.units), not a copy of it.
    assert Units is GaitUnits and type(units_of({"attrs": {"units_json": '{"force": "N"}'}})) is GaitUnits


def test_palettes_are_disjoint():
    """The slip colours are not series colours (vermilion was both backward slip and link 2), and
    they differ in lightness, so they stay apart in greyscale: CIE L* of stick, forward and
    backward at least 20 apart."""
    slip = {to_hex(c) for c in SLIP_COLOURS.values()}
    assert not slip & {to_hex(c) for c in PALETTE}
    assert not slip & {to_hex(c) for c in colours(20)}
    assert len(slip) == 3

    def lightness(colour):
        rgb = np.array([int(colour[k : k + 2], 16) / 255 for k in (1, 3, 5)])
        linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
        y = linear @ [0.2126, 0.7152, 0.0722]
        return 116 * y ** (1 / 3) - 16 if y > 0.008856 else 903.3 * y

    values = sorted(lightness(c) for c in slip)
    assert min(np.diff(values)) >= 20, values


# --------------------------------------------------------------------------------------------
# 1. Motion


@pytest.mark.parametrize("name", ["inching-2", "peristalsis-4"])
def test_motion_lines_are_the_trajectory(run_file, name):
    r = results_of(run_file, name)
    t, x = r["trajectory"]["t"], r["trajectory"]["x"]
    N = x.shape[1]
    fig = motion_figure(r)
    (ax,) = fig.axes
    lines = ax.get_lines()
    assert len(lines) == N + 2
    t0, T = r["limit_attrs"]["start"], r["attrs"]["period"]
    for j in range(N):
        np.testing.assert_array_equal(lines[j].get_xdata(), t / T)
        np.testing.assert_array_equal(lines[j].get_ydata(), x[:, j])
    np.testing.assert_allclose(lines[N].get_ydata(), x.mean(axis=1), rtol=0, atol=1e-14)
    (xs, ys) = lines[N + 1].get_data()
    v0 = r["attrs"]["v0"]
    # Time in periods: the slope in the figure is the displacement per period v0 T.
    assert (ys[1] - ys[0]) / (xs[1] - xs[0]) == pytest.approx(v0 * T, abs=1e-12)
    y_t0 = np.interp(t0, t, x.mean(axis=1))
    assert np.interp(t0 / T, xs, ys) == pytest.approx(y_t0, abs=1e-12)
    (span,) = ax.patches  # axvspan: a Rectangle from matplotlib 3.9, a Polygon before
    span_x = (
        span.get_path().transformed(span.get_patch_transform()).vertices[:, 0]
        if hasattr(span, "get_width")
        else span.get_xy()[:, 0]
    )
    assert (min(span_x), max(span_x)) == pytest.approx((t0 / T, t0 / T + 1))
    assert ax.get_xlim() == (t[0] / T, t[-1] / T)
    assert ax.get_xlabel() == "time $t/T$" and ax.get_ylabel() == "position $x_j/\\ell$"


def test_motion_in_the_files_units(run_file, tmp_path):
    """A results file with ``units_json`` (length mm, time s) is drawn in seconds: the x data are
    the file's times, not t/T, and the labels and the v0 legend carry the units."""
    path = tmp_path / "units.h5"
    shutil.copy(run_file("peristalsis-4"), path)
    with h5py.File(path, "a") as f:
        f.attrs["units_json"] = json.dumps({"length": "mm", "time": "s", "force": "N"})
        f.attrs["period"] = 2.0  # a period of 2 s: t/T would halve the times
    r = read_results(path)
    assert units_of(r) == Units("mm", "s", "N")
    ax = motion_figure(r).axes[0]
    np.testing.assert_array_equal(ax.get_lines()[0].get_xdata(), r["trajectory"]["t"])
    assert ax.get_xlabel() == "time $t$ (s)"
    assert ax.get_ylabel() == "position $x_j$ (mm)"
    assert f"{r['attrs']['v0']:.4g} mm/s" in ax.get_lines()[-1].get_label()
    fig = gait_figure(r)
    assert [a.get_ylabel() for a in fig.axes[1:3]] == ["length $L_i, z_i$ (mm)", "stress $\\sigma_i$ (N)"]
    assert [a.get_ylabel() for a in fig.axes[3:]] == ["$f_{1}$", "$f_{2}$", "$f_{3}$", "$f_{4}$"]
    assert "elastic force on\neach block $f_j$ (N)" in list(_all_texts(fig))
    assert fig.axes[-1].get_xlabel() == "time in the limit period $t - t_0$ (s)"
    _check_labels(fig, Units("mm", "s", "N"))
    assert convergence_figure(r).axes[0].get_ylabel() == "distance $\\Delta w$ (N)"
    assert shape_space_figure(r).axes[0].get_xlabel() == "shape coordinate $w_{1}$ (N)"


def test_motion_inching_closed_form(run_file):
    """inching-2 moves 0.4 a period (gaits/inching-2.yaml: ΔL - (μ1⁺ + μ2⁺)/k = 0.6 - 0.2):
    the v0 line of the figure has that slope, and meets the barycentre at every period start,
    since the gait is periodic from the first period."""
    r = results_of(run_file, "inching-2")
    line = motion_figure(r).axes[0].get_lines()[-1]
    xs, ys = line.get_data()
    assert (ys[1] - ys[0]) / (xs[1] - xs[0]) == pytest.approx(0.4, abs=1e-12)
    t, y = r["trajectory"]["t"], r["trajectory"]["x"].mean(axis=1)
    starts = np.isclose(t % 1.0, 0.0) & (t >= 1.0)
    np.testing.assert_allclose(np.interp(t[starts], xs, ys), y[starts], atol=1e-12)


# --------------------------------------------------------------------------------------------
# 2. Gait diagram


@pytest.mark.parametrize("count", [1, 2, 7, 8, 9, 40, 999])
def test_shown_series_are_evenly_spaced_and_keep_both_ends(count):
    shown = shown_series(count, MAX_SERIES)
    if count <= MAX_SERIES:
        np.testing.assert_array_equal(shown, np.arange(count))
        return
    assert len(shown) == MAX_SERIES and shown[0] == 0 and shown[-1] == count - 1
    gaps = np.diff(shown)
    assert np.all(gaps > 0) and gaps.max() - gaps.min() <= 1


def wave_file(tmp_path, N: int, steps: int = 40) -> Path:
    """A results file of the retrograde cosine wave of N blocks (catch-up, a few periods)."""
    doc = {
        "name": f"wave-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": -i / 10 % 1} for i in range(N - 1)],
        # 1:2.5 keeps the uniqueness condition at every N (|J| = 2.5 (N - |J|) has no
        # integer solution for the N used here, 12 and 41).
        "friction": {"forward": 1.0, "backward": 2.5},
        "simulation": {"steps_per_period": steps, "max_periods": 3, "integrator": "catch-up"},
    }
    out = tmp_path / f"wave-{N}.h5"
    api.run(gait_from_document(doc, f"wave-{N}"), output=out)
    return out


def test_many_blocks_are_drawn_thinned_and_the_slip_pattern_whole(tmp_path):
    """Beyond MAX_SERIES links the line panels draw MAX_SERIES evenly spaced links and blocks
    (the file's own series, named in the legend, whose title says how many of how many), the slip
    panel is still one cell per block and step, and the figure stops growing with N."""
    N = 41
    r = read_results(wave_file(tmp_path, N))
    lim = r["limit"]
    fig = gait_figure(r)
    bands, lengths, stresses, *forces = fig.axes
    (mesh,) = bands.collections
    np.testing.assert_array_equal(np.asarray(mesh.get_array()).reshape(N, -1), lim["slip"].T)
    links, blocks = shown_series(N - 1, MAX_SERIES), shown_series(N, MAX_FORCE_ROWS)
    lines = lengths.get_lines()
    assert len(lines) == 2 * MAX_SERIES
    for k, i in enumerate(links):
        np.testing.assert_array_equal(lines[k].get_ydata(), lim["lengths"][:, i])
        np.testing.assert_array_equal(lines[MAX_SERIES + k].get_ydata(), lim["shape"][:, i])
        assert lines[k].get_label() == f"$L_{{{i + 1}}}$ actuator"
    assert lengths.get_legend().get_title().get_text() == f"{MAX_SERIES} of {N - 1} links"
    # 41 blocks: bounds up to min(20 mu+, 21 mu-) = 20 dwarf the stresses, which are drawn over
    # their bounds (sigma_i / bound), the bounds being the lines +-1.
    low, high = stress_bounds(lim["friction"])
    assert stress_mode(lim["stress"][:, links], low[:, links], high[:, links]) == "relative"
    lines = stresses.get_lines()
    assert len(lines) == MAX_SERIES + 3  # the ratios, the bounds +-1, the zero line
    ratio = relative_stress(lim["stress"], low, high)
    for k, i in enumerate(links):
        np.testing.assert_array_equal(lines[k].get_ydata(), ratio[:, i])
    assert [tuple(line.get_ydata()) for line in lines[MAX_SERIES:]] == [(1, 1), (-1, -1), (0, 0)]
    assert len(forces) == MAX_FORCE_ROWS
    f = block_forces(lim["stress"])
    for ax, j in zip(forces, blocks):
        np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), f[:, j])
        assert ax.get_ylabel() == f"$f_{{{j + 1}}}$"
    assert forces[0].get_legend().get_title().get_text() == f"{MAX_FORCE_ROWS} of {N} blocks"
    ticks = [int(tl.get_text()) for tl in bands.get_yticklabels()]
    assert ticks[0] == 1 and ticks[-1] == N and len(ticks) == 6
    np.testing.assert_array_equal(bands.get_yticks(), np.array(ticks) - 1)
    small = gait_figure(read_results(wave_file(tmp_path, MAX_BAND_LABELS)))
    assert fig.get_size_inches()[1] == small.get_size_inches()[1]

    # beyond MAX_MOTION_BLOCKS blocks the motion figure follows the crawler over its last periods
    assert N > MAX_MOTION_BLOCKS
    motion = motion_figure(r).axes[0]
    assert motion.get_title() == f"wave-{N}: the last {FOLLOW_PERIODS} periods"
    drawn = shown_series(N, 8)
    lines = motion.get_lines()
    assert len(lines) == len(drawn) + 2
    x = r["trajectory"]["x"][r["trajectory"]["t"] >= r["trajectory"]["t"][-1] - FOLLOW_PERIODS - 1e-9]
    for k, j in enumerate(drawn):
        np.testing.assert_array_equal(lines[k].get_ydata(), x[:, j] - x[0, j])
    assert motion.get_legend().get_title().get_text() == f"8 of {N} blocks"
    names = {t.get_text() for t in motion.get_legend().get_texts()}
    assert {f"block {j + 1}" for j in drawn} <= names  # each of the eight, to tell the steps apart


def test_slip_runs_tile_the_period():
    t = np.array([0.0, 0.1, 0.3, 0.6, 1.0])
    runs = slip_runs(np.array([0, 1, 1, -1], dtype=np.int8), t)
    assert runs == [(0, 0.0, 0.1), (1, 0.1, 0.6), (-1, 0.6, 1.0)]


def test_stress_bounds_closed_form():
    """Four blocks, mu^+ = 1, mu^- = 2: sigma_i in [-min(i mu+, (N-i) mu-), min(i mu-, (N-i) mu+)]
    gives [-1, 2], [-2, 2], [-2, 1] for the three links."""
    friction = np.tile(np.r_[np.ones(4), 2 * np.ones(4)], (3, 1))
    low, high = stress_bounds(friction)
    np.testing.assert_array_equal(low, np.tile([-1.0, -2.0, -2.0], (3, 1)))
    np.testing.assert_array_equal(high, np.tile([2.0, 2.0, 1.0], (3, 1)))


def test_block_forces_are_d_transpose_sigma():
    sigma = np.array([[1.0, -2.0, 0.5]])
    D = np.diff(np.eye(4), axis=0)
    np.testing.assert_allclose(block_forces(sigma), sigma @ D)
    assert block_forces(sigma).sum() == pytest.approx(0.0)


def test_figures_ask_the_crawler_of_the_run(run_file):
    """The gait diagram's stress bounds and block forces are the model's (one implementation,
    crawlsim.model.crawler), and on a results file's arrays they give what the compiled
    process's Crawler gives: the file's /limit/stress is sigma = w + K L(t) of its /limit/w,
    its /limit/shape z = -w / k, the bounds those of its /limit/friction, and the forces sum to
    zero on every row (D^T sigma has zero column sums)."""
    assert gait_diagram.stress_bounds is crawler_module.stress_bounds
    assert gait_diagram.block_forces is crawler_module.block_forces
    res = read_results(run_file("peristalsis-4"))
    lim = res["limit"]
    c = compile_gait(with_simulation(load_gait(GAITS / "peristalsis-4.yaml"), steps_per_period=STEPS)).crawler
    assert c is not None and c.blocks == 4
    np.testing.assert_allclose(lim["stress"], c.stress(lim["w"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(lim["shape"], c.shape(lim["w"]), rtol=0, atol=1e-12)
    low, high = stress_bounds(lim["friction"])
    c_low, c_high = c.stress_bounds()
    np.testing.assert_allclose(low, c_low, rtol=0, atol=1e-12)
    np.testing.assert_allclose(high, c_high, rtol=0, atol=1e-12)
    f = block_forces(lim["stress"])
    np.testing.assert_allclose(f, c.block_forces(lim["w"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.sum(axis=1), 0.0, atol=1e-12)
    # the stresses of the limit lie within their bounds (the crawler's state is admissible)
    assert np.all(lim["stress"] >= low - 1e-9) and np.all(lim["stress"] <= high + 1e-9)


def test_relative_stress_closed_form():
    """sigma over its bound on the side of its sign: 1 in [-1, 2] is 1/2, -2 in [-4, 2] is -1/2,
    2 in [-1, 2] is 1 (on its bound), and a bound of 0 holds a stress of 0, drawn as 0. The
    figure switches to ratios when the largest bound exceeds RELATIVE_STRESS_RATIO = 5 times the
    largest stress: 4 <= 5 x 2 keeps stresses, 4 > 5 x 0.2 does not."""
    sigma = np.array([[1.0, -2.0, 0.0, 2.0]])
    low = np.array([[-1.0, -4.0, -1.0, -1.0]])
    high = np.array([[2.0, 2.0, 0.0, 2.0]])
    np.testing.assert_array_equal(relative_stress(sigma, low, high), [[0.5, -0.5, 0.0, 1.0]])
    assert stress_mode(sigma, low, high) == "absolute"
    assert stress_mode(sigma / 10, low, high) == "relative"
    with pytest.raises(ValueError, match="stress='ratio'"):
        gait_figure({}, stress="ratio")


def test_gait_diagram_stress_bounds_in_link_colours(run_file):
    """peristalsis-4 (mu+ = 1, mu- = 2; bounds up to 2, stresses up to 4/3) keeps its stresses;
    each link's two bounds are dotted in its colour, and the one legend entry "friction bounds"
    is drawn in the links' colours (its first dash in link 1's), not in a grey no line has."""
    fig = gait_figure(results_of(run_file, "peristalsis-4"))
    stresses = fig.axes[2]
    assert stresses.get_ylabel() == "stress $\\sigma_i/F$"
    lines = stresses.get_lines()
    for i in range(3):
        sigma, high, low = lines[3 * i : 3 * i + 3]
        assert to_hex(sigma.get_color()) == to_hex(high.get_color()) == to_hex(low.get_color())
        assert to_hex(sigma.get_color()) == to_hex(PALETTE[i])
        assert high.get_linestyle() == low.get_linestyle() == ":"
    legend = stresses.get_legend()
    names = [t.get_text() for t in legend.get_texts()]
    assert names == ["$\\sigma_{1}$", "$\\sigma_{2}$", "$\\sigma_{3}$", "friction bounds"]
    assert to_hex(legend.legend_handles[-1].get_color()) == to_hex(PALETTE[0])


def test_motion_v0_line_visible_and_legend_in_the_order_of_the_curves(run_file):
    """The v0 line meets the barycentre at each period start of the limit: it is drawn as a
    wide translucent band under the (dashed) barycentre, so both show. The legend lists the
    curves from top to bottom as they end on the right (front block first), then the shaded
    limit period."""
    ax = motion_figure(results_of(run_file, "peristalsis-4")).axes[0]
    *blocks, barycentre, slope = ax.get_lines()
    assert slope.get_linewidth() >= 3 * barycentre.get_linewidth()
    assert slope.get_zorder() < min(b.get_zorder() for b in blocks) < barycentre.get_zorder()
    assert slope.get_alpha() < 0.5
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    by_label = {line.get_label(): line for line in ax.get_lines()}
    ends = [float(by_label[name].get_ydata()[-1]) for name in texts[:-1]]
    assert ends == sorted(ends, reverse=True)
    assert texts[0] == "block 4" and texts[-1] == "limit period" and len(texts) == 7


def _inside_axes(fig, ax) -> bool:
    import io

    fig.savefig(io.BytesIO(), format="png")  # lays out and draws: extents are final
    title, box = ax.title.get_window_extent(), ax.get_window_extent()
    return title.x0 >= box.x0 - 1 and title.x1 <= box.x1 + 1


@pytest.mark.parametrize("name", ["smooth-friction-3", "peristalsis-4", "anchoring-2"])
def test_shape_space_title_stays_within_its_axes(run_file, name):
    fig = shape_space_figure(results_of(run_file, name))
    assert _inside_axes(fig, fig.axes[0])


def test_titles_of_a_long_crawler_stay_within_their_axes(tmp_path):
    """A 41-block crawler, named "earthworm-100" (a long name): sections in coordinates (1, 2)
    of 40, the longest shape-space title, and the convergence title with its verdict."""
    path = wave_file(tmp_path, 41)
    with h5py.File(path, "a") as f:
        f.attrs["name"] = "earthworm-100"
    r = read_results(path)
    fig = shape_space_figure(r)
    assert "(1, 2) of 40" in fig.axes[0].get_title()
    assert _inside_axes(fig, fig.axes[0])
    for draw in (motion_figure, convergence_figure):
        fig = draw(r)
        assert "earthworm-100" in fig.axes[0].get_title()
        assert _inside_axes(fig, fig.axes[0])


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize("name", ["peristalsis-4", "smooth-friction-3", "anchoring-2"])
def test_gait_diagram_content(run_file, name, integrator):
    r = read_results(run_file(name, integrator))
    assert r["attrs"]["integrator"] == integrator
    lim = r["limit"]
    t, slip = lim["t"], lim["slip"]
    N = slip.shape[1]
    T = r["attrs"]["period"]
    fig = gait_figure(r, stress="absolute")
    bands, lengths, stresses, *rows = fig.axes
    assert "gait diagram" in fig._suptitle.get_text() and name in fig._suptitle.get_text()

    # Bands: one cell per block and step, the cells of each block tile the period, [0, 1] in
    # (t - t0)/T, on the steps of the file, and their colours are the slip states.
    (mesh,) = bands.collections
    corners = mesh.get_coordinates()
    assert corners.shape == (N + 1, len(t), 2)
    np.testing.assert_array_equal(corners[0, :, 0], t / T)
    np.testing.assert_array_equal(corners[:, 0, 1], np.arange(N + 1) - 0.5)
    np.testing.assert_array_equal(np.asarray(mesh.get_array()).reshape(N, -1), slip.T)
    for state, colour in SLIP_COLOURS.items():
        assert to_hex(mesh.cmap(mesh.norm(state))) == to_hex(colour)
    assert mesh.get_rasterized()
    assert [tl.get_text() for tl in bands.get_yticklabels()] == [f"block {j + 1}" for j in range(N)]

    # Lengths: L_i then z_i, the file's data.
    lines = lengths.get_lines()
    assert len(lines) == 2 * (N - 1)
    for i in range(N - 1):
        np.testing.assert_array_equal(lines[i].get_ydata(), lim["lengths"][:, i])
        np.testing.assert_array_equal(lines[N - 1 + i].get_ydata(), lim["shape"][:, i])
        np.testing.assert_array_equal(lines[i].get_xdata(), t / T)

    # Stresses: sigma_i and its two bounds per link, plus the zero line; within the bounds.
    lines = stresses.get_lines()
    assert len(lines) == 3 * (N - 1) + 1
    low, high = stress_bounds(lim["friction"])
    tol = 1e-9 * np.max(np.abs(lim["stress"]))
    assert np.all(lim["stress"] >= low - tol) and np.all(lim["stress"] <= high + tol)
    for i in range(N - 1):
        np.testing.assert_array_equal(lines[3 * i].get_ydata(), lim["stress"][:, i])

    # Forces: f = D^T sigma, admissible (-mu^- <= f <= mu^+), and on the friction limit, with the
    # sign of the slip, wherever the block is slipping. A catch-up step is a projection, so by
    # complementarity a block that slipped over a step ends it on its face (docs/model.md §3).
    # The exact integrator follows the motion within the step: a block may stop before the step
    # ends, so only the grid points inside a run of slipping steps are surely on the face.
    # One small panel per block (small multiples: forces on the same limit at once are not
    # drawn on top of each other), sharing one force axis: f_j, then mu_j^+ and -mu_j^-.
    assert len(rows) == N
    plus, minus = lim["friction"][:, :N], lim["friction"][:, N:]
    for j, ax in enumerate(rows):
        lines = ax.get_lines()
        assert len(lines) == 3
        np.testing.assert_array_equal(lines[1].get_ydata(), plus[:, j])
        np.testing.assert_array_equal(lines[2].get_ydata(), -minus[:, j])
        assert ax.get_ylim() == rows[0].get_ylim()
    f = np.column_stack([ax.get_lines()[0].get_ydata() for ax in rows])
    np.testing.assert_allclose(f, block_forces(lim["stress"]))
    tol = 1e-9 * max(np.max(np.abs(f)), 1.0)
    assert np.all(f <= plus + tol) and np.all(f >= -minus - tol)
    # Slipping steps are shaded in the slip colours behind each block's force, on the steps of
    # /limit/slip: the runs of slip_runs, stick left blank.
    for j, ax in enumerate(rows):
        spans = [(*_x_extent(p), to_hex(p.get_facecolor())) for p in ax.patches]
        runs = [(a, b, to_hex(SLIP_COLOURS[state])) for state, a, b in slip_runs(slip[:, j], t / T) if state != 0]
        assert [(pytest.approx(a), pytest.approx(b), c) for a, b, c in spans] == runs
    end = f[1:]
    if integrator == "catch-up":
        forward, backward = slip == 1, slip == -1
    else:
        forward = np.zeros_like(slip, dtype=bool)
        backward = np.zeros_like(slip, dtype=bool)
        forward[:-1] = (slip[:-1] == 1) & (slip[1:] == 1)
        backward[:-1] = (slip[:-1] == -1) & (slip[1:] == -1)
    assert np.any(forward)
    np.testing.assert_allclose(end[forward], plus[1:][forward], atol=tol)
    np.testing.assert_allclose(end[backward], -minus[1:][backward], atol=tol)
    assert rows[-1].get_xlim() == (0.0, 1.0)
    assert rows[-1].get_xlabel() == "time in the limit period $(t - t_0)/T$"
    assert stresses.get_ylabel() == "stress $\\sigma_i/F$"
    # The slip bands use none of the series colours of the lines.
    line_colours = {to_hex(l.get_color()) for a in (lengths, stresses, *rows) for l in a.get_lines()}
    assert not line_colours & {to_hex(c) for c in SLIP_COLOURS.values()}


# --------------------------------------------------------------------------------------------
# 3. Convergence


def _tick_texts(axis):
    return [t.get_text() for t in axis.get_ticklabels() if t.get_text()]


def test_convergence_finite_time(run_file):
    """peristalsis-4 is periodic from period 1: the Poincare step and the W^{1,2} distance of
    period 1 are exactly 0, drawn as 0 on a linear axis (no log axis, no "0" tick standing for a
    floor), with the vertical line and the words "periodic from period 1". The lower panel is the
    file's displacement per period, against v0 T."""
    r = results_of(run_file, "peristalsis-4")
    conv, T = r["convergence"], r["attrs"]["period"]
    fig = convergence_figure(r)
    state, motion = fig.axes
    assert state.get_yscale() == "linear" and state.get_ylim()[0] == 0.0
    assert r["attrs"]["periodic_from"] == 1
    poincare, w12, vline = state.get_lines()
    for line, value in ((poincare, conv["poincare_step"]), (w12, conv["w12_distance"])):
        np.testing.assert_array_equal(line.get_xdata(), conv["period"])
        np.testing.assert_array_equal(line.get_ydata(), value)
    assert conv["poincare_step"][1] == 0 and conv["w12_distance"][1] == 0
    # Both are 0 at period 1: the Poincare step's dot is drawn above the distance's open,
    # larger square, so both show.
    assert poincare.get_zorder() > w12.get_zorder()
    assert w12.get_markerfacecolor() == "none" and w12.get_marker() == "s"
    assert poincare.get_marker() == "o" and w12.get_markersize() > poincare.get_markersize()
    np.testing.assert_array_equal(vline.get_xdata(), [1, 1])
    assert "periodic from period 1" in vline.get_label()
    assert any(t.get_text().strip() == "periodic from period 1" for t in state.texts)
    (d,) = [l for l in motion.get_lines() if l.get_label().startswith("$d_q$")]
    (target,) = [l for l in motion.get_lines() if l.get_label().startswith("$v_0T$")]
    np.testing.assert_array_equal(d.get_ydata(), conv["displacement"])
    assert target.get_ydata()[0] == pytest.approx(r["attrs"]["v0"] * T)
    assert motion.get_xlabel() == "period index $q$"
    assert motion.get_ylabel() == "displacement $d_q/\\ell$"
    assert state.get_ylabel() == "distance $\\Delta w/F$"
    # Two periods: the axis holds them with a margin and ticks only at the periods.
    assert [round(v) for v in motion.get_xticks() if -0.5 < v < 1.5] == [0, 1]


def test_convergence_asymptotic_rate_line(run_file):
    """An asymptotic run (synthetic history: Poincare steps 2^-q, the last distance 0 as always
    against the last period) is drawn on a log axis: the geometric decay of the fitted rate, r^q
    through the last step, no finite-time line, the exact 0 left out and no tick labelled 0."""
    r = results_of(run_file, "peristalsis-3")
    q = np.arange(12)
    step = 0.5**q
    w12 = 3 * step
    w12[-1] = 0.0
    r = {
        **r,
        "attrs": {**r["attrs"], "convergence": "asymptotic", "periodic_from": -1, "contraction_rate": 0.5, "v0": 1.0},
        "convergence": {"period": q, "poincare_step": step, "w12_distance": w12, "displacement": 1.0 + step / 7},
    }
    fig = convergence_figure(r)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"
    lines = ax.get_lines()
    assert len(lines) == 3
    np.testing.assert_array_equal(lines[0].get_ydata(), step)
    np.testing.assert_array_equal(np.isnan(lines[1].get_ydata()), w12 == 0)
    fitted = lines[-1]
    np.testing.assert_allclose(fitted.get_ydata(), step, rtol=1e-12)
    assert "0.5" in fitted.get_label()
    assert "asymptotic" in ax.get_title()
    fig.canvas.draw()
    assert "0" not in _tick_texts(ax.yaxis)
    np.testing.assert_allclose(fig.axes[1].get_lines()[0].get_ydata(), 1.0 + step / 7)
    assert not any("periodic from" in l.get_label() for a in fig.axes for l in a.get_lines())


def test_convergence_triangle_rate_one_eighth(run_file):
    """The paper's triangle under wide movements (Section 5, docs/model.md §5) converges only
    asymptotically: one period is phi^3 with phi(z) = (1 - z)/2, a contraction by 1/8. The figure
    draws the fitted rate as a geometric line of ratio 1/8 and no finite-time line."""
    r = results_of(run_file, "paper/triangle")
    assert r["attrs"]["convergence"] == "asymptotic"
    fig = convergence_figure(r)
    assert len(fig.axes) == 1  # a process without a velocity: no displacement panel
    ax = fig.axes[0]
    assert ax.get_yscale() == "log" and ax.get_ylabel() == "distance $\\Delta z$"
    fitted = ax.get_lines()[-1]
    y = fitted.get_ydata()
    np.testing.assert_allclose(y[1:] / y[:-1], r["attrs"]["contraction_rate"], rtol=1e-12)
    assert r["attrs"]["contraction_rate"] == pytest.approx(1 / 8, rel=1e-3)
    assert "0.125" in fitted.get_label()
    assert fitted.get_zorder() > max(l.get_zorder() for l in ax.get_lines()[:2])  # on top
    assert not any("periodic from" in l.get_label() for l in ax.get_lines())
    count = len(r["convergence"]["period"])
    for line in ax.get_lines()[:2]:
        assert line.get_markevery() == marked_periods(count)


# --------------------------------------------------------------------------------------------
# 4. Shape space


def _area(v):
    x, y = v[:, 0], v[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _inside(v, p, tol=1e-9):
    """p is in the convex polygon with counter-clockwise vertices v (boundary included)."""
    edges = np.roll(v, -1, axis=0) - v
    rel = p - v
    return bool(np.all(edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0] >= -tol))


def test_polygon_of_a_square():
    A = np.vstack([np.eye(2), -np.eye(2)])
    v = polygon(A, np.array([1.0, 2.0, 0.0, 0.0]))
    assert len(v) == 4 and _area(v) == pytest.approx(2.0)
    assert _inside(v, np.array([0.5, 1.0])) and not _inside(v, np.array([1.5, 1.0]))
    v = polygon(np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([1.0, 1.0]), box=([-1, -1], [5, 5]))
    assert _area(v) == pytest.approx(4.0)


def _legend_handles_visible(ax):
    """Every legend entry stands for an artist the reader can see: a patch with area, a line
    with extent, or a marker."""
    legend = ax.get_legend()
    for text in legend.get_texts():
        name = text.get_text()
        drawn = [a for a in ax.get_children() if getattr(a, "get_label", lambda: None)() == name]
        assert drawn, name
        for artist in drawn:
            if isinstance(artist, Polygon):
                assert _area(artist.get_xy()[:-1]) > 0, name
            elif hasattr(artist, "get_xydata"):
                xy = np.asarray(artist.get_xydata(), dtype=float)
                xy = xy[np.all(np.isfinite(xy), axis=1)]
                assert len(xy), name
                extent = np.ptp(xy, axis=0).max()
                assert extent > 0 or artist.get_marker() not in (None, "None", ""), name


def _distinct_polygons(polys):
    """No polygon lies on top of another (same vertices): each one drawn is seen."""
    for a in range(len(polys)):
        for b in range(a):
            va, vb = polys[a].get_xy()[:-1], polys[b].get_xy()[:-1]
            assert va.shape != vb.shape or not np.allclose(va, vb, atol=1e-9), (a, b)


def test_shape_space_three_blocks_hexagon(run_file):
    """peristalsis-3 (mu^+ = 1, mu^- = 1.5, k = 10). K(t) + K L(t) is the stress set C: with
    f_1 = -sigma_1, f_2 = sigma_1 - sigma_2, f_3 = sigma_2 the box [-1, 1.5] x [-1.5, 1] (area
    6.25) cut by -1.5 <= sigma_1 - sigma_2 <= 1, which removes corner triangles of legs 2 and 0.5:
    area 6.25 - 2 - 0.125 = 4.125, at every time. The figure draws one polygon per instant of
    `shape_space_instants` (200 steps a period: fifths of the period, labelled as fractions),
    each containing w at its instants, and the orbit lines are the file's w."""
    r = results_of(run_file, "peristalsis-3")
    lim, B = r["limit"], r["process"]["normals"]
    fig = shape_space_figure(r)
    (ax,) = fig.axes
    polys = [p for p in ax.patches if isinstance(p, Polygon)]
    groups = shape_space_instants(lim["t"], r["attrs"]["period"], lambda k: lim["offsets"][k])
    assert [text for _, text in groups] == ["0", "1/5", "2/5", "3/5", "4/5"]
    assert [p.get_label() for p in polys] == [text for _, text in groups]
    lines = ax.get_lines()
    for poly, (members, _) in zip(polys, groups):
        v = poly.get_xy()[:-1]
        assert _area(v) == pytest.approx(4.125, rel=1e-9)
        for k in members:
            assert np.all(v @ B.T <= lim["offsets"][k] + 1e-9)
            sigma = v + 10.0 * lim["lengths"][k]
            f = np.column_stack([-sigma[:, 0], sigma[:, 0] - sigma[:, 1], sigma[:, 1]])
            assert np.all((f <= 1 + 1e-9) & (f >= -1.5 - 1e-9))
            marker = lines.pop(0)
            w = np.array([marker.get_xdata()[0], marker.get_ydata()[0]])
            np.testing.assert_array_equal(w, lim["w"][k])
            assert _inside(v, w)
            assert np.all(B @ w <= lim["offsets"][k] + 1e-9)
    _distinct_polygons(polys)
    assert [l.get_label() for l in lines] == ["earlier periods", "limit cycle", "start $w(0)$"]
    earlier, limit, start = lines
    np.testing.assert_array_equal(limit.get_xdata(), lim["w"][:, 0])
    np.testing.assert_array_equal(limit.get_ydata(), lim["w"][:, 1])
    assert limit.get_linewidth() > 2 * earlier.get_linewidth()
    t, w = r["trajectory"]["t"], r["trajectory"]["w"]
    np.testing.assert_array_equal(earlier.get_xdata(), w[t <= r["limit_attrs"]["start"] + 1e-9, 0])
    assert ax.get_xlabel() == "shape coordinate $w_{1}/F$"
    _legend_handles_visible(ax)


def test_shape_space_acute_angle_every_polygon_seen(tmp_path):
    """The paper's acute angle (Section 5.2, corrected l(t) = (0, t) on [0, T/2], (0, T - t) on
    [T/2, T]) slides down and back up, so C(t) = C(T - t): at 60 steps a period the figure draws
    tenths of the period, merging t and T - t, six distinct polygons whose lower edges z_2 = -l_2(t)
    sit at 0, -0.1, ..., -0.5. The limit is the constant state (gamma, 0) = (1/2, 0), drawn as a
    marker (a zero-length line would be a legend entry with nothing to see)."""
    out = tmp_path / "acute.h5"
    api.run(with_simulation(load_gait(GAITS / "paper/acute-angle.yaml"), steps_per_period=60), output=out)
    r = read_results(out)
    ax = shape_space_figure(r).axes[0]
    polys = [p for p in ax.patches if isinstance(p, Polygon)]
    assert [p.get_label() for p in polys] == ["0", "1/10, 9/10", "1/5, 4/5", "3/10, 7/10", "2/5, 3/5", "1/2"]
    np.testing.assert_allclose([p.get_xy()[:, 1].min() for p in polys], -np.arange(6) / 10, atol=1e-12)
    _distinct_polygons(polys)
    (limit,) = [l for l in ax.get_lines() if l.get_label().startswith("limit")]
    assert limit.get_label() == "limit (a constant state)" and limit.get_marker() == "o"
    np.testing.assert_allclose(limit.get_xydata()[0], [0.5, 0.0], atol=1e-9)
    assert ax.get_xlabel() == "shape coordinate $z_{1}$"
    assert "C(t)" in ax.get_legend().get_title().get_text()
    _legend_handles_visible(ax)


def test_shape_space_instants():
    """Instants at exact fractions of the period, sets that coincide merged: a set placed by
    |sin 2 pi t| is at the same place at t, T/2 - t, T/2 + t and T - t: on a 64-step grid the
    eighths are exact, with 3 distinct sets (0 and 1/2; 1/8, 3/8, 5/8, 7/8; 1/4 and 3/4); a
    7-step grid (no division but 1 holds) falls back to the grid times, labelled by value."""
    t = np.linspace(0.0, 1.0, 65)
    key = np.abs(np.sin(2 * np.pi * t)).round(12)
    groups = shape_space_instants(t, 1.0, lambda k: key[k : k + 1])
    assert groups == [([0, 32], "0, 1/2"), ([8, 24, 40, 56], "1/8, 3/8, 5/8, 7/8"), ([16, 48], "1/4, 3/4")]
    t = np.linspace(0.0, 2.0, 8)
    groups = shape_space_instants(t, 2.0, lambda k: t[k : k + 1])
    kept = [0, 1, 2, 4, 5, 6]  # round(linspace(0, 7, 7)), 3.5 rounding to even
    assert groups == [([k], f"{k / 7:.4g}") for k in kept]


def test_shape_space_sections_four_blocks(run_file):
    """peristalsis-4 has a 3-D shape space: each polygon is the section of K(t) through w(t) in
    the chosen coordinates, so it contains the projected w(t) at each of its instants, and every
    vertex completed with the other coordinate of w(t) satisfies B w <= c(t)."""
    r = results_of(run_file, "peristalsis-4")
    lim, B = r["limit"], r["process"]["normals"]
    ax = shape_space_figure(r, coords=(0, 2)).axes[0]
    assert "(1, 3) of 3" in ax.get_title()
    assert ax.get_ylabel() == "shape coordinate $w_{3}/F$"
    polys = [p for p in ax.patches if isinstance(p, Polygon)]
    assert 2 <= len(polys) <= 6
    G = len(lim["t"]) - 1  # a cosine gait: the grid is uniform, instant j/n is index G j/n
    for poly in polys:
        v = poly.get_xy()[:-1]
        for text in poly.get_label().split(", "):
            k = int(Fraction(text) * G)
            full = np.column_stack([v[:, 0], np.full(len(v), lim["w"][k, 1]), v[:, 1]])
            assert np.all(full @ B.T <= lim["offsets"][k] + 1e-9)
            assert _inside(v, lim["w"][k, [0, 2]])
    _distinct_polygons(polys)
    with pytest.raises(ValueError, match="between 1 and 3"):
        shape_space_figure(r, coords=(0, 3))


def test_shape_space_section_without_interior(run_file):
    """A state on a face of K(t) that maximises w_2 (a vertex or an edge: no row of
    B = [D^T; -D^T] of four blocks has the normal e_2) cuts K(t) in the plane of w_1, w_3 in a
    segment or a point. Such a section has no polygon: its instants get their markers and a
    legend entry that says so, instead of the figure failing (long crawlers meet this often)."""
    r = copy.deepcopy(results_of(run_file, "peristalsis-4"))
    lim, B = r["limit"], r["process"]["normals"]
    extreme = []
    for c in lim["offsets"]:
        res = linprog([0.0, -1.0, 0.0], A_ub=B, b_ub=c, bounds=[(None, None)] * 3, method="highs")
        assert res.status == 0
        extreme.append(res.x)
    lim["w"] = np.array(extreme)
    ax = shape_space_figure(r, coords=(0, 2)).axes[0]
    assert not [p for p in ax.patches if isinstance(p, Polygon)]
    labels = ax.get_legend_handles_labels()[1]
    flagged = [s for s in labels if s.endswith("(section without interior)")]
    assert 2 <= len(flagged) <= 6
    with pytest.raises(ValueError, match="empty interior"):
        polygon(*section(B, lim["offsets"][0], lim["w"][0], (0, 2)))


def test_shape_space_two_blocks_interval(run_file):
    """inching-2: with f_1 = -sigma, f_2 = sigma, sigma ranges over
    [-min(mu_1^+, mu_2^-), min(mu_1^-, mu_2^+)] = [-1, 1]: K(t) is an interval of width 2."""
    r = results_of(run_file, "inching-2")
    ax = shape_space_figure(r).axes[0]
    (band,) = [c for c in ax.collections if isinstance(c, PolyCollection)]
    lines = ax.get_lines()
    high, low = lines[0].get_ydata(), lines[1].get_ydata()
    np.testing.assert_allclose(high - low, 2.0, rtol=1e-12)
    limit = [l for l in lines if l.get_label() == "limit cycle"][0]
    np.testing.assert_array_equal(limit.get_ydata(), r["limit"]["w"][:, 0])
    assert np.all((limit.get_ydata() >= low - 1e-9) & (limit.get_ydata() <= high + 1e-9))


# --------------------------------------------------------------------------------------------
# 5. Sweeps


def test_sweep_one_parameter():
    """v0 at the swept points (the line breaks where there is none), failed and invalid points
    marked on the parameter axis, a tick at every swept value."""
    values = np.linspace(1.0, 3.0, 5)
    v0 = np.array([0.1, 0.2, np.nan, 0.4, np.nan])
    status = np.array(["ok", "ok", "failed", "not-converged", "invalid"], dtype=object)
    fig = sweep_figure({"friction.backward": values}, v0, status, "inching-2: v0 sweep")
    (ax,) = fig.axes
    curve = ax.get_lines()[0]
    np.testing.assert_array_equal(curve.get_xdata(), values)
    np.testing.assert_array_equal(curve.get_ydata(), v0)
    marks = {l.get_label(): l for l in ax.get_lines()[1:]}
    np.testing.assert_array_equal(marks["failed"].get_xdata(), [2.0])
    np.testing.assert_array_equal(marks["invalid gait"].get_xdata(), [3.0])
    np.testing.assert_array_equal(marks["not converged"].get_xydata(), [[2.5, 0.4]])
    np.testing.assert_array_equal(ax.get_xticks(), values)
    assert ax.get_xlabel() == "friction.backward ($F$)"
    assert ax.get_ylabel() == "average velocity $v_0$"
    assert ax.get_title() == "inching-2: v0 sweep"
    # Given the displacement per period (and no time unit), that is what is drawn: v0 T / l.
    fig = sweep_figure({"links.1.phase": values}, v0, status == "failed", "t", displacement=2 * v0)
    ax = fig.axes[0]
    np.testing.assert_array_equal(
        ax.get_lines()[0].get_ydata(), np.where(np.isin(status, ["ok", "not-converged"]), 2 * v0, np.nan)
    )
    assert ax.get_ylabel() == "displacement per period $v_0T/\\ell$"
    assert ax.get_xlabel() == "links.1.phase (cycles)"


def test_sweep_two_parameters_heatmap():
    """Cells centred on the swept values, ticks at the swept values, the one colour map, the
    contour v0 = 0 where v0 changes sign, hatched cells with a status marker where there is no
    value, and the units on every axis."""
    a, b = np.array([1.0, 2.0, 3.0]), np.array([0.5, 1.0])
    v0 = np.array([[0.1, -0.2], [np.nan, 0.4], [0.5, np.nan]])
    status = np.array([["ok", "ok"], ["failed", "ok"], ["ok", "invalid"]], dtype=object)
    units = Units(length="mm", time="s", force="N")
    fig = sweep_figure({"friction.backward": a, "links.0.amplitude": b}, v0, status, "sweep", units=units)
    ax, bar = fig.axes
    (mesh,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    data = np.ma.filled(mesh.get_array(), np.nan).reshape(2, 3)
    np.testing.assert_array_equal(np.isnan(data), np.isnan(v0.T))
    np.testing.assert_array_equal(data[~np.isnan(data)], v0.T[~np.isnan(v0.T)])
    assert mesh.get_cmap().name.startswith(COLOUR_MAP)
    xe, ye = mesh.get_coordinates()[0, :, 0], mesh.get_coordinates()[:, 0, 1]
    np.testing.assert_allclose((xe[1:] + xe[:-1]) / 2, a)
    np.testing.assert_allclose((ye[1:] + ye[:-1]) / 2, b)
    np.testing.assert_array_equal(ax.get_xticks(), a)
    np.testing.assert_array_equal(ax.get_yticks(), b)
    hatched = [p for p in ax.patches if isinstance(p, Rectangle) and p.get_hatch()]
    assert sorted((p.get_x() + p.get_width() / 2, p.get_y() + p.get_height() / 2) for p in hatched) == [
        (2.0, 0.5),
        (3.0, 1.0),
    ]
    marks = {l.get_label(): l.get_xydata().tolist() for l in ax.get_lines()}
    assert marks == {"failed": [[2.0, 0.5]], "invalid gait": [[3.0, 1.0]]}
    # v0 changes sign between (1, 0.5) and (1, 1), but every square of the grid has a corner
    # without a value, so there is no square to interpolate a zero in: no contour.
    assert len(ax.collections) == 1
    assert ax.get_xlabel() == "friction.backward (N)"
    assert ax.get_ylabel() == "links.0.amplitude (mm)"
    assert bar.get_ylabel() == "average velocity $v_0$ (mm/s)"
    one_sign = sweep_figure({"a": a, "b": b}, np.abs(np.nan_to_num(v0)), np.zeros((3, 2), bool), "s")
    assert len(one_sign.axes[0].collections) == 1  # no contour when v0 keeps its sign


def test_jumps_closed_forms():
    """A line and a kink are continuous; a step from -0.4 to +0.4 between 0.375 and 0.5 is one
    jump, whatever the slope beside it; three values are too few to tell."""
    x = np.linspace(0.0, 1.0, 9)
    assert not jumps(x, 2 * x + 1).any()
    assert not jumps(x, np.abs(x - 0.5)).any()
    step = np.where(x < 0.45, -0.4, 0.4) + 0.01 * x
    np.testing.assert_array_equal(jumps(x, step), x[:-1] == 0.375)
    assert not jumps(x[:3], step[:3]).any()
    # At an end a saturating curve (1 - e^{-8x}) changes far more than beside it: no jump; a
    # step in the first interval cannot be told from it.
    assert not jumps(x, 1 - np.exp(-8 * x)).any()
    assert not jumps(x, np.where(x < 0.1, 0.0, 1.0)).any()
    # Each row of a 2-D array on its own; a log axis takes slopes in log space.
    np.testing.assert_array_equal(jumps(x, np.vstack([step, 2 * x])), [x[:-1] == 0.375, np.zeros(8, bool)])
    g = np.geomspace(1, 100, 7)
    assert not jumps(g, np.log(g), log=True).any()


def _jump_grid():
    """v0 = (x - 0.3)/2 on x < 0.55, and 0.8 less beyond: a smooth zero at x = 0.3, and a jump
    from +0.1 (x = 0.5) to -0.6375 (x = 0.625) where v0 changes sign too."""
    x, y = np.linspace(0.0, 1.0, 9), np.linspace(0.0, 1.0, 5)
    v0 = np.repeat((0.5 * (x - 0.3) - 0.8 * (x > 0.55))[:, None], len(y), axis=1)
    return x, y, v0


def test_zero_contour_is_not_drawn_across_a_jump():
    """The contour v0 = 0 is the smooth zero at x = 0.3 alone (linear data: the interpolated
    crossings are exact), nothing at the jump; the jump is a wall on the cell boundary between
    0.5 and 0.625 (x = 0.5625), across the whole y range."""
    from matplotlib.collections import LineCollection

    x, y, v0 = _jump_grid()
    fig = sweep_figure({"a": x, "b": y}, v0, np.full(v0.shape, "ok", dtype=object), "jump")
    ax = fig.axes[0]
    contour, wall = [c for c in ax.collections if isinstance(c, LineCollection)]
    points = np.concatenate(contour.get_segments())
    np.testing.assert_allclose(points[:, 0], 0.3, rtol=0, atol=1e-12)
    assert points[:, 1].min() == 0.0 and points[:, 1].max() == 1.0
    walls = np.concatenate(wall.get_segments())
    np.testing.assert_allclose(walls[:, 0], 0.5625, rtol=0, atol=1e-12)
    assert walls[:, 1].min() == pytest.approx(-0.125) and walls[:, 1].max() == pytest.approx(1.125)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["$v_0$ = 0", "jump of $v_0$"]
    # The same sweep along one parameter: the line breaks at the jump (a NaN between 0.5 and
    # 0.625), and the jump is a dotted vertical at its middle.
    fig = sweep_figure({"a": x}, v0[:, 0], np.full(9, "ok", dtype=object), "jump")
    curve, jump = fig.axes[0].get_lines()[:2]
    assert np.count_nonzero(np.isnan(curve.get_xdata())) == 1
    assert np.isnan(curve.get_xdata()[5]) and np.isnan(curve.get_ydata()[5])
    np.testing.assert_allclose(jump.get_xdata(), [0.5625, 0.5625])
    np.testing.assert_allclose(jump.get_ydata(), [v0[4, 0], v0[5, 0]])
    assert jump.get_label() == "jump of $v_0$"


def test_zero_contour_saddle_and_log_axes():
    """On a saddle square (v0 = x y on [-1, 1]^2, shifted) the crossings are paired, never
    crossing the square; on log axes the crossings are interpolated in log space: v0 = log10 x
    - 1 is zero at x = 10 exactly."""
    x = np.array([1.0, 100.0])
    y = np.array([1.0, 2.0])
    v0 = np.log10(x)[:, None] - 1 + 0 * y[None, :]
    (segment,) = zero_contour(x, y, v0, np.zeros((1, 2), bool), np.zeros((2, 1), bool), (True, False))
    np.testing.assert_allclose(segment[:, 0], 10.0)
    v0 = np.array([[1.0, -1.0], [-1.0, 1.0]])
    segments = zero_contour([0.0, 1.0], [0.0, 1.0], v0, np.zeros((1, 2), bool), np.zeros((2, 1), bool))
    assert len(segments) == 2
    np.testing.assert_allclose(np.sort(np.concatenate(segments).ravel()), [0, 0, 0.5, 0.5, 0.5, 0.5, 1, 1])


def test_sweep_ticks_and_cells():
    """Long axes keep a labelled tick on every k-th value (both ends when k allows), the others
    minor; log-spaced values give a log axis with cells centred in log space."""
    major, minor = swept_ticks(np.linspace(0, 1, 21))
    np.testing.assert_allclose(major, np.linspace(0, 1, 6))
    assert len(minor) == 15
    major, minor = swept_ticks(np.arange(5.0))
    np.testing.assert_array_equal(major, np.arange(5.0))
    assert minor.size == 0
    assert is_geometric(np.geomspace(0.1, 10, 9)) and not is_geometric(np.linspace(1, 9, 9))
    np.testing.assert_allclose(cell_edges(np.array([1.0, 2.0, 4.0])), [0.5, 1.5, 3.0, 5.0])
    edges = cell_edges(np.geomspace(1, 100, 3), log=True)
    np.testing.assert_allclose(edges, np.sqrt(10) * np.array([0.1, 1, 10, 100]))
    fig = sweep_figure(
        {"stiffness": np.geomspace(1, 100, 3), "period": [1.0, 2.0]}, np.ones((3, 2)), np.zeros((3, 2), bool), "log"
    )
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "linear"
    np.testing.assert_allclose(ax.get_xticks(), [1, 10, 100])
    assert ax.get_xlabel() == "stiffness ($F$/$\\ell$)" and ax.get_ylabel() == "period"


def test_sweep_file_plot(tmp_path):
    """`crawlsim plot` on a sweep file draws its one figure (the sweep of `crawlsim velocity`,
    with its units when the gait file gives them): the heat map holds the file's values."""
    from crawlsim.io.sweepfile import write_sweep

    a, b = np.array([1.5, 2.0, 2.5]), np.array([5.0, 10.0])
    v0 = np.array([0.1, 0.2, np.nan, 0.4, 0.5, 0.6])
    status = np.array(["ok", "ok", "invalid", "ok", "ok", "not-converged"], dtype=object)
    path = tmp_path / "grid.h5"
    write_sweep(
        path,
        paths=["friction.backward", "stiffness"],
        axes=[a, b],
        points=np.arange(6),
        columns={
            "friction.backward": np.repeat(a, 2),
            "stiffness": np.tile(b, 3),
            "v0": v0,
            "displacement_per_period": 2 * v0,
            "convergence": np.array(["finite-time"] * 6, dtype=object),
            "periods": np.full(6, 2),
            "status": status,
            "message": np.array([""] * 6, dtype=object),
        },
        gait_yaml="name: wave\nunits: {length: mm, force: N}\n",
        source="wave.yaml",
        shard="",
        steps=np.full(6, 10),
    )
    result = CliRunner().invoke(main, ["plot", str(path), "-o", str(tmp_path / "figs")])
    assert result.exit_code == 0, result.output
    (out,) = (tmp_path / "figs").iterdir()
    assert out.name == "grid-sweep.png" and result.output.strip() == str(out)
    from crawlsim.io.sweepfile import read_sweep
    from crawlsim.plotting import sweep_data_figure

    fig = sweep_data_figure(read_sweep(path))
    ax, bar = fig.axes
    (mesh,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    data = np.ma.filled(mesh.get_array(), np.nan).reshape(2, 3)
    expected = np.where(status == "invalid", np.nan, 2 * v0).reshape(3, 2).T
    np.testing.assert_array_equal(data, expected)
    assert bar.get_ylabel() == "displacement per period $v_0T$ (mm)"
    assert ax.get_xlabel() == "friction.backward (N)"
    assert ax.get_ylabel() == "stiffness (N/mm)"
    assert ax.get_title() == "wave: average velocity over a sweep"
    result = CliRunner().invoke(main, ["plot", str(path), "--only", "motion"])
    assert result.exit_code == 2 and "sweep" in result.output


def test_sweep_bad_shapes():
    with pytest.raises(ValueError, match="one or two"):
        sweep_figure({"a": [1], "b": [1], "c": [1]}, np.zeros((1, 1, 1)), np.zeros((1, 1, 1), bool), "t")
    with pytest.raises(ValueError, match="grid's shape"):
        sweep_figure({"a": [1, 2]}, np.zeros(3), np.zeros(3, bool), "t")


# --------------------------------------------------------------------------------------------
# Command line


def test_cli_plot_formats_and_only(run_file, tmp_path):
    path = run_file("peristalsis-3")
    result = CliRunner().invoke(
        main, ["plot", str(path), "-o", str(tmp_path / "figs"), "--format", "svg", "--only", "gait-diagram"]
    )
    assert result.exit_code == 0, result.output
    (out,) = (tmp_path / "figs").iterdir()
    assert out.name == "peristalsis-3-gait-diagram.svg"
    assert result.output.strip() == str(out)
    assert b"<svg" in out.read_bytes()[:500]


def test_cli_run_plot(tmp_path):
    gait = tmp_path / "inching-2.yaml"
    gait.write_text((GAITS / "inching-2.yaml").read_text())
    out = tmp_path / "run.h5"
    result = CliRunner().invoke(main, ["run", str(gait), "-o", str(out), "--plot", "--steps-per-period", "50"])
    assert result.exit_code == 0, result.output
    for name in FIGURE_NAMES:
        assert (tmp_path / f"run-{name}.png").stat().st_size > 1000
        assert f"run-{name}.png" in result.output


def _without(src: Path, dst: Path, dataset: str) -> Path:
    shutil.copy(src, dst)
    with h5py.File(dst, "a") as f:
        del f[dataset]
    return dst


@pytest.mark.parametrize(
    "dataset, only, message",
    [
        ("limit/lengths", "gait-diagram", "/limit/lengths"),
        ("limit/friction", None, "/limit/friction"),
        ("process", "shape-space", "/process/normals"),
        ("trajectory/x", "motion", "/trajectory/x"),
        ("convergence", None, "missing group /convergence"),
    ],
)
def test_cli_missing_data_exit_2(run_file, tmp_path, dataset, only, message):
    """A figure that cannot be drawn: exit 2, a message naming the file and what is missing, no
    traceback, and no figure written (not even the ones that could be drawn)."""
    bad = _without(run_file("peristalsis-3"), tmp_path / "bad.h5", dataset)
    args = ["plot", str(bad)] + (["--only", only] if only else [])
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2
    assert message in result.output and str(bad) in result.output
    assert "Traceback" not in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.h5"]


def test_cli_wrong_files_exit_2(tmp_path):
    not_h5 = tmp_path / "notes.txt"
    not_h5.write_text("name: x\n")
    gait = tmp_path / "gait.yaml"
    gait.write_text("name: x\n")
    empty = tmp_path / "empty.h5"
    h5py.File(empty, "w").close()
    for path, message in (
        (tmp_path / "none.h5", "no such results file"),
        (not_h5, "not an HDF5 file"),
        (gait, f"{gait}: a gait file, not a results file: `crawlsim run {gait} --plot` runs it"),
        (empty, "not a crawlsim results file"),
    ):
        result = CliRunner().invoke(main, ["plot", str(path)])
        assert result.exit_code == 2 and message in result.output, result.output


def test_cli_bad_coords(run_file):
    path = run_file("peristalsis-4")
    result = CliRunner().invoke(main, ["plot", str(path), "--coords", "1,4"])
    assert result.exit_code == 2 and "between 1 and 3" in result.output
    result = CliRunner().invoke(main, ["plot", str(path), "--coords", "2,2"])
    assert result.exit_code == 2 and "--coords" in result.output


def test_generic_process_skips_crawler_figures(run_file):
    r = results_of(run_file, "peristalsis-3")
    assert available_figures(r) == list(FIGURE_NAMES)
    generic = {**r, "attrs": {**r["attrs"], "kind": "sweeping-process"}}
    assert available_figures(generic) == ["convergence", "shape-space"]


def _x_extent(patch) -> tuple[float, float]:
    """The x range of an axvspan: a Rectangle from matplotlib 3.9, a Polygon before."""
    if hasattr(patch, "get_width"):
        return patch.get_x(), patch.get_x() + patch.get_width()
    x = np.asarray(patch.get_xy())[:, 0]
    return float(x.min()), float(x.max())


# --------------------------------------------------------------------------------------------
# Result objects: crawlsim.plotting.motion_figure(crawlsim.simulate(gait))


def _drawn(fig):
    """What a figure shows, in drawing order: every line's data, every polygon's vertices, and
    every text."""
    lines = [np.asarray(line.get_xydata(), dtype=float) for ax in fig.axes for line in ax.get_lines()]
    polygons = [np.asarray(p.get_xy(), dtype=float) for p in fig.findobj(Polygon)]
    return lines, polygons, sorted(_all_texts(fig))


@pytest.mark.parametrize("name", ["peristalsis-4", "paper/triangle"])
def test_figures_of_a_result_object_are_those_of_its_file(name, tmp_path):
    """A figure of the result of crawlsim.simulate is the figure of the results file of the same
    run: the same lines (to 1e-12), polygons and texts, for every figure of the run; the
    converted result holds the file's datasets that the figures read, to 1e-12."""
    gait = with_simulation(load_gait(GAITS / f"{name}.yaml"), steps_per_period=STEPS)
    result = api.simulate(gait)
    path = tmp_path / "run.h5"
    written = api.run(gait, output=path)
    stored = read_results(path)
    # A result that wrote a file is drawn from it (its object keeps no trajectory).
    assert run_data(written)["attrs"]["gait_yaml"] == stored["attrs"]["gait_yaml"]
    data = run_data(result)
    for group, names in (
        ("limit", ("t", "w", "offsets", "lengths", "friction", "x", "slip")),
        ("trajectory", ("t", "w", "x")),
        ("convergence", ("period", "poincare_step", "w12_distance")),
        ("process", ("normals",)),
    ):
        for key in names:
            if key in stored[group]:
                np.testing.assert_allclose(
                    data[group][key], stored[group][key], rtol=1e-12, atol=1e-12, err_msg=f"{group}/{key}"
                )
            else:
                assert key not in data[group], f"{group}/{key}"
    for key in ("name", "kind", "convergence", "periodic_from"):
        assert data["attrs"][key] == stored["attrs"][key], key
    assert available_figures(data) == available_figures(stored)
    for figure in available_figures(stored):
        function = {
            "motion": motion_figure,
            "gait-diagram": gait_figure,
            "kymograph": kymograph_figure,
            "convergence": convergence_figure,
            "shape-space": shape_space_figure,
        }[figure]
        (lines, polygons, texts), (file_lines, file_polygons, file_texts) = (
            _drawn(function(result)),
            _drawn(function(stored)),
        )
        assert texts == file_texts, figure
        assert len(lines) == len(file_lines) and len(polygons) == len(file_polygons), figure
        for a, b in zip(lines + polygons, file_lines + file_polygons):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=figure)
    # A path is read: the same figure as its dict.
    assert _drawn(convergence_figure(str(path)))[2] == _drawn(convergence_figure(stored))[2]


def test_a_result_without_trajectory_says_what_to_do():
    """crawlsim.api.run without output keeps no trajectory: the motion figure says so and how to
    get one; the gait diagram (limit period only) is drawn; anything else is a TypeError."""
    gait = with_simulation(load_gait(GAITS / "peristalsis-4.yaml"), steps_per_period=STEPS)
    result = api.run(gait)
    with pytest.raises(
        ResultsFileError,
        match=r"needs /trajectory/t, which is missing \(this "
        r"result keeps no trajectory: use crawlsim\."
        r"simulate",
    ):
        motion_figure(result)
    fig = gait_figure(result)
    assert fig._suptitle.get_text() == "peristalsis-4: gait diagram over the limit period"
    with pytest.raises(TypeError, match="takes a results file.*got int"):
        motion_figure(3)


def test_convergence_markers_thinned_beyond_the_transient():
    """Every one of the first 10 periods has a marker, then 30 evenly spaced ones with the last;
    the lines still join every period."""
    assert marked_periods(4) == [0, 1, 2, 3]
    assert marked_periods(30) == list(range(30))
    marked = marked_periods(100)
    assert marked[:10] == list(range(10)) and marked[-1] == 99
    assert set(shown_series(100, MAX_MARKERS)) <= set(marked) and len(marked) <= 10 + MAX_MARKERS
    steps = np.diff([m for m in marked if m >= 10])
    assert steps.max() - steps.min() <= 1  # evenly spaced, to rounding


def test_pareto_title_stays_within_its_axes():
    """The Pareto front's title says what is drawn against what (cost of transport against v0)
    and lists the free parameters on wrapped lines of their own: with five long dotted paths it
    stays within the axes (one line ran past both ends of the axes)."""
    from crawlsim.plotting import pareto_figure

    paths = ["links.1.phase", "links.2.phase", "links.*.amplitude", "friction.backward", "loads.slope.angle"]
    v0 = np.linspace(0.1, 0.7, 7)
    data = {
        "attrs": {"name": "peristalsis-4", "units_json": "{}", "free_json": json.dumps([{"path": p} for p in paths])},
        "evaluations": {"v0": v0, "cost_of_transport": 4 + v0, "status": ["ok"] * 7},
        "front": {"v0": v0[::2], "cost_of_transport": 4 + v0[::2], "chosen": np.array([True, False, False, True])},
    }
    fig = pareto_figure(data)
    text = fig.axes[0].get_title()
    first, *rest = text.split("\n")
    assert first == "peristalsis-4: cost of transport against $v_0$"
    assert " ".join(rest).replace("over ", "", 1).split(", ") == paths
    assert len(rest) >= 2
    assert _inside_axes(fig, fig.axes[0])


# --------------------------------------------------------------------------------------------
# Large crawlers (issue 35): the kymograph, the motion figure following the crawler


@pytest.mark.parametrize("N", [4, 41])
def test_the_kymograph_is_the_limit_period_over_the_body(tmp_path, N):
    """Three images over (time, index): the strain z_i / mean(z_i) - 1 of every link, the slip
    state of every block, the stress of every link, exactly the file's /limit datasets, at 4 and
    at 41 blocks alike; with last=2, the last two periods of the trajectory (the slip states the
    signs of the blocks' displacements, the strains over that window's means)."""
    from crawlsim.plotting.kymograph import kymograph_figure
    from crawlsim.plotting.source import step_slip

    r = read_results(wave_file(tmp_path, N))
    lim = r["limit"]
    strain, slip, stress = kymograph_figure(r).axes[:3]
    z = lim["shape"]
    for ax, expected in ((strain, (z / z.mean(axis=0) - 1).T), (slip, lim["slip"].T), (stress, lim["stress"].T)):
        (mesh,) = ax.collections
        np.testing.assert_array_equal(np.asarray(mesh.get_array()).reshape(expected.shape), expected)
    assert [strain.get_ylabel(), slip.get_ylabel(), stress.get_ylabel()] == ["link $i$", "block $j$", "link $i$"]
    assert slip.get_ylim() == (0.5, N + 0.5) and strain.get_ylim() == (0.5, N - 0.5)
    tr = r["trajectory"]
    window = tr["t"] >= tr["t"][-1] - 2 - 1e-9
    last = kymograph_figure(r, last=2)
    strain, slip, _ = last.axes[:3]
    z = np.diff(tr["x"][window], axis=1)
    np.testing.assert_array_equal(
        np.asarray(strain.collections[0].get_array()).ravel(), (z / z.mean(axis=0) - 1).T.ravel()
    )
    np.testing.assert_array_equal(
        np.asarray(slip.collections[0].get_array()).ravel(), step_slip(tr["x"][window]).T.ravel()
    )
    assert strain.get_xlim() == (tr["t"][-1] - 2, tr["t"][-1])
    assert last._suptitle.get_text() == f"wave-{N}: kymograph, the last 2 periods"


def test_the_motion_figure_follows_the_crawler_over_the_last_period(run_file):
    """peristalsis-4 is periodic from period 1: over its last period every block advances by
    the same v0 T (the shape repeats), which the figure following the crawler shows as lines
    from 0 to v0 T, the barycentre's among them, and the slope line from 0 at t_a."""
    r = results_of(run_file, "peristalsis-4")
    v0, T = float(r["attrs"]["v0"]), 1.0
    ax = motion_figure(r, last=1).axes[0]
    assert ax.get_ylabel() == "displacement $\\Delta x_j/\\ell$"
    lines = ax.get_lines()
    for line in lines[:5]:  # four blocks and the barycentre
        y = np.asarray(line.get_ydata())
        assert y[0] == 0.0 and y[-1] == pytest.approx(v0 * T, abs=1e-12)
    slope = np.asarray(lines[5].get_ydata())
    assert slope[0] == 0.0 and slope[-1] == pytest.approx(v0 * T, abs=1e-12)
    assert ax.get_xlim() == (1.0, 2.0)


def test_a_narrow_figure_keeps_most_of_its_width_for_the_plot(run_file, tmp_path):
    """--figsize 3.4,2.4 left the motion plot 40 % of the width, the legend on its right taking
    the rest; a figure narrower than NARROW gets the legend below, in columns."""
    from crawlsim.plotting import save_figure

    fig = motion_figure(results_of(run_file, "peristalsis-4"))
    save_figure(fig, tmp_path / "m.png", figsize=(3.4, 2.4))
    assert fig.axes[0].get_position().width > 0.75
    assert fig.axes[0].get_legend() is None and len(fig.legends) == 1
    assert [t.get_text() for t in fig.legends[0].get_texts()][:2] == ["block 4", "block 3"]


def test_plot_methods_of_results_and_sweeps(run_file, tmp_path):
    """result.plot(), grid.crawlsim.plot() (the Dataset of crawlsim.sweep; without xarray, the
    SweepTable it returns then, grid.plot()) and table.plot() draw what crawlsim plot draws,
    without importing crawlsim.plotting."""
    import crawlsim
    from crawlsim.study.table import SweepTable, read_table

    result = crawlsim.open_run(run_file("peristalsis-4"))
    assert result.plot().axes[0].get_title() == "peristalsis-4: block positions"
    assert result.plot("kymograph", last=1)._suptitle.get_text() == "peristalsis-4: kymograph, the last 1 period"
    with pytest.raises(ValueError, match="unknown figure"):
        result.plot("motions")
    out = tmp_path / "s.h5"
    grid = crawlsim.sweep(GAITS / "inching-2-towing.yaml", {"loads.force.0": [0.0, -0.4, -0.8, -1.2, -1.6]}, output=out)
    first = grid.plot() if isinstance(grid, SweepTable) else grid.crawlsim.plot()
    for fig in (first, read_table(out).plot()):
        ax = fig.axes[0]
        assert ax.get_xlabel() == "loads.force.0 ($F$)"
        assert "stall force -1 (jump)" in [t.get_text() for t in ax.get_legend().get_texts()]
