"""The exact, event-driven integrator against closed forms, catch-up convergence and its guards.

Two-block closed forms. Two blocks, one link: stress sigma = k (L(t) - z), forces
f = (-sigma, sigma). Block 1 slips forward at sigma = -mu1+, backward at sigma = mu1-; block 2
forward at sigma = mu2+, backward at sigma = -mu2-. So sigma lives in [-a, b] with
a = min(mu1+, mu2-), b = min(mu1-, mu2+) and is the play operator of k L(t). With
L = 1 + A cos(2 pi t/T) the stroke is 2A and, in the periodic regime, each half period ends with
a slip of delta = 2A - (a + b)/k (when positive):

* mu+ < mu- on both blocks (equal mu+ = mu): a = b = mu. At t = 0 (L maximal) sigma = mu and
  the link starts to shorten: sigma = mu + k A (cos(2 pi t/T) - 1) reaches -mu at
  t1 = T arccos(1 - 2 mu/(k A)) / (2 pi); block 1 slips forward from t1 until L stops shortening
  at T/2 (a release: the slip rate k A 2 pi/T sin(2 pi t/T) vanishes); sigma then rises again and
  reaches mu at t2 = t1 + T/2, from which block 2 slips forward until T. Displacement per period
  delta = 2A - 2 mu/k, dissipation 2 mu delta; the limit period's events are {0, t1, T/2, t2}.
* block 1 friction 1/1, block 2 friction 3/3: a = b = 1, attained by block 1 both ways: block 1
  slips back by delta, then forward by delta; v0 = 0, dissipation (mu1+ + mu1-) delta.
* k 2A < a + b: below the threshold of motion, nothing slips after the first period.
"""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from crawlsim.analysis.run import simulate
from crawlsim.api import run
from crawlsim.cli import main
from crawlsim.errors import EventError, GaitError, LicqWarning
from crawlsim.gait.document import load_gait, parse_gait, with_simulation
from crawlsim.integrate.exact import EventStepper
from crawlsim.integrate.stepping import make_stepper
from crawlsim.io.runread import read_results
from crawlsim.model.process import compile as compile_any
from crawlsim.model.process import compile_gait
from crawlsim.study import paper

from .conftest import GAITS, iterated_examples, two_block


def exact(gait, steps=None, **options):
    return simulate(
        compile_gait(gait, steps),
        max_periods=gait.simulation.max_periods,
        tolerance=gait.simulation.tolerance,
        integrator="exact",
        **options,
    )


# -- two-block closed forms -----------------------------------------------------------------


@pytest.mark.parametrize(
    "amplitude,k,mu_plus,mu_minus", [(0.3, 10.0, 1.0, 2.0), (0.5, 4.0, 0.3, 0.7), (0.25, 25.0, 2.0, 5.0)]
)
def test_two_block_inching_closed_form(amplitude, k, mu_plus, mu_minus):
    gait = two_block(amplitude, k, {"forward": mu_plus, "backward": mu_minus}, steps=7)
    process = compile_gait(gait)
    stepper = EventStepper(process)
    records = [stepper.step_period() for _ in range(3)]
    delta = 2 * amplitude - 2 * mu_plus / k
    for rec in records[1:]:
        assert np.mean(rec.x[-1] - rec.x[0]) == pytest.approx(delta, abs=1e-13)
        assert np.max(np.abs(rec.w[-1] - rec.w[0])) <= 1e-13 * process.scale
    t1 = math.acos(1 - 2 * mu_plus / (k * amplitude)) / (2 * math.pi)
    events = records[-1].events
    np.testing.assert_allclose(events.t - records[-1].start, [0.0, t1, 0.5, t1 + 0.5], rtol=0, atol=1e-13)
    # Block 1 slips from t1 to T/2, block 2 from t2 to T, each by delta.
    dx = np.diff(events.x, axis=0, append=records[-1].x[-1][None])
    np.testing.assert_allclose(dx, [[0, 0], [delta, 0], [0, 0], [0, delta]], atol=1e-13)
    res = exact(gait)
    assert res.v0 == pytest.approx(delta, abs=1e-13)
    assert res.energy.dissipation == pytest.approx(2 * mu_plus * delta, abs=1e-13)
    assert res.convergence == "finite-time" and res.periodic_from == 1


