"""The batch scripts in scripts/ that need no cluster, run on small grids; the SLURM template
is checked for syntax only (it needs sbatch)."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from crawlsim.cli import main

from .conftest import console_env

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"


def _v0(path, *options):
    r = CliRunner().invoke(main, ["velocity", str(path), *options])
    assert r.exit_code == 0, r.output
    return float(r.output)


@pytest.mark.slow  # the script runs crawlsim once per gait, a process each
def test_v0_folder(tmp_path):
    """One row per gait file, each v0 equal to `crawlsim velocity` on that file."""
    folder = tmp_path / "gaits"
    folder.mkdir()
    for name in ("inching-2.yaml", "peristalsis-3.yaml"):
        (folder / name).write_text((ROOT / "gaits" / name).read_text())
    (folder / "broken.yaml").write_text("blocks: 1\n")
    (folder / "triangle.yaml").write_text((ROOT / "gaits" / "paper" / "triangle.yaml").read_text())
    out = tmp_path / "v0.csv"
    done = subprocess.run(
        ["bash", SCRIPTS / "v0-folder.sh", folder, out, "--steps-per-period", "80"],
        check=True,
        capture_output=True,
        text=True,
        env=console_env(),
    )
    rows = list(csv.DictReader(out.open()))
    assert [r["gait"] for r in rows] == ["broken", "inching-2", "peristalsis-3", "triangle"]
    assert rows[0]["status"] == "failed" and rows[0]["v0"] == ""
    # a sweeping process has no velocity: skipped, not failed, and said so
    assert rows[3]["status"] == "skipped" and rows[3]["v0"] == ""
    assert "skipped" in done.stderr and "triangle.yaml" in done.stderr
    for row in rows[1:3]:
        assert row["status"] == "ok"
        # the script runs `crawlsim velocity` on this machine: the same printed digits
        assert float(row["v0"]) == _v0(folder / f"{row['gait']}.yaml", "--steps-per-period", "80")
    assert float(rows[1]["v0"]) == pytest.approx(0.4, abs=1e-12)  # inching closed form


@pytest.mark.slow  # the script runs a sweep in a process
def test_phase_lag_sweep(tmp_path):
    """Signals are periodic in cycles, so a lag of a whole period is the gait with lag 0: v0
    agrees at both ends of the sweep to roundoff. The table has the requested points and the
    plot is written."""
    subprocess.run(
        ["bash", SCRIPTS / "phase-lag-sweep.sh", tmp_path / "lag", "5", "--steps-per-period", "60"],
        check=True,
        capture_output=True,
        env=console_env(),
    )
    rows = list(csv.DictReader((tmp_path / "lag" / "phase-lag.csv").open()))
    assert [float(r["links.1.phase"]) for r in rows] == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert all(r["status"] == "ok" for r in rows)
    assert float(rows[0]["v0"]) == pytest.approx(float(rows[-1]["v0"]), abs=1e-12)
    png = (tmp_path / "lag" / "phase-lag-sweep.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_the_scripts_call_this_environments_crawlsim():
    """Run as ``venv/bin/python -m pytest tests`` without activating the venv, PATH has no
    crawlsim (or another install's): the scripts' subprocesses get this interpreter's first."""
    bare = {**os.environ, "PATH": "/usr/bin:/bin"}
    found = subprocess.run(
        ["bash", "-c", "command -v crawlsim"], env=console_env(bare), capture_output=True, text=True, check=True
    )
    assert Path(found.stdout.strip()).parent == Path(sys.executable).parent


def test_slurm_template_parses():
    subprocess.run(["bash", "-n", SCRIPTS / "slurm-sweep.sh"], check=True)
