"""Loads and slopes (docs/model.md §6): closed forms, the ledger, invariances and refusals.

**The two-block closed form under constant loads.** Two blocks, one link of stiffness k whose
length rises monotonically by Delta and falls back (a monotone stroke), constant shifted
thresholds a_j = mu_j^+ cos(alpha) - F~_j and b_j = mu_j^- cos(alpha) + F~_j. The stress sigma =
k (L - z) puts f_1 = -sigma, f_2 = sigma, so the admissible stresses are [-m^-, m^+] with m^+ =
min(b_1, a_2), m^- = min(a_1, b_2). During the extension sigma rises to m^+, and the link then grows
by slipping: the front block forward if a_2 < b_1, the rear block backward otherwise; during the
contraction sigma falls to -m^-: the rear block forward if a_1 < b_2, the front block backward
otherwise. In the periodic regime each half-stroke slips by s = (Delta - (m^+ + m^-)/k)^+, so

    d = s (e + c) / 2,   e = +1 if a_2 < b_1 else -1,   c = +1 if a_1 < b_2 else -1.

Each block moves by d per period; the slipping blocks do so at thresholds mu^{+-} cos(alpha) (the
friction) and against F~: the work against the loads is W_load = -(F~_1 + F~_2) d and the
friction dissipation D = cos(alpha) (mu^{+-}_slipping-block-1 + mu^{+-}_slipping-block-2) |d|
when e = c (every block slips one way); with W = D + J + W_load and J = 0 for a smooth stroke.
"""

import csv
import io
import json
import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from crawlsim.api import run
from crawlsim.cli import main
from crawlsim.errors import GaitError
from crawlsim.gait.crawler_spec import admissibility_violation
from crawlsim.gait.document import parse_gait

from .conftest import make_gait


def two_block_doc(
    amplitude=0.3, k=10.0, mu_plus=1.0, mu_minus=2.0, loads=None, link=None, period=1.0, integrator="exact", steps=400
):
    doc = {
        "blocks": 2,
        "period": period,
        "stiffness": k,
        "links": [link or {"kind": "cosine", "mean": 1.0, "amplitude": amplitude}],
        "friction": {"forward": mu_plus, "backward": mu_minus},
        "simulation": {"steps_per_period": steps, "max_periods": 50, "integrator": integrator},
    }
    if loads is not None:
        doc["loads"] = loads
    return doc


def closed_form_d(delta, k, mu_plus, mu_minus, forces, angle=0.0, weight=0.0):
    """d = s (e + c)/2 of the module docstring, for constant forces (F_1, F_2)."""
    ca, sa = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    total = [f - weight * sa for f in forces]
    a = [mu_plus * ca - f for f in total]
    b = [mu_minus * ca + f for f in total]
    m_plus, m_minus = min(b[0], a[1]), min(a[0], b[1])
    s = max(delta - (m_plus + m_minus) / k, 0.0)
    e = 1.0 if a[1] < b[0] else -1.0
    c = 1.0 if a[0] < b[1] else -1.0
    return s * (e + c) / 2


# (amplitude, k, mu+, mu-, F_1, F_2): forward, towing, stalled (v0 = 0), backward, both loaded,
# a rear block whose backward threshold is negative (held only by its link)
CASES = [
    (0.3, 10.0, 1.0, 2.0, -0.5, 0.0),
    (0.3, 10.0, 1.0, 2.0, -0.8, 0.0),
    (0.12, 10.0, 1.0, 2.0, -0.6, 0.0),
    (0.3, 10.0, 1.0, 2.0, -1.2, 0.0),
    (0.3, 10.0, 1.0, 2.0, -0.3, -0.2),
    (0.3, 10.0, 1.0, 2.0, 0.4, 0.25),
    (0.3, 10.0, 1.0, 2.0, -2.5, 0.0),
    (0.5, 4.0, 0.5, 1.5, 0.0, -0.7),
]


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
@pytest.mark.parametrize("amplitude, k, mu_plus, mu_minus, f1, f2", CASES)
def test_two_blocks_constant_forces_closed_form(amplitude, k, mu_plus, mu_minus, f1, f2, integrator):
    """v0 T = d of the module docstring, to 1e-9, with the stroke Delta = 2 amplitude. Catch-up
    is exact here too: with constant thresholds the cosine stroke is monotone between the grid
    points 0 and T/2, and every slip is at the one threshold the closed form names."""
    gait = make_gait(two_block_doc(amplitude, k, mu_plus, mu_minus, {"force": [f1, f2]}, integrator=integrator))
    result = run(gait, history=False)
    d = closed_form_d(2 * amplitude, k, mu_plus, mu_minus, (f1, f2))
    assert result.v0 * gait.period == pytest.approx(d, abs=1e-9)
    assert result.energy.load_work == pytest.approx(-(f1 + f2) * d, abs=1e-9)
    assert abs(result.energy.balance_residual) <= 1e-12 * max(1.0, result.energy.actuator_work)


