"""Two-block crawlers against closed forms, and the paper's Theorem th:1dim.

Derivation. Two blocks, one link: shape z = x2 - x1, stress sigma = k (L(t) - z) (compression
positive), elastic forces f = D^T sigma = (-sigma, sigma). Block 1 slips forward only at
f1 = mu1+, i.e. sigma = -mu1+, backward only at sigma = mu1-; block 2 slips forward only at
sigma = mu2+, backward only at sigma = -mu2-. So sigma lives in [-a, b] with
a = min(mu1+, mu2-) and b = min(mu1-, mu2+), and it is a play operator of k L(t): while
-a < sigma < b nothing moves; at sigma = b (L increasing) the block that attains b slips so that
z follows L; at sigma = -a (L decreasing) the block that attains a slips.

With L = 1 + A cos(2 pi t/T), the stroke is 2A. In the periodic regime the stress sweeps the
whole range a + b in each half period, after which the link's remaining stroke
delta = 2A - (a + b)/k is taken up by a slip (if delta > 0):

* mu1+ < mu2- and mu2+ < mu1- (both blocks slip forward more easily): extension moves block 2
  forward by delta, contraction moves block 1 forward by delta. Displacement per period of the
  barycentre = delta = 2A - (mu1+ + mu2+)/k; dissipation per period = (mu1+ + mu2+) delta.
* mu1- < mu2+ and mu1+ < mu2- (block 1 is the weak one both ways): block 1 slips back by delta
  during extension and forward by delta during contraction; zero net motion, dissipation
  (mu1+ + mu1-) delta.
* k 2A < a + b (below the threshold of motion): after the first period nothing slips: v0 = 0 and
  no dissipation.

The cosine's extremes (u = 0 and 1/2) are grid points when steps_per_period is even, so catch-up
on the grid reproduces the play operator exactly, to roundoff.
"""

import numpy as np
import pytest

from crawlsim.api import run
from crawlsim.gait.crawler_spec import admissibility_violation
from crawlsim.gait.document import load_gait, with_simulation

from .conftest import GAITS, make_gait, two_block


@pytest.mark.parametrize(
    "amplitude,k,mu_plus,mu_minus", [(0.3, 10.0, 1.0, 2.0), (0.5, 4.0, 0.3, 0.7), (0.25, 25.0, 2.0, 5.0)]
)
def test_moving_gait(amplitude, k, mu_plus, mu_minus):
    gait = two_block(amplitude, k, {"forward": mu_plus, "backward": mu_minus})
    res = run(gait)
    delta = 2 * amplitude - 2 * mu_plus / k
    assert delta > 0
    assert res.estimate.displacement == pytest.approx(delta, abs=1e-13)
    assert res.v0 == pytest.approx(delta, abs=1e-13)
    assert res.energy.dissipation == pytest.approx(2 * mu_plus * delta, abs=1e-12)
    assert res.energy.cost_of_transport == pytest.approx(2 * mu_plus, abs=1e-11)
    # In the limit period block 2 slips forward while the link extends, block 1 while it contracts.
    slip = res.limit.slip
    assert set(np.unique(slip[:, 0])) == {0, 1} and set(np.unique(slip[:, 1])) == {0, 1}
    first_half = res.limit.t[1:] <= 0.5 + 1e-12  # L decreases: the link contracts
    assert not np.any(slip[first_half, 1] == 1)
    assert not np.any(slip[~first_half, 0] == 1)


def test_back_and_forth_with_zero_net_motion():
    friction = [{"forward": 1.0, "backward": 1.0}, {"forward": 3.0, "backward": 3.0}]
    res = run(two_block(0.3, 10.0, friction))
    delta = 0.6 - 2.0 / 10.0
    assert res.v0 == pytest.approx(0.0, abs=1e-14)
    assert res.energy.dissipation == pytest.approx(2.0 * delta, abs=1e-12)
    assert res.energy.cost_of_transport is None
    dx = np.diff(res.limit.x + res.v0 * res.limit.t[:, None], axis=0)
    assert np.sum(np.clip(dx[:, 0], 0, None)) == pytest.approx(delta, abs=1e-12)
    assert np.sum(np.clip(-dx[:, 0], 0, None)) == pytest.approx(delta, abs=1e-12)
    assert np.max(np.abs(dx[:, 1])) < 1e-14  # the heavy block never moves


