"""``crawlsim stall`` and `crawlsim.analysis.stall` on closed forms (docs/model.md §6).

Two blocks, stroke Delta, stiffness k, friction mu+ < mu- on both, a towed load P on the rear
block (F_1 = -P): a_1 = mu+ + P, b_1 = mu- - P, a_2 = mu+, b_2 = mu-. While P < mu- - mu+ both
half-strokes slip forward and d = Delta - (2 mu+ + P)/k (tests/test_loads.py derives the general
two-block formula). So the stall force is P* = k Delta - 2 mu+, a smooth zero of v0, when that is
below mu- - mu+ (v0 is then identically 0 up to the flip); otherwise v0 jumps from
(Delta - (mu+ + mu-)/k)/T to minus that at P* = mu- - mu+, where a_2 = b_1 (the uniqueness
condition fails for J = {1} and J = {2}).

On a slope of angle alpha with W = 1 on both blocks and no force: a = cos + sin, b = 2 cos - sin
(mu+ = 1, mu- = 2); the slips flip at a = b, tan(alpha) = 1/2, before the smooth zero (2a/k =
Delta has no solution for Delta = 0.6, k = 10: 2a/k <= 0.283): the steepest slope is atan(1/2),
a jump. gaits/climbing-3.yaml derives its steepest slope atan(2/3), also a jump.
"""

import json
import math

import pytest
import yaml
from click.testing import CliRunner

from crawlsim.analysis.stall import StallCause
from crawlsim.cli import main
from crawlsim.design.stall import stall
from crawlsim.errors import InputError
from crawlsim.gait.document import parse_gait

from .conftest import GAITS


def towing(tmp_path, amplitude, force=0.0, name="g.yaml", extra=None):
    doc = {
        "blocks": 2,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": amplitude}],
        "friction": {"forward": 1.0, "backward": 2.0},
        "loads": {"force": [force, 0.0], **(extra or {})},
        "simulation": {"steps_per_period": 200, "max_periods": 50},
    }
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return path


def test_stall_force_at_a_jump(tmp_path):
    """Delta = 0.6: k Delta - 2 mu+ = 4 > mu- - mu+ = 1, so v0 jumps at P* = 1 from 0.3 to -0.3."""
    result = stall(towing(tmp_path, 0.3, -0.5), force="loads.force.0")
    assert result.value == pytest.approx(-1.0, abs=1e-6)
    assert result.cause == StallCause.JUMP
    assert result.subset in ((1,), (2,))
    assert min(result.bracket) <= -1.0 + 1e-8 and max(result.bracket) >= -1.0 - 1e-8
    assert result.v0_moving == pytest.approx(0.3, abs=1e-6)
    assert result.v0_stopped == pytest.approx(-0.3, abs=1e-6)


def test_stall_force_at_a_smooth_zero_then_v0_is_zero(tmp_path):
    """Delta = 0.24: P* = 2.4 - 2 = 0.4 < 1, a smooth zero, with v0 = 0 on [0.4, 1] beyond it
    (the bisection must not be misled by that interval)."""
    result = stall(towing(tmp_path, 0.12), force="loads.force.0")
    assert result.value == pytest.approx(-0.4, abs=1e-6)
    assert result.cause == StallCause.SMOOTH_ZERO
    assert result.v0_start == pytest.approx(0.04, abs=1e-12)


def test_steepest_slope_two_blocks(tmp_path):
    path = towing(tmp_path, 0.3, extra={"slope": {"angle": 0.0, "weight": 1.0}})
    result = stall(path, slope=True)
    assert result.value == pytest.approx(math.degrees(math.atan(0.5)), abs=1e-6)
    assert result.cause == StallCause.JUMP
    assert result.unit == "degree"


def test_steepest_slope_of_climbing_3():
    result = stall(GAITS / "climbing-3.yaml", slope=True)
    assert result.value == pytest.approx(math.degrees(math.atan(2 / 3)), abs=1e-6)
    assert result.cause == StallCause.JUMP
    a = 5 / math.sqrt(13)  # cos + sin at tan = 2/3
    assert result.v0_moving == pytest.approx(2 * (0.6 - 3 * a / 10), abs=1e-6)


def test_stall_of_a_gait_object_and_refusals(tmp_path):
    gait = parse_gait(towing(tmp_path, 0.3, -0.5).read_text())
    assert stall(gait, force="loads.force.0").value == pytest.approx(-1.0, abs=1e-6)
    with pytest.raises(InputError, match="weights"):
        stall(gait, slope=True)
    with pytest.raises(InputError, match="loads.force"):
        stall(gait, force="friction.forward")
    with pytest.raises(InputError, match="does not move"):
        stall(gait.replace("links.0.amplitude", 0.05), force="loads.force.0")