def test_piecewise_linear_monotone_stroke_and_uniform_force():
    """Any monotone stroke: an asymmetric piecewise-linear one (up on [0, 0.7], down on [0.7, 1])
    under a uniform force F = -0.2 on both blocks. a_j = 1.2, b_j = 1.8: e = c = +1, m^+ = a_2,
    m^- = a_1, d = Delta - 2.4/k = 0.5 - 0.24 = 0.26."""
    link = {"kind": "piecewise-linear", "times": [0.0, 0.7, 1.0], "values": [1.0, 1.5, 1.0]}
    gait = make_gait(two_block_doc(loads={"force": -0.2}, link=link))
    result = run(gait, history=False)
    assert result.v0 == pytest.approx(0.26, abs=1e-12)
    assert closed_form_d(0.5, 10.0, 1.0, 2.0, (-0.2, -0.2)) == pytest.approx(0.26, abs=1e-15)


def test_where_v0_jumps():
    """Towing P on the rear block (F_1 = -P), mu+ = 1, mu- = 2, k = 10, Delta = 0.6: e and c both
    flip at P = mu- - mu+ = 1 (a_2 = b_1 and a_1 = b_2: the uniqueness condition fails for J = {2}
    and J = {1}), where v0 T jumps from Delta - (mu+ + mu-)/k = 0.3 to -0.3. At P = 1 exactly the
    gait is refused by the uniqueness check of the shifted thresholds."""
    below = run(make_gait(two_block_doc(loads={"force": [-(1 - 1e-6), 0.0]})), history=False)
    above = run(make_gait(two_block_doc(loads={"force": [-(1 + 1e-6), 0.0]})), history=False)
    assert below.v0 == pytest.approx(0.3 + 1e-7, abs=1e-12)  # 0.6 - (3 - 1e-6)/10
    assert above.v0 == pytest.approx(-0.3 - 1e-7, abs=1e-12)  # -(0.6 - (1 - 1e-6 + 2)/10)
    with pytest.raises(GaitError, match="uniqueness"):
        make_gait(two_block_doc(loads={"force": [-1.0, 0.0]}))


