"""Random valid gaits never crash: a seeded corpus through both integrators (slow).

Each gait of `crawlsim.gait.corpus.random_gait` (every signal kind, per-link stiffness over three
decades, per-block, time-varying and switched friction over two decades either way) runs with
catch-up and with the exact integrator. Every step of either is certified by the KKT kernel,
so a certificate or event failure on a valid gait would be an exit-1 bug: there must be none.
Catch-up must converge to the exact integrator's v0 as the step shrinks: its error is first order
in the step (docs/model.md §3), so sixteen times as many steps per period must leave at most half
the error, up to the exact v0's own bound. The margin is generous on purpose: besides the first
order term, a coarse grid can miss a slip that the exact solution makes near a tangential
contact, an error set by that slip's size and not by the step (seed 37: 5.1e-7 at 200, 400
and 800 steps per period, 4.4e-7 at 1600, 1.0e-9 at 3200), which vanishes only once the grid
resolves the contact. A catch-up grid time may land on an instant where the model does
not determine the motion (`DegenerateModelError`, exit 2); the exact integrator, which resolves
instants exactly, must then still run.

The ill-conditioned corpus (stiffness spread to 1e6, friction ratios to 1e3) is
``scripts/random-gait-corpus.py --size 120``; this file runs its first seeds at small N so that
it fits in CI, the seeds of that corpus whose exact runs failed their certificate before each
multiplier was held to its own row's tolerance (`crawlsim.kernel.chain.row_duals`), and a gait
whose offsets have 1000 piecewise-linear knots (pieces 1e-7 of a cycle long with slopes of 1e5,
where the sampled trajectory's tolerance must follow the size of the numbers summed).
"""

from __future__ import annotations

import numpy as np
import pytest

from crawlsim.analysis.run import simulate
from crawlsim.errors import DegenerateModelError
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import gait_from_document
from crawlsim.model.process import compile_gait

STEPS = 200
SEEDS = range(40)


def converges_with_both_integrators(gait) -> None:
    """Exact converges; catch-up with 16 times the steps has at most half the error."""
    process = compile_gait(gait, STEPS)
    exact = simulate(process, integrator="exact", max_periods=300, tolerance=1e-11, history=False)
    assert exact.converged and exact.v0 is not None and exact.estimate.error_estimate is not None
    errors = []
    for steps in (STEPS, 16 * STEPS):
        try:
            catch_up = simulate(
                compile_gait(gait, steps), integrator="catch-up", max_periods=300, tolerance=1e-11, history=False
            )
        except DegenerateModelError:
            return  # a grid time on a degenerate instant: refused with its reason, not a crash
        assert catch_up.converged and catch_up.v0 is not None
        errors.append(abs(catch_up.v0 - exact.v0))
    assert errors[1] <= errors[0] / 2 + exact.estimate.error_estimate + 1e-12, errors


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
def test_random_gait_runs_with_both_integrators(seed):
    converges_with_both_integrators(random_gait(seed, blocks=(2, 8), steps_per_period=STEPS, max_periods=300))


#: Seeds of the ill-conditioned corpus (N <= 12) whose exact run failed its certificate when the
#: sign of every multiplier was held to one scalar tolerance, set by the stiffest link.
ILL_CONDITIONED = (10, 22)


@pytest.mark.slow
@pytest.mark.parametrize("seed", ILL_CONDITIONED)
def test_ill_conditioned_gait_runs_with_both_integrators(seed):
    converges_with_both_integrators(
        random_gait(seed, blocks=(2, 12), stiffness_ratio=1e6, friction_ratio=1e3, max_periods=300)
    )


def knotted_gait(knots: int = 1000):
    """Three blocks, two links driven by piecewise-linear signals with ``knots`` random knots
    (a cosine wave plus noise): some pieces are 1e-7 cycle long with slopes near 1e5."""
    rng = np.random.default_rng(1)
    times = [0.0, *np.sort(rng.uniform(0.0005, 0.9995, knots - 2)).tolist(), 1.0]

    def values(phase):
        v = 1.0 + 0.3 * np.cos(2 * np.pi * (np.array(times) - phase))
        v += 0.02 * rng.normal(size=len(times))
        v[-1] = v[0]
        return v.tolist()

    doc = {
        "name": "knots",
        "blocks": 3,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [
            {"kind": "piecewise-linear", "times": times, "values": values(0.0)},
            {"kind": "piecewise-linear", "times": times, "values": values(0.33)},
        ],
        "friction": {"forward": 1.0, "backward": 1.5},
        "simulation": {"steps_per_period": 1000, "max_periods": 50, "tolerance": 1e-12},
    }
    return gait_from_document(doc, "knots", default_name="knots")


@pytest.mark.slow
def test_a_thousand_knots_run_exactly():
    """The exact run of the 1000-knot gait is certified to the end and agrees with catch-up on
    its own grid (which holds every knot, 1998 steps) to catch-up's first-order error: the
    largest stroke velocity times a few steps."""
    gait = knotted_gait()
    process = compile_gait(gait)
    exact = simulate(process, integrator="exact", max_periods=50, tolerance=1e-12, history=False)
    catch_up = simulate(process, integrator="catch-up", max_periods=50, tolerance=1e-12, history=False)
    assert exact.converged and catch_up.converged
    assert exact.v0 is not None and catch_up.v0 is not None
    L = process.crawler.lengths
    stroke = float(np.max(L.max(axis=0) - L.min(axis=0))) / gait.period
    assert 0.0 < abs(catch_up.v0 - exact.v0) <= 10 * stroke / process.steps
