"""What a gait says before any run (crawlsim/gait/apriori.py): the margin to the uniqueness
condition, found by hand here, and the cell theorem's verdict, checked against the runs."""

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

import crawlsim
from crawlsim.cli import main
from crawlsim.gait.apriori import cell_verdict, margin
from crawlsim.gait.corpus import random_document, random_gait
from crawlsim.gait.signals import Constant

from .conftest import GAITS, iterated_examples, make_gait


def test_the_margin_of_peristalsis_4_by_hand():
    """mu+ = 1, mu- = 2 on N = 4 blocks: g_J = |J| mu+ - (4 - |J|) mu- = 3 |J| - 8, that is -8,
    -5, -2, 1, 4 for |J| = 0 ... 4. The margin is 1, reached by the subsets of three blocks (the
    first, {1, 2, 3}) at every time. The shared friction.forward enters their g_J three times:
    3 mu+ - mu- = 0 at mu+ = 2/3 (a change of 1/3); friction.backward once, with a minus sign:
    mu- = 3 (a change of 1). The smallest change is friction.forward to 2/3."""
    found = margin(crawlsim.load_gait(GAITS / "peristalsis-4.yaml"))
    assert found.value == pytest.approx(1.0, abs=1e-14)
    assert list(np.flatnonzero(found.subset) + 1) == [1, 2, 3]
    assert found.time == 0.0
    assert found.change == "friction.forward from 1 to 0.666667"
    out = CliRunner().invoke(main, ["validate", "--explain", str(GAITS / "peristalsis-4.yaml")])
    assert "= 1, for J = {1, 2, 3} at t = 0; friction.forward from 1 to 0.666667 closes it" in out.output
    assert "only the run can tell" in out.output


def test_the_margin_of_time_controlled_friction():
    """Two blocks, mu_1^+ = 1 + 0.5 cos 2 pi t, mu_1^- = 3, mu_2^+ = 1, mu_2^- = 2:
    g_{1} = mu_1^+ - mu_2^- = -1 + 0.5 cos 2 pi t, g_{2} = 1 - 3, g_{} = -5, g_{1,2} >= 1.5.
    The margin is 0.5, for J = {1} at t = 0, where the cosine's mean closes it at 1.5."""
    friction = [
        {"forward": {"kind": "cosine", "mean": 1.0, "amplitude": 0.5}, "backward": 3.0},
        {"forward": 1.0, "backward": 2.0},
    ]
    gait = make_gait(
        {
            "blocks": 2,
            "period": 1.0,
            "stiffness": 10.0,
            "links": [{"kind": "cosine", "mean": 1, "amplitude": 0.3}],
            "friction": friction,
        }
    )
    found = margin(gait)
    assert found.value == pytest.approx(0.5, abs=1e-12)
    assert list(found.subset) == [True, False]
    assert min(found.time, 1.0 - found.time) < 1e-5
    assert found.change.startswith("friction.0.forward.mean from 1 to 1.5")


def test_a_margin_that_reaches_zero_at_an_instant_or_on_an_interval():
    """smooth-friction-3: g_{1,3} changes sign in time, which the uniqueness condition allows
    (an isolated instant); its margin is 0 there. Equal friction both ways on four blocks: two
    forward and two backward balance at every time, and the margin says the condition fails."""
    found = margin(crawlsim.load_gait(GAITS / "smooth-friction-3.yaml"))
    assert found.value == 0.0 and not found.failing and "isolated instant" in found.text()
    gait = crawlsim.load_gait(GAITS / "peristalsis-4.yaml")
    tied = dataclasses.replace(gait, forward=(Constant(1.0),) * 4, backward=(Constant(1.0),) * 4)
    found = margin(tied)
    assert found.value == 0.0 and found.failing and len(found.blocks) == 2


def three_blocks_held_in_the_middle(seed):
    """A random three-block gait whose middle block has more friction each way than both others
    together: it never slips, and K(t) is a rectangle."""
    doc = random_document(seed, blocks=(3, 3))
    outer = [{"forward": 1.0, "backward": 2.0}, {"forward": 0.7, "backward": 1.5}]
    doc["friction"] = [outer[0], {"forward": 3.6, "backward": 1.8}, outer[1]]
    return make_gait(doc)


def verdict_cases():
    examples = [crawlsim.load_gait(p) for p in iterated_examples() + sorted((GAITS / "paper").glob("*.yaml"))]
    two = [random_gait(seed, blocks=(2, 2), loads=seed % 2 == 0) for seed in range(8)]
    return examples + two + [three_blocks_held_in_the_middle(seed) for seed in range(3)]


@pytest.mark.parametrize("spec", verdict_cases(), ids=lambda s: s.name)
def test_the_cell_verdict_agrees_with_the_run(spec):
    """Where the cell theorem applies (paper Theorem th:1dim, Corollary cor:cell) the run finds
    the motion periodic from the first period on (finite-time, periodic from period <= 1)."""
    verdict = cell_verdict(spec)
    blocks = getattr(spec, "blocks", None)
    assert (verdict is not None) == (
        blocks == 2 or spec.name in ("cell-3",) or spec.name.startswith("random-") and blocks == 3
    )
    if verdict is not None:
        result = crawlsim.run(spec, history=True)
        assert result.convergence == "finite-time" and result.periodic_from <= 1