def test_slope_is_forces_and_scaled_friction():
    """Invariance (docs/model.md §6): a slope of angle alpha with weights W_j is the flat crawler
    with forces -W_j sin(alpha) and every threshold multiplied by cos(alpha): same v0, same
    dissipation, same load work, same actuator work (to roundoff), with time-varying friction and
    a time-varying force on top."""
    alpha, weights = 17.0, [0.4, 0.9, 0.6]
    ca, sa = math.cos(math.radians(alpha)), math.sin(math.radians(alpha))
    forward = [1.0, {"kind": "cosine", "mean": 1.2, "amplitude": 0.1}, 0.9]
    backward = [2.0, 2.5, {"kind": "steps", "times": [0.0, 0.5], "values": [1.8, 2.2]}]
    force = [{"kind": "cosine", "mean": -0.1, "amplitude": 0.05, "phase": 0.3}, 0.0, 0.05]

    def scaled(signal, factor):
        if isinstance(signal, float):
            return signal * factor
        out = dict(signal)
        for key in ("mean", "amplitude"):
            if key in out:
                out[key] *= factor
        if "values" in out:
            out["values"] = [v * factor for v in out["values"]]
        return out

    def doc(friction, loads):
        return {
            "blocks": 3,
            "period": 1.0,
            "stiffness": [10.0, 12.0],
            "links": [
                {"kind": "cosine", "mean": 1.0, "amplitude": 0.3},
                {"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 0.25},
            ],
            "friction": friction,
            "loads": loads,
            "simulation": {"steps_per_period": 400, "max_periods": 200},
        }

    slope = make_gait(
        doc(
            [{"forward": f, "backward": b} for f, b in zip(forward, backward)],
            {"force": force, "slope": {"angle": alpha, "weight": weights}},
        )
    )
    flat_force = [
        {**force[0], "mean": force[0]["mean"] - weights[0] * sa},
        -weights[1] * sa,
        force[2] - weights[2] * sa,
    ]
    flat = make_gait(
        doc(
            [{"forward": scaled(f, ca), "backward": scaled(b, ca)} for f, b in zip(forward, backward)],
            {"force": flat_force},
        )
    )
    a, b = run(slope, history=False), run(flat, history=False)
    assert a.v0 == pytest.approx(b.v0, abs=1e-10)
    assert a.v0 != 0
    for key in ("dissipation", "load_work", "actuator_work"):
        assert getattr(a.energy, key) == pytest.approx(getattr(b.energy, key), abs=1e-10), key
    assert abs(a.energy.balance_residual) <= 1e-11 * a.energy.actuator_work


def test_slope_closed_form_and_potential_energy():
    """Two blocks on a slope of 20 degrees, W = 1 each, no force: F~_j = -sin 20°, a_j = cos 20° +
    sin 20° = 1.2817, b_j = 2 cos 20° - sin 20° = 1.5373: e = c = +1 and d = 0.6 - 2 a/k; the work
    against the load is the potential energy gained, 2 W sin(20°) d."""
    gait = make_gait(two_block_doc(loads={"slope": {"angle": 20.0, "weight": 1.0}}))
    result = run(gait, history=False)
    sa, ca = math.sin(math.radians(20)), math.cos(math.radians(20))
    d = 0.6 - 2 * (ca + sa) / 10.0
    assert result.v0 == pytest.approx(d, abs=1e-12)
    assert closed_form_d(0.6, 10.0, 1.0, 2.0, (0.0, 0.0), 20.0, 1.0) == pytest.approx(d, abs=1e-15)
    assert result.energy.load_work == pytest.approx(2 * sa * d, abs=1e-12)
    assert result.energy.efficiency == pytest.approx(result.energy.load_work / result.energy.actuator_work, rel=1e-12)


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_energy_balance_with_loads_and_jumps(integrator):
    """W = D + J + W_load (+ catch-up's discretisation loss) on the limit period to roundoff, for a
    gait with switched (steps) friction, which makes jumps (J > 0), a periodic force and a slope,
    on four blocks."""
    doc = {
        "blocks": 4,
        "period": 2.0,
        "stiffness": 8.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.25, "phase": p} for p in (0.0, 0.25, 0.5)],
        "friction": {"forward": {"kind": "steps", "times": [0.0, 0.5], "values": [1.0, 1.4]}, "backward": 2.0},
        "loads": {
            "force": [{"kind": "cosine", "mean": -0.2, "amplitude": 0.1}, 0.0, 0.0, 0.1],
            "slope": {"angle": 5.0, "weight": [0.5, 0.5, 1.0, 1.0]},
        },
        "simulation": {"steps_per_period": 400, "max_periods": 400, "integrator": integrator},
    }
    result = run(make_gait(doc), history=False)
    W = result.energy.actuator_work
    total = result.energy.dissipation + result.energy.jump_loss + result.energy.load_work
    total += result.energy.discretisation_loss or 0.0
    assert W > 0 and result.energy.load_work != 0
    assert W - total == pytest.approx(0.0, abs=1e-11 * W)
    assert result.energy.balance_residual == pytest.approx(W - total, abs=1e-12 * W)


def test_rate_independence_with_loads():
    """v0 T does not depend on T (docs/model.md §4: the normal cone is a cone; the loads are
    signals of t/T like every other): T = 1 and T = 7.5 give the same displacement per period,
    load work and dissipation."""
    loads = {
        "force": [{"kind": "cosine", "mean": -0.3, "amplitude": 0.2}, 0.1],
        "slope": {"angle": 8.0, "weight": [1.0, 0.5]},
    }
    one = run(make_gait(two_block_doc(loads=loads)), history=False)
    slow = run(make_gait(two_block_doc(loads=loads, period=7.5)), history=False)
    assert slow.estimate.displacement == pytest.approx(one.estimate.displacement, abs=1e-12)
    assert slow.v0 * 7.5 == pytest.approx(one.v0, abs=1e-12)
    assert slow.energy.load_work == pytest.approx(one.energy.load_work, abs=1e-12)
    assert slow.energy.dissipation == pytest.approx(one.energy.dissipation, abs=1e-12)


