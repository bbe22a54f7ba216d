"""Figures: every figure of every example gait is drawn, and its content is checked against the
results file and against closed forms of the crawler model (MODEL.md §1-2).

Runs use 200 steps a period: the figures' content is compared with the file they are drawn from,
so the step size does not matter, and the closed forms below hold on any grid.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.collections import PolyCollection, QuadMesh
from matplotlib.colors import to_hex
from matplotlib.patches import Polygon, Rectangle

from crawlsim import api
from crawlsim.cli import main
from crawlsim.gait import load_gait, with_simulation
from crawlsim.h5io import read_results
from crawlsim.plotting import (
    FIGURE_NAMES,
    available_figures,
    convergence_figure,
    gait_figure,
    motion_figure,
    plot_results,
    shape_space_figure,
    sweep_figure,
)
from crawlsim.plotting.figures import block_forces, polygon, slip_runs, stress_bounds, zero_floor
from crawlsim.plotting.style import DIMENSIONLESS, SLIP_COLOURS

GAITS = Path(__file__).resolve().parents[1] / "gaits"
GAIT_FILES = sorted(GAITS.rglob("*.yaml"))
STEPS = 200


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """Path of a 200-step run of a gait file, computed once per gait."""
    folder = tmp_path_factory.mktemp("runs")
    cache = {}

    def get(name: str) -> Path:
        if name not in cache:
            out = folder / f"{Path(name).name}.h5"
            api.run(with_simulation(load_gait(GAITS / f"{name}.yaml"), steps_per_period=STEPS),
                    output=out)
            cache[name] = out
        return cache[name]

    return get


def results_of(run_file, name):
    return read_results(run_file(name))


def _all_labels(fig):
    for ax in fig.axes:
        yield ax.get_xlabel()
        yield ax.get_ylabel()


def _check_labels(fig):
    labels = [s for s in _all_labels(fig) if s]
    assert labels and all(DIMENSIONLESS in s for s in labels), labels


# --------------------------------------------------------------------------------------------
# Every figure of every gait file


@pytest.mark.parametrize("gait_file", GAIT_FILES, ids=lambda p: p.stem)
def test_every_figure_of_every_gait(run_file, gait_file, tmp_path):
    """Every figure a file supports is written for each example gait (all four for crawlers,
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
    draws = {"motion": motion_figure, "gait-diagram": gait_figure,
             "convergence": convergence_figure, "shape-space": shape_space_figure}
    for name in names:
        fig = draws[name](results)
        titles = [ax.get_title() for ax in fig.axes] + [fig._suptitle.get_text()
                                                        if fig._suptitle else ""]
        assert any(gait_file.stem in s for s in titles)
        _check_labels(fig)
    assert not list(tmp_path.glob(".*.tmp"))


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
    for j in range(N):
        np.testing.assert_array_equal(lines[j].get_xdata(), t)
        np.testing.assert_array_equal(lines[j].get_ydata(), x[:, j])
    np.testing.assert_allclose(lines[N].get_ydata(), x.mean(axis=1), rtol=0, atol=1e-14)
    (xs, ys) = lines[N + 1].get_data()
    v0 = r["attrs"]["v0"]
    assert (ys[1] - ys[0]) / (xs[1] - xs[0]) == pytest.approx(v0, abs=1e-12)
    t0, T = r["limit_attrs"]["start"], r["attrs"]["period"]
    y_t0 = np.interp(t0, t, x.mean(axis=1))
    assert np.interp(t0, xs, ys) == pytest.approx(y_t0, abs=1e-12)
    (span,) = ax.patches
    assert (span.get_x(), span.get_x() + span.get_width()) == pytest.approx((t0, t0 + T))
    assert ax.get_xlim() == (t[0], t[-1])


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


def _band_rectangles(ax):
    return [p for p in ax.patches if isinstance(p, Rectangle)]


@pytest.mark.parametrize("name", ["peristalsis-4", "smooth-friction-3", "anchoring-2"])
def test_gait_diagram_content(run_file, name):
    r = results_of(run_file, name)
    lim = r["limit"]
    t, slip = lim["t"], lim["slip"]
    N = slip.shape[1]
    T = r["attrs"]["period"]
    fig = gait_figure(r)
    bands, lengths, stresses, forces = fig.axes
    assert "gait diagram" in fig._suptitle.get_text() and name in fig._suptitle.get_text()

    # Bands: per block, the rectangles tile [0, T] and their colours are the slip states.
    colour_state = {to_hex(c): s for s, c in SLIP_COLOURS.items()}
    rects = _band_rectangles(bands)
    assert len(rects) == sum(len(slip_runs(slip[:, j], t)) for j in range(N))
    for j in range(N):
        mine = sorted((r_ for r_ in rects if abs(r_.get_y() + r_.get_height() / 2 - j) < 1e-9),
                      key=lambda r_: r_.get_x())
        assert mine[0].get_x() == pytest.approx(0.0)
        assert sum(r_.get_width() for r_ in mine) == pytest.approx(T)
        for r_ in mine:
            a, b = r_.get_x(), r_.get_x() + r_.get_width()
            steps = (t[:-1] >= a - 1e-12) & (t[1:] <= b + 1e-12)
            assert np.all(slip[steps, j] == colour_state[to_hex(r_.get_facecolor())])
    assert [tl.get_text() for tl in bands.get_yticklabels()] == [f"block {j + 1}"
                                                                for j in range(N)]

    # Lengths: L_i then z_i, the file's data.
    lines = lengths.get_lines()
    assert len(lines) == 2 * (N - 1)
    for i in range(N - 1):
        np.testing.assert_array_equal(lines[i].get_ydata(), lim["lengths"][:, i])
        np.testing.assert_array_equal(lines[N - 1 + i].get_ydata(), lim["shape"][:, i])
        np.testing.assert_array_equal(lines[i].get_xdata(), t)

    # Stresses: sigma_i and its two bounds per link, plus the zero line; within the bounds.
    lines = stresses.get_lines()
    assert len(lines) == 3 * (N - 1) + 1
    low, high = stress_bounds(lim["friction"])
    tol = 1e-9 * np.max(np.abs(lim["stress"]))
    assert np.all(lim["stress"] >= low - tol) and np.all(lim["stress"] <= high + tol)
    for i in range(N - 1):
        np.testing.assert_array_equal(lines[3 * i].get_ydata(), lim["stress"][:, i])

    # Forces: f = D^T sigma, admissible (-mu^- <= f <= mu^+), and on the friction limit at the end
    # of every slipping step, with the sign of the slip (the catch-up step ends on the face).
    lines = forces.get_lines()
    plus, minus = lim["friction"][:, :N], lim["friction"][:, N:]
    shared = np.all(plus == plus[:, :1]) and np.all(minus == minus[:, :1])
    assert len(lines) == N + 2 * (1 if shared else N)
    f = np.column_stack([lines[j].get_ydata() for j in range(N)])
    np.testing.assert_allclose(f, block_forces(lim["stress"]))
    tol = 1e-9 * max(np.max(np.abs(f)), 1.0)
    assert np.all(f <= plus + tol) and np.all(f >= -minus - tol)
    end = f[1:]
    np.testing.assert_allclose(end[slip == 1], plus[1:][slip == 1], atol=tol)
    np.testing.assert_allclose(end[slip == -1], -minus[1:][slip == -1], atol=tol)
    assert forces.get_xlim() == (0.0, T)


# --------------------------------------------------------------------------------------------
# 3. Convergence


def test_zero_floor():
    """A decade below the smallest positive value, rounded down to a power of ten."""
    assert zero_floor([np.array([0.0, 0.074, 3.0])]) == pytest.approx(1e-3)
    assert zero_floor([np.array([0.0, 0.0])]) == 1e-16


def test_convergence_finite_time(run_file):
    """peristalsis-4 is periodic from period 1: Poincare step, W^{1,2} distance and |v_q - v0|
    are 0 at q = 1, drawn on the floor of the log axis (tick "0"), with the finite-time line."""
    r = results_of(run_file, "peristalsis-4")
    conv = r["convergence"]
    fig = convergence_figure(r)
    (ax,) = fig.axes
    assert ax.get_yscale() == "log"
    assert r["attrs"]["periodic_from"] == 1
    lines = ax.get_lines()
    series = [conv["poincare_step"], conv["w12_distance"], np.abs(conv["velocity"] -
                                                                 r["attrs"]["v0"])]
    floor = zero_floor(series)
    assert ax.get_ylim()[0] == pytest.approx(floor)
    k = 0
    for value in series:
        ydata = lines[k].get_ydata()
        np.testing.assert_array_equal(lines[k].get_xdata(), conv["period"])
        np.testing.assert_array_equal(np.isnan(ydata), value == 0)
        np.testing.assert_array_equal(ydata[value > 0], value[value > 0])
        k += 1
        if np.any(value == 0):
            np.testing.assert_array_equal(lines[k].get_xdata(), conv["period"][value == 0])
            np.testing.assert_allclose(lines[k].get_ydata(), floor)
            k += 1
    vline = lines[k]
    np.testing.assert_array_equal(vline.get_xdata(), [1, 1])
    assert "periodic from period 1" in vline.get_label()
    assert len(lines) == k + 1
    ticks = {round(np.log10(y)): ax.yaxis.get_major_formatter()(y) for y in ax.get_yticks()}
    assert ticks[round(np.log10(floor))] == "0"
    assert ax.get_xlabel() == f"period index $q$ {DIMENSIONLESS}"


def test_convergence_asymptotic_rate_line(run_file):
    """An asymptotic run (synthetic history: Poincare steps 2^-q) shows the geometric decay of
    the fitted rate, r^q through the last step, and no finite-time line."""
    r = results_of(run_file, "peristalsis-3")
    q = np.arange(12)
    step = 0.5 ** q
    r = {**r, "attrs": {**r["attrs"], "convergence": "asymptotic", "periodic_from": -1,
                        "contraction_rate": 0.5, "v0": 1.0},
         "convergence": {"period": q, "poincare_step": step, "w12_distance": 3 * step,
                         "velocity": 1.0 + step / 7}}
    ax = convergence_figure(r).axes[0]
    lines = ax.get_lines()
    assert len(lines) == 4
    fitted = lines[-1]
    np.testing.assert_allclose(fitted.get_ydata(), step, rtol=1e-12)
    assert "0.5" in fitted.get_label()
    np.testing.assert_allclose(lines[2].get_ydata(), step / 7, rtol=1e-9)
    assert "asymptotic" in ax.get_title()


def test_convergence_triangle_rate_one_eighth(run_file):
    """The paper's triangle under wide movements (Section 5, MODEL.md §5) converges only
    asymptotically: one period is phi^3 with phi(z) = (1 - z)/2, a contraction by 1/8. The figure
    draws the fitted rate as a geometric line of ratio 1/8 and no finite-time line."""
    r = results_of(run_file, "paper/triangle")
    assert r["attrs"]["convergence"] == "asymptotic"
    ax = convergence_figure(r).axes[0]
    fitted = ax.get_lines()[-1]
    y = fitted.get_ydata()
    np.testing.assert_allclose(y[1:] / y[:-1], r["attrs"]["contraction_rate"], rtol=1e-12)
    assert r["attrs"]["contraction_rate"] == pytest.approx(1 / 8, rel=1e-3)
    assert "0.125" in fitted.get_label()
    assert not any("periodic from" in l.get_label() for l in ax.get_lines())


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


def test_shape_space_three_blocks_hexagon(run_file):
    """peristalsis-3 (mu^+ = 1, mu^- = 1.5, k = 10). K(t) + K L(t) is the stress set C: with
    f_1 = -sigma_1, f_2 = sigma_1 - sigma_2, f_3 = sigma_2 the box [-1, 1.5] x [-1.5, 1] (area
    6.25) cut by -1.5 <= sigma_1 - sigma_2 <= 1, which removes corner triangles of legs 2 and 0.5:
    area 6.25 - 2 - 0.125 = 4.125, at every time. The figure draws one polygon per instant, each
    containing w at that instant, and the orbit lines are the file's w."""
    r = results_of(run_file, "peristalsis-3")
    lim, B = r["limit"], r["process"]["normals"]
    fig = shape_space_figure(r)
    (ax,) = fig.axes
    polys = [p for p in ax.patches if isinstance(p, Polygon)]
    assert len(polys) == 6
    G = len(lim["t"]) - 1
    instants = np.round(np.linspace(0, G, 7)[:-1]).astype(int)
    markers = ax.get_lines()[:6]
    for poly, k, marker in zip(polys, instants, markers):
        v = poly.get_xy()[:-1]
        assert _area(v) == pytest.approx(4.125, rel=1e-9)
        assert np.all(v @ B.T <= lim["offsets"][k] + 1e-9)
        sigma = v + 10.0 * lim["lengths"][k]
        f = np.column_stack([-sigma[:, 0], sigma[:, 0] - sigma[:, 1], sigma[:, 1]])
        assert np.all((f <= 1 + 1e-9) & (f >= -1.5 - 1e-9))
        w = np.array([marker.get_xdata()[0], marker.get_ydata()[0]])
        np.testing.assert_array_equal(w, lim["w"][k])
        assert _inside(v, w)
        assert np.all(B @ w <= lim["offsets"][k] + 1e-9)
    names = [l.get_label() for l in ax.get_lines()]
    assert names[6:] == ["earlier periods", "limit cycle", "start $w(0)$"]
    earlier, limit, start = ax.get_lines()[6:]
    np.testing.assert_array_equal(limit.get_xdata(), lim["w"][:, 0])
    np.testing.assert_array_equal(limit.get_ydata(), lim["w"][:, 1])
    assert limit.get_linewidth() > 2 * earlier.get_linewidth()
    t, w = r["trajectory"]["t"], r["trajectory"]["w"]
    np.testing.assert_array_equal(earlier.get_xdata(), w[t <= r["limit_attrs"]["start"] + 1e-9, 0])
    assert ax.get_xlabel().startswith("shape coordinate $w_{1}")


def test_shape_space_sections_four_blocks(run_file):
    """peristalsis-4 has a 3-D shape space: each polygon is the section of K(t) through w(t) in
    the chosen coordinates, so it contains the projected w(t), and every vertex completed with
    the other coordinate of w(t) satisfies B w <= c(t)."""
    r = results_of(run_file, "peristalsis-4")
    lim, B = r["limit"], r["process"]["normals"]
    G = len(lim["t"]) - 1
    instants = np.round(np.linspace(0, G, 7)[:-1]).astype(int)
    ax = shape_space_figure(r, coords=(0, 2)).axes[0]
    assert "(1, 3) of 3" in ax.get_title()
    assert ax.get_ylabel().startswith("shape coordinate $w_{3}")
    polys = [p for p in ax.patches if isinstance(p, Polygon)]
    assert len(polys) == 6
    for poly, k in zip(polys, instants):
        v = poly.get_xy()[:-1]
        full = np.column_stack([v[:, 0], np.full(len(v), lim["w"][k, 1]), v[:, 1]])
        assert np.all(full @ B.T <= lim["offsets"][k] + 1e-9)
        assert _inside(v, lim["w"][k, [0, 2]])
    with pytest.raises(ValueError, match="between 1 and 3"):
        shape_space_figure(r, coords=(0, 3))


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
    values = np.linspace(1.0, 3.0, 5)
    v0 = np.array([0.1, 0.2, np.nan, 0.4, 0.5])
    failed = np.array([False, False, True, False, True])
    fig = sweep_figure({"friction.backward": values}, v0, failed, "inching-2: v0 sweep")
    (ax,) = fig.axes
    curve, crosses = ax.get_lines()[:2]
    np.testing.assert_array_equal(curve.get_xdata(), values[[0, 1, 3]])
    np.testing.assert_array_equal(curve.get_ydata(), v0[[0, 1, 3]])
    np.testing.assert_array_equal(crosses.get_xdata(), values[[2, 4]])
    assert ax.get_xlabel() == f"friction.backward {DIMENSIONLESS}"
    assert ax.get_ylabel() == f"average velocity $v_0$ {DIMENSIONLESS}"
    assert ax.get_title() == "inching-2: v0 sweep"


def test_sweep_two_parameters_heatmap():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([0.5, 1.0])
    v0 = np.array([[0.1, -0.2], [0.3, 0.4], [0.5, 0.6]])
    failed = np.zeros((3, 2), bool)
    failed[1, 0] = True
    fig = sweep_figure({"friction.backward": a, "links[0].amplitude": b}, v0, failed, "sweep")
    ax, bar = fig.axes
    (mesh,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    data = np.ma.filled(mesh.get_array(), np.nan).reshape(2, 3)
    expected = np.where(failed, np.nan, v0).T
    np.testing.assert_array_equal(np.isnan(data), np.isnan(expected))
    np.testing.assert_array_equal(data[~np.isnan(data)], expected[~np.isnan(expected)])
    assert mesh.get_cmap().name == "PuOr_r" and mesh.norm.vcenter == 0
    (cross,) = ax.get_lines()
    assert (cross.get_xdata()[0], cross.get_ydata()[0]) == (2.0, 0.5)
    assert ax.get_xlabel().startswith("friction.backward")
    assert ax.get_ylabel().startswith("links[0].amplitude")
    assert bar.get_ylabel() == f"average velocity $v_0$ {DIMENSIONLESS}"
    one_sign = sweep_figure({"a": a, "b": b}, np.abs(v0), np.zeros((3, 2), bool), "s")
    assert list(one_sign.axes[0].collections)[0].get_cmap().name == "cividis"


def test_sweep_bad_shapes():
    with pytest.raises(ValueError, match="one or two"):
        sweep_figure({"a": [1], "b": [1], "c": [1]}, np.zeros((1, 1, 1)),
                     np.zeros((1, 1, 1), bool), "t")
    with pytest.raises(ValueError, match="grid's shape"):
        sweep_figure({"a": [1, 2]}, np.zeros(3), np.zeros(3, bool), "t")


# --------------------------------------------------------------------------------------------
# Command line


def test_cli_plot_formats_and_only(run_file, tmp_path):
    path = run_file("peristalsis-3")
    result = CliRunner().invoke(main, ["plot", str(path), "-o", str(tmp_path / "figs"),
                                       "--format", "svg", "--only", "gait-diagram"])
    assert result.exit_code == 0, result.output
    (out,) = (tmp_path / "figs").iterdir()
    assert out.name == "peristalsis-3-gait-diagram.svg"
    assert result.output.strip() == str(out)
    assert b"<svg" in out.read_bytes()[:500]


def test_cli_run_plot(tmp_path):
    gait = tmp_path / "inching-2.yaml"
    gait.write_text((GAITS / "inching-2.yaml").read_text())
    out = tmp_path / "run.h5"
    result = CliRunner().invoke(main, ["run", str(gait), "-o", str(out), "--plot",
                                       "--steps-per-period", "50"])
    assert result.exit_code == 0, result.output
    for name in FIGURE_NAMES:
        assert (tmp_path / f"run-{name}.png").stat().st_size > 1000
        assert f"run-{name}.png" in result.output


def _without(src: Path, dst: Path, dataset: str) -> Path:
    shutil.copy(src, dst)
    with h5py.File(dst, "a") as f:
        del f[dataset]
    return dst


@pytest.mark.parametrize("dataset, only, message", [
    ("limit/lengths", "gait-diagram", "/limit/lengths"),
    ("limit/friction", None, "/limit/friction"),
    ("process", "shape-space", "/process/normals"),
    ("trajectory/x", "motion", "/trajectory/x"),
    ("convergence", None, "missing group /convergence"),
])
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
    not_h5 = tmp_path / "gait.yaml"
    not_h5.write_text("name: x\n")
    empty = tmp_path / "empty.h5"
    h5py.File(empty, "w").close()
    for path, message in ((tmp_path / "none.h5", "no such results file"),
                          (not_h5, "not an HDF5 file"), (empty, "not a crawlsim results file")):
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
