"""Provenance: every results file records what ran (the effective gait document, the integrator
and its settings), how (the command line or the Python call), with what (library versions) and
when; ``crawlsim run --from RESULT.h5`` reruns it and reproduces it bit for bit."""

import json
import subprocess
import sys
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import crawlsim
from crawlsim.cli import main
from crawlsim.io.runread import read_results

ROOT = Path(__file__).resolve().parents[1]
GAITS = ROOT / "gaits"
DATA = Path(__file__).resolve().parent / "data"

#: Five crawler runs with different overrides (and a generic process), each rerun with --from.
RUNS = {
    "inching": ["inching-2.yaml", "--steps-per-period", "100"],
    "tolerance": ["peristalsis-3.yaml", "--steps-per-period", "250", "--tolerance", "1e-10"],
    "exact": ["peristalsis-4.yaml", "--integrator", "exact", "--steps-per-period", "300"],
    "max-periods": ["anchoring-2.yaml", "--max-periods", "3", "--save-every", "7"],
    "check-every-step": ["smooth-friction-3.yaml", "--steps-per-period", "120", "--check-every-step"],
    "process": ["paper/acute-angle.yaml", "--steps-per-period", "100"],
}


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.mark.parametrize("case", list(RUNS))
def test_rerun_from_results_reproduces_the_run_bit_for_bit(tmp_path, case):
    """Rerunning a file's recorded run gives the same v0 (==, not approx), the same periods and
    the same limit period: the file holds every override. Rerunning the gait file alone would
    not: the recorded document differs from the file's text exactly by the overrides."""
    gait, *options = RUNS[case]
    first, again = tmp_path / "first.h5", tmp_path / "again.h5"
    r = cli("run", GAITS / gait, *options, "-o", first)
    assert r.exit_code in (0, 3), r.output
    r = cli("run", "--from", first, "-o", again)
    assert r.exit_code in (0, 3), r.output
    a, b = read_results(first), read_results(again)
    if case != "process":
        assert np.isfinite(a["attrs"]["v0"])
        # the same computation rerun on this machine: bit for bit is the point (reproducibility)
        assert a["attrs"]["v0"] == b["attrs"]["v0"]
    for group in ("convergence", "limit", "trajectory"):
        for name, value in a[group].items():
            assert np.array_equal(value, b[group][name], equal_nan=True), f"{group}/{name}"
    assert a["attrs"]["gait_yaml"] == b["attrs"]["gait_yaml"]
    assert a["attrs"]["integrator_json"] == b["attrs"]["integrator_json"]
    assert a["attrs"]["save_every"] == b["attrs"]["save_every"]
    recorded = yaml.safe_load(a["attrs"]["gait_yaml"])
    original = yaml.safe_load((GAITS / gait).read_text())
    overrides = dict(zip(options[::2], options[1::2]))
    simulation = recorded["simulation"]
    for option, key, kind in (
        ("--steps-per-period", "steps_per_period", int),
        ("--tolerance", "tolerance", float),
        ("--integrator", "integrator", str),
        ("--max-periods", "max_periods", int),
    ):
        if option in overrides:
            assert simulation[key] == kind(overrides[option])
            assert original.get("simulation", {}).get(key) != kind(overrides[option])
    settings = json.loads(a["attrs"]["integrator_json"])
    assert settings["check_every_step"] == ("--check-every-step" in options)
    assert (
        settings["integrator"] == a["attrs"]["integrator"] == simulation.get("integrator", "exact")
    )  # the default integrator


def test_rerun_options_override_the_recorded_ones(tmp_path):
    first = tmp_path / "first.h5"
    assert cli("run", GAITS / "inching-2.yaml", "--steps-per-period", "100", "-o", first).exit_code == 0
    r = cli("run", "--from", first, "--steps-per-period", "40", "--json", "-o", tmp_path / "b.h5")
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["steps_per_period"] == 40
    assert yaml.safe_load(read_results(tmp_path / "b.h5")["attrs"]["gait_yaml"])["simulation"]["steps_per_period"] == 40