def test_below_threshold_of_motion():
    """2 A k = 0.8 < a + b = 2. Start in tension at sigma = -a = -1 when L begins to shorten:
    block 1 slides forward by the whole stroke 2A during the first half period, then nothing
    moves again. Displacement of period 0 = 2A/2; v0 = 0; periodic from period 1."""
    A, k = 0.04, 10.0
    L0 = 1 + A
    gait = two_block(A, k, initial={"positions": [0.0, L0 + 1.0 / k]})
    res = run(gait)
    assert res.history.displacement[0] == pytest.approx(A, abs=1e-14)
    assert res.v0 == 0.0
    assert res.energy.dissipation == 0.0
    assert res.convergence == "finite-time" and res.periodic_from == 1
    assert np.all(res.limit.slip == 0)


@pytest.mark.parametrize("seed", range(6))
def test_two_blocks_are_periodic_from_period_one(seed):
    """Paper Theorem th:1dim: every two-block crawler is periodic from t0 + T."""
    rng = np.random.default_rng(seed)
    mu = rng.uniform(0.5, 3.0, size=4)
    friction = [
        {"forward": float(mu[0]), "backward": float(mu[1])},
        {"forward": float(mu[2]), "backward": float(mu[3])},
    ]
    if abs(mu[0] - mu[3]) < 1e-3 or abs(mu[2] - mu[1]) < 1e-3:
        pytest.skip("too close to the uniqueness condition")
    gait = two_block(
        float(rng.uniform(0.05, 0.4)),
        float(rng.uniform(2, 20)),
        friction,
        links=[
            {
                "kind": "fourier",
                "mean": 1.0,
                "cos": rng.uniform(-0.2, 0.2, 2).tolist(),
                "sin": rng.uniform(-0.2, 0.2, 2).tolist(),
            }
        ],
    )
    res = run(gait)
    assert res.convergence == "finite-time"
    assert res.periodic_from <= 1
    assert res.history.poincare_step[-1] <= 1e-13 * max(1.0, np.max(np.abs(res.limit.w)))


def test_rate_independence():
    """Rescaling the period leaves the displacement per period unchanged: v0 T is constant."""
    base = load_gait(GAITS / "peristalsis-4.yaml")
    values = []
    for T in (0.25, 1.0, 7.0):
        doc = dict(base.document, period=T, simulation={"steps_per_period": 300})
        res = run(make_gait(doc))
        values.append(res.v0 * T)
    assert np.ptp(values) < 1e-12 * abs(values[0])


def test_v0_does_not_depend_on_the_initial_state():
    """Theorem th:speed: v0 is the same from every admissible start."""
    gait = with_simulation(load_gait(GAITS / "peristalsis-4.yaml"), steps_per_period=300)
    rng = np.random.default_rng(1)
    v0s = []
    x_default = gait.initial_positions
    starts = [x_default]
    while len(starts) < 5:
        x = x_default + np.concatenate([[0.0], np.cumsum(rng.uniform(-0.12, 0.12, 3))]) + 5.0
        if admissibility_violation(gait, x) is None:
            starts.append(x)
    for x in starts:
        doc = dict(gait.document, initial={"positions": [float(v) for v in x]})
        v0s.append(run(make_gait(doc)).v0)
    assert np.ptp(v0s) < 1e-12