def test_default_start_when_stress_free_is_not_admissible():
    """F_1 = -2.5 > mu_1^-: the rear block alone would slide backward (b_1 = -0.5 < 0), so the
    stress-free start is not admissible; the body holds (sum b = 1.5 > 0). crawlsim starts every
    block at the same fraction theta = 1.5/6 of its interval, admissibly, and v0 T is the closed
    form: m^+ = -0.5, m^- = 2, s = 0.6 - 0.15, e = c = -1, d = -0.45."""
    gait = make_gait(two_block_doc(loads={"force": [-2.5, 0.0]}))
    assert admissibility_violation(gait, gait.initial_positions) is None
    x = gait.initial_positions
    sigma = 10.0 * (1.3 - (x[1] - x[0]))
    theta = 1.5 / 6.0
    b_1 = -0.5
    assert -sigma == pytest.approx(-b_1 + theta * 3.0, abs=1e-12)  # f_1 = -b_1 + theta (a_1 + b_1)
    assert run(gait, history=False).v0 == pytest.approx(-0.45, abs=1e-12)


def test_inadmissible_initial_positions_get_a_suggestion():
    doc = two_block_doc(loads={"force": [-2.5, 0.0]})
    doc["initial"] = {"positions": [0.0, 1.3]}
    with pytest.raises(GaitError, match=r"initial: \{positions: \[") as info:
        make_gait(doc)
    suggested = yaml.safe_load(str(info.value).split("initial: ", 1)[1].split(" (docs", 1)[0])
    doc["initial"] = suggested
    make_gait(doc)


REFUSED = [
    ({"force": [-4.5, 0.0]}, "loads", "too large"),
    ({"force": [3.5, 0.0]}, "loads", "too large"),
    ({"force": [".nan", 0.0]}, "loads.force[0]", "finite"),
    ({"slope": {"angle": 90.0, "weight": 1.0}}, "loads.slope.angle", "-90 and 90"),
    ({"slope": {"angle": -95.0, "weight": 1.0}}, "loads.slope.angle", "-90 and 90"),
    ({"slope": {"angle": 10.0, "weight": -1.0}}, "loads.slope.weight", "W >= 0"),
    ({"slope": {"angle": 10.0, "weight": [1.0, -0.5]}}, "loads.slope.weight", "W >= 0"),
    ({"slope": {"angle": 10.0, "weight": [1.0]}}, "loads.slope.weight", "expected 2 weights"),
    ({"force": [0.1, 0.2, 0.3]}, "loads.force", "expected 2 force signals"),
    ({"force": {"kind": "cosine", "mean": 0.0}}, "loads.force", "amplitude"),
    ({"slope": {"angle": 75.0, "weight": 10.0}}, "loads", "too large"),
    ({"frce": 1.0}, "loads", "frce"),
]


@pytest.mark.parametrize("loads, keypath, needle", REFUSED)
def test_bad_loads_exit_2_with_key_path_and_no_file(tmp_path, loads, keypath, needle):
    text = yaml.safe_dump(two_block_doc(loads=loads)).replace("'.nan'", ".nan")
    gait = tmp_path / "gait.yaml"
    gait.write_text(text)
    result = CliRunner().invoke(main, ["run", str(gait), "-o", str(tmp_path / "out.h5")])
    assert result.exit_code == 2, result.output
    assert f"{gait}: {keypath}" in result.output and needle in result.output, result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out.h5").exists()


