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
