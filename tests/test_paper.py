"""The paper's Section 5 and Theorem th:speed, as numbers (the same claims as
``scripts/reproduce-paper.sh``; derivations in `crawlsim.study.paper`)."""

import numpy as np
import pytest

from crawlsim.api import run
from crawlsim.gait.document import gait_from_document, load_gait, with_simulation
from crawlsim.model.process import compile
from crawlsim.study import paper

from .conftest import GAITS

PAPER = GAITS / "paper"


def test_the_example_files_are_the_paper_examples():
    """The files equal the generators (alpha = 1, T = 1 for the angle; alpha = 3 for the
    triangle), so checking the generators for other alpha checks the same construction."""
    angle = load_gait(PAPER / "acute-angle.yaml")
    generated = gait_from_document(paper.acute_angle_document(1.0, 1.0, 0.1), "<g>")
    assert np.array_equal(angle.normals, generated.normals)
    t = np.linspace(0, 1, 41)
    assert np.array_equal(angle.offset_values(t), generated.offset_values(t))
    triangle = load_gait(PAPER / "triangle.yaml")
    generated = gait_from_document(paper.triangle_document(3.0, 1.0), "<g>")
    assert np.allclose(triangle.normals, generated.normals, atol=1e-16, rtol=0)
    assert np.allclose(triangle.offset_values(t), generated.offset_values(t), atol=1e-15, rtol=0)


def test_triangle_offsets_are_the_shifted_triangle():
    """z in C(t) iff z + F(t) in PQR: the vertices of PQR - F(t) are tight on two faces each."""
    spec = load_gait(PAPER / "triangle.yaml")
    V = paper.triangle_vertices()
    for t in (0.0, 0.2, 1 / 3, 0.5, 0.9):
        c = spec.offset_values([t])[0]
        F = paper.triangle_shift([t], 3.0)[0]
        slack = (V - F) @ spec.normals.T - c  # (vertex, face)
        assert np.sum(np.abs(slack) <= 1e-14, axis=1).tolist() == [2, 2, 2]
        assert np.all(slack <= 1e-14)


