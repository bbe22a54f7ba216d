"""Exact sensitivities (`crawlsim.sensitivity`, docs/sensitivity.md) against closed forms,
invariances and central finite differences of crawlsim's own exact v0.

**The two-block crawler.** One link L(t) = L0 + a cos 2 pi t/T between two blocks with forward
friction mu_1^+, mu_2^+ and backward friction large enough never to be reached (the forward
regime). The stress sigma = k (L - z) must reach -mu_1^+ (block 1, pulled forward, slips) or
mu_2^+ (block 2, pushed forward, slips) for anything to move; over a period of the limit the
link extends by 2a, of which (mu_1^+ + mu_2^+)/k is taken up by the spring between the two
friction limits, so each block slips forward by

    d = 2 a - (mu_1^+ + mu_2^+) / k       (2 a k > mu_1^+ + mu_2^+),

and v0 = d / T. Each block slips forward by d at its forward limit, so the dissipation is
D = (mu_1^+ + mu_2^+) d and the cost of transport D / d = mu_1^+ + mu_2^+. Hence

    dv0/da = 2/T,  dv0/dk = (mu_1^+ + mu_2^+) / (k^2 T),  dv0/dmu_j^+ = -1 / (k T),
    dv0/dT = -v0/T,  dD/da = 2 (mu_1^+ + mu_2^+),  dD/dmu_1^+ = d - (mu_1^+ + mu_2^+)/k,
    d(cost of transport)/dmu_1^+ = 1,  d(cost of transport)/da = d(cost of transport)/dk = 0.

**Rate independence** (docs/model.md §4): Y and D do not depend on T, so dv0/dT = -v0/T.

**Common phase shift.** Shifting every signal's phase by s is the time shift t -> t - s T of
the whole gait, which does not change v0: the sum of dv0/dphase over the phases of every
non-constant signal is 0.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import crawlsim
from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.analysis.sensitivity_terms import find_limit as _limit
from crawlsim.errors import CrawlsimError
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import gait_from_document


def _two_block(a=0.3, k=10.0, mu1=1.0, mu2=1.0, T=1.0, integrator="exact"):
    doc = {
        "name": "two-block",
        "blocks": 2,
        "period": T,
        "stiffness": k,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": a}],
        "friction": [{"forward": mu1, "backward": 5.0}, {"forward": mu2, "backward": 5.0}],
        "simulation": {"steps_per_period": 200, "max_periods": 50, "tolerance": 1e-12, "integrator": integrator},
    }
    return gait_from_document(doc, "two-block")


@pytest.mark.parametrize(
    "a,k,mu1,mu2,T", [(0.3, 10.0, 1.0, 1.0, 1.0), (0.25, 17.0, 0.7, 1.3, 2.5), (0.4, 6.0, 1.1, 0.6, 0.8)]
)
@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_two_block_closed_forms(a, k, mu1, mu2, T, integrator):
    """Both integrators meet the closed forms: the grid holds L's extremes, so catch-up's own
    discrete map has the exact derivatives too (and says it is catch-up's)."""
    r = sensitivity(
        _two_block(a, k, mu1, mu2, T, integrator),
        ["links.0.amplitude", "stiffness", "friction.0.forward", "friction.1.forward", "period"],
    )
    mus = mu1 + mu2
    d = 2 * a - mus / k
    assert r.displacement_per_period == pytest.approx(d, abs=1e-12)
    expected_v0 = {
        "links.0.amplitude": 2 / T,
        "stiffness": mus / (k * k * T),
        "friction.0.forward": -1 / (k * T),
        "friction.1.forward": -1 / (k * T),
        "period": -d / T / T,
    }
    for path, value in expected_v0.items():
        p = r[path]
        assert p.smooth, (path, p.reason)
        if integrator == "catch-up":
            assert p.method == ("rate-independence" if path == "period" else "catch-up")
        assert p.v0.value == pytest.approx(value, abs=1e-8), path
        assert p.v0.error_estimate is not None and p.v0.error_estimate < 1e-10
    assert r["links.0.amplitude"].dissipation_per_period.value == pytest.approx(2 * mus, abs=1e-8)
    assert r["friction.0.forward"].dissipation_per_period.value == pytest.approx(d - mus / k, abs=1e-8)
    assert r["friction.0.forward"].cost_of_transport.value == pytest.approx(1.0, abs=1e-8)
    assert r["links.0.amplitude"].cost_of_transport.value == pytest.approx(0.0, abs=1e-8)
    assert r["stiffness"].cost_of_transport.value == pytest.approx(0.0, abs=1e-8)
    assert r["period"].displacement_per_period.value == 0.0
    assert r["period"].method == "rate-independence"


def test_rate_independence_multi_block():
    gait = crawlsim.load_gait("gaits/smooth-friction-3.yaml")
    r = sensitivity(gait, ["period"])
    assert r["period"].v0.value == pytest.approx(-r.v0 / gait.period, rel=1e-14)
    # and the finite difference of crawlsim's own v0 agrees (central, h and h/2)
    T = gait.period
    fd = [
        (_limit(gait.replace("period", T + h)).v0 - _limit(gait.replace("period", T - h)).v0) / (2 * h)
        for h in (1e-3, 5e-4)
    ]
    assert abs(fd[1] - r["period"].v0.value) <= 2 * abs(fd[0] - fd[1]) + 1e-10


def test_common_phase_shift_is_invariant():
    gait = crawlsim.load_gait("gaits/smooth-friction-3.yaml")
    phases = [
        "links.*.phase",
        "friction.0.forward.phase",
        "friction.0.backward.phase",
        "friction.1.forward.phase",
        "friction.1.backward.phase",
    ]
    r = sensitivity(gait, phases)
    assert len(r.parameters) == 6
    assert all(p.smooth and p.method == "exact" for p in r.parameters)
    values = [p.v0.value for p in r.parameters]
    assert max(abs(v) for v in values) > 0.1  # each phase matters on its own ...
    total = math.fsum(values)  # ... but a common shift does not
    assert abs(total) <= sum(p.v0.error_estimate for p in r.parameters) + 1e-12
    dD = math.fsum(p.dissipation_per_period.value for p in r.parameters)
    assert abs(dD) <= sum(p.dissipation_per_period.error_estimate for p in r.parameters) + 1e-12


def _leaves(doc, prefix=()):
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield from _leaves(value, prefix + (key,))
    elif isinstance(doc, list):
        for i, value in enumerate(doc):
            yield from _leaves(value, prefix + (i,))
    elif isinstance(doc, (int, float)) and not isinstance(doc, bool):
        yield prefix, doc


def _kind_of(doc, keys) -> tuple[str, str]:
    """(signal kind, parameter kind) of a leaf of a gait document."""
    if keys[0] in ("stiffness", "period"):
        return "-", keys[0]
    node, parent = doc, None
    for key in keys[:-1]:
        parent, node = node, node[key]
    if isinstance(node, dict) and "kind" in node:
        return node["kind"], str(keys[-1])
    if isinstance(node, list) and isinstance(parent, dict) and "kind" in parent:
        return parent["kind"], str(keys[-2])  # fourier cos/sin, knot values
    return "constant", "friction" if keys[0] == "friction" else "value"


def _candidates(gait):
    out = {}
    for keys, _ in _leaves(gait.document):
        if keys[0] in ("simulation", "blocks", "name", "initial_positions") or "times" in keys:
            continue
        kind = _kind_of(gait.document, keys)
        if kind[0] in ("piecewise-linear", "steps") and kind[1] == "phase":
            continue  # moves the breakpoints: reported unsupported (test below)
        if kind == ("piecewise-linear", "values") and keys[-1] in (0, len(_node(gait.document, keys[:-1])) - 1):
            continue  # values[0] = values[-1]: moving one alone is refused
        out.setdefault(kind, []).append(".".join(map(str, keys)))
    return out


def _node(doc, keys):
    for key in keys:
        doc = doc[key]
    return doc


def _central(gait, path, value, h):
    plus, minus = _limit(gait.replace(path, value + h)), _limit(gait.replace(path, value - h))
    return (
        (plus.v0 - minus.v0) / (2 * h),
        (plus.dissipation - minus.dissipation) / (2 * h),
        (plus.v0_error + minus.v0_error) / (2 * h),
    )


def test_random_gaits_against_finite_differences():
    """At least 30 seeded random gaits (2 to 4 blocks, every signal kind), up to three numbers
    each, chosen to cover every kind of signal and parameter; every smooth derivative agrees
    with the central difference of crawlsim's own exact v0 (and dissipation) to the
    difference's error, estimated from steps h and h/2 plus the runs' errors over h."""
    covered: set[tuple[str, str]] = set()
    checked_gaits = 0
    seed = 0
    while checked_gaits < 32:
        gait = random_gait(1000 + seed, blocks=(2, 4), max_periods=300)
        seed += 1
        rng = np.random.default_rng(seed)
        cand = _candidates(gait)
        kinds = sorted(cand, key=lambda kd: (kd in covered, rng.uniform()))[:3]
        paths = [cand[kd][int(rng.integers(len(cand[kd])))] for kd in kinds]
        try:
            r = sensitivity(gait, paths, one_sided=False)
        except CrawlsimError:
            continue
        checked = False
        for kd, path in zip(kinds, paths):
            p = r[path]
            if not p.smooth or p.method != "exact":
                continue
            scale = max(abs(p.value), 1.0)
            d1, D1, e1 = _central(gait, path, p.value, 1e-4 * scale)
            d2, D2, e2 = _central(gait, path, p.value, 5e-5 * scale)
            tol = 2 * abs(d1 - d2) + 4 * e2 + p.v0.error_estimate + 1e-13
            assert abs(p.v0.value - d2) <= tol, (gait.name, path, p.v0, d1, d2)
            tolD = (
                2 * abs(D1 - D2)
                + 4 * e2 * max(r.dissipation_per_period, 1.0) / max(abs(r.v0), 1e-3)
                + p.dissipation_per_period.error_estimate
                + 1e-12
            )
            assert abs(p.dissipation_per_period.value - D2) <= max(tolD, 1e-7 * abs(D2)), (
                gait.name,
                path,
                p.dissipation_per_period,
                D1,
                D2,
            )
            covered.add(kd)
            checked = True
        checked_gaits += checked
    signal_kinds = {kd[0] for kd in covered}
    assert {"constant", "cosine", "fourier", "piecewise-linear", "steps"} <= signal_kinds
    param_kinds = {kd[1] for kd in covered}
    assert {"mean", "amplitude", "phase", "cos", "sin", "values", "stiffness", "friction"} <= param_kinds, param_kinds


def test_breakpoint_parameters_are_reported_unsupported():
    doc = {
        "name": "steps",
        "blocks": 2,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "steps", "times": [0.0, 0.5], "values": [0.8, 1.2]}],
        "friction": {"forward": 1.0, "backward": 2.0},
        "simulation": {"steps_per_period": 100, "max_periods": 50, "tolerance": 1e-12},
    }
    r = sensitivity(gait_from_document(doc, "steps"), ["links.0.times.1", "links.0.phase", "links.0.values.1"])
    for path in ("links.0.times.1", "links.0.phase"):
        assert r[path].method == "unsupported"
        assert "breakpoints" in (r[path].reason or "")
        assert r[path].v0.value is None
    # a step of the link by 0.4 at u = 0.5 and back at u = 0: the two-block closed form with
    # stroke 2a -> the jump 0.4 (values.1 - values.0): d = (v1 - v0) - 2 mu^+ / k
    p = r["links.0.values.1"]
    assert p.smooth and p.v0.value == pytest.approx(1.0, abs=1e-8)
    assert r.displacement_per_period == pytest.approx(0.4 - 0.2, abs=1e-12)


