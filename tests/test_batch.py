"""Batched exact stepping (crawlsim.study.batch) against the single-run stepper.

A certified KKT point of the strictly convex projection is the projection itself, so a gait
stepped in a batch must take the same steps as in a single run up to roundoff: v0 agrees to
1e-12, and the period count and the convergence verdict are the same.
"""

import numpy as np
import pytest

from crawlsim.analysis.run import simulate
from crawlsim.errors import DegenerateModelError
from crawlsim.gait.document import gait_from_document, load_gait, parse_gait, with_simulation
from crawlsim.model.process import compile_gait
from crawlsim.study.batch import simulate_batch

from .conftest import iterated_examples

GAITS = iterated_examples()
STEPS = 120


def _single(process, gait):
    s = gait.simulation
    return simulate(process, max_periods=s.max_periods, tolerance=s.tolerance, limit="iterate")


def _assert_same(run, single):
    assert run.status == ("ok" if single.converged else "not-converged")
    assert run.convergence == single.convergence
    assert run.periods == single.periods
    assert run.periodic_from == single.periodic_from
    assert run.v0 == pytest.approx(single.v0, abs=1e-12, rel=0)
    assert run.displacement_per_period == pytest.approx(single.estimate.displacement, abs=1e-12, rel=0)
    assert run.dissipation_per_period == pytest.approx(single.energy.dissipation, abs=1e-11, rel=1e-12)
    if single.rate is None:
        assert run.contraction_rate is None
    else:
        assert run.contraction_rate == pytest.approx(single.rate.rate, rel=1e-6)
    assert run.v0_error_estimate == pytest.approx(single.estimate.error_estimate, rel=1e-6, abs=1e-15)
    if single.energy.cost_of_transport is None:
        assert run.cost_of_transport is None
    else:
        assert run.cost_of_transport == pytest.approx(single.energy.cost_of_transport, rel=1e-10)


def test_every_gait_file_in_one_batch_matches_single_runs():
    """Gaits of different block counts are grouped; each agrees with its own single run."""
    gaits = [with_simulation(load_gait(p), steps_per_period=STEPS) for p in GAITS]
    processes = [compile_gait(g) for g in gaits]
    runs = simulate_batch(
        processes,
        max_periods=[g.simulation.max_periods for g in gaits],
        tolerance=[g.simulation.tolerance for g in gaits],
    )
    assert len(runs) == len(GAITS)
    for run, process, gait in zip(runs, processes, gaits):
        _assert_same(run, _single(process, gait))


def test_amplitude_family_with_refill_matches_single_runs():
    """A family with finite-time and asymptotic members, stepped 5 at a time so the batch is
    refilled at period boundaries; every member's v0 agrees with its single run to 1e-12."""
    base = with_simulation(load_gait(GAITS[0].parent / "peristalsis-4.yaml"), steps_per_period=80)
    gaits = []
    for a in np.linspace(0.08, 0.4, 12):
        doc = base.document | {"links": [dict(l, amplitude=float(a)) for l in base.document["links"]]}
        gaits.append(gait_from_document(doc, "family"))
    processes = [compile_gait(g) for g in gaits]
    runs = simulate_batch(processes, max_periods=1000, tolerance=1e-12, capacity=5)
    verdicts = set()
    for run, process, gait in zip(runs, processes, gaits):
        single = _single(process, gait)
        _assert_same(run, single)
        verdicts.add(single.convergence)
    assert verdicts == {"finite-time", "asymptotic"}


def test_two_block_closed_form():
    """Inching with anisotropic friction (forward 1, backward 2, k = 10, L = 1 + 0.3 cos):
    displacement per period = Delta L - (mu1+ + mu2+)/k = 0.6 - 0.2 = 0.4, periodic from the
    first period on (paper Theorem th:1dim; the link saturates both forward limits once per
    extension and contraction), for every stiffness k >= 4 the formula gives 0.6 - 2/k."""
    base = load_gait(GAITS[0].parent / "inching-2.yaml")
    ks = [5.0, 10.0, 20.0]
    gaits = [
        with_simulation(gait_from_document(base.document | {"stiffness": k}, "inch"), steps_per_period=64) for k in ks
    ]
    runs = simulate_batch([compile_gait(g) for g in gaits], max_periods=50, tolerance=1e-12)
    for k, run in zip(ks, runs):
        assert run.displacement_per_period == pytest.approx(0.6 - 2.0 / k, abs=1e-12)
        assert run.convergence == "finite-time"


LICQ_GAIT = """
name: licq-2
blocks: 2
period: 1.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3}
friction:
  - forward: {kind: cosine, mean: 1.0, amplitude: 0.5}
    backward: 3.0
  - forward: 2.0
    backward: 1.0
simulation: {steps_per_period: 100, max_periods: 20}
"""


def test_instant_uniqueness_violation_is_refused_like_a_single_run():
    """mu1+ = 1 + 0.5 cos(2 pi t) equals mu2- = 1 at t = 1/4 while the link contracts: both
    blocks are at a friction limit, the active normals are dependent (LICQ fails; the paper's
    uniqueness condition fails at that instant) and the step's slips are unique only up to a
    rigid translation. With 100 steps t = 1/4 is a grid time: the point is refused (invalid) with
    the single run's message; with 101 steps it is not, and the point runs."""
    gaits = [with_simulation(parse_gait(LICQ_GAIT), steps_per_period=s) for s in (100, 101)]
    processes = [compile_gait(g) for g in gaits]
    on_grid, off_grid = simulate_batch(processes, max_periods=20, tolerance=1e-12)
    assert on_grid.status == "invalid" and on_grid.v0 is None
    assert "does not determine the motion at t = 0.25: J = {1, 2}" in on_grid.message
    with pytest.raises(DegenerateModelError) as single:
        _single(processes[0], gaits[0])
    assert str(single.value) == on_grid.message
    _assert_same(off_grid, _single(processes[1], gaits[1]))
