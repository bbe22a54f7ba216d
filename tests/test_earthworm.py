"""gaits/earthworm-100.yaml: a 100-segment crawler runs, moves forward, and obeys the symmetries
of the model, at the cost of a few periods (the periodic-limit solver, not 5000 iterated ones)."""

from __future__ import annotations

import copy

import pytest
import yaml

from crawlsim import api
from crawlsim.gait.document import gait_from_document

from .conftest import GAITS

PATH = GAITS / "earthworm-100.yaml"


@pytest.fixture(scope="module")
def document() -> dict:
    return yaml.safe_load(PATH.read_text())


def v0_of(document: dict, **simulation):
    """The run of ``document`` as `crawlsim velocity` does it: v0 at the verified limit."""
    doc = copy.deepcopy(document)
    doc["simulation"] = {**doc.get("simulation", {}), **simulation}
    return api.run(gait_from_document(doc, doc["name"]), history=False)


@pytest.fixture(scope="module")
def exact(document):
    return v0_of(document)


def test_the_file_is_the_wave_it_says(document):
    """101 blocks, 100 links (the segments), phase -(i-1)/10 modulo 1 on link i: a wave ten
    segments long running from the head (block 101) to the tail, in one line (the wave
    shorthand). Its links are, bit for bit, the 100 lines the file spelt out before (phases 0,
    0.9, 0.8, ..., 0.1 as typed, k/10 correctly rounded), so its results are those of that file."""
    assert document["blocks"] == 101
    assert document["links"] == {"wave": {"kind": "cosine", "mean": 1.0, "amplitude": 0.2}, "phase_step": -0.1}
    spelt = [{"kind": "cosine", "mean": 1.0, "amplitude": 0.2, "phase": (10 - i % 10) % 10 / 10} for i in range(100)]
    assert [link["phase"] for link in spelt[:11]] == [0.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1, 0.0]
    assert gait_from_document(document, "wave").links == gait_from_document({**document, "links": spelt}, "list").links
    assert document["friction"] == {"forward": 1.0, "backward": 3.0}


def test_it_moves_forward_and_converges_only_asymptotically(exact):
    """v0 > 0 beyond its error bound, found by the periodic-limit solver in a few periods although
    the iterates contract only by about 0.995 a period (5,500 periods to 1e-12 by iteration).

    Cost of transport: in the limit every block advances v0 T per period. If no block ever slips
    backward, the energy dissipated in a period is sum_j mu_j^+ (forward slip of block j) =
    N mu^+ v0 T, so the cost of transport (dissipation per distance) is N mu^+ = 101 exactly; a
    backward slip anywhere would add mu^- |dx| for no progress and raise it.
    """
    assert exact.converged and exact.solver.method == "newton"
    assert exact.v0 - exact.estimate.error_estimate > 0
    assert exact.estimate.error_estimate <= 1e-12
    assert exact.v0 == pytest.approx(0.0694830455579, abs=1e-12)
    assert exact.convergence == "asymptotic"
    assert 0.99 < exact.solver.jacobian_rate < 1.0
    assert exact.solver.periods <= 10
    assert exact.energy.cost_of_transport == pytest.approx(101.0, rel=1e-12)


def test_catch_up_agrees_with_exact_within_the_first_order_bound(document, exact):
    """The catch-up scheme is first order in the step (docs/model.md §4): at 100 steps per period
    its v0 is within 1/100 of the exact one, and differs from it (it is a discretisation)."""
    steps = 100
    catch_up = v0_of(document, integrator="catch-up", steps_per_period=steps)
    assert catch_up.converged
    difference = abs(catch_up.v0 - exact.v0)
    assert 1e-9 < difference <= 1 / steps


def test_direction_of_the_wave_and_friction_mirror(document, exact):
    """Two symmetries of the crawler (docs/model.md §1), exact to roundoff.

    (a) Mirror x -> -x with the same labels: z -> -z, and with L -> -L the stress
    sigma = k (L - z) and the forces f = D^T sigma change sign, so forward and backward slips
    swap: the mirrored crawler has friction mu^+ <-> mu^- and v0 -> -v0. Adding a constant to L
    translates K(t) = C(t) - K L(t) rigidly and leaves the slips alone, and
    -(1 + a cos 2 pi (u - p)) = -1 + a cos 2 pi (u - p - 1/2) is L half a period later, which
    does not change v0. So swapping forward and backward friction negates v0.

    (b) Reversal x_j -> -x_{N+1-j}: the links run in the opposite order, z'_i = z_{N-i}, and
    again forward and backward swap. Reversing the retrograde wave (link i at phase
    -(i-1)/10) gives link i at phase -(100-i)/10 = (i-1)/10 + 0.1 (mod 1): the direct wave, a tenth
    of a period later. With (a), the direct wave has the same v0 as the retrograde one.
    """
    swapped = copy.deepcopy(document)
    swapped["friction"] = {"forward": 3.0, "backward": 1.0}
    assert v0_of(swapped).v0 == pytest.approx(-exact.v0, abs=1e-12)
    direct = copy.deepcopy(document)
    direct["links"]["phase_step"] = 0.1  # link i at phase (i - 1)/10
    assert v0_of(direct).v0 == pytest.approx(exact.v0, abs=1e-12)
