"""The energy ledger (crawlsim/analysis/energy.py): balance, closed forms, jump losses, the bound on the
cost of transport.

Stress is positive in compression, sigma = K (L - z), and the actuator work W = sum_i oint
sigma_i dL_i is the work done by the actuators on the body (docs/model.md §1, §4). Over a period
W = D + J + E(end) - E(start): D the friction dissipation, J the jump losses, E the elastic
energy; in the periodic regime E is periodic and W = D + J.
"""

import json
import math

import numpy as np
import pytest
import yaml
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from crawlsim.analysis import energy
from crawlsim.analysis.report import summary_text
from crawlsim.analysis.run import simulate
from crawlsim.api import run as api_run
from crawlsim.errors import InputError
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.gait.signals import Fourier
from crawlsim.integrate import ledger
from crawlsim.integrate.stepping import make_stepper
from crawlsim.io.runread import read_results
from crawlsim.model.offsets import Basis
from crawlsim.model.process import compile as compile_any
from crawlsim.model.process import compile_gait
from crawlsim.study.grid import make_grid
from crawlsim.study.points import run_points

from .conftest import GAITS, make_gait

CRAWLERS = sorted(
    p
    for p in list(GAITS.glob("*.yaml")) + list(GAITS.glob("paper/*.yaml"))
    if compile_any(load_gait(p)).crawler is not None
)


def _run(gait, integrator="exact", **options):
    s = gait.simulation
    return simulate(
        compile_gait(gait), max_periods=s.max_periods, tolerance=s.tolerance, integrator=integrator, **options
    )


# -- the balance on every example gait -----------------------------------------------------------
@pytest.mark.parametrize("path", CRAWLERS, ids=lambda p: p.stem)
def test_balance_on_every_example_gait_with_the_exact_integrator(path):
    """In the periodic regime W = D + J + W_load to 1e-10 relative (W_load, the work against
    the loads of docs/model.md §6, is 0 without loads), and the dissipation is positive (every
    example crawler moves)."""
    run = _run(load_gait(path))
    assert run.converged
    W, D, J = run.energy.actuator_work, run.energy.dissipation, run.energy.jump_loss
    assert W is not None and D is not None and J is not None
    assert D > 0 and J >= 0
    assert abs(run.energy.balance_residual) <= 1e-10 * W
    load = run.energy.load_work or 0.0
    assert W - D - J - load == pytest.approx(run.energy.balance_residual, abs=1e-15 * W)


@pytest.mark.parametrize("path", CRAWLERS, ids=lambda p: p.stem)
def test_every_exact_period_balances_with_the_change_of_elastic_energy(path):
    """W - D - J = E(end) - E(start) on every period, also the transient first one, where the
    elastic energy changes: D comes from the friction signals and the slip rates, W from the
    stresses and the actuators, so this checks that the active blocks sit at their limits."""
    process = compile_gait(load_gait(path))
    stepper = make_stepper(process, "exact")
    changes = []
    for _ in range(3):
        e = energy.period_energy(process, stepper.step_period())
        assert e is not None
        assert abs(e.residual - e.energy_change) <= 1e-12 * e.scale
        changes.append(abs(e.energy_change))
    assert changes[0] > 1e-6  # the first period is a transient: the check is not 0 = 0


@pytest.mark.parametrize("path", CRAWLERS, ids=lambda p: p.stem)
def test_catch_up_discrete_balance_is_exact_for_the_scheme(path):
    """W_h = D_h + J_h + E^G - E^0 on every catch-up period (module docstring of
    crawlsim.analysis.energy: each step is an elastic predictor, whose work is (sigma^n + K dL/2) . dL,
    and a K^-1-projection, which releases f^{n+1} . dx + sum k (dz)^2 / 2)."""
    gait = load_gait(path)
    process = compile_gait(gait, 400)
    stepper = make_stepper(process, "catch-up")
    for _ in range(3):
        record = stepper.step_period()
        e = energy.catch_up_energy(process, record)
        assert abs(e.residual - e.energy_change) <= 1e-12 * e.scale
        # the ledger's dissipation is the run's
        assert e.dissipation == energy.period_dissipation(process, record)


