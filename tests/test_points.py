"""Sweep points (crawlsim.study.points) against single runs of their gaits.

A point runs as its single run does (`crawlsim.analysis.run.settle`, no history): its row holds
that run's numbers bit for bit, whatever the integrator, and a point that is refused gives the
single run's message.
"""

import numpy as np
import pytest

from crawlsim.analysis.run import simulate
from crawlsim.errors import DegenerateModelError
from crawlsim.gait.document import gait_from_document, load_gait, parse_gait, with_simulation
from crawlsim.model.process import compile_gait
from crawlsim.status import PointStatus
from crawlsim.study.points import evaluate

from .conftest import iterated_examples

GAITS = iterated_examples()
STEPS = 120


def _single(gait):
    s = gait.simulation
    return simulate(
        compile_gait(gait), max_periods=s.max_periods, tolerance=s.tolerance, integrator=s.integrator, limit=s.limit
    )


def _assert_same(row, single):
    assert row.status == (PointStatus.OK if single.converged else PointStatus.NOT_CONVERGED)
    assert row.convergence == single.convergence
    assert (row.v0, row.displacement_per_period) == (single.v0, single.estimate.displacement)
    assert (row.dissipation_per_period, row.cost_of_transport) == (
        single.energy.dissipation,
        single.energy.cost_of_transport,
    )
    expected = single.estimate.error_estimate if single.integrator == "exact" else None  # catch-up: unmeasured
    assert row.v0_error_estimate == expected


@pytest.mark.parametrize("integrator", ["catch-up", "exact"])
def test_every_example_gait_is_its_single_run(integrator):
    gaits = [with_simulation(load_gait(p), steps_per_period=STEPS, integrator=integrator) for p in GAITS]
    rows = evaluate(gaits, range(len(gaits)))
    assert [r.index for r in rows] == list(range(len(GAITS)))
    for row, gait in zip(rows, gaits):
        _assert_same(row, _single(gait))


def test_amplitude_family_matches_single_runs():
    """A family with finite-time and asymptotic members: every row is its single run's."""
    base = with_simulation(load_gait(GAITS[0].parent / "peristalsis-4.yaml"), steps_per_period=80)
    gaits = []
    for a in np.linspace(0.08, 0.4, 12):
        doc = base.document | {"links": [dict(l, amplitude=float(a)) for l in base.document["links"]]}
        gaits.append(with_simulation(gait_from_document(doc, "family"), integrator="catch-up", limit="iterate"))
    verdicts = set()
    for row, gait in zip(evaluate(gaits, range(len(gaits))), gaits):
        single = _single(gait)
        _assert_same(row, single)
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
    for k, row in zip(ks, evaluate([with_simulation(g, integrator="catch-up") for g in gaits], range(3))):
        assert row.displacement_per_period == pytest.approx(0.6 - 2.0 / k, abs=1e-12)
        assert row.convergence == "finite-time"


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
simulation: {steps_per_period: 100, max_periods: 20, integrator: catch-up}
"""


def test_instant_uniqueness_violation_is_refused_like_a_single_run():
    """mu1+ = 1 + 0.5 cos(2 pi t) equals mu2- = 1 at t = 1/4 while the link contracts: both
    blocks are at a friction limit, the active normals are dependent (LICQ fails; the paper's
    uniqueness condition fails at that instant) and the step's slips are unique only up to a
    rigid translation. With 100 steps t = 1/4 is a grid time: the point is refused (invalid) with
    the single run's message; with 101 steps it is not, and the point runs."""
    gaits = [with_simulation(parse_gait(LICQ_GAIT), steps_per_period=s) for s in (100, 101)]
    on_grid, off_grid = evaluate(gaits, [0, 1])
    assert on_grid.status == "invalid" and on_grid.v0 is None
    assert "does not determine the motion at t = 0.25: J = {1, 2}" in on_grid.message
    with pytest.raises(DegenerateModelError) as single:
        _single(gaits[0])
    assert str(single.value) == on_grid.message
    _assert_same(off_grid, _single(gaits[1]))