def test_rerun_default_output_does_not_replace_the_source(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli("run", GAITS / "inching-2.yaml", "--steps-per-period", "50").exit_code == 0
    before = Path("inching-2.h5").read_bytes()
    assert cli("run", "--from", "inching-2.h5").exit_code == 0
    assert Path("inching-2-rerun.h5").exists() and Path("inching-2.h5").read_bytes() == before


@pytest.mark.parametrize(
    "args, message",
    [
        (["--from", DATA / "v1-run.h5"], "format_version 1 files do not record"),
        (["--from", DATA / "v1-sweep.h5"], "a sweep file"),
        ([GAITS / "inching-2.yaml", "--from", DATA / "v1-run.h5"], "one of the two"),
        ([], "one of the two"),
    ],
)
def test_rerun_refusals_exit_2_and_write_nothing(tmp_path, args, message):
    r = cli("run", *args, "-o", tmp_path / "out.h5")
    assert r.exit_code == 2, r.output
    assert message in r.output and "Traceback" not in r.output
    assert not (tmp_path / "out.h5").exists()


def test_files_record_versions_time_and_the_command_line(tmp_path):
    """``sys.argv`` is the command line of a real process; the versions are those installed."""
    out = tmp_path / "r.h5"
    before = datetime.now(UTC).replace(microsecond=0)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "crawlsim",
            "run",
            str(GAITS / "inching-2.yaml"),
            "--steps-per-period",
            "20",
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    after = datetime.now(UTC)
    a = read_results(out)["attrs"]
    assert a["command_line"].endswith(f"run {GAITS / 'inching-2.yaml'} --steps-per-period 20 -o {out}")
    created = datetime.fromisoformat(a["created"])
    assert created.tzinfo is not None and before <= created <= after
    versions = json.loads(a["versions_json"])
    assert versions["crawlsim"] == crawlsim.__version__
    assert versions["python"] == ".".join(map(str, sys.version_info[:3]))
    for name in ("numpy", "scipy", "clarabel", "h5py"):
        assert versions[name] == metadata.version(name)
    assert a["gait_file"] == str(GAITS / "inching-2.yaml")
    assert a["gait_file_text"] == (GAITS / "inching-2.yaml").read_text()


def test_the_api_records_the_call_and_its_result_reruns_from_the_cli(tmp_path):
    gait = crawlsim.load_gait(GAITS / "peristalsis-3.yaml").replace("links.*.amplitude", 0.25)
    result = crawlsim.simulate(gait, integrator="exact", steps_per_period=64)
    call = (
        "crawlsim.simulate(<gait '"
        + str(GAITS / "peristalsis-3.yaml")
        + " with links.*.amplitude=0.25'>, integrator='exact', steps_per_period=64)"
    )
    assert result.provenance.command_line == call
    saved = result.save(tmp_path / "api.h5")
    a = read_results(saved)["attrs"]
    assert a["command_line"] == call and a["integrator"] == "exact"
    document = yaml.safe_load(a["gait_yaml"])
    assert [link["amplitude"] for link in document["links"]] == [0.25, 0.25]
    r = cli("run", "--from", saved, "--json", "-o", tmp_path / "again.h5")
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["v0"] == result.v0  # a rerun on this machine: bit for bit


def test_sweep_files_record_the_base_document_specs_and_versions(tmp_path):
    out = tmp_path / "s.h5"
    r = cli(
        "velocity",
        GAITS / "peristalsis-3.yaml",
        "--steps-per-period",
        "60",
        "--integrator",
        "catch-up",
        "--sweep",
        "links.1.phase=0.2,0.4",
        "-o",
        out,
    )
    assert r.exit_code == 0, r.output
    with h5py.File(out) as f:
        a = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    assert yaml.safe_load(a["gait_yaml"])["simulation"]["steps_per_period"] == 60
    assert json.loads(a["sweep_json"]) == [{"path": "links.1.phase", "name": "links_1_phase", "values": [0.2, 0.4]}]
    assert json.loads(a["versions_json"])["numpy"] == metadata.version("numpy")
    assert a["integrator"] == "catch-up"
    assert datetime.fromisoformat(a["created"]).tzinfo is not None
    assert "command_line" in a


def test_python_call_text():
    from crawlsim.io.provenance import command_line, python_call, recording

    assert python_call("f", 1, x="a", y=None) == "f(1, x='a')"
    assert python_call("f", Path("g.yaml")) == "f('g.yaml')"
    with recording("f(1)"):
        assert command_line() == "f(1)"
    assert command_line() != "f(1)"