def test_catch_up_numerical_dissipation_is_first_order():
    """Without jumps J_h = sum_n sum_i k_i (dz_i)^2 / 2 is the scheme's numerical dissipation,
    reported as the discretisation loss, not as jump losses (which are 0 without a jump; issue
    35: a catch-up run of inching-2 reported it as 'jump losses'): on inching-2 only slipping
    steps change z, by dz = dL = O(h), so J_h ~ (k/2) h int L'^2 over the slip phases: halving h
    halves it; and W_h tends to the exact W = 0.8."""
    gait = load_gait(GAITS / "inching-2.yaml")
    values = []
    for G in (400, 800, 1600):
        process = compile_gait(gait, G)
        stepper = make_stepper(process, "catch-up")
        stepper.step_period()
        e = energy.catch_up_energy(process, stepper.step_period())
        assert e.jump_loss == 0.0 and e.discretisation_loss > 0
        values.append((e.discretisation_loss, e.work))
    (j1, w1), (j2, w2), (j3, w3) = values
    assert j2 / j1 == pytest.approx(0.5, rel=0.01)
    assert j3 / j2 == pytest.approx(0.5, rel=0.01)
    assert (w2 - 0.8) / (w1 - 0.8) == pytest.approx(0.5, rel=0.01)
    assert (w3 - 0.8) / (w2 - 0.8) == pytest.approx(0.5, rel=0.01)


# -- closed forms -----------------------------------------------------------------------------------
@pytest.mark.parametrize("k, a, m1, m2", [(8.0, 0.35, 0.7, 1.1), (10.0, 0.3, 1.0, 1.0), (25.0, 0.2, 0.4, 1.9)])
def test_two_block_inching_closed_form(k, a, m1, m2):
    """Two blocks, L = 1 + a cos(2 pi t/T), forward friction m1 (rear), m2 (front), backward 3.

    The force on the rear block is -sigma and on the front one +sigma, so sigma stays in
    [-m1, m2] (the backward limits, sigma = 3 or -3, are never reached) and the link is a play
    operator. Extending by 2a, sigma climbs from -m1 to m2 while both stick (Delta L = (m1 +
    m2)/k, work int sigma dL = (m2^2 - m1^2)/(2k)), then the front slides by d = 2a - (m1 + m2)/k
    at sigma = m2 (work m2 d). Contracting, sigma falls back to -m1 (work (m1^2 - m2^2)/(2k))
    and the rear slides by d at sigma = -m1 with dL < 0 (work m1 d). So

        W = D = (m1 + m2) d,   J = 0,

    and each block slips forward only, at constant friction: the bound (m1 + m2) is attained
    and the efficiency is 1.
    """
    gait = make_gait(
        {
            "blocks": 2,
            "period": 1.0,
            "stiffness": k,
            "links": [{"kind": "cosine", "mean": 1.0, "amplitude": a}],
            "friction": [{"forward": m1, "backward": 3.0}, {"forward": m2, "backward": 3.0}],
            "simulation": {"steps_per_period": 200, "max_periods": 10},
        }
    )
    run = _run(gait)
    d = 2 * a - (m1 + m2) / k
    assert run.estimate.displacement == pytest.approx(d, rel=1e-13)
    assert run.energy.actuator_work == pytest.approx((m1 + m2) * d, rel=1e-13)
    assert run.energy.dissipation == pytest.approx((m1 + m2) * d, rel=1e-13)
    assert run.energy.jump_loss == pytest.approx(0.0, abs=1e-15)
    assert run.energy.cost_of_transport_bound == m1 + m2
    assert run.energy.efficiency == pytest.approx(1.0, rel=1e-12)


def jump_gait(k=8.0, A=0.5, m=0.9, mu=1.2, mu_after=0.5, steps=200):
    """Two blocks, L piecewise linear 1 -> 1 + A -> 1 on [0, T/2, T]; rear forward friction m,
    front forward friction mu on [0, T/2) switched to mu_after < mu at T/2; backward 3."""
    return make_gait(
        {
            "blocks": 2,
            "period": 1.0,
            "stiffness": k,
            "links": [{"kind": "piecewise-linear", "times": [0.0, 0.5, 1.0], "values": [1.0, 1.0 + A, 1.0]}],
            "friction": [
                {"forward": m, "backward": 3.0},
                {"forward": {"kind": "steps", "times": [0.0, 0.5], "values": [mu, mu_after]}, "backward": 3.0},
            ],
            "simulation": {"steps_per_period": steps, "max_periods": 10},
        }
    )