#: Two blocks whose friction sums touch 0 at u = 1/2 without changing sign: on the boundary of
#: the uniqueness condition (test_uniqueness_boundary_is_one_sided, test_piece_derivative_at_a_kink_is_one_side).
BOUNDARY = {
    "name": "boundary",
    "blocks": 2,
    "period": 1.0,
    "stiffness": 10.0,
    "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3}],
    "friction": [
        {"forward": {"kind": "cosine", "mean": 2.0, "amplitude": 1.0}, "backward": 3.0},
        {"forward": 1.0, "backward": 1.0},
    ],
    "simulation": {"steps_per_period": 200, "max_periods": 50, "tolerance": 1e-12},
}


def test_uniqueness_boundary_is_one_sided():
    """mu_1^+ = 2 + cos 2 pi u and mu_2^- = 1: g_J = mu_1^+ - mu_2^- for J = {1} touches 0 at
    u = 1/2 without changing sign, the boundary of the uniqueness condition. Moving mu_2^- up
    makes g_J change sign on an interval, moving it down keeps it positive: v0 is not
    differentiable there, so the result is one-sided, both sides measured."""
    doc = BOUNDARY
    gait = gait_from_document(doc, "boundary")
    r = sensitivity(gait, ["friction.1.backward", "friction.0.forward.mean"])
    for p in r.parameters:
        assert not p.smooth
        assert "uniqueness" in (p.reason or "")
        assert p.v0.value is None
        assert p.left is not None and p.right is not None
        assert p.left.value is not None and p.right.value is not None
        # the two sides differ by far more than their errors: a kink, not a smooth point
        assert abs(p.left.value - p.right.value) > 10 * (p.left.error_estimate + p.right.error_estimate)
    # the right derivative of mu_2^- is that of crawlsim's own v0 from above
    h = 1e-4
    above = (_limit(gait.replace("friction.1.backward", 1.0 + h)).v0 - r.v0) / h
    assert r["friction.1.backward"].right.value == pytest.approx(above, abs=1e-6)