def test_cli(tmp_path):
    path = towing(tmp_path, 0.3, -0.5)
    runner = CliRunner()
    r = runner.invoke(main, ["stall", str(path), "--force", "loads.force.0", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert out["stall"] == pytest.approx(-1.0, abs=1e-6) and out["cause"] == "jump"
    assert out["stall_force"] == out["stall"] and out["bracket"][0] > out["bracket"][1]
    assert out["error_estimate"] <= 1e-6
    r = runner.invoke(main, ["stall", str(path), "--force", "loads.force.0"])
    assert r.exit_code == 0 and "jump" in r.output
    first = r.output.splitlines()[0]
    # only the supported digits: the value is printed to the bracket's decimal place
    value = first.split(": ", 1)[1].split(" ")[0]
    assert abs(float(value) + 1.0) <= 1e-6 and len(value.split(".")[1]) <= 10
    for args in (
        ["stall", str(path)],
        ["stall", str(path), "--slope", "--force", "loads.force.0"],
        ["stall", str(path), "--slope"],
        ["stall", str(tmp_path / "missing.yaml"), "--slope"],
    ):
        r = runner.invoke(main, args)
        assert r.exit_code == 2 and "Traceback" not in r.output, (args, r.output)


def test_force_velocity_figure_marks_the_jump_and_the_stall(tmp_path):
    """The sweep figure of a load: the jump of v0 at P = 1 (tests/test_loads.py) is located by
    the shifted uniqueness sums to 1e-9 and the line is broken there, not joined across; the
    stall force is the jump. With the smooth stroke (Delta = 0.24) v0 = 0.04 - P/10 is affine
    up to its zero at P = 0.4 and 0 beyond: the secant of the moving side finds 0.4 exactly."""
    from crawlsim.analysis.stall import curve_marks
    from crawlsim.plotting import sweep_figure

    path = towing(tmp_path, 0.3, -0.5)
    r = CliRunner().invoke(main, ["velocity", str(path), "--sweep", "loads.force.0=0.1:-1.75:12"])
    assert r.exit_code == 0, r.output
    rows = [line.split(",") for line in r.output.splitlines()[1:13]]
    x = [float(row[0]) for row in rows]
    v0 = [float(row[1]) if row[1] else float("nan") for row in rows]
    marks = curve_marks(path.read_text(), "loads.force.0", x, v0)
    assert len(marks.jumps) == 1 and marks.jumps[0] == pytest.approx(-1.0, abs=1e-9)
    assert marks.stall == pytest.approx(-1.0, abs=1e-9) and marks.cause == StallCause.JUMP
    fig = sweep_figure({"loads.force.0": x}, v0, ["ok"] * len(x), "fv", marks=marks)
    line = fig.axes[0].get_lines()[0]
    xs = list(line.get_xdata())
    assert any(math.isnan(value) for value in xs)  # broken at the jump
    # the legend names the curve, the stall and the jump (and the axis keeps its zero line)
    legend = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    assert legend[0] == "$v_0$" and "jump of $v_0$" in legend
    assert any(text.startswith("stall force -1 (jump)") for text in legend), legend
    assert any(list(line.get_ydata()) == [0.0, 0.0] for line in fig.axes[0].get_lines())
    smooth = towing(tmp_path, 0.12, name="s.yaml")
    xs = [0.0, -0.1, -0.2, -0.3, -0.45, -0.6]
    v0 = [0.024 - 0.1 * (-s) + 0.016 if -s < 0.4 else 0.0 for s in xs]  # 0.04 - P/10, then 0
    marks = curve_marks(smooth.read_text(), "loads.force.0", xs, v0)
    assert marks.cause == StallCause.SMOOTH_ZERO
    assert marks.stall == pytest.approx(-0.4, abs=1e-12)


def test_stall_of_a_gait_without_loads_uses_zero_forces():
    """inching-2 has no loads: block. With one force F on both blocks (loads.force) a = mu+ - F,
    b = mu- + F, and the slips flip at a = b: F* = (mu+ - mu-)/2 = -0.5, a jump (v0 from
    Delta - 2 a/k = 0.6 - 0.3 = 0.3 to -0.3)."""
    result = stall(GAITS / "inching-2.yaml", force="loads.force")
    assert result.value == pytest.approx(-0.5, abs=1e-6)
    assert result.cause == StallCause.JUMP
    assert result.v0_moving == pytest.approx(0.3, abs=1e-6)
    assert result.v0_stopped == pytest.approx(-0.3, abs=1e-6)


def test_the_slope_sweep_figure_agrees_with_crawlsim_stall(tmp_path):
    """gaits/climbing-3.yaml swept over 0..40 degrees (issue 35): beyond the jump at atan(2/3)
    = 33.69 degrees v0 is roundoff (3.7e-17 at 34, 36 and 38 degrees, exactly 0 at 37), which is
    not motion. The figure marks the steepest slope where `crawlsim stall` finds it, as a jump
    between the grid points 33 and 34, and its axis carries the unit of the angle."""
    from crawlsim.io.sweepfile import read_sweep
    from crawlsim.plotting.sweeps import sweep_data_figure

    out = tmp_path / "slope.h5"
    r = CliRunner().invoke(
        main, ["velocity", str(GAITS / "climbing-3.yaml"), "--sweep", "loads.slope.angle=0:40:41", "-o", str(out)]
    )
    assert r.exit_code == 0, r.output
    fig = sweep_data_figure(read_sweep(out))
    ax = fig.axes[0]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    steepest = math.degrees(math.atan(2 / 3))
    assert f"steepest slope {steepest:.6g} (jump)" in legend
    (marker,) = [line for line in ax.get_lines() if line.get_label().startswith("steepest slope")]
    assert marker.get_xdata()[0] == pytest.approx(steepest, abs=1e-9)
    assert ax.get_xlabel() == "loads.slope.angle (degrees)"