@pytest.mark.parametrize("k, A, m, mu, mu_after", [(8.0, 0.5, 0.9, 1.2, 0.5), (10.0, 0.6, 1.0, 1.0, 0.5)])
def test_jump_loss_at_a_friction_switch(k, A, m, mu, mu_after):
    """sigma lives in [-m, mu(t)]. Extending (first half), sigma climbs from -m to mu while both
    blocks stick (work (mu^2 - m^2)/(2k)), then the front slides at sigma = mu by A - (mu + m)/k.
    At T/2 the front's limit drops to mu_after < mu: the stress is outside the new set, and the
    front slips at once by (mu - mu_after)/k, sigma -> mu_after. That slip's friction work at the
    new limit is mu_after (mu - mu_after)/k; the elastic energy released is (mu^2 - mu_after^2)/(2k),
    so the jump loss is the difference, (mu - mu_after)^2/(2k). Contracting, sigma falls from
    mu_after to -m (work (m^2 - mu_after^2)/(2k)), then the rear slides by d = A - (mu_after +
    m)/k at sigma = -m (work m d). Back at t = T the limit rises again: no jump. Hence

        d = A - (mu_after + m)/k,
        D = mu (A - (mu + m)/k) + mu_after (mu - mu_after)/k + m d,
        J = (mu - mu_after)^2 / (2k),
        W = mu (A - (mu + m)/k) + (mu^2 - mu_after^2)/(2k) + m d = D + J,

    and the bound is (m + mu_after) d <= D.
    """
    run = _run(jump_gait(k, A, m, mu, mu_after))
    d = A - (mu_after + m) / k
    D = mu * (A - (mu + m) / k) + mu_after * (mu - mu_after) / k + m * d
    J = (mu - mu_after) ** 2 / (2 * k)
    W = mu * (A - (mu + m) / k) + (mu * mu - mu_after * mu_after) / (2 * k) + m * d
    assert W == pytest.approx(D + J, rel=1e-15)
    assert run.estimate.displacement == pytest.approx(d, rel=1e-13)
    assert run.energy.dissipation == pytest.approx(D, rel=1e-13)
    assert run.energy.jump_loss == pytest.approx(J, rel=1e-12)
    assert run.energy.actuator_work == pytest.approx(W, rel=1e-13)
    assert run.energy.cost_of_transport_bound == m + mu_after
    assert run.energy.efficiency == pytest.approx((m + mu_after) * d / D, rel=1e-12)
    assert run.energy.efficiency < 1


def test_catch_up_jump_loss_converges_to_the_jump_loss():
    """In catch-up the jump is one step of the scheme: its loss is the jump loss J + O(h) (the
    step also moves L by O(h)), and the other steps' loss is the discretisation loss, O(h), which
    the ledger reports apart; W_h = D_h + J_h + discretisation loss to roundoff."""
    k, A, m, mu, mu_after = 8.0, 0.5, 0.9, 1.2, 0.5
    J = (mu - mu_after) ** 2 / (2 * k)
    errors, numerical = [], []
    for G in (400, 800, 1600):
        run = _run(jump_gait(k, A, m, mu, mu_after, steps=G), "catch-up")
        errors.append(run.energy.jump_loss - J)
        numerical.append(run.energy.discretisation_loss)
        assert abs(run.energy.balance_residual) <= 1e-12 * run.energy.actuator_work
    assert errors[0] > 0
    assert errors[1] / errors[0] == pytest.approx(0.5, rel=0.02)
    assert errors[2] / errors[1] == pytest.approx(0.5, rel=0.02)
    assert numerical[1] / numerical[0] == pytest.approx(0.5, rel=0.02)
    assert numerical[2] / numerical[1] == pytest.approx(0.5, rel=0.02)


