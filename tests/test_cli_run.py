"""`crawlsim run` through click's CliRunner: outputs, the HDF5 layout, exit codes, refusals."""

import json
import os

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from crawlsim import __version__
from crawlsim.cli import main
from crawlsim.io.runread import read_results

from .conftest import iterated_examples

INCHING = """\
blocks: 2
period: 1.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3}
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 100, max_periods: 20}
"""


@pytest.fixture
def runner(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return CliRunner()


def write(tmp_path, text, name="gait.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_run_writes_default_file_and_summary(runner, tmp_path):
    gait = write(tmp_path, INCHING, "inch.yaml")
    result = runner.invoke(main, ["run", str(gait)])
    assert result.exit_code == 0, result.output
    assert "v0                       0.4" in result.output
    assert "finite-time: periodic from period 1" in result.output
    assert (tmp_path / "inch.h5").exists()
    one = runner.invoke(main, ["run", str(gait), "--max-periods", "1", "-o", "one.h5", "--force"])
    assert one.exit_code == 3 and one.output.splitlines()[0] == "gait inch: 1 period of 100 steps", one.output


def test_run_json_keys_and_values(runner, tmp_path):
    gait = write(tmp_path, INCHING)
    result = runner.invoke(main, ["run", str(gait), "--json", "-o", "out.h5"])
    assert result.exit_code == 0
    data = json.loads(result.output)
    for key in (
        "name",
        "v0",
        "displacement_per_period",
        "convergence",
        "periodic_from",
        "contraction_rate",
        "periods",
        "steps_per_period",
        "v0_error_estimate",
        "dissipation_per_period",
        "output",
    ):
        assert key in data
    assert data["v0"] == pytest.approx(0.4, abs=1e-13)
    assert data["convergence"] == "finite-time" and data["periodic_from"] == 1
    assert data["contraction_rate"] is None and data["steps_per_period"] == 100
    assert data["output"].endswith("out.h5")


def test_hdf5_layout_round_trips(runner, tmp_path):
    gait = write(tmp_path, INCHING)
    result = runner.invoke(main, ["run", str(gait), "-o", "r.h5", "--save-every", "3"])
    assert result.exit_code == 0
    with h5py.File(tmp_path / "r.h5") as f:
        a = f.attrs
        assert a["crawlsim_version"] == __version__ and a["format_version"] == 2
        assert a["convergence"] == "finite-time" and a["periodic_from"] == 1
        assert a["v0"] == pytest.approx(0.4, abs=1e-13)
        assert a["gait_file_text"] == INCHING  # the text as read; gait_yaml is the effective one
        t = f["trajectory/t"][()]
        assert np.allclose(np.diff(t), 0.03)  # every third of 100 steps per period
        assert f["trajectory/x"].shape == (len(t), 2)
        assert f["trajectory/stress"].shape == (len(t), 1)
        for name in ("period", "displacement", "poincare_step", "w12_distance"):
            assert f[f"convergence/{name}"].shape == (2,)
        assert f["limit/x"].shape == (101, 2) and f["limit/slip"].shape == (100, 2)
        assert f["limit/stress"].shape == (101, 1)
    data = read_results(tmp_path / "r.h5")
    assert data["convergence"]["displacement"][-1] == pytest.approx(0.4, abs=1e-13)
    # the stress of the trajectory is k (L - z) with z = x2 - x1
    x, s, t = data["trajectory"]["x"], data["trajectory"]["stress"], data["trajectory"]["t"]
    L = 1 + 0.3 * np.cos(2 * np.pi * t)
    assert np.allclose(s[:, 0], 10 * (L - (x[:, 1] - x[:, 0])), atol=1e-12)


def test_not_converged_exit_code_3_still_writes(runner, tmp_path):
    text = """\
blocks: 3
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.12}, 1.0]
friction: {forward: 1.0, backward: 1.5}
simulation: {steps_per_period: 100}
"""
    gait = write(tmp_path, text)
    # 2 periods: the plain ones before the periodic-limit solver (with a third, its first
    # Newton step lands on this gait's limit)
    result = runner.invoke(main, ["run", str(gait), "--max-periods", "2", "--json"])
    assert result.exit_code == 3
    assert json.loads(result.stdout)["convergence"] == "not-converged"
    # the reason and what to change, in one line on stderr (the JSON on stdout stays parseable)
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "max_periods = 2" in result.stderr and "--max-periods" in result.stderr
    assert (tmp_path / "gait.h5").exists()
    # the line is the run's own message: the tolerance it names is the one used, 1e-15 clamped
    # to the roundoff floor
    result = runner.invoke(main, ["run", str(gait), "--max-periods", "2", "--tolerance", "1e-15", "--json", "--force"])
    message = json.loads(result.stdout)["message"]
    assert "tolerance 1e-13 relative" in message
    assert result.stderr == f"Not converged: {message}. The numbers printed are those of the last period.\n"


def test_overrides_apply(runner, tmp_path):
    gait = write(tmp_path, INCHING)
    result = runner.invoke(main, ["run", str(gait), "--json", "--steps-per-period", "40", "--tolerance", "1e-10"])
    assert json.loads(result.output)["steps_per_period"] == 40


BAD = [
    ("blocks: 2\nperiod: 1.0\nstiffness: 10.0\nlinks: [1.0, 1.0]\nfriction: {forward: 1.0, backward: 2.0}\n", "links"),
    (INCHING.replace("backward: 2.0", "backward: -2.0"), "friction.backward"),
    (INCHING.replace("stiffness: 10.0", "stiffness: 0"), "stiffness"),
    (INCHING.replace("period: 1.0", "period: -1"), "period"),
    (INCHING.replace("backward: 2.0", "backwrad: 2.0"), "did you mean 'backward'"),
    (
        INCHING.replace(
            "{kind: cosine, mean: 1.0, amplitude: 0.3}",
            "{kind: piecewise-linear, times: [0, 0.5, 1], values: [1, 1.3, 1.1]}",
        ),
        "links[0]",
    ),
    (INCHING.replace("backward: 2.0", "backward: 1.0"), "uniqueness"),
    (INCHING + "initial: {positions: [0.0, 2.0]}\n", "initial.positions"),
    (
        INCHING.replace("friction: {forward: 1.0, backward: 2.0}", "friction: [{forward: 1.0, backward: 2.0}]"),
        "friction",
    ),
    ("blocks: [2\n", "line"),
]


@pytest.mark.parametrize("text,needle", BAD)
def test_bad_input_exit_2_names_the_key_and_writes_nothing(runner, tmp_path, text, needle):
    gait = write(tmp_path, text)
    result = runner.invoke(main, ["run", str(gait), "-o", "out.h5"])
    assert result.exit_code == 2, result.output
    assert str(gait) in result.output
    assert needle in result.output
    assert "Traceback" not in result.output
    assert sorted(os.listdir(tmp_path)) == ["gait.yaml"]


def test_bad_command_line(runner, tmp_path):
    gait = write(tmp_path, INCHING)
    for args in (
        ["run", "missing.yaml"],
        ["run", str(gait), "--steps-per-period", "0"],
        ["run", str(gait), "--tolerance", "-1"],
        ["run", str(gait), "-o", "no/such/folder/out.h5"],
    ):
        result = runner.invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        assert "Traceback" not in result.output
    assert sorted(os.listdir(tmp_path)) == ["gait.yaml"]


def test_every_example_gait_runs_from_the_cli(runner, tmp_path):
    for path in iterated_examples():
        result = runner.invoke(main, ["run", str(path), "--json", "--steps-per-period", "100", "-o", f"{path.stem}.h5"])
        assert result.exit_code == 0, (path, result.output)
        assert np.isfinite(json.loads(result.output)["v0"])


def test_python_dash_m_entry_point(tmp_path):
    import subprocess
    import sys

    gait = write(tmp_path, INCHING)
    out = subprocess.run(
        [sys.executable, "-m", "crawlsim", "run", str(gait), "--json", "-o", str(tmp_path / "m.h5")],
        capture_output=True,
        text=True,
        check=True,
    )
    assert json.loads(out.stdout)["v0"] == pytest.approx(0.4, abs=1e-13)


def test_run_refuses_stdout_for_hdf5(runner, tmp_path):
    gait = write(tmp_path, INCHING)
    result = runner.invoke(main, ["run", str(gait), "-o", "-"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "cannot be streamed to stdout" in result.output and "--json" in result.output
    assert sorted(os.listdir(tmp_path)) == ["gait.yaml"]


def test_info_summarises_a_run(runner, tmp_path):
    """`crawlsim info` reports what the file's attributes say (the closed-form v0 0.4 of the
    inching gait, finite-time from period 1), text and JSON alike, without the trajectory."""
    gait = write(tmp_path, INCHING, "inch.yaml")
    run = runner.invoke(main, ["run", str(gait), "-o", "r.h5"])
    assert run.exit_code == 0
    text = runner.invoke(main, ["info", "r.h5"])
    assert text.exit_code == 0, text.output
    lines = text.output.splitlines()
    # the numbers crawlsim run prints, with their estimates; no attribute that does not apply
    # (NaN: the load work and slope of a run without loads)
    for label in ("v0", "displacement per period", "dissipation per period", "cost of transport"):
        (printed,) = [line for line in run.output.splitlines() if line.startswith(f"  {label:<24} ")]
        assert printed.split(" (")[0] in lines  # v0 without its explanation
    assert not [line for line in lines if line.endswith(" nan")]
    assert lines[0] == "r.h5: run of gait inch"
    assert "  integrator               exact" in lines  # the default
    assert any(line.startswith("  v0                       0.4") for line in lines)
    assert "  convergence              finite-time: periodic from period 1" in lines
    assert "  periods                  2 of 100 steps (period 1)" in lines
    assert f"  written by               crawlsim {__version__} (format 2)" in lines
    data = json.loads(runner.invoke(main, ["info", "r.h5", "--json"]).output)
    attrs = read_results(tmp_path / "r.h5")["attrs"]
    assert data["file_kind"] == "run" and data["kind"] == "crawler" and data["name"] == "inch"
    assert data["v0"] == attrs["v0"] == pytest.approx(0.4, abs=1e-13)
    assert data["v0_error_estimate"] == attrs["v0_error_estimate"]
    assert data["convergence"] == "finite-time" and data["periodic_from"] == 1
    assert data["contraction_rate"] is None and data["periods"] == 2


def test_info_summarises_a_sweep(runner, tmp_path):
    gait = write(tmp_path, INCHING, "inch.yaml")
    r = runner.invoke(
        main,
        [
            "velocity",
            str(gait),
            "--sweep",
            "friction.backward=[0.5,1,2]",
            "--sweep",
            "period=1,2",
            "--link",
            "links.0.amplitude=0.3,0.2",
            "-o",
            "s.h5",
        ],
    )
    assert r.exit_code == 0, r.output
    text = runner.invoke(main, ["info", "s.h5"]).output.splitlines()
    assert text[0] == f"s.h5: sweep of gait inch, from {gait}"
    assert "  dimension 1              friction.backward: 3 values in [0.5, 2]" in text
    assert "  dimension 2              period with links.0.amplitude: 2 values in [1, 2]" in text
    assert "  points                   6: 2 invalid, 4 ok" in text
    data = json.loads(runner.invoke(main, ["info", "s.h5", "--json"]).output)
    assert data["file_kind"] == "sweep" and data["statuses"] == {"ok": 4, "invalid": 2}
    assert data["integrator"] == "exact" and data["shard"] is None
    # v0 of the ok points: backward 0.5 moves backward, 2 forward (tests/test_sweep.py)
    assert data["v0_min"] == pytest.approx(-(0.6 - 2 * 0.5 / 10), abs=1e-12)
    assert data["v0_max"] == pytest.approx(0.6 - 0.2, abs=1e-12)


def test_info_refuses_what_is_not_a_results_file(runner, tmp_path):
    (tmp_path / "notes.h5").write_text("not HDF5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = [1, 2]
    for name, text in (
        ("notes.h5", "not an HDF5 file"),
        ("other.h5", "not a crawlsim results"),
        ("missing.h5", "no such results file"),
    ):
        r = runner.invoke(main, ["info", name])
        assert r.exit_code == 2 and text in r.output and "Traceback" not in r.output, name