def test_inching_2_example_is_exactly_0_4():
    res = exact(load_gait(GAITS / "inching-2.yaml"), steps=13)
    assert res.v0 == pytest.approx(0.4, abs=1e-13)


def test_two_block_back_and_forth_with_zero_net_motion():
    friction = [{"forward": 1.0, "backward": 1.0}, {"forward": 3.0, "backward": 3.0}]
    res = exact(two_block(0.3, 10.0, friction), steps=11)
    delta = 0.6 - 2.0 / 10.0
    assert res.v0 == pytest.approx(0.0, abs=1e-14)
    assert res.energy.dissipation == pytest.approx(2.0 * delta, abs=1e-13)
    dx = np.diff(res.limit.x + res.v0 * res.limit.t[:, None], axis=0)
    assert np.sum(np.clip(dx[:, 0], 0, None)) == pytest.approx(delta, abs=1e-13)
    assert np.sum(np.clip(-dx[:, 0], 0, None)) == pytest.approx(delta, abs=1e-13)
    assert np.max(np.abs(dx[:, 1])) == 0.0  # the heavy block never moves


def test_two_block_below_threshold():
    """Start in tension at sigma = -1 as L begins to shorten: block 1 slides forward by the whole
    stroke 2A in the first half period, then nothing moves: displacement of period 0 = A."""
    A, k = 0.04, 10.0
    gait = two_block(A, k, steps=9, initial={"positions": [0.0, 1 + A + 1.0 / k]})
    res = exact(gait)
    assert res.history.displacement[0] == pytest.approx(A, abs=1e-14)
    assert res.v0 == 0.0 and res.energy.dissipation == 0.0
    assert res.convergence == "finite-time" and res.periodic_from == 1


# -- agreement with catch-up as the step shrinks --------------------------------------------

# (gait, catch-up steps per period, fitted order range, envelope). Measured against the exact v0:
# catch-up is first order, with an irregular constant on the smooth gaits (|error| G wanders in
# 0.002..0.3 from one G to the next, as docs/model.md warns), so the order is fitted by least squares
# over eight step counts spanning a factor 128, and every error must lie in the first-order
# envelope. anchoring-2 is first order with a constant error 1.2 h (odd G): at each friction jump
# catch-up assigns one step's slip to the wrong block. inching-2 is second order at odd G (its
# events are releases at the extremes of L, where an O(h) error in the event time costs O(h^2))
# and exact to roundoff at even G, where the extremes are grid times.
SPREAD = [61, 127, 251, 499, 1009, 2003, 4001, 8009]
CONVERGENCE = [
    ("inching-2", [100, 200, 400], None, 1e-12),
    ("inching-2", [101, 201, 401, 801, 1601], (1.8, 2.2), 1.6),
    ("peristalsis-3", SPREAD, (0.7, 1.45), 0.3),
    ("peristalsis-4", SPREAD, (0.7, 1.45), 0.3),
    ("anchoring-2", [101, 201, 401, 801, 1601], (0.99, 1.01), 1.21),
    ("smooth-friction-3", SPREAD, (0.7, 1.45), 0.5),
]


@pytest.mark.parametrize("name,steps,slope,bound", CONVERGENCE, ids=[f"{c[0]}-{c[1][0]}" for c in CONVERGENCE])
def test_catch_up_converges_to_the_exact_v0(name, steps, slope, bound):
    gait = load_gait(GAITS / f"{name}.yaml")
    reference = exact(gait, steps=10).v0
    h = gait.period / np.array(steps)
    error = np.array([simulate(compile_gait(gait, G), max_periods=50).v0 - reference for G in steps])
    if slope is None:
        assert np.max(np.abs(error)) <= bound
        return
    fitted = np.polyfit(np.log(h), np.log(np.abs(error)), 1)[0]
    assert slope[0] <= fitted <= slope[1]
    # The error envelope: |error| <= bound h^order with the observed order rounded down.
    order = 2 if slope[0] > 1.5 else 1
    assert np.all(np.abs(error) <= bound * (h / gait.period) ** order)