# -- the pieces of the exact ledger ----------------------------------------------------------------
@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@pytest.mark.parametrize("linear, harmonics", [(False, 0), (True, 0), (False, 2), (True, 3)])
@pytest.mark.parametrize("a, b", [(0.0, 1.0), (0.123, 0.77), (0.5, 0.5 + 1e-9), (0.9, 1.0)])
def test_gram_matrix_is_the_integral_of_the_basis_products(linear, harmonics, a, b):
    """P[k, l] = int_a^b phi_k phi_l du, against adaptive quadrature (tiny pieces included)."""
    basis = Basis(linear, harmonics)
    P = ledger.gram(basis, a, b)
    assert np.array_equal(P, P.T)
    for i in range(basis.size):
        for j in range(basis.size):
            ref, _ = quad(
                lambda u, i=i, j=j: basis.values(u)[0, i] * basis.values(u)[0, j],
                a,
                b,
                epsabs=1e-15,
                epsrel=1e-13,
                limit=200,
            )
            assert P[i, j] == pytest.approx(ref, rel=1e-11, abs=1e-15 * (b - a) + 1e-17)


@settings(max_examples=40)
@given(
    st.lists(st.floats(-2, 2), min_size=1, max_size=4),
    st.lists(st.floats(-2, 2), min_size=0, max_size=4),
    st.floats(0, 1),
)
@example([1.0, 0.0, 0.0, 0.0], [], 0.0)  # zero top harmonics: a lower-degree polynomial
@example([1.0], [2.0, 4.846239413359878e-85], 0.0)  # a harmonic below roundoff (found by Hypothesis)
def test_fourier_friction_minimum_is_exact(cos, sin, phase):
    """The minimum of a Fourier signal from the critical points is a value of the signal, and
    no sample of a fine grid is below it."""
    signal = Fourier(3.0, tuple(cos), tuple(sin), phase)
    low = energy.friction_minimum(signal)
    u = np.linspace(0.0, 1.0, 200_001)
    sampled = float(np.min(signal(u)))
    assert low <= sampled + 1e-12
    # the grid's spacing bounds how far its best sample can be above the minimum
    H = signal.harmonics
    curvature = sum(
        (2 * math.pi * n) ** 2 * (abs(c) + abs(s))
        for n, (c, s) in enumerate(zip(list(cos) + [0.0] * H, list(sin) + [0.0] * H), start=1)
    )
    assert low >= sampled - curvature * (0.5 / 200_000) ** 2 / 2 - 1e-12


# -- the bound on the cost of transport ------------------------------------------------------------
def _bound_holds(gait, row) -> float:
    process = compile_gait(gait)
    bound = energy.cost_of_transport_bound(process, row.displacement_per_period)
    assert bound is not None and row.cost_of_transport is not None
    assert row.cost_of_transport >= bound * (1 - 1e-12)
    return bound / row.cost_of_transport


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize(
    "name, axes",
    [
        ("peristalsis-3.yaml", ["friction.backward=1.3:2.6:3", "links.*.amplitude=[0.2,0.35]"]),
        ("smooth-friction-3.yaml", ["friction.0.forward.amplitude=[0.2,0.6]", "links.1.phase=[0.25,0.5]"]),
        ("anchoring-2.yaml", ["friction.0.forward.values.1=[0.5,0.7,1.1]"]),
    ],
)
def test_cost_of_transport_bound_holds_on_a_sweep(name, axes, integrator):
    """Every evaluated point of a small sweep, with either integrator: cost_of_transport >=
    sum_j min_t mu_j^{sign d}, so the efficiency is at most 1."""
    doc = yaml.safe_load((GAITS / name).read_text())
    doc["simulation"].update(integrator=integrator, steps_per_period=200)
    grid = make_grid(make_gait(doc), axes)
    rows = run_points(grid, range(grid.size))
    checked = 0
    for i, row in enumerate(rows):
        if row.cost_of_transport is None:
            continue
        assert _bound_holds(grid.gait(i), row) <= 1 + 1e-12
        checked += 1
    assert checked >= grid.size - 1