def test_summary_keys():
    r = sensitivity(_two_block(), ["links.*.amplitude", "period"])
    s = r.summary()
    assert set(s) == {"links.0.amplitude", "period"}
    assert {"value", "error_estimate", "smooth"} <= set(s["links.0.amplitude"])
    assert s["links.0.amplitude"]["smooth"] is True


def test_api_export():
    r = crawlsim.sensitivity(_two_block(), ["stiffness"])
    assert r["stiffness"].v0.value == pytest.approx(2.0 / 100.0, abs=1e-10)


# -- the command line --------------------------------------------------------------------------
def _cli(*args):
    from click.testing import CliRunner

    from crawlsim.cli import main

    return CliRunner().invoke(main, ["velocity", *args])


def test_cli_prints_supported_digits():
    """inching-2: dv0/dk = (mu_1^+ + mu_2^+)/(k^2 T) = 2/100, dv0/dT = -v0/T = -0.4; each
    printed with the digits its error estimate supports (crawlsim.analysis.digits)."""
    from crawlsim.analysis.digits import supported

    res = _cli("gaits/inching-2.yaml", "--sensitivity", "stiffness", "--sensitivity", "period")
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert len(lines) == 3
    name, _, rest = lines[1].partition(" = ")
    assert name == "dv0/dstiffness"
    value, _, error = rest.partition(" ± ")
    assert abs(float(value) - 0.02) <= float(error) <= 1e-12
    r = sensitivity(crawlsim.load_gait("gaits/inching-2.yaml"), ["stiffness"])
    assert value == supported(r["stiffness"].v0.value, r["stiffness"].v0.error_estimate)[0]
    assert lines[2].startswith("dv0/dperiod = -0.4")