@pytest.mark.parametrize("path", iterated_examples(), ids=lambda p: p.stem)
def test_every_example_gait_runs_exactly(path):
    gait = load_gait(path)
    res = exact(gait, steps=50)
    assert res.converged and np.isfinite(res.v0)
    # The output grid only samples the solution: a finer one gives the same v0 and states.
    fine = exact(gait, steps=200)
    assert fine.v0 == pytest.approx(res.v0, abs=1e-13)
    common = np.isin(fine.limit.t, res.limit.t)
    np.testing.assert_allclose(fine.limit.w[common], res.limit.w, atol=1e-13 * 10)
    # Nor does the sampling used where zeros have no closed form.
    coarse = EventStepper(compile_gait(gait, 50), cells_per_cycle=8)
    for _ in range(res.periods):
        rec = coarse.step_period()
    assert np.mean(rec.x[-1] - rec.x[0]) / gait.period == pytest.approx(res.v0, abs=1e-13)


def test_clarabel_confirms_every_sampled_state():
    gait = load_gait(GAITS / "smooth-friction-3.yaml")
    process = compile_gait(gait, 40)
    checked = EventStepper(process, check_every_step=True)
    plain = EventStepper(process)
    for _ in range(2):
        a, b = checked.step_period(), plain.step_period()
        np.testing.assert_array_equal(a.w, b.w)
    assert checked.projector.clarabel_calls >= plain.projector.clarabel_calls + 2 * 41


# -- generic processes: tangential and simultaneous contacts ---------------------------------


def generic(normals, metric, offsets, initial, steps=16):
    """A one-period process {w : B w <= c(t)} from a process document (T = 1)."""
    doc = {
        "kind": "sweeping-process",
        "name": "test",
        "period": 1.0,
        "normals": np.atleast_2d(normals).tolist(),
        "metric": np.atleast_2d(metric).tolist(),
        "offsets": offsets,
        "initial": list(initial),
        "allow_unbounded": True,
        "simulation": {"steps_per_period": steps},
    }
    return compile_any(parse_gait(yaml.safe_dump(doc), source="test.yaml"))


def bump(depth, phase=0.3):
    """c(t) = 1/2 (1 + cos 2 pi (t - phase)) - depth: its minimum -depth is at t = phase + 1/2."""
    return {"kind": "cosine", "mean": 0.5 - depth, "amplitude": 0.5, "phase": phase}


def test_tangential_touch_moves_nothing():
    """w <= c(t) with min c = 0 touched at t = 0.8, w0 = 0: the constraint touches w
    tangentially and lets go, so nothing moves and no event is reported."""
    stepper = EventStepper(generic([[1.0]], [[1.0]], [bump(0.0)], [0.0]))
    rec = stepper.step_period()
    assert np.all(rec.w == 0.0) and np.all(rec.multipliers == 0.0)
    np.testing.assert_array_equal(rec.events.t, [0.0])


@pytest.mark.parametrize("depth", [1e-8, 1e-4])
def test_shallow_contact_is_found(depth):
    """min c = -depth < 0 for a time ~ sqrt(depth): w is pushed to -depth (the 1-D sweeping
    process gives w(t) = min(w0, min_{s<=t} c(s))), with total slip depth, entered at the root of
    c and released at its minimum t = 0.8."""
    stepper = EventStepper(generic([[1.0]], [[1.0]], [bump(depth)], [0.0]))
    rec = stepper.step_period()
    assert rec.w[-1, 0] == pytest.approx(-depth, abs=1e-15)
    assert np.sum(rec.multipliers) == pytest.approx(depth, abs=1e-15)
    enter = 0.3 + math.acos(2 * depth - 1) / (2 * math.pi)
    np.testing.assert_allclose(rec.events.t, [0.0, enter, 0.8], atol=1e-12)