@st.composite
def random_gaits(draw):
    N = draw(st.integers(2, 3))
    period = draw(st.sampled_from([0.5, 1.0, 2.0]))
    links = [
        {"kind": "cosine", "mean": 1.0, "amplitude": draw(st.floats(0.05, 0.4)), "phase": draw(st.floats(0.0, 1.0))}
        for _ in range(N - 1)
    ]

    def friction():
        kind = draw(st.sampled_from(["constant", "cosine", "steps", "fourier"]))
        mean = draw(st.floats(0.5, 2.5))
        if kind == "constant":
            return mean
        if kind == "fourier":  # |cos| + |sin| coefficients < 0.9 mean: positive friction
            return {
                "kind": "fourier",
                "mean": mean,
                "cos": [draw(st.floats(-0.3, 0.3)) * mean for _ in range(2)],
                "sin": [draw(st.floats(-0.3, 0.3)) * mean],
            }
        if kind == "cosine":
            return {
                "kind": "cosine",
                "mean": mean,
                "amplitude": draw(st.floats(0.0, 0.45)) * mean,
                "phase": draw(st.floats(0.0, 1.0)),
            }
        switch = draw(st.sampled_from([0.25, 0.5, 0.75]))
        return {"kind": "steps", "times": [0.0, switch], "values": [mean, draw(st.floats(0.3, 2.5))]}

    return {
        "blocks": N,
        "period": period,
        "stiffness": draw(st.floats(5.0, 20.0)),
        "links": links,
        "friction": [{"forward": friction(), "backward": friction()} for _ in range(N)],
        "simulation": {"steps_per_period": 64, "max_periods": 200},
    }


@settings(max_examples=30)
@given(random_gaits())
@example(
    {
        "blocks": 2,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 0.0}],
        "friction": [
            {"forward": 1.0, "backward": {"kind": "steps", "times": [0.0, 0.5], "values": [2.0, 0.6]}},
            {"forward": {"kind": "steps", "times": [0.0, 0.25], "values": [1.5, 0.4]}, "backward": 2.0},
        ],
        "simulation": {"steps_per_period": 64, "max_periods": 200},
    }
)
def test_balance_and_bound_on_random_gaits(doc):
    """Random two- and three-block gaits with constant, cosine, steps and Fourier friction: the
    balance W = D + J holds in the periodic regime and the efficiency is at most 1."""
    try:
        gait = make_gait(doc)
        run = _run(gait, history=False)
    except InputError:
        return  # a friction that breaks the uniqueness condition: not a gait
    assert run.converged
    W = run.energy.actuator_work
    assert W is not None and run.energy.jump_loss >= 0
    assert abs(run.energy.balance_residual) <= 1e-9 * max(W, 1e-12) + 1e-14
    if run.energy.efficiency is not None:
        assert run.energy.efficiency <= 1 + 1e-12
        forward, backward = energy.friction_minima(compile_gait(gait))
        d = run.estimate.displacement
        assert run.energy.dissipation >= float(np.sum(forward if d > 0 else backward)) * abs(d) * (1 - 1e-12)


# -- where the ledger is reported ------------------------------------------------------------------
def test_ledger_in_the_summary_and_the_results_file(tmp_path):
    """The ledger's numbers go to the summary dict (--json), the text summary, and /energy of
    the results file (with units and long_name) and its root attributes, unchanged."""
    import h5py

    out = tmp_path / "jump.h5"
    run = api_run(jump_gait(), output=out)
    summary = json.loads(json.dumps(run.summary()))
    e = run.energy
    assert [summary[f"{key}_per_period"] for key in ("actuator_work", "jump_loss")] == [e.actuator_work, e.jump_loss]
    assert summary["energy_balance_residual"] == e.balance_residual
    assert [summary[key] for key in ("cost_of_transport_bound", "efficiency")] == [
        e.cost_of_transport_bound,
        e.efficiency,
    ]
    text = summary_text(run.run)
    assert f"actuator work per period {run.energy.actuator_work:.12g}" in text
    assert "jump losses per period" in text and "cost of transport bound" in text
    data = read_results(out)
    assert data["energy"]["actuator_work"] == run.energy.actuator_work
    assert data["energy"]["dissipation"] == run.energy.dissipation
    assert data["energy"]["jump_loss"] == run.energy.jump_loss
    assert data["energy"]["efficiency"] == run.energy.efficiency
    assert data["attrs"]["cost_of_transport_bound"] == run.energy.cost_of_transport_bound
    units = json.loads(data["attrs"]["attribute_units_json"])
    assert units["actuator_work_per_period"] == units["dissipation_per_period"]
    with h5py.File(out, "r") as f:
        assert set(f["energy"]) == {
            "actuator_work",
            "dissipation",
            "jump_loss",
            "balance_residual",
            "cost_of_transport_bound",
            "efficiency",
        }
        for name, ds in f["energy"].items():
            assert ds.attrs["long_name"] and ds.attrs["units"] == "1", name
    # the exact integrator has no discretisation loss; catch-up's is its own number
    assert summary["discretisation_loss_per_period"] is None and "discretisation loss" not in text
    catch_up = api_run(with_simulation(jump_gait(), integrator="catch-up"), output=tmp_path / "c.h5")
    assert read_results(tmp_path / "c.h5")["energy"]["discretisation_loss"] == catch_up.energy.discretisation_loss
    assert catch_up.energy.discretisation_loss > 0
    assert f"discretisation loss      {catch_up.energy.discretisation_loss:.3g} per period" in summary_text(catch_up)


