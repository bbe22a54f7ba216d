"""v0's printed error estimate covers the roundoff of stiff chains.

Two exact computations of the same gait, the compiled event loop (`crawlsim.kernel.eventloop`)
and the Python loop of `crawlsim.integrate.exact` (``kernel=False``), differ only by roundoff:
their v0 must agree to within the error estimate each of them prints. On chains whose stiffness
spreads over five or six decades the state is large (c ~ k_max L) and each piece reads its
slips off it through the softest link, so the displacement's roundoff is eps c_scale / k_min
per piece, sqrt(pieces) of it over a period
(`crawlsim.analysis.convergence.displacement_roundoff`), not the eps x steps x slip of the
sums alone: on these seeds of the random-gait corpus the two loops differed by 10 to 250 times
that first estimate before it carried the second term, and by up to 1.43 times the second
with one piece (seed 13, 86 pieces a period).
"""

from __future__ import annotations

import numpy as np
import pytest

from crawlsim.analysis.convergence import displacement_roundoff
from crawlsim.analysis.run import simulate
from crawlsim.gait.corpus import random_gait
from crawlsim.integrate import exact
from crawlsim.model.process import compile as compile_spec


def _python_loop(monkeypatch):
    init = exact.EventStepper.__init__

    def python_only(self, process, **options):
        options["kernel"] = False
        init(self, process, **options)

    monkeypatch.setattr(exact.EventStepper, "__init__", python_only)


@pytest.mark.parametrize("seed", [13, 29, 39])
def test_two_exact_loops_agree_within_the_estimate(seed, monkeypatch):
    gait = random_gait(seed, blocks=(2, 12), stiffness_ratio=1e6, friction_ratio=1e3)
    process = compile_spec(gait, 1000)
    s = gait.simulation
    runs = []
    for python in (False, True):
        if python:
            _python_loop(monkeypatch)
        runs.append(
            simulate(process, max_periods=s.max_periods, tolerance=s.tolerance, integrator="exact", history=False)
        )
    compiled, python = runs
    assert compiled.v0 is not None and python.v0 is not None
    assert compiled.estimate.error_estimate is not None and python.estimate.error_estimate is not None
    k = np.asarray(process.crawler.stiffness, dtype=float)
    assert k.max() / k.min() > 1e4  # a stiff chain: the case this is about
    difference = abs(compiled.v0 - python.v0)
    assert difference <= min(compiled.estimate.error_estimate, python.estimate.error_estimate)
    # the stiffness term is what covers it: the rest of the estimate alone does not
    pieces = len(exact.EventStepper(process).step_period().transitions)
    stiff = displacement_roundoff(process, 0, 0.0, pieces) / process.period
    assert difference > compiled.estimate.error_estimate - stiff
