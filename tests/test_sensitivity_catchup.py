"""Catch-up sensitivities (issue 22): the derivative of the catch-up scheme's own discrete
period map w -> proj(... proj(w)), not of the exact v0, reported with ``method: catch-up``.

**Closed forms.** The two-block crawler of tests/test_sensitivity.py slips by
d = 2 a - (mu_1^+ + mu_2^+)/k per period under catch-up too, whenever the grid holds the
extremes of L(u) = L0 + a cos 2 pi u (u = 0 and 1/2: an even number of steps): the stroke the
scheme sees is the full 2 a. So the catch-up map's derivatives are the closed forms themselves.

**Finite differences.** On other gaits the map's v0 differs from the exact one by O(1/G), and
its derivative is checked against central differences of catch-up's own v0. It is not an
approximation of the exact derivative: where a parameter moves events across the fixed grid (a
phase), v0_G(theta) wiggles by O(1/G) with a period O(1/G) in theta, so the derivatives differ
by O(1) however fine the grid (peristalsis-4's dv0/dlinks.1.phase: 0.87 at G = 200 against the
exact 0.82).
"""

from __future__ import annotations

import numpy as np
import pytest

import crawlsim
from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.errors import CrawlsimError
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import gait_from_document

from .test_sensitivity import _central


def _check(gait, paths) -> int:
    """Every smooth derivative of ``paths`` against central differences of catch-up's own v0
    and dissipation (h and h/2: their change estimates the difference's error)."""
    r = sensitivity(gait, paths, one_sided=False)
    checked = 0
    for p in r.parameters:
        if not p.smooth or p.method != "catch-up":
            continue
        scale = max(abs(p.value), 1.0)
        d1, D1, e1 = _central(gait, p.path, p.value, 1e-4 * scale)
        d2, D2, e2 = _central(gait, p.path, p.value, 5e-5 * scale)
        tol = 2 * abs(d1 - d2) + 4 * e2 + p.v0.error_estimate + 1e-11
        assert abs(p.v0.value - d2) <= tol, (gait.name, p.path, p.v0, d1, d2)
        tolD = 2 * abs(D1 - D2) + 1e-9 * max(abs(D2), 1.0) + p.dissipation_per_period.error_estimate
        assert abs(p.dissipation_per_period.value - D2) <= tolD, (gait.name, p.path)
        checked += 1
    return checked


def test_corpus_gaits_against_finite_differences():
    per = crawlsim.load_gait("gaits/peristalsis-4.yaml").replace(
        "simulation.integrator", "catch-up", "simulation.steps_per_period", 200
    )
    assert _check(per, ["links.*.phase", "links.0.amplitude", "links.2.mean", "stiffness", "friction.forward"]) == 7
    smooth = crawlsim.load_gait("gaits/smooth-friction-3.yaml").replace(
        "simulation.integrator", "catch-up", "simulation.steps_per_period", 200
    )
    assert (
        _check(
            smooth,
            [
                "links.1.phase",
                "links.0.cos.1",
                "stiffness.1",
                "friction.0.forward.amplitude",
                "friction.1.backward.phase",
                "friction.2.forward",
            ],
        )
        == 6
    )


def test_random_gaits_against_finite_differences():
    """Ten seeded random gaits (every signal kind among them) on a catch-up grid of 160 steps:
    the smooth derivatives of a mean, an amplitude or value, a phase and the stiffness."""
    checked = gaits = 0
    seed = 0
    while gaits < 10:
        gait = random_gait(5000 + seed, blocks=(2, 3), max_periods=300)
        seed += 1
        gait = gait.replace("simulation.integrator", "catch-up", "simulation.steps_per_period", 160)
        paths = [
            p
            for p in (
                "links.0.mean",
                "links.0.amplitude",
                "links.0.phase",
                "links.0.values.1",
                "links.0.cos.0",
                "stiffness",
            )
            if _names(gait, p)
        ]
        try:
            n = _check(gait, paths)
        except CrawlsimError:
            continue
        checked += n
        gaits += n > 0
    assert checked >= 15


def _names(gait, path) -> bool:
    node = gait.document
    for key in path.split("."):
        key = int(key) if key.isdigit() else key
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            return False
    return isinstance(node, (int, float)) and not isinstance(node, bool)


def test_cli_json_says_catch_up(tmp_path):
    import json

    from click.testing import CliRunner

    from crawlsim.cli import main

    res = CliRunner().invoke(
        main,
        [
            "velocity",
            "gaits/inching-2.yaml",
            "--integrator",
            "catch-up",
            "--steps-per-period",
            "100",
            "--json",
            "--sensitivity",
            "stiffness",
        ],
    )
    assert res.exit_code == 0, res.output
    entry = json.loads(res.stdout)["sensitivity"]["stiffness"]
    assert entry["method"] == "catch-up" and entry["smooth"] is True
    assert entry["value"] == pytest.approx(0.02, abs=1e-10)  # (mu_1^+ + mu_2^+)/(k^2 T)
    assert np.isfinite(entry["error_estimate"])