def test_generic_process_has_no_ledger():
    """A generic sweeping process has no actuators or friction: every ledger key is null."""
    spec = load_gait(GAITS / "paper" / "cell-3.yaml")
    run = simulate(compile_any(spec), max_periods=5, integrator="exact")
    summary = run.summary()
    for key in (
        "actuator_work_per_period",
        "jump_loss_per_period",
        "energy_balance_residual",
        "cost_of_transport_bound",
        "efficiency",
    ):
        assert summary[key] is None
    assert "actuator work" not in summary_text(run)


def test_the_balance_covers_every_example_crawler():
    """The parametrized balance tests see every crawler gait shipped, steps friction included."""
    assert {p.stem for p in CRAWLERS} >= {
        "anchoring-2",
        "inching-2",
        "peristalsis-3",
        "peristalsis-4",
        "smooth-friction-3",
        "speed-peristalsis-4",
    }


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize("k, a, p, q", [(10.0, 0.5, 1.0, 1.0), (8.0, 0.6, 1.3, 0.7)])
def test_actuator_jumps_closed_form(integrator, k, a, p, q):
    """A link that jumps: L = 1 on [0, T/2), 1 + a on [T/2, T); front forward friction p, rear
    forward friction q, backward 3 (never reached). sigma sits at -q before the jump up (the rear
    block's forward limit); the jump moves the actuator with the blocks held, so sigma^tr =
    k a - q, and the actuator works E(sigma^tr) - E(-q) = ((k a - q)^2 - q^2)/(2k). Beyond p
    the front slips at once by s = a - (p + q)/k (k a > p + q), at friction p: friction work
    p s, jump loss k s^2/2. The jump down at T mirrors it (sigma^tr = p - k a, work
    ((k a - p)^2 - p^2)/(2k), the rear slips by s at friction q). Hence

        d = s,   W = k a^2 - a (p + q),   D = (p + q) s,   J = k s^2,

    and W = D + J. Nothing moves between the jumps, so catch-up, whose steps are exactly such
    jumps, gives the same numbers; every block slips forward only, at constant friction, so the
    efficiency is 1.
    """
    gait = make_gait(
        {
            "blocks": 2,
            "period": 1.0,
            "stiffness": k,
            "links": [{"kind": "steps", "times": [0.0, 0.5], "values": [1.0, 1.0 + a]}],
            "friction": [{"forward": q, "backward": 3.0}, {"forward": p, "backward": 3.0}],
            "simulation": {"steps_per_period": 50, "max_periods": 10},
        }
    )
    run = _run(gait, integrator)
    s = a - (p + q) / k
    assert run.estimate.displacement == pytest.approx(s, rel=1e-13)
    assert run.energy.actuator_work == pytest.approx(k * a * a - a * (p + q), rel=1e-13)
    assert run.energy.dissipation == pytest.approx((p + q) * s, rel=1e-13)
    assert run.energy.jump_loss == pytest.approx(k * s * s, rel=1e-12)
    assert run.energy.efficiency == pytest.approx(1.0, rel=1e-12)