def test_sweep_paths_reach_the_loads(tmp_path):
    """``--sweep loads.force.0=...`` and ``loads.slope.angle=...`` edit the document; each point
    is the closed form."""
    gait = tmp_path / "gait.yaml"
    gait.write_text(yaml.safe_dump(two_block_doc(loads={"force": [0.0, 0.0], "slope": {"angle": 0.0, "weight": 1.0}})))
    r = CliRunner().invoke(main, ["velocity", str(gait), "--sweep", "loads.force.0=0:-0.8:5"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(io.StringIO(r.output.split("\n5 points")[0])))
    assert len(rows) == 5
    for row in rows:
        P = -float(row["loads.force.0"])
        assert float(row["v0"]) == pytest.approx(0.6 - (2.0 + P) / 10.0, abs=1e-9)
    r = CliRunner().invoke(main, ["velocity", str(gait), "--sweep", "loads.slope.angle=0:30:4"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(io.StringIO(r.output.split("\n4 points")[0])))
    assert len(rows) == 4
    for row in rows:
        alpha = float(row["loads.slope.angle"])
        expected = closed_form_d(0.6, 10.0, 1.0, 2.0, (0.0, 0.0), alpha, 1.0)
        assert float(row["v0"]) == pytest.approx(expected, abs=1e-9)


def test_replace_reaches_the_loads():
    gait = parse_gait(yaml.safe_dump(two_block_doc(loads={"force": [0.0, 0.0]})))
    towed = gait.replace("loads.force.0", -0.5)
    assert run(towed, history=False).v0 == pytest.approx(0.35, abs=1e-12)
    np.testing.assert_array_equal(towed.loads.total(np.zeros(1))[0], [-0.5, 0.0])


def test_run_file_records_the_loads(tmp_path):
    """The run file holds the loads' share of the thresholds on the limit period, the load work
    (also a root attribute) and the slope angle in degrees; the effective document (gait_yaml)
    holds the loads: block."""
    import h5py

    gait = make_gait(two_block_doc(loads={"force": [-0.5, 0.0], "slope": {"angle": 20.0, "weight": 1.0}}))
    result = run(gait, output=tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5") as f:
        assert f.attrs["slope_angle"] == 20.0
        assert json.loads(f.attrs["attribute_units_json"])["slope_angle"] == "degree"
        assert f.attrs["load_work_per_period"] == pytest.approx(result.energy.load_work, abs=1e-15)
        assert f["energy/load_work"][()] == pytest.approx(result.energy.load_work, abs=1e-15)
        load = f["limit/load"][()]
        total = -0.5 - math.sin(math.radians(20.0))
        np.testing.assert_allclose(load[:, 0], -total, atol=1e-15)  # forward row: -F~_1
        np.testing.assert_allclose(load[:, 3], -math.sin(math.radians(20.0)), atol=1e-15)
        assert yaml.safe_load(f.attrs["gait_yaml"])["loads"]["force"] == [-0.5, 0.0]


def test_sweep_file_records_the_swept_load_with_units(tmp_path):
    import h5py

    gait = tmp_path / "gait.yaml"
    doc = two_block_doc(loads={"force": [0.0, 0.0], "slope": {"angle": 0.0, "weight": 1.0}})
    doc["units"] = {"length": "mm", "time": "s", "force": "N"}
    gait.write_text(yaml.safe_dump(doc))
    r = CliRunner().invoke(
        main,
        [
            "velocity",
            str(gait),
            "--sweep",
            "loads.slope.angle=0:20:3",
            "--sweep",
            "loads.force.0=0:-0.2:2",
            "-o",
            str(tmp_path / "s.h5"),
        ],
    )
    assert r.exit_code == 0, r.output
    with h5py.File(tmp_path / "s.h5") as f:
        assert f["grid/loads_slope_angle"].attrs["units"] == "degree"
        assert f["grid/loads_force_0"].attrs["path"] == "loads.force.0"
        assert f["grid/loads_force_0"].attrs["units"] == "N"


def test_a_load_that_cannot_be_held_part_of_the_cycle_is_refused_with_the_time():
    """F(t) = -1 + 1.5 cos 2 pi t on each of 3 blocks, mu- = 2: sum mu~^- = 6 + 3 F(t) is
    negative around t = T/2 (minimum -1.5 there): no quasistatic motion, refused naming t."""
    doc = {
        "blocks": 3,
        "period": 2.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3}, 1.0],
        "friction": {"forward": 1.0, "backward": 2.0},
        "loads": {"force": {"kind": "cosine", "mean": -1.0, "amplitude": 1.5}},
    }
    with pytest.raises(
        GaitError,
        match=r"loads: the loads are too large .* at t = 1 "
        r"the total load sum_j F~_j = -7.5",
    ):
        make_gait(doc)
    doc["loads"]["force"]["amplitude"] = 0.9  # minimum 6 - 5.7 = 0.3 > 0: held
    make_gait(doc)


@pytest.mark.parametrize(
    "signals",
    [
        [1.0, {"kind": "steps", "times": [0.0, 0.3, 0.8], "values": [0.2, -0.7, 0.1]}],
        [
            {"kind": "piecewise-linear", "times": [0.0, 0.4, 1.0], "values": [0.0, -1.0, 0.0]},
            {"kind": "steps", "times": [0.0, 0.7], "values": [0.3, -0.2]},
        ],
        [
            {"kind": "cosine", "mean": 1.0, "amplitude": 0.5, "phase": 0.1},
            {"kind": "steps", "times": [0.0, 0.25], "values": [0.0, -0.6]},
        ],
    ],
)
def test_combination_minimum(signals):
    """The least value of a sum of signals over the cycle (the body's hold condition): exact
    for constants, steps and piecewise-linear (affine between breakpoints: a one-sided limit at a
    piece's end), and at least as low as a dense sample otherwise, never below the true one."""
    from crawlsim.gait.loads import combination
    from crawlsim.gait.signals import parse_signal

    parsed = [parse_signal(s, "s", "<test>") for s in signals]
    total = combination([(1.0, s) for s in parsed], 0.25)
    value, at = total.minimum()
    u = np.linspace(0.0, 1.0, 200001)[:-1]
    sampled = 0.25 + sum(s(u) for s in parsed)
    assert value <= sampled.min() + 1e-9
    assert value >= sampled.min() - 1e-4  # the one-sided limit at a jump is not sampled exactly
    assert total(np.array([at]))[0] == pytest.approx(value, abs=1e-4)


def test_square_wave_gait_under_a_uniform_force():
    """A square-wave stroke (a steps link: L jumps from 1 to 1.6 at t = 0 and back at T/2) under
    the uniform force F = -0.2 on both blocks, mu+ = 1, mu- = 2, k = 10: a = 1.2, b = 1.8, e = c
    = +1 and each jump of L slips by Delta - 2a/k = 0.6 - 0.24 = 0.36 (the jump loss is the
    elastic energy of the jump beyond friction: the ledger still balances)."""
    doc = two_block_doc(loads={"force": -0.2}, link={"kind": "steps", "times": [0.0, 0.5], "values": [1.6, 1.0]})
    for integrator in ("exact", "catch-up"):
        doc["simulation"]["integrator"] = integrator
        result = run(make_gait(doc), history=False)
        assert result.v0 == pytest.approx(0.36, abs=1e-12)
        assert result.energy.load_work == pytest.approx(0.4 * 0.36, abs=1e-12)
        assert result.energy.jump_loss > 0
        assert abs(result.energy.balance_residual) <= 1e-12 * result.energy.actuator_work


def test_climbing_3_closed_form():
    """gaits/climbing-3.yaml's header: every block advances 2 (Delta - 3a/k) per period, a =
    cos 10° + sin 10°, and the work against gravity is 3 W sin 10° d."""
    from .conftest import GAITS

    result = run(GAITS / "climbing-3.yaml", history=False)
    a = math.cos(math.radians(10)) + math.sin(math.radians(10))
    d = 2 * (0.6 - 3 * a / 10)
    assert result.v0 == pytest.approx(d, abs=1e-12)
    assert result.energy.load_work == pytest.approx(3 * math.sin(math.radians(10)) * d, abs=1e-12)


def test_inching_2_towing_header():
    from .conftest import GAITS

    result = run(GAITS / "inching-2-towing.yaml", history=False)
    assert result.v0 == pytest.approx(0.35, abs=1e-12)
    assert result.energy.load_work == pytest.approx(0.175, abs=1e-12)
    assert result.energy.dissipation == pytest.approx(0.7, abs=1e-12)
    assert result.energy.actuator_work == pytest.approx(0.875, abs=1e-12)
    assert result.energy.efficiency == pytest.approx(0.2, abs=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(24))
def test_random_gaits_with_loads_never_crash(seed):
    """The random-gait corpus with random loads (forces of every kind, some beyond a block's own
    friction, slopes up to 30 degrees): both integrators run to convergence, or catch-up meets a
    degenerate grid instant and says so (exit 2); never a certificate or internal failure."""
    from crawlsim.analysis.run import simulate
    from crawlsim.errors import DegenerateModelError
    from crawlsim.gait.corpus import random_gait
    from crawlsim.model.process import compile_gait

    gait = random_gait(seed, blocks=(2, 8), steps_per_period=200, max_periods=300, loads=True)
    assert gait.loads is not None
    exact = simulate(compile_gait(gait), integrator="exact", max_periods=300, tolerance=1e-11, history=False)
    assert exact.converged and abs(exact.energy.balance_residual) <= 1e-9 * max(1.0, abs(exact.energy.actuator_work))
    try:
        catch_up = simulate(compile_gait(gait), integrator="catch-up", max_periods=300, tolerance=1e-11, history=False)
    except DegenerateModelError:
        return
    assert catch_up.converged


@given(
    mu_plus=st.floats(0.2, 3.0),
    mu_minus=st.floats(0.2, 3.0),
    k=st.floats(2.0, 50.0),
    stroke=st.floats(0.05, 1.0),
    rise=st.floats(0.1, 0.9),
    f1=st.floats(-2.0, 2.0),
    f2=st.floats(-2.0, 2.0),
    angle=st.floats(-40.0, 40.0),
    weight=st.floats(0.0, 1.5),
)
@settings(max_examples=40)
def test_two_blocks_closed_form_any_monotone_stroke(mu_plus, mu_minus, k, stroke, rise, f1, f2, angle, weight):
    """The module docstring's d = s (e + c)/2 for random friction, stiffness, constant forces,
    slope and a piecewise-linear monotone stroke rising on [0, rise T] and falling back: the
    exact integrator's v0 T to 1e-9. Draws within 1e-3 of a degenerate case (the body barely
    holding, a flip of e or c, the slip s at 0) are left out: there v0 is discontinuous or the
    gait is refused."""
    ca, sa = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    total = [f1 - weight * sa, f2 - weight * sa]
    a = [mu_plus * ca - t for t in total]
    b = [mu_minus * ca + t for t in total]
    assume(sum(a) > 1e-2 and sum(b) > 1e-2)
    assume(abs(a[1] - b[0]) > 1e-3 and abs(a[0] - b[1]) > 1e-3)
    s = stroke - (min(b[0], a[1]) + min(a[0], b[1])) / k
    assume(abs(s) > 1e-3)
    link = {"kind": "piecewise-linear", "times": [0.0, rise, 1.0], "values": [1.0, 1.0 + stroke, 1.0]}
    doc = two_block_doc(
        k=k,
        mu_plus=mu_plus,
        mu_minus=mu_minus,
        link=link,
        loads={"force": [f1, f2], "slope": {"angle": angle, "weight": weight}},
    )
    result = run(make_gait(doc), history=False)
    d = closed_form_d(stroke, k, mu_plus, mu_minus, (f1, f2), angle, weight)
    assert result.v0 == pytest.approx(d, abs=1e-9)
    W = result.energy.actuator_work
    assert abs(result.energy.balance_residual) <= 1e-11 * max(W, 1.0)


def test_a_towing_load_on_the_uniqueness_boundary_is_fixed_by_the_suggested_change():
    """At P = 1 both J = {1} and J = {2} violate the condition on the shifted thresholds
    (mu+ = 1, mu- = 2, F_1 = -1: mu~_1^+ = 2 = mu~_2^-, mu~_2^+ = 1 = mu~_1^-); the refusal names
    both and a change of one friction coefficient after which the gait is valid."""
    import re

    from crawlsim.gait.docpaths import edited

    doc = two_block_doc(loads={"force": [-1.0, 0.0]})
    with pytest.raises(GaitError) as info:
        make_gait(doc)
    message = info.value.message
    assert info.value.keypath == "loads"
    assert "for J = {1} (forward) and the rest {2} (backward)" in message
    assert "J = {2} (forward) and the rest {1} (backward) for t in [0, 1]" in message
    change = re.search(r"change (\S+) from (\S+) to ([0-9.e+-]+)(?: \(path (\S+)\))?: ", message)
    assert change is not None
    fixed = make_gait(edited(doc, [(change[4] or change[1], float(change[3]))], "fixed.yaml"))
    assert fixed.blocks == 2
    assert 0 < abs(float(change[3]) - float(change[2])) <= 0.05 * float(change[2])