@pytest.mark.parametrize("steps,coefficient", [(1000, -1.6), (500, -1.6), (999, -1.2), (101, -1.2)])
def test_anchoring_catch_up_error_depends_on_the_parity_of_the_step_count(steps, coefficient):
    """gaits/anchoring-2.yaml: catch-up's v0 is 0.3 + coefficient * h (h = T / steps, T = 1),
    coefficient -1.6 for an even step count and -1.2 for an odd one.

    Derivation. The link extends at rate 0.8 on [0, 1/2) and contracts at 0.8 on [1/2, 1); at
    t = 1/2 and t = 1 the friction of the two blocks swaps (2 <-> 0.5). In the periodic regime
    the stress is held at +0.5 by block 2 slipping forward at the end of the extension and at
    -0.5 by block 1 slipping forward at the end of the contraction (v0 = 0.3 exactly). Catch-up
    projects the step that ends at a switching time onto K at that time, with the friction
    already swapped: the link's stroke 0.8 h_s over that step (length h_s) is taken by the other
    block, which slips backward by 0.8 h_s instead of the block ahead forward by 0.8 h_s; the
    barycentre moves 0.8 h_s less, and the state at the end of the step is the same. So the error
    per period is -0.8 (h_a + h_b) over the two steps ending at t = 1/2 and t = 1. For an even
    step count both are uniform steps h: -1.6 h. For an odd one t = 1/2 is inserted in the
    middle of a uniform step (`crawlsim.model.process.period_grid`), whose first half, h / 2, ends at
    the switch: -0.8 (h / 2 + h) = -1.2 h. Tolerance 1e-9 on the coefficient: v0's roundoff,
    1e-13, over h >= 1e-3."""
    gait = with_simulation(load_gait(GAITS / "anchoring-2.yaml"), integrator="catch-up", steps_per_period=steps)
    res = run(gait)
    assert (res.v0 - 0.3) * steps == pytest.approx(coefficient, abs=1e-9)


#: The largest stiffness crawlsim accepts for two_block(0.3, k) with friction 1 / 2: the
#: stress scale k max|L| / min mu = 1.3 k at most `STRESS_SCALE_LIMIT`.
def _largest_stiffness():
    from crawlsim.gait.crawler_limits import STRESS_SCALE_LIMIT

    return STRESS_SCALE_LIMIT / 1.3


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize("k", [1e1, 1e3, 1e5, 1e7, 1e8, 1e9, "largest"])
def test_stiff_crawler_closed_form_up_to_the_largest_accepted_stiffness(k, integrator):
    """Issue 19, item 7. The moving gait of the module docstring, v0 = 2A - 2 mu+ / k
    (A = 0.3, mu+ = 1: 0.6 - 2/k), at stiffnesses up to the largest one accepted: v0 is
    within its printed estimate of the closed form (before the limit on the stress scale, k =
    1e12 gave 19 times the estimate and k = 1e18 a Clarabel failure)."""
    k = _largest_stiffness() * (1 - 1e-12) if k == "largest" else k
    gait = two_block(
        0.3,
        k,
        {"forward": 1.0, "backward": 2.0},
        steps=100,
        simulation={"steps_per_period": 100, "max_periods": 20, "integrator": integrator},
    )
    res = run(gait)
    assert res.converged
    closed = 0.6 - 2.0 / k
    assert abs(res.v0 - closed) <= res.estimate.error_estimate, (res.v0, closed, res.estimate.error_estimate)
    assert abs(res.v0 - closed) <= 1e-13


@pytest.mark.parametrize("factor", [1.01, 1e2, 1e4, 1e8, 1e90])
def test_stiffer_crawlers_are_refused_with_the_reason(factor, tmp_path):
    """Beyond the largest stiffness: exit code 2, naming the key, the ratio and the largest
    stiffness these lengths and friction allow; nothing is computed or written."""
    from click.testing import CliRunner

    from crawlsim.cli import main

    k = _largest_stiffness() * factor
    path = tmp_path / "stiff.yaml"
    path.write_text(
        f"blocks: 2\nperiod: 1.0\nstiffness: {k!r}\n"
        "links: [{kind: cosine, mean: 1.0, amplitude: 0.3}]\n"
        "friction: {forward: 1.0, backward: 2.0}\n"
    )
    for args in (["run", str(path), "-o", str(tmp_path / "out.h5")], ["velocity", str(path)], ["validate", str(path)]):
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2, r.output
        assert "Traceback" not in r.output
        # run and velocity: one line on stderr; validate lists each file's errors on stdout
        message = (r.stdout if args[0] == "validate" else r.stderr).strip()
        assert len(message.splitlines()) == 1, message
        assert f"{path}: stiffness: " in message and "too stiff for this friction" in message
        assert "up to 7.69e+09" in message
    assert not (tmp_path / "out.h5").exists()
