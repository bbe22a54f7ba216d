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

``scripts/random-gait-corpus.py --count 500`` is the full corpus (measured figures in the
closing notes); this test runs its first seeds at small N so that it fits in CI.
"""

from __future__ import annotations

import pytest

from crawlsim.analysis.run import simulate
from crawlsim.errors import DegenerateModelError
from crawlsim.gait.corpus import random_gait
from crawlsim.model.process import compile_gait

STEPS = 200
SEEDS = range(40)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
def test_random_gait_runs_with_both_integrators(seed):
    gait = random_gait(seed, blocks=(2, 8), steps_per_period=STEPS, max_periods=300)
    process = compile_gait(gait)
    exact = simulate(process, integrator="exact", max_periods=300, tolerance=1e-11,
                     history=False)
    assert exact.converged and exact.v0 is not None and exact.v0_error_estimate is not None
    errors = []
    for steps in (STEPS, 16 * STEPS):
        try:
            catch_up = simulate(compile_gait(gait, steps), integrator="catch-up",
                                max_periods=300, tolerance=1e-11, history=False)
        except DegenerateModelError:
            return  # a grid time on a degenerate instant: refused with its reason, not a crash
        assert catch_up.converged and catch_up.v0 is not None
        errors.append(abs(catch_up.v0 - exact.v0))
    assert errors[1] <= errors[0] / 2 + exact.v0_error_estimate + 1e-12, errors