def test_simultaneous_contacts_with_coupled_metric():
    """B = I, c1 = c2 = c(t), w0 = 0 and M = [[2, 1], [1, 2]]: both gaps close at the same
    instant; with both active w = c(t) and lambda = -G^{-1} c' = -M c' (G = M^{-1}), so both rows
    stay active together while c decreases and release together at its minimum. w(T) = (-d, -d)
    with d = 0.25, and the slip integrals are M (d, d) = (3d, 3d)."""
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    rec = EventStepper(generic(np.eye(2), M, [bump(0.25), bump(0.25)], [0.0, 0.0])).step_period()
    np.testing.assert_allclose(rec.w[-1], [-0.25, -0.25], atol=1e-15)
    np.testing.assert_allclose(rec.multipliers.sum(axis=0), [0.75, 0.75], atol=1e-15)
    enter = 0.3 + 1 / 3  # c = 0 where cos 2 pi (t - 0.3) = -1/2
    np.testing.assert_allclose(rec.events.t, [0.0, enter, 0.8], atol=1e-14)


def test_tangential_contact_of_a_fourier_offset_between_samples():
    """c(t) = 1/4 + 1/4 cos 2 pi t + 1/8 cos 4 pi t (a fourier offset: no closed-form zeros,
    found by sampling): its minimum over a period is at cos 2 pi t = -1/2, c = 1/4 - 1/8 - 1/16
    = 1/16 > 0, so from w0 = 0 nothing ever moves; lowered by 1/16 + d it dips below 0 once and
    w ends at -d, whatever the sampling."""
    for d, cells in ((0.0, 64), (1e-6, 8), (1e-6, 64)):
        offset = {"kind": "fourier", "mean": 0.25 - 1 / 16 - d, "cos": [0.25, 0.125]}
        rec = EventStepper(generic([[1.0]], [[1.0]], [offset], [0.0], steps=10), cells_per_cycle=cells).step_period()
        assert rec.w[-1, 0] == pytest.approx(-d, abs=1e-15)
        assert np.sum(rec.multipliers) == pytest.approx(d, abs=1e-15)


def test_sampled_crossing_survives_a_bracket_the_scalar_rounds_differently():
    """f = -cos 2 pi u (a two-harmonic basis) crosses t just below the sample F[k+1] > t; if
    the tabulated sample rounds above t but the scalar evaluation of f at it below (emulated by
    raising the tabulated sample by delta), the bracket [s_k, s_{k+1}] has no sign change: the
    crossing is taken at its end and the zero reported is still the root of the scalar f,
    -cos 2 pi u = 0 at u = 1/4, not a failed brentq."""
    from crawlsim.kernel import sampling
    from crawlsim.model.offsets import Basis

    b = Basis(False, 2)
    z = np.zeros(b.size)
    z[b.first_harmonic] = -1.0
    cells = sampling.cells(0.0, 1.0, 64, b.harmonics)
    s = np.empty(cells + 1)
    sampling.grid(0.0, 1.0, cells, s)
    np.testing.assert_array_equal(s, np.linspace(0.0, 1.0, cells + 1))
    k = int(np.searchsorted(s, 1 / 3)) - 1  # the cell of the crossing of t ~ 1/2
    delta = 2e-3
    tol = b.scalar(float(s[k + 1]), z) + delta / 2
    PHIS = b.values(s)
    PHIS[k + 1, b.first_harmonic] -= delta  # F[k+1] = f(s_{k+1}) + delta > tol
    assert PHIS[k + 1] @ z > tol > b.scalar(float(s[k + 1]), z)  # no sign change in the cell
    filled = np.array([cells + 1])  # every sample tabulated (the perturbed ones)
    found = sampling.crossing(z, tol, 0.0, 1.0, False, 2, 1.0, s, PHIS, filled)
    assert found == pytest.approx(0.25, abs=1e-15)
    # the same f and tol, the samples exact: the crossing is where f = 0 as well, and the
    # time above tol (the zero counts) is after s_k
    exact_found = sampling.crossing(z, tol, 0.0, 1.0, False, 2, 1.0, s, b.values(s), np.array([cells + 1]))
    assert exact_found == pytest.approx(0.25, abs=1e-15)