def test_cli_json_and_star_paths():
    import json

    res = _cli("gaits/peristalsis-4.yaml", "--json", "--sensitivity", "links.*.phase")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    sens = out["sensitivity"]
    assert list(sens) == ["links.0.phase", "links.1.phase", "links.2.phase"]
    for entry in sens.values():
        assert entry["smooth"] is True
        assert entry["error_estimate"] < 1e-10
    # a common phase shift of the three links (the friction is constant): gradient sum 0
    assert abs(sum(e["value"] for e in sens.values())) <= sum(e["error_estimate"] for e in sens.values())


def test_cli_not_smooth_prints_both_sides(tmp_path):
    import json
    import textwrap

    gait = tmp_path / "boundary.yaml"
    gait.write_text(
        textwrap.dedent("""\
        name: boundary
        blocks: 2
        period: 1.0
        stiffness: 10.0
        links: [{kind: cosine, mean: 1.0, amplitude: 0.3}]
        friction:
          - {forward: {kind: cosine, mean: 2.0, amplitude: 1.0}, backward: 3.0}
          - {forward: 1.0, backward: 1.0}
        simulation: {steps_per_period: 200, max_periods: 50, tolerance: 1.0e-12}
        """)
    )
    res = _cli(str(gait), "--sensitivity", "friction.1.backward")
    assert res.exit_code == 0, res.output
    assert "not smooth (the friction is on the boundary of the uniqueness" in res.output
    assert "left " in res.output and "right " in res.output
    res = _cli(str(gait), "--json", "--sensitivity", "friction.1.backward")
    entry = json.loads(res.output)["sensitivity"]["friction.1.backward"]
    assert entry["smooth"] is False and entry["value"] is None
    assert entry["left"] is not None and entry["right"] is not None


