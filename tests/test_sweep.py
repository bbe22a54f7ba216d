"""Parameter sweeps: grid specs, validation before work, agreement with single runs, outputs,
resume after an interruption, shards and merge, local worker processes, plots."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from crawlsim import sweep as sweeps
from crawlsim.cli import main
from crawlsim.errors import GaitError
from crawlsim.gait import load_gait, with_simulation

GAITS = Path(__file__).resolve().parents[1] / "gaits"
P4 = str(GAITS / "peristalsis-4.yaml")
FAST = ["--steps-per-period", "40"]
AMP = "links.*.amplitude=0.1:0.3:5"
LAG = "links.1.phase=0.2,0.33,0.4"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def vel(*args):
    return cli("velocity", *args)


def base(steps=40, path=P4):
    return with_simulation(load_gait(path), steps_per_period=steps)


# -- specs and paths ---------------------------------------------------------------------------
def test_axis_specs():
    a = sweeps.parse_axis("links.*.amplitude=0.1:0.3:5")
    assert a.path == "links.*.amplitude" and a.keys == ("links", "*", "amplitude")
    np.testing.assert_allclose(a.values, [0.1, 0.15, 0.2, 0.25, 0.3], rtol=0, atol=1e-15)
    assert a.values[0] == 0.1 and a.values[-1] == 0.3  # inclusive ends, exactly
    assert sweeps.parse_axis("period=1,2.5, 3").values == (1, 2.5, 3)
    assert sweeps.parse_axis("period=2:2:1").values == (2.0,)
    for bad in ("period", "period=", "=1,2", "period=1:2", "period=1:2:x", "period=0:1:0",
                "period=a,b", "period=1,nan", "links..phase=1"):
        with pytest.raises(GaitError):
            sweeps.parse_axis(bad)


def test_paths_expand_and_refuse():
    doc = base().document
    assert sweeps.resolve_path(doc, sweeps.parse_axis("links.*.phase=0"), "g") == [
        ("links", 0, "phase"), ("links", 1, "phase"), ("links", 2, "phase")]
    assert sweeps.resolve_path(doc, sweeps.parse_axis("friction.backward=1"), "g") == [
        ("friction", "backward")]
    messages = {
        "links.3.phase=0": "index 3 is out of range",
        "links.phase=0": "must be an index or '*'",
        "friction.*.backward=1": "'*' needs a list",
        "stiffness.0=1": "has no key 0",
        "links=1": "not a number",
        "gait.period=1": "has no key 'gait'",
    }
    for spec, text in messages.items():
        with pytest.raises(GaitError, match=text):
            sweeps.resolve_path(doc, sweeps.parse_axis(spec), "g")
    with pytest.raises(GaitError, match="sets links.1.phase, which --sweep links.1.phase"):
        sweeps.make_grid(base(), [sweeps.parse_axis("links.1.phase=0"),
                                  sweeps.parse_axis("links.*.phase=0")])


def test_grid_order_is_c_order_and_points_are_edited_documents():
    grid = sweeps.make_grid(base(), [sweeps.parse_axis(AMP), sweeps.parse_axis(LAG)])
    assert grid.shape == (5, 3) and grid.size == 15
    assert grid.values(0) == (0.1, 0.2) and grid.values(1) == (0.1, 0.33)
    assert grid.values(3) == (0.15, 0.2) and grid.values(14) == (0.3, 0.4)
    doc = grid.document(4)
    assert [l["amplitude"] for l in doc["links"]] == [0.15] * 3
    assert [l["phase"] for l in doc["links"]] == [0.0, 0.33, 0.6666666666666666]
    assert grid.base.document["links"][0]["amplitude"] == 0.3  # the base is untouched
    assert list(grid.indices((2, 4))) == [1, 5, 9, 13]
    steps = sweeps.make_grid(base(), [sweeps.parse_axis("simulation.steps_per_period=50,60")])
    assert steps.gait(1).simulation.steps_per_period == 60
    assert isinstance(steps.document(1)["simulation"]["steps_per_period"], int)


@pytest.mark.parametrize("spec, text", [
    ("links.*.amplitud=0.1", "unknown key 'amplitud'; did you mean 'amplitude'"),
    ("friction.backward=0,1", "friction.backward=0: friction.backward: friction must be positive"),
    ("links.9.phase=0", "index 9 is out of range"),
])
def test_invalid_grid_is_refused_before_any_work(tmp_path, spec, text):
    out = tmp_path / "out.csv"
    r = vel(P4, *FAST, "--sweep", "period=1,2", "--sweep", spec, "-o", out)
    assert r.exit_code == 2
    assert text in r.output and "Traceback" not in r.output
    assert list(tmp_path.iterdir()) == []  # no table, no journal


# -- agreement with single runs ----------------------------------------------------------------
def test_sweep_points_equal_single_velocity_runs(tmp_path):
    """Every point of a 5 x 3 sweep (batched) equals `crawlsim velocity` on that point's gait
    file (single run) to 1e-12, with the same convergence and period count."""
    gait = base()
    grid = sweeps.make_grid(gait, [sweeps.parse_axis(AMP), sweeps.parse_axis(LAG)])
    table = sweeps.sweep(gait, [AMP, LAG])
    assert table.counts()["ok"] == 15
    for i in (0, 4, 7, 11, 14):
        path = tmp_path / f"point-{i}.yaml"
        path.write_text(yaml.safe_dump(grid.document(i)))
        single = json.loads(vel(path, "--json").output)
        row = table.rows[i]
        assert row.v0 == pytest.approx(single["v0"], abs=1e-12, rel=0)
        assert row.convergence == single["convergence"] and row.periods == single["periods"]
        assert float(vel(path).output) == pytest.approx(single["v0"], abs=0, rel=0)


def test_velocity_single_run_output_and_exit_codes():
    r = vel(P4, *FAST)
    assert r.exit_code == 0 and len(r.output.splitlines()) == 1
    v0 = float(r.output)
    s = json.loads(vel(P4, *FAST, "--json").output)
    assert s["v0"] == v0 and s["convergence"] in ("finite-time", "asymptotic")
    assert repr(s["v0"]) == r.output.strip()  # full precision
    slow = vel(GAITS / "peristalsis-4.yaml", "--steps-per-period", "40", "--sweep",
               "links.*.amplitude=0.1", "--max-periods", "2")
    assert slow.exit_code == 0 and ",not-converged,2,not-converged," in slow.output
    assert vel(P4, "--steps-per-period", "40", "--max-periods", "1",
               "--tolerance", "1e-15").exit_code == 3


def test_failed_points_are_recorded_not_fatal(tmp_path):
    """A point whose grid hits an instant of a uniqueness violation is refused with its reason
    (status invalid, see tests/test_batch.py); the others run and the exit code is 0."""
    from tests.test_batch import LICQ_GAIT

    path = tmp_path / "licq.yaml"
    path.write_text(LICQ_GAIT)
    r = vel(path, "--sweep", "simulation.steps_per_period=100,101,102", "-o", tmp_path / "t.csv")
    assert r.exit_code == 0
    assert "3 points: 1 invalid, 0 failed, 0 not converged" in r.output
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert rows[0] == ("simulation.steps_per_period,v0,displacement_per_period,convergence,"
                       "periods,status,message")
    assert rows[1].startswith("100,,,,0,invalid,\"the model does not determine the motion at t = 0.25")
    assert ",finite-time,2,ok," in rows[2] and ",finite-time,2,ok," in rows[3]


# -- outputs ------------------------------------------------------------------------------------
def test_csv_and_hdf5_hold_the_same_table(tmp_path):
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", tmp_path / "s.csv").exit_code == 0
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", tmp_path / "s.h5").exit_code == 0
    stdout = vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG).output
    csv_text = (tmp_path / "s.csv").read_text()
    assert stdout == csv_text
    table = sweeps.read_table(tmp_path / "s.h5")
    assert table.to_csv() == csv_text
    with h5py.File(tmp_path / "s.h5") as f:
        assert f.attrs["kind"] == "sweep"
        assert json.loads(f.attrs["paths"]) == ["links.*.amplitude", "links.1.phase"]
        assert yaml.safe_load(f.attrs["gait_yaml"])["simulation"]["steps_per_period"] == 40
        np.testing.assert_array_equal(f["grid/links_1_phase"][()], [0.2, 0.33, 0.4])
        assert f["grid/links_1_phase"].attrs["path"] == "links.1.phase"
        assert len(f["results/v0"]) == 15
        np.testing.assert_array_equal(f["results/links_all_amplitude"][()],
                                      np.repeat([0.1, 0.15, 0.2, 0.25, 0.3], 3))
        np.testing.assert_array_equal(f["grid/v0"][()].ravel(), f["results/v0"][()])
        assert list(f["results/status"].asstr()[()]) == ["ok"] * 15
    data = np.genfromtxt(tmp_path / "s.csv", delimiter=",", names=True, dtype=None,
                         encoding="utf-8")
    np.testing.assert_array_equal(data["v0"], table.columns()["v0"])  # repr round-trips


def test_jobs_give_the_same_table(tmp_path):
    one = sweeps.sweep(base(), [AMP, LAG])
    two = sweeps.sweep(base(), [AMP, LAG], jobs=2)
    assert two.to_csv() == one.to_csv()


def test_shards_merge_into_the_unsharded_file(tmp_path):
    full = tmp_path / "full.h5"
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", full).exit_code == 0
    parts = []
    for i in (1, 2, 3, 4):
        part = tmp_path / f"part-{i}.h5"
        assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "--shard", f"{i}/4",
                   "-o", part).exit_code == 0
        assert len(sweeps.read_table(part).rows) == len(range(i - 1, 15, 4))
        parts.append(part)
    merged = tmp_path / "merged.h5"
    r = cli("merge", *reversed(parts), "-o", merged)
    assert r.exit_code == 0, r.output
    with h5py.File(full) as a, h5py.File(merged) as b:
        assert dict(a.attrs) .keys() == dict(b.attrs).keys()
        for key in set(a.attrs) - {"created", "command_line"}:  # provenance of each command
            assert np.array_equal(a.attrs[key], b.attrs[key]), key
        names = []
        a.visit(names.append)
        other = []
        b.visit(other.append)
        assert names == other
        for name in names:
            if isinstance(a[name], h5py.Dataset):
                assert np.array_equal(a[name][()], b[name][()]), name
    missing = cli("merge", *parts[:3], "-o", tmp_path / "bad.h5")
    assert missing.exit_code == 2 and "missing [4]" in missing.output
    assert not (tmp_path / "bad.h5").exists()
    assert cli("merge", full, "-o", tmp_path / "bad.h5").exit_code == 2
    assert vel(P4, *FAST, "--sweep", AMP, "--shard", "1/2").exit_code == 2
    assert vel(P4, *FAST, "--sweep", AMP, "--shard", "3/2", "-o", tmp_path / "x.h5").exit_code == 2


# -- resume ---------------------------------------------------------------------------------------
def test_interrupted_sweep_resumes_without_recomputing(tmp_path):
    """Stop after the first of two chunks (test hook): the journal keeps its points; the rerun
    simulates only the others and writes the same file as an uninterrupted run."""
    axes = ["links.*.amplitude=0.1:0.3:8", "links.1.phase=0.2:0.45:5"]  # 40 points, 2 chunks
    gait = base()
    reference = sweeps.sweep(gait, axes)
    out = tmp_path / "s.csv"
    grid = sweeps.make_grid(gait, [sweeps.parse_axis(a) for a in axes])
    journal = sweeps.Journal(sweeps.journal_path(out), grid.fingerprint(None))
    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(grid, journal=journal, fail_after=1)
    assert not out.exists()
    kept = journal.load()
    assert 0 < len(kept) < 40
    for index, row in kept.items():
        assert row == reference.rows[index]
    resumed = sweeps.sweep(gait, axes, output=out)
    assert resumed.computed == 40 - len(kept)
    assert out.read_text() == reference.to_csv()
    assert not sweeps.journal_path(out).exists()
    other = sweeps.Journal(sweeps.journal_path(out), "another sweep")
    sweeps.journal_path(out).write_text(json.dumps({"fingerprint": "x"}) + "\n")
    with pytest.raises(GaitError, match="belongs to a different sweep"):
        other.load()


def test_killed_process_resumes(tmp_path):
    """SIGKILL a sweep process once its journal holds finished points; the rerun of the same
    command completes the table, equal to an uninterrupted run's."""
    args = [sys.executable, "-m", "crawlsim", "velocity", P4, "--steps-per-period", "40",
            "--sweep", "links.*.amplitude=0.1:0.3:30", "--sweep", "links.1.phase=0.2:0.45:20"]
    out = tmp_path / "s.h5"
    journal = sweeps.journal_path(out)
    proc = subprocess.Popen(args + ["-o", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while time.time() < deadline and proc.poll() is None:
        if journal.exists() and journal.read_text().count("\n") >= 2:
            break
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not out.exists()
    lines = journal.read_text().count("\n") - 1
    assert 0 < lines < 600
    done = subprocess.run(args + ["-o", str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert not journal.exists()
    fresh = tmp_path / "fresh.h5"
    subprocess.run(args + ["-o", str(fresh)], check=True, capture_output=True)
    assert sweeps.read_table(out).to_csv() == sweeps.read_table(fresh).to_csv()


# -- plot ---------------------------------------------------------------------------------------
def test_plot_one_and_two_paths(tmp_path):
    import matplotlib.image as mpimg

    for axes, name in (([AMP], "one.png"), ([AMP, LAG], "two.png")):
        args = [P4, *FAST] + [x for a in axes for x in ("--sweep", a)] + ["--plot",
                                                                          tmp_path / name]
        assert vel(*args).exit_code == 0
        image = mpimg.imread(tmp_path / name)
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 300
        assert image[..., :3].std() > 0.05  # not blank
    r = vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "--sweep", "period=1,2", "--plot",
            tmp_path / "three.png")
    assert r.exit_code == 2 and "one or two swept paths" in r.output
    assert not (tmp_path / "three.png").exists()