@pytest.mark.parametrize("seed", range(3))
def test_compiled_brent_steps_are_scipys(seed):
    """`crawlsim.kernel.sampling` runs scipy's brentq and bounded minimisation step for step:
    on random sums of harmonics and a linear part, the roots and maxima are scipy's, bit for
    bit (both evaluate f by `Basis.scalar`, which is `sampling.scalar`: phi(u) @ z to
    roundoff)."""
    from scipy.optimize import brentq, minimize_scalar

    from crawlsim.kernel import sampling
    from crawlsim.model.offsets import Basis

    rng = np.random.default_rng(seed)
    roots = 0
    for _ in range(200):
        linear, H = bool(rng.integers(2)), int(rng.integers(1, 4))
        b = Basis(linear, H)
        z = rng.normal(size=b.size) * 10.0 ** rng.uniform(-3, 3)
        lo, hi = sorted(rng.uniform(0, 1, 2))
        assert b.scalar(lo, z) == pytest.approx((b.values(lo) @ z)[0], abs=1e-14 * float(np.sum(np.abs(z))))
        res = minimize_scalar(
            lambda x, b=b, z=z: -b.scalar(x, z), bounds=(lo, hi), method="bounded", options={"xatol": 1e-15}
        )
        assert sampling.maximum(z, lo, hi, linear, H) == (res.x, -res.fun)
        t = float(rng.uniform(-0.3, 0.3) * np.sum(np.abs(z)))
        if (b.scalar(lo, z) - t) * (b.scalar(hi, z) - t) < 0:
            roots += 1
            expected = brentq(lambda x, b=b, z=z, t=t: b.scalar(x, z) - t, lo, hi, xtol=1e-15)
            assert sampling.brentq(z, t, lo, hi, linear, H) == expected
    assert roots >= 30


def test_sampled_crossing_finds_the_zero_before_the_tolerance():
    """f(u) = -1/2 + cos 2 pi (u - 0.6) + 0.2 cos 4 pi (u - 0.6) - 0.1 u has no closed form: its
    first upward zero after u0 = 0.1 is the root of f (checked against a fine grid), and with a
    tolerance above max f there is none; nor after a horizon before it."""
    from crawlsim.kernel import sampling
    from crawlsim.model.offsets import Basis

    b = Basis(True, 2)
    p = 2 * math.pi * 0.6
    z = np.array([-0.5, -0.1, math.cos(p), math.sin(p), 0.2 * math.cos(2 * p), 0.2 * math.sin(2 * p)])
    u = np.linspace(0.1, 1.0, 2_000_001)
    f = b.values(u) @ z
    up = np.flatnonzero((f[:-1] < 0) & (f[1:] >= 0))
    expected = u[up[0]]

    def find(tol, horizon=1.0):
        count = sampling.cells(0.1, 1.0, 64, 2)
        S = np.empty(count + 1)
        sampling.grid(0.1, 1.0, count, S)
        return sampling.crossing(
            z, tol, 0.1, 1.0, True, 2, horizon, S, np.empty((count + 1, b.size)), np.zeros(1, dtype=np.int64)
        )

    assert find(1e-12) == pytest.approx(expected, abs=1e-6)
    assert abs(b.scalar(find(1e-12), z)) <= 1e-14
    assert find(float(np.max(f)) + 1e-9) == math.inf
    assert find(1e-12, horizon=expected - 0.05) == math.inf


