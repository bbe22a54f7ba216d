"""``crawlsim velocity A.yaml B.yaml ...``: many gait files in one process, a row per file.

Each row is the file's own single run (the same v0, estimate, energy and verdict), a bad file
is a row with its reason, and the table is a sweep whose one dimension is the file: CSV, JSON
lines, HDF5 (`crawlsim.open_sweep`), local workers, and the journal that resumes it."""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

import crawlsim
from crawlsim.cli import main
from crawlsim.study.grid import FileGrid
from crawlsim.study.journal import Journal, journal_path
from crawlsim.study.sweep import run_sweep

GAITS = Path(__file__).resolve().parents[1] / "gaits"
SAME = ("v0", "v0_error_estimate", "displacement_per_period", "dissipation_per_period", "cost_of_transport")


def velocity(*args):
    return CliRunner().invoke(main, ["velocity", *map(str, args)], catch_exceptions=False)


@pytest.fixture
def folder(tmp_path):
    """Four example gaits, one file that is not a gait and one that breaks the model."""
    for name in ("inching-2", "peristalsis-3", "peristalsis-4", "climbing-3"):
        shutil.copy(GAITS / f"{name}.yaml", tmp_path / f"{name}.yaml")
    (tmp_path / "a-notes.yaml").write_text("blocks: 2\nperiod: 1.0\n")
    text = (GAITS / "inching-2.yaml").read_text().replace("stiffness: 10.0", "stiffness: -1.0")
    assert "stiffness: -1.0" in text
    (tmp_path / "b-negative.yaml").write_text(text)
    return tmp_path


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.yaml"))


def test_each_row_is_the_files_own_run_and_bad_files_are_rows(folder):
    done = velocity(*_files(folder))
    assert done.exit_code == 0, done.output
    rows = list(csv.DictReader(io.StringIO(done.stdout)))
    assert [r["gait"] for r in rows] == [str(f) for f in _files(folder)]
    assert list(rows[0])[:2] == ["gait", "v0"]
    for row in rows:
        if Path(row["gait"]).stem in ("a-notes", "b-negative"):
            assert row["status"] == "invalid" and row["v0"] == ""
            assert row["message"].startswith(row["gait"])
            continue
        single = json.loads(velocity(row["gait"], "--json").stdout)
        assert row["status"] == "ok" and row["convergence"] == single["convergence"]
        for key in SAME:  # the same computation: the same bits
            assert float(row[key]) == single[key], (row["gait"], key)
    assert "6 gait files: 4 ok, 2 invalid" in done.stderr


def test_json_lines_and_no_valid_file(folder):
    done = velocity(*_files(folder), "--json")
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert [Path(r["gait"]).name for r in lines] == [f.name for f in _files(folder)]
    assert lines[0]["status"] == "invalid" and lines[0]["v0"] is None
    assert all(isinstance(r["v0"], float) and math.isfinite(r["v0"]) for r in lines[2:])
    bad = velocity(folder / "a-notes.yaml", folder / "b-negative.yaml")
    assert bad.exit_code == 2 and "no gait file is a valid gait: all 2 are refused" in bad.output


def test_hdf5_has_the_file_as_its_dimension(folder, tmp_path):
    out = tmp_path / "all.h5"
    assert velocity(*_files(folder), "-o", out).exit_code == 0
    ds = crawlsim.open_sweep(out)
    files = [str(f) for f in _files(folder)]
    assert [str(g) for g in ds["gait"].values] == files
    table = velocity(*_files(folder)).stdout
    v0 = {r["gait"]: r["v0"] for r in csv.DictReader(io.StringIO(table))}
    for g, value in zip(files, ds["v0"].values):
        assert (math.isnan(value) and v0[g] == "") or value == float(v0[g])
    info = CliRunner().invoke(main, ["info", str(out)])
    assert "v0 of 6 gait files" in info.output and "gait: 6 values" in info.output


def test_workers_and_the_journal_give_the_same_table(folder, tmp_path):
    files = [str(f) for f in _files(folder)]
    alone = velocity(*files).stdout
    assert velocity(*files, "-j", "2").stdout == alone
    # a journal holding two finished files: the rerun computes the four others only
    grid = FileGrid.of(files)
    out = tmp_path / "t.csv"
    first = run_sweep(grid)
    journal = Journal(journal_path(out), grid.fingerprint(None))
    journal.append(list(first.rows[:2]))
    journal.close()
    again = run_sweep(grid, journal=Journal(journal_path(out), grid.fingerprint(None)))
    assert again.computed == len(files) - 2 and again.to_csv() == first.to_csv()
    # an edited file is another sweep: its journal is not read
    before = grid.fingerprint(None)
    Path(files[2]).write_text(Path(files[2]).read_text() + "\n# edited\n")
    assert FileGrid.of(files).fingerprint(None) != before


def test_options_of_one_file_are_refused_with_several(folder):
    for extra in (["--sweep", "period=1,2"], ["--sensitivity", "stiffness"], ["--plot"], ["--rigid"]):
        done = velocity(*_files(folder), *extra)
        assert done.exit_code == 2 and "take one gait file" in done.output