def test_cli_bad_input():
    res = _cli("gaits/inching-2.yaml", "--sensitivity", "links.3.amplitude")
    assert res.exit_code == 2
    assert "links.3.amplitude" in res.output and "out of range" in res.output
    res = _cli("gaits/inching-2.yaml", "--sensitivity", "links.3.amplitude", "--sweep", "period=1:2:2")
    assert res.exit_code == 2
    assert "links.3.amplitude" in res.output and "out of range" in res.output
    res = _cli("gaits/inching-2.yaml", "--sensitivity", "links")
    assert res.exit_code == 2 and "not a number" in res.output
    # a misspelt key: the did-you-mean of --sweep and of the gait files, not "found None"
    hint = "links[0].phse: unknown key 'phse'; did you mean 'phase'? (allowed here: amplitude, kind, mean, phase)"
    for extra in ([], ["--sweep", "period=1:2:2"]):
        res = _cli("gaits/peristalsis-4.yaml", "--sensitivity", "links.*.phse", *extra)
        assert res.exit_code == 2 and res.output == f"Error: gaits/peristalsis-4.yaml: {hint}\n", res.output
    res = _cli("gaits/peristalsis-4.yaml", "--sweep", "links.*.phse=0:1:2")
    assert res.exit_code == 2 and hint in res.output
    res = _cli("gaits/peristalsis-4.yaml", "--sensitivity", "frction.forward")
    assert res.exit_code == 2 and "no key 'frction'; did you mean 'friction'?" in res.output


# -- gradient-based design ---------------------------------------------------------------------
def test_gradient_search_two_block_bound():
    """Two blocks: v0 = (2 a - (mu_1^+ + mu_2^+)/k) / T grows with the amplitude a, so over
    a in [0.1, 0.35] the maximum is at the upper bound, v0 = (0.7 - 0.2) / 1 = 0.5, which the
    gradient search of `crawlsim optimize` (exact gradients, bounds) reaches to roundoff. The
    two-lag example is tests/test_optimize.py's."""
    from crawlsim.design import optimize as opt
    from crawlsim.design.problem import Method, make_problem

    problem = make_problem(_two_block(a=0.2), ["links.0.amplitude=0.1:0.35"])
    result = opt.optimize(problem, Method(search="gradient", max_evaluations=40))
    assert result.feasible
    assert result.value == pytest.approx(0.5, abs=1e-12)


def test_piece_derivative_at_a_kink_is_one_side():
    """At a kink the derivative on the limit period's own pieces is one of the one-sided
    derivatives (the uniqueness-boundary gait of the test above)."""
    doc = BOUNDARY
    p = sensitivity(gait_from_document(doc, "boundary"), ["friction.1.backward"])["friction.1.backward"]
    assert not p.smooth and p.left is not None and p.right is not None
    assert p.v0_on_pieces is not None
    assert min(abs(p.v0_on_pieces - p.left.value), abs(p.v0_on_pieces - p.right.value)) <= 1e-6