@pytest.mark.parametrize("alpha", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("steps", [7, 64])
def test_acute_angle_iterates_are_the_paper_map(alpha, steps):
    """z1(qT) = P^q(z1(0)), P(z1) = (alpha^2 gamma + z1)/(alpha^2 + 1) for z1 < gamma and z1
    otherwise, and z2(qT) = 0: to roundoff on any grid (one face at a time pushes the point)."""
    gamma = 1 / (2 * alpha)
    for f in (0.0, 0.4, 0.9, 1.5):
        z = paper.acute_angle_iterates(alpha, f * gamma, periods=10, steps=steps)
        expected = [f * gamma]
        for _ in range(10):
            expected.append(paper.acute_angle_map(expected[-1], alpha))
        assert np.max(np.abs(z[:, 0] - expected)) <= 1e-15
        assert np.max(np.abs(z[:, 1])) <= 1e-15
        if f < 1:
            assert np.all(np.diff(z[:, 0]) > 0)  # strictly increasing, never reaching gamma
            assert np.all(z[:, 0] < gamma)


@pytest.mark.parametrize("alpha", [0.5, 2.0])
def test_acute_angle_contracts_by_one_over_one_plus_alpha_squared(alpha):
    """|P(z) - P(z')| = |z - z'| / (1 + alpha^2), so successive Poincare steps shrink by that
    factor, and crawlsim reports asymptotic convergence with that rate."""
    result = paper.acute_angle_run(alpha, 0.0, steps=16)
    steps = result.history.poincare_step
    usable = steps[steps > 1e-6 * steps[0]]
    assert np.max(np.abs(usable[1:] / usable[:-1] - 1 / (1 + alpha**2))) <= 1e-8
    assert result.convergence == "asymptotic" and result.periodic_from is None
    assert result.rate.rate == pytest.approx(1 / (1 + alpha**2), rel=1e-3)
    assert result.limit.w[0] == pytest.approx([1 / (2 * alpha), 0.0], abs=1e-11)


def _triangle(start, steps=30):
    spec = with_simulation(load_gait(PAPER / "triangle.yaml"), steps_per_period=steps)
    return gait_from_document({**spec.document, "initial": list(start)}, "<t>")


@pytest.mark.parametrize("start", [(0.1, 0.05), (-0.3, -0.2), (0.0, 0.5)])
def test_triangle_edge_map_and_its_one_eighth_contraction(start):
    """At the end of each third the point is on the next edge, at arc parameter phi(s) =
    (1 - s)/2 of the previous one; per period |s - 1/3| shrinks by exactly 1/8 (phi^3(s) =
    (3 - s)/8)."""
    edges = paper.triangle_edges(_triangle(start), periods=8, alpha=3.0)
    s, distance = edges[:, 0], edges[:, 1]
    assert np.max(np.abs(distance)) <= 1e-15
    assert np.max(np.abs(s[1:] - paper.phi(s[:-1]))) <= 1e-15
    dev = np.abs(s[0::3] - 1 / 3)
    good = dev[:-1] > 1e-6 * dev[0]
    assert np.count_nonzero(good) >= 5
    assert np.max(np.abs(dev[1:][good] / dev[:-1][good] - 1 / 8)) <= 1e-8


def test_triangle_has_one_periodic_solution_reached_only_asymptotically():
    limits = []
    for start in [(0.1, 0.05), (-0.3, -0.2), (0.45, -0.25)]:
        result = run(_triangle(start))
        assert result.convergence == "asymptotic"
        assert result.rate.rate == pytest.approx(1 / 8, rel=1e-3)
        limits.append(result.limit.w[-1])
        s, distance = paper.edge_parameter(result.limit.w[-1], 2)
        assert s == pytest.approx(1 / 3, abs=1e-11) and abs(distance) <= 1e-15
    assert np.max(np.abs(np.array(limits) - limits[0])) <= 1e-11


def test_exact_integrator_agrees_on_the_paper_maps():
    if not paper._exact_available():
        pytest.skip("integrator 'exact' not available")
    for row in paper.acute_angle_checks(alphas=(1.0,), periods=6, integrator="exact"):
        assert row.error <= 1e-15, row
    edges = paper.triangle_edges(_triangle((0.1, 0.05)), periods=4, alpha=3.0, integrator="exact")
    assert np.max(np.abs(edges[1:, 0] - paper.phi(edges[:-1, 0]))) <= 1e-15


@pytest.mark.parametrize("start", [[0.2, 0.8, -0.9], [0.1, -0.9, 0.0], [0.45, 0.9, -0.5]])
def test_cell_is_periodic_after_one_period(start):
    """Corollary cor:cell: z(2T) = z(T) exactly and every later period equals the first
    periodic one, while the first period moved the point."""
    spec = with_simulation(load_gait(PAPER / "cell-3.yaml"), steps_per_period=40)
    records = paper._periods(gait_from_document({**spec.document, "initial": start}, "<c>"), 4)
    assert np.linalg.norm(records[0].w[-1] - records[0].w[0]) > 0.4
    for later in records[2:]:
        assert np.array_equal(later.w, records[1].w)


def test_cell_limit_is_the_one_dimensional_play():
    """Coordinate 3 of cell-3 lives in [a3, b3] = [-1, 1] narrowing linearly to [0.2, 0.4] on
    [0.4 T, 0.6 T]: any start ends period 0 inside [0.2, 0.4] and then stays put, because the
    interval only widens again. So z3 is constant from T on, equal to clip(z3(0), 0.2, 0.4)."""
    spec = with_simulation(load_gait(PAPER / "cell-3.yaml"), steps_per_period=40)
    for z3 in (-0.9, 0.3, 0.95):
        doc = {**spec.document, "initial": [0.2, 0.0, z3]}
        records = paper._periods(gait_from_document(doc, "<c>"), 2)
        assert np.all(records[1].w[:, 2] == np.clip(z3, 0.2, 0.4))


def test_two_block_crawler_is_periodic_from_T():
    rows = paper.two_block_checks(GAITS / "inching-2.yaml", steps=100)
    assert len(rows) == 4 and all(row.ok for row in rows)
    assert all(row.error == 0.0 for row in rows)


def test_speed_is_independent_of_the_start_and_periods_converge_in_w12():
    """Theorem th:speed on the four-block wave from four admissible starts."""
    gait = with_simulation(load_gait(PAPER / "speed-peristalsis-4.yaml"), steps_per_period=100)
    starts = paper.admissible_starts(gait, 4)
    assert len({tuple(np.round(x, 12)) for x in starts}) == 4
    results = [run(gait_from_document({**gait.document, "initial": {"positions": x.tolist()}}, "<s>")) for x in starts]
    v0 = np.array([r.v0 for r in results])
    assert abs(v0[0]) > 0.3
    assert np.ptp(v0) <= 1e-13
    times = compile(gait).times
    for x in starts[1:]:
        doc = {**gait.document, "initial": {"positions": x.tolist()}}
        d = paper.w12_distances(paper._periods(gait_from_document(doc, "<s>"), 4), times)
        assert d[0] > 0.1 and np.all(d[1:] <= 1e-12)
    dw = [np.diff(r.limit.w, axis=0) for r in results]
    assert max(np.max(np.abs(d - dw[0])) for d in dw) <= 1e-13


def test_the_reproduction_table_passes_and_names_each_claim():
    rows = paper.all_checks(quick=True, folder=PAPER)
    assert all(row.ok for row in rows), [r for r in rows if not r.ok]
    table = paper.format_table(rows)
    for words in ("cor:cell", "th:1dim", "acute angle alpha = 0.5", "phi(s) = (1 - s)/2", "1/8", "th:speed", "W^{1,2}"):
        assert words in table
    assert f"{len(rows)} of {len(rows)} checks pass." in table