@pytest.mark.parametrize("seed", [18, 5, 4])
def test_sampled_zeros_and_jumps_stay_in_the_compiled_loop(seed):
    """Corpus gaits whose offsets need sampled zeros (a linear part and harmonics, or several
    harmonics) and whose steps signals jump: every period runs in the compiled loop (no
    handoff), and its states, slips and event times are those of the Python loop to roundoff
    (the same certified KKT points and the same sampled zeros)."""
    from crawlsim.gait.corpus import random_gait

    process = compile_gait(random_gait(seed, blocks=(2, 5), stiffness_ratio=1e6, friction_ratio=1e3), 100)
    compiled, python = EventStepper(process), EventStepper(process, kernel=False)
    assert compiled._loop is not None and compiled.basis.harmonics + compiled.basis.linear >= 2
    assert compiled._jump.any()
    for _ in range(2):
        a, b = compiled.step_period(), python.step_period()
        scale = max(1.0, float(np.max(np.abs(b.w))))
        np.testing.assert_allclose(a.w, b.w, rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(
            a.multipliers, b.multipliers, rtol=0, atol=1e-11 * max(1.0, float(np.max(np.abs(b.multipliers))))
        )
        np.testing.assert_allclose(a.events.t, b.events.t, rtol=0, atol=1e-12)
    assert compiled._loop is not None and compiled._loop.handoffs == 0


# -- the paper's Section 5 maps ---------------------------------------------------------------


@pytest.mark.parametrize("alpha", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("fraction", [0.0, 0.4, 0.9, 1.5])
def test_acute_angle_poincare_map_iterate_by_iterate(alpha, fraction):
    """Paper Section 5.2 (corrected l(t), docs/model.md, Correction 2): on the edge z2 = 0 the Poincare map
    is z1 -> (alpha^2 gamma + z1)/(alpha^2 + 1) for z1 < gamma = T/(2 alpha), the identity
    beyond; exact integration reproduces every iterate."""
    gamma = 1 / (2 * alpha)
    z = paper.acute_angle_iterates(alpha, fraction * gamma, 10, steps=8, integrator="exact")
    expected = [fraction * gamma]
    for _ in range(10):
        expected.append(paper.acute_angle_map(expected[-1], alpha))
    np.testing.assert_allclose(z[:, 0], expected, rtol=0, atol=1e-13)
    assert np.max(np.abs(z[:, 1])) <= 1e-13


@pytest.mark.parametrize("path", sorted((GAITS / "paper").glob("*.yaml")), ids=lambda p: p.stem)
def test_paper_files_agree_with_catch_up(path):
    """The paper's processes are piecewise-linear with their kinks on the grid; there catch-up
    agrees with the exact solution to roundoff at every grid time (measured, 4 periods). The
    crawler file (cosine links) runs, and its exact v0 does not depend on the output grid."""
    spec = load_gait(path)
    process = compile_any(spec, 30)
    exact_stepper, catch_up = make_stepper(process, "exact"), make_stepper(process, "catch-up")
    records = [(exact_stepper.step_period(), catch_up.step_period()) for _ in range(4)]
    if process.crawler is not None:
        v0 = [np.mean(r.x[-1] - r.x[0]) for r, _ in records[-2:]]
        other = EventStepper(compile_any(spec, 7))
        for _ in range(4):
            rec = other.step_period()
        assert np.mean(rec.x[-1] - rec.x[0]) == pytest.approx(v0[-1], abs=1e-13)
        return
    for a, b in records:
        np.testing.assert_allclose(a.w, b.w, rtol=0, atol=1e-13)
        np.testing.assert_allclose(a.multipliers, b.multipliers, rtol=0, atol=1e-13)


def test_triangle_edge_map_every_third():
    """Paper Section 5.3: at the end of every third the point is on the pushing edge, at arc
    parameter phi(s) = (1 - s)/2 of the previous one."""
    spec = with_simulation(load_gait(GAITS / "paper" / "triangle.yaml"), steps_per_period=12)
    edges = paper.triangle_edges(spec, 6, paper._triangle_alpha(spec), integrator="exact")
    s = edges[:, 0]
    np.testing.assert_allclose(s[1:], [paper.phi(v) for v in s[:-1]], rtol=0, atol=1e-13)
    assert np.max(np.abs(edges[:, 1])) <= 1e-13


def test_dependent_normals_of_a_process_warn_and_the_point_is_right():
    """The square [-1, 1]^2 translated by -(s, s), s rising to 1/2 at T/2 and back, with the
    redundant face z1 + z2 <= 2 - 2 s through its corner: from (0.9, 0.9) the corner (1 - s, 1 - s)
    catches the point at s = 0.1 (an event at t = 0.1) and carries it to (0.5, 0.5). Three tight
    normals in the plane are dependent: a LicqWarning naming the process's rows, not an error."""
    corner = {
        "kind": "sweeping-process",
        "name": "corner",
        "period": 1.0,
        "normals": [[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1]],
        "offsets": [
            {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": v}
            for v in ([1, 0.5, 1], [1, 1.5, 1], [1, 0.5, 1], [1, 1.5, 1], [2, 1, 2])
        ],
        "initial": [0.9, 0.9],
        "simulation": {"steps_per_period": 10, "max_periods": 10},
    }
    stepper = EventStepper(compile_any(parse_gait(yaml.safe_dump(corner), source="c.yaml")))
    with pytest.warns(LicqWarning, match=r"LICQ fails at t = 0.1: .*\{0, 2, 4\}"):
        rec = stepper.step_period()
    np.testing.assert_allclose(rec.events.t, [0.0, 0.1, 0.5], atol=1e-15)
    np.testing.assert_allclose(rec.w[5], [0.5, 0.5], atol=1e-15)
    np.testing.assert_allclose(rec.w[-1], [0.5, 0.5], atol=1e-15)


# -- guards ------------------------------------------------------------------------------------


def test_event_bound_stops_with_a_clear_message():
    process = compile_gait(load_gait(GAITS / "peristalsis-4.yaml"), 10)
    with pytest.raises(EventError, match="more than 3 events in period 0.*max_events"):
        EventStepper(process, max_events=3).step_period()


def test_accumulating_events_are_reported_not_looped():
    process = compile_gait(load_gait(GAITS / "peristalsis-4.yaml"), 10)
    with pytest.raises(EventError, match="Zeno-like accumulation of events: 4 events"):
        EventStepper(process, zeno_events=4, zeno_window=0.5).step_period()


# -- integration: YAML, CLI, HDF5 -----------------------------------------------------------


def test_gait_file_selects_the_exact_integrator():
    gait = with_simulation(load_gait(GAITS / "anchoring-2.yaml"), integrator="exact", steps_per_period=20)
    assert run(gait).v0 == pytest.approx(0.3, abs=1e-14)  # catch-up: 0.3 - 1.2 h
    with pytest.raises(GaitError, match="simulation.integrator"):
        with_simulation(gait, integrator="runge-kutta")


def test_cli_run_exact_writes_events(tmp_path):
    out = tmp_path / "inching.h5"
    result = CliRunner().invoke(
        main,
        [
            "run",
            str(GAITS / "inching-2.yaml"),
            "--integrator",
            "exact",
            "--steps-per-period",
            "20",
            "--json",
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    assert '"v0": 0.4' in result.output or '"v0": 0.39999999999999' in result.output
    data = read_results(out)
    t1 = math.acos(1 / 3) / (2 * math.pi)
    ev = data["events"]
    assert ev["t"].shape[0] == ev["w"].shape[0] == ev["x"].shape[0]
    np.testing.assert_allclose(ev["t"][-4:] - ev["t"][-4], [0.0, t1, 0.5, t1 + 0.5], atol=1e-13)
    bad = CliRunner().invoke(
        main, ["run", str(GAITS / "inching-2.yaml"), "--integrator", "rk4", "-o", str(tmp_path / "bad.h5")]
    )
    assert bad.exit_code == 2 and not (tmp_path / "bad.h5").exists()


def test_exact_integrator_does_not_cut_an_asymptotic_decay_short():
    """The acute angle converges only asymptotically (paper Section 5.2, rate 1/(1+alpha^2) =
    1/2 for alpha = 1). Event tolerances at roundoff keep the decay going to the run's
    tolerance: the verdict and the rate are those of the paper, as with catch-up."""
    from crawlsim.api import run as run_file
    from crawlsim.gait.document import load_gait, with_simulation

    gait = load_gait(Path(__file__).resolve().parents[1] / "gaits" / "paper" / "acute-angle.yaml")
    res = run_file(with_simulation(gait, integrator="exact"))
    assert res.convergence == "asymptotic"
    assert res.rate.rate == pytest.approx(0.5, rel=1e-6)
    steps = res.history.poincare_step
    assert np.allclose(steps[-5:] / steps[-6:-1], 0.5, rtol=1e-3)  # roundoff near 1e-12