def test_cli_optimize_gradient(tmp_path):
    import json

    from click.testing import CliRunner

    from crawlsim.cli import main

    best = tmp_path / "best.yaml"
    res = CliRunner().invoke(
        main,
        [
            "optimize",
            "gaits/peristalsis-4.yaml",
            "--free",
            "links.1.phase=0:1",
            "--free",
            "links.2.phase=0:1",
            "--method",
            "gradient",
            "--steps-per-period",
            "20",
            "--json",
            "--write-best",
            str(best),
            "-q",
            "-o",
            str(tmp_path / "gradient.h5"),
        ],
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["v0"] == pytest.approx(7 / 15, abs=1e-6)
    assert out["evaluations"] <= 72
    # the best gait file reproduces its v0
    assert crawlsim.api.run(crawlsim.load_gait(best), history=False).v0 == pytest.approx(out["v0"], abs=1e-12)
    # the gradient search runs a Pareto front too (tests/test_optimize.py checks it)
    res = CliRunner().invoke(
        main,
        [
            "optimize",
            "gaits/peristalsis-4.yaml",
            "--free",
            "links.1.phase=0:1",
            "--method",
            "gradient",
            "--pareto",
            "--front-points",
            "1",
            "--steps-per-period",
            "20",
            "-q",
            "-o",
            str(tmp_path / "front.h5"),
        ],
    )
    assert res.exit_code == 0, res.output


def test_cli_catch_up_says_whose_derivative():
    res = _cli(
        "gaits/inching-2.yaml", "--integrator", "catch-up", "--steps-per-period", "100", "--sensitivity", "stiffness"
    )
    assert res.exit_code == 0, res.output
    assert "derivatives of the catch-up scheme's own discrete period map" in res.output
    res = _cli("gaits/paper/acute-angle.yaml", "--sensitivity", "period")
    assert res.exit_code == 2 and "crawler gait" in res.output


def test_threshold_of_motion_is_one_sided():
    """Two blocks at the threshold of motion, 2 a k = mu_1^+ + mu_2^+ (a = 1/8, k = 8,
    mu^+ = 1): the stress just touches both forward limits and nothing slips. Below, v0 = 0;
    above, v0 = (2 a - 2/k)/T (the closed form of the module docstring). So dv0/da is 0 from
    the left and 2/T from the right, and dv0/dk is 0 and 2/(k^2 T) = 1/32."""
    r = sensitivity(_two_block(a=0.125, k=8.0, mu1=1.0, mu2=1.0), ["links.0.amplitude", "stiffness"])
    assert r.v0 == 0.0
    for path, right in (("links.0.amplitude", 2.0), ("stiffness", 1 / 32)):
        p = r[path]
        assert not p.smooth and "touch zero gap" in (p.reason or "")
        assert p.left is not None and p.right is not None
        assert abs(p.left.value) <= p.left.error_estimate + 1e-12
        assert p.right.value == pytest.approx(right, abs=p.right.error_estimate + 1e-8)


@pytest.mark.parametrize(
    "source",
    [1000, 1001, 1002, 1003, 1004, 1005, "peristalsis-4", "smooth-friction-3", "climbing-3", "inching-2-towing"],
)
def test_closed_form_columns_match_differences_of_the_coefficients(source):
    """The closed-form columns dC, dMu of a constant, cosine or fourier signal's number
    (`_closed_form_change`) against the central difference of the coefficients of the gait
    compiled with that number moved by +-h: exact for the affine numbers (mean, amplitude,
    cos, sin, a constant) up to roundoff eps |C| / h, and to h^2 (2 pi n)^3 |a| / 6 for a
    phase (h = 1e-5: below 3e-8 |C| for the harmonics of these gaits). Random gaits and three
    example files: friction shared by every block, per block, and on a slope (scaled by the
    cosine of its angle), and a force on each block."""
    from crawlsim.analysis.sensitivity_terms import _closed_form_change, coefficients_of

    gait = (
        random_gait(source, blocks=(2, 4), max_periods=300)
        if isinstance(source, int)
        else crawlsim.load_gait(f"gaits/{source}.yaml")
    )
    base = coefficients_of(gait)
    size = float(np.max(np.abs(base.C))) + float(np.max(np.abs(base.Mu)))
    closed = 0
    for keys, value in _leaves(gait.document):
        signal = keys[0] in ("links", "friction") or keys[:2] == ("loads", "force")
        if not signal or "times" in keys:
            continue
        got = _closed_form_change(gait, base, keys)
        kind = _kind_of(gait.document, keys)[0]
        if kind in ("piecewise-linear", "steps"):
            assert got is None, keys  # not a smooth signal: differenced, not closed
            continue
        assert got is not None, keys
        path = ".".join(map(str, keys))
        h = 1e-5 * max(abs(value), 1.0)
        try:
            plus = coefficients_of(gait.replace(path, value + h))
            minus = coefficients_of(gait.replace(path, value - h))
        except CrawlsimError:
            continue  # the move leaves the valid gaits (a friction at its bound)
        harmonics = max(base.basis.harmonics, 1)
        tol = 3e-8 * harmonics**3 * size
        np.testing.assert_allclose(got[0], (plus.C - minus.C) / (2 * h), rtol=0, atol=tol, err_msg=path)
        np.testing.assert_allclose(got[1], (plus.Mu - minus.Mu) / (2 * h), rtol=0, atol=tol, err_msg=path)
        closed += 1
    assert closed >= 2


def test_cli_summarises_many_coincident_events():
    """earthworm-100's links.0.phase sits on 37 coincident events (a 3000-character line): the
    line counts them, names the first and says the one-sided derivatives agree; the JSON keeps
    every reason. Few reasons are printed whole, and sides that differ are not said to agree."""
    from types import SimpleNamespace

    from crawlsim.analysis.sensitivity import Derivative, ParameterSensitivity
    from crawlsim.cli.velocity import _sensitivity_lines as lines

    none = Derivative(None, None)
    kinks = [f"a constraint is reached at t/T = {k / 10 + 0.03:.12g}, at the time of another event" for k in range(37)]

    def entry(reason, right):
        return ParameterSensitivity(
            "links.0.phase", 0.0, none, none, none, none, False, "one-sided", reason, Derivative(0.0538037, 8e-7), right
        )

    many = entry("; ".join(kinks), Derivative(0.0538038, 7e-7))
    (line,) = lines(SimpleNamespace(parameters=[many], v0=0.07), "exact")
    assert line == (
        f"dv0/dlinks.0.phase: not smooth (37 coincident events, the first: {kinks[0]}; --json lists them all); "
        "left 0.0538037 ± 8e-07, right 0.0538038 ± 7e-07: the one-sided derivatives agree"
    )
    assert many.summary()["reason"].count("at the time of another event") == 37
    few = entry("; ".join(kinks[:2]), Derivative(0.06, 1e-7))
    (line,) = lines(SimpleNamespace(parameters=[few], v0=0.07), "exact")
    assert (
        line
        == f"dv0/dlinks.0.phase: not smooth ({kinks[0]}; {kinks[1]}); left 0.0538037 ± 8e-07, right 0.0600000 ± 1e-07"
    )


def test_a_waves_numbers_differentiate_by_the_chain_rule():
    """peristalsis-4 written as a wave (links: {wave: ..., phase_step: 1/3}): links.wave.amplitude
    moves every link's amplitude by the same amount and links.phase_step link i's phase by i
    times it (crawlsim.gait.docpaths.wave_links), so dv0/d(wave amplitude) = sum_i
    dv0/d(links.i.amplitude) and dv0/d(phase_step) = sum_i i dv0/d(links.i.phase), within the
    sum of their error estimates; the generated links' own paths work on the wave too."""
    import yaml

    doc = yaml.safe_load(open("gaits/peristalsis-4.yaml").read())
    doc["links"] = {"wave": {"kind": "cosine", "mean": 1.0, "amplitude": 0.3}, "phase_step": 0.3333333333333333}
    r = sensitivity(gait_from_document(doc, "wave"), ["links.wave.amplitude", "links.phase_step", "links.*.amplitude"])
    each = sensitivity(crawlsim.load_gait("gaits/peristalsis-4.yaml"), ["links.*.amplitude", "links.*.phase"])
    for path, weights in (("links.wave.amplitude", ("amplitude", 1, 1, 1)), ("links.phase_step", ("phase", 0, 1, 2))):
        name, *w = weights
        parts = [each[f"links.{i}.{name}"].v0 for i in range(3)]
        total = sum(k * p.value for k, p in zip(w, parts))
        bound = r[path].v0.error_estimate + sum(k * p.error_estimate for k, p in zip(w, parts))
        assert r[path].smooth and abs(r[path].v0.value - total) <= bound, (path, r[path].v0, total)
        assert abs(total) > 1e3 * bound  # a real derivative, not roundoff
    assert r["links.1.amplitude"].v0.value == pytest.approx(each["links.1.amplitude"].v0.value, abs=1e-9)