# -- loads (docs/model.md §6), both integrators ------------------------------------------------
@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_towing_force_closed_form(integrator):
    """inching-2-towing: a force F = -0.5 on the rear block adds -F to the friction it must
    overcome, d = 2 a - (mu_1^+ + mu_2^+ - F)/k, so dv0/dF = 1/(k T) = 0.1 and the dissipation
    (mu_1^+ + mu_2^+) d moves by (mu_1^+ + mu_2^+)/k = 0.2."""
    gait = crawlsim.load_gait("gaits/inching-2-towing.yaml")
    if integrator == "catch-up":
        gait = gait.replace("simulation.integrator", "catch-up", "simulation.steps_per_period", 200)
    p = sensitivity(gait, ["loads.force.0"])["loads.force.0"]
    assert p.smooth and p.method == integrator
    assert p.v0.value == pytest.approx(0.1, abs=1e-10)
    assert p.dissipation_per_period.value == pytest.approx(0.2, abs=1e-10)


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_slope_against_finite_differences(integrator):
    """climbing-3 on a 10 degree slope: the angle (through cos and sin, not affinely), the
    weight and the friction (weighted by cos(angle) in the dissipation) against central
    differences of the integrator's own v0 and dissipation."""
    gait = crawlsim.load_gait("gaits/climbing-3.yaml")
    if integrator == "catch-up":
        gait = gait.replace("simulation.integrator", "catch-up", "simulation.steps_per_period", 200)
    r = sensitivity(gait, ["loads.slope.angle", "loads.slope.weight", "friction.forward"], one_sided=False)
    for p in r.parameters:
        assert p.smooth and p.method == integrator, (p.path, p.reason)
        h = 1e-4 * max(abs(p.value), 1.0)
        d1, D1, e1 = _central(gait, p.path, p.value, h)
        d2, D2, e2 = _central(gait, p.path, p.value, h / 2)
        assert abs(p.v0.value - d2) <= 2 * abs(d1 - d2) + 4 * e2 + 1e-10, (p.path, p.v0, d2)
        assert abs(p.dissipation_per_period.value - D2) <= 2 * abs(D1 - D2) + 1e-8, (
            p.path,
            p.dissipation_per_period,
            D2,
        )


def _steps_gait(values0, values1, integrator="catch-up"):
    doc = {
        "name": "steps",
        "blocks": 3,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [
            {"kind": "steps", "times": [0.0, 0.5], "values": values0},
            {"kind": "piecewise-linear", "times": [0.0, 0.3, 0.7, 1.0], "values": values1},
        ],
        "friction": {"forward": 1.0, "backward": 2.5},
        "simulation": {"steps_per_period": 100, "max_periods": 50, "tolerance": 1e-12, "integrator": integrator},
    }
    return gait_from_document(doc, "steps")


def test_steps_and_piecewise_linear_signals():
    """A steps link (its jump at u = 1 is the one at u = 0: the grid's last offsets are c(0))
    and a piecewise-linear one: each knot value against central differences, and the same
    values as the exact integrator (the jumps and the knots sit on the grid)."""
    gait = _steps_gait([0.83, 1.21], [1.0, 1.27, 0.93, 1.0])
    paths = ["links.0.values.0", "links.0.values.1", "links.1.values.1", "links.1.values.2", "stiffness"]
    assert _check(gait, paths) == 5
    exact = sensitivity(_steps_gait([0.83, 1.21], [1.0, 1.27, 0.93, 1.0], "exact"), paths)
    r = sensitivity(gait, paths)
    for p, q in zip(r.parameters, exact.parameters):
        assert p.v0.value == pytest.approx(q.v0.value, abs=1e-9), p.path


def test_event_on_a_grid_time_is_a_kink():
    """With round numbers the third block's forward limit is reached exactly at a grid time
    (its gap falls by 0.1 a step from -0.4): a kink of the catch-up map for the numbers that
    move that gap, reported with the step; a number that does not move it stays smooth."""
    r = sensitivity(
        _steps_gait([0.8, 1.2], [1.0, 1.3, 0.9, 1.0]), ["links.1.values.1", "friction.backward"], one_sided=False
    )
    p = r["links.1.values.1"]
    assert not p.smooth and "tight with a zero multiplier" in (p.reason or "")
    assert p.left is None and "not requested" in (p.left_reason or "")
    assert r["friction.backward"].smooth
