"""Parameter sweeps: grid specs (linear, log-spaced, lists, linked paths), bad paths refused
before work, invalid and failed points recorded, agreement with single runs and closed forms,
outputs, the time-based journal and resume after an interruption (Ctrl-C exits 130), shards
and merge, local worker processes, plots."""

import csv
import io
import json
import os
import re
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

from crawlsim.analysis.digits import supported
from crawlsim.cli import main
from crawlsim.errors import GaitError, InputError
from crawlsim.gait.docpaths import resolve_path
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.study import sweep as sweeps
from crawlsim.study.executors import MAX_CHUNK, TASK_SECONDS, Chunker
from crawlsim.study.grid import parse_axis
from crawlsim.study.points import PointResult
from crawlsim.study.table import LATER_COLUMNS, read_table

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
    a = parse_axis("links.*.amplitude=0.1:0.3:5")
    assert a.path == "links.*.amplitude" and a.keys == ("links", "*", "amplitude")
    np.testing.assert_allclose(a.values, [0.1, 0.15, 0.2, 0.25, 0.3], rtol=0, atol=1e-15)
    assert a.values[0] == 0.1 and a.values[-1] == 0.3  # inclusive ends, exactly
    assert parse_axis("period=1,2.5, 3").values == (1, 2.5, 3)
    assert parse_axis("period=[1,2.5, 3]").values == (1, 2.5, 3)
    assert parse_axis("period=[0.5]").values == (0.5,)
    assert parse_axis("period=2:2:1").values == (2.0,)
    for bad in (
        "period",
        "period=",
        "=1,2",
        "period=1:2",
        "period=1:2:x",
        "period=0:1:0",
        "period=a,b",
        "period=1,nan",
        "links..phase=1",
        "period=[1,2",
        "period=[]",
        "period=1,2]",
        "period=log:0:1:3",
        "period=log:-1:1:3",
        "period=log:1:2",
        "period=log:1:2:0",
        "period=log:1:inf:3",
    ):
        with pytest.raises(InputError, match="--sweep"):
            parse_axis(bad)
    with pytest.raises(InputError, match="--link period=1:2"):
        parse_axis("period=1:2", "--link")


def test_evenly_spaced_values_are_the_numbers_asked_for():
    """START:STOP:NUM gives the double nearest each exact value START + k (STOP - START)/(NUM - 1)
    (linspace gave 0.30000000000000004 for 0:1:11), so the CSV, the files' attributes and the
    messages print 0.3."""
    assert parse_axis("links.1.phase=0:1:11").values == tuple(k / 10 for k in range(11))
    assert parse_axis("period=1e-3:2e-3:3").values == (0.001, 0.0015, 0.002)
    assert parse_axis("period=0:1:4").values == (0.0, 1 / 3, 2 / 3, 1.0)
    assert parse_axis("period=3:-1:5").values == (3.0, 2.0, 1.0, 0.0, -1.0)
    gait = with_simulation(load_gait(GAITS / "peristalsis-3.yaml"), integrator="catch-up", steps_per_period=20)
    grid = sweeps.make_grid(gait, ["links.1.phase=0:1:11"])
    assert grid.label(3).endswith("with links.1.phase=0.3")
    r = CliRunner().invoke(
        main,
        [
            "velocity",
            str(GAITS / "peristalsis-3.yaml"),
            "--sweep",
            "links.1.phase=0:1:11",
            "--integrator",
            "catch-up",
            "--steps-per-period",
            "20",
        ],
    )
    assert r.exit_code == 0, r.output
    assert [row.split(",")[0] for row in r.output.splitlines()[1:]] == [str(k / 10) for k in range(11)]


def test_log_spaced_axis_is_geometric_with_exact_ends():
    """log:LO:HI:NUM: consecutive ratios all equal (HI/LO)^(1/(NUM-1)), ends as written."""
    a = parse_axis("stiffness=log:5:50:10")
    v = np.array(a.values)
    assert len(v) == 10 and v[0] == 5 and v[-1] == 50
    np.testing.assert_allclose(v[1:] / v[:-1], 10 ** (1 / 9), rtol=1e-14, atol=0)
    assert parse_axis("period=log:1e-2:1e2:5").values == pytest.approx((0.01, 0.1, 1, 10, 100), rel=1e-15)
    assert parse_axis("period=log:3:3:1").values == (3.0,)


def test_paths_expand_and_refuse():
    doc = base().document
    assert resolve_path(doc, parse_axis("links.*.phase=0"), "g") == [
        ("links", 0, "phase"),
        ("links", 1, "phase"),
        ("links", 2, "phase"),
    ]
    assert resolve_path(doc, parse_axis("friction.backward=1"), "g") == [("friction", "backward")]
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
            resolve_path(doc, parse_axis(spec), "g")
    with pytest.raises(GaitError, match="sets links.1.phase, which --sweep links.1.phase"):
        sweeps.make_grid(base(), [parse_axis("links.1.phase=0"), parse_axis("links.*.phase=0")])


def test_grid_order_is_c_order_and_points_are_edited_documents():
    grid = sweeps.make_grid(base(), [parse_axis(AMP), parse_axis(LAG)])
    assert grid.shape == (5, 3) and grid.size == 15
    assert grid.values(0) == (0.1, 0.2) and grid.values(1) == (0.1, 0.33)
    assert grid.values(3) == (0.15, 0.2) and grid.values(14) == (0.3, 0.4)
    doc = grid.document(4)
    assert [l["amplitude"] for l in doc["links"]] == [0.15] * 3
    assert [l["phase"] for l in doc["links"]] == [0.0, 0.33, 0.6666666666666666]
    assert grid.base.document["links"][0]["amplitude"] == 0.3  # the base is untouched
    assert list(grid.indices((2, 4))) == [1, 5, 9, 13]
    steps = sweeps.make_grid(base(), [parse_axis("simulation.steps_per_period=50,60")])
    assert steps.gait(1).simulation.steps_per_period == 60
    assert isinstance(steps.document(1)["simulation"]["steps_per_period"], int)


def test_linked_paths_vary_together():
    """A linked group is one grid dimension: value k of every path goes with index k."""
    grid = sweeps.make_grid(base(), [("links.0.phase=0:0.5:3", "links.1.phase=[0.3,0.6,0.9]"), "period=1,2"])
    assert grid.shape == (3, 2) and grid.size == 6 and grid.dims == (0, 0, 1)
    assert grid.values(0) == (0.0, 0.3, 1) and grid.values(5) == (0.5, 0.9, 2)
    doc = grid.document(3)  # dimension indices (1, 1)
    assert [l["phase"] for l in doc["links"]][:2] == [0.25, 0.6] and doc["period"] == 2
    with pytest.raises(
        InputError,
        match="--link links.1.phase: links.1.phase: has 2 values, but the path it is linked to .links.0.phase. has 3",
    ):
        sweeps.make_grid(base(), [("links.0.phase=0:0.5:3", "links.1.phase=0,1")])
    with pytest.raises(GaitError, match="which --link links.*.phase sets too"):
        sweeps.make_grid(base(), [("period=1,2", "links.*.phase=0,1"), "links.1.phase=0"])
    assert grid.fingerprint(None) != sweeps.make_grid(
        base(), ["links.0.phase=0:0.5:3", "links.1.phase=[0.3,0.6,0.9]", "period=1,2"]
    ).fingerprint(None)


def test_linked_phase_shift_is_a_time_shift():
    """Shifting the phase of every link by the same s is the same gait started s periods later:
    with constant friction, v0 does not depend on the initial state (the paper's Theorem), and
    a shift by whole steps of the grid (s = 10/40) moves the grid with it, so v0 agrees to
    roundoff along the linked axis. Unlinked, the same two paths make a 3 x 3 grid whose
    off-diagonal points are other gaits."""
    p3 = GAITS / "peristalsis-3.yaml"
    linked = vel(
        p3,
        *FAST,
        "--sweep",
        "links.0.phase=0:0.5:3",
        "--link",
        "links.1.phase=[0.3333333333333333,0.5833333333333333,0.8333333333333333]",
    )
    assert linked.exit_code == 0, linked.output
    rows = list(csv.DictReader(io.StringIO(linked.output)))
    assert [float(r["links.0.phase"]) for r in rows] == [0.0, 0.25, 0.5]
    v0 = [float(r["v0"]) for r in rows]
    assert max(v0) - min(v0) <= 1e-12 and abs(v0[0]) > 0.01
    crossed = vel(
        p3,
        *FAST,
        "--sweep",
        "links.0.phase=0:0.5:3",
        "--sweep",
        "links.1.phase=[0.3333333333333333,0.5833333333333333,0.8333333333333333]",
    )
    cells = list(csv.DictReader(io.StringIO(crossed.output)))
    assert len(cells) == 9 and abs(float(cells[1]["v0"]) - v0[0]) > 1e-6
    first = vel(p3, *FAST, "--link", "links.1.phase=0,1", "--sweep", "links.0.phase=0,1")
    assert first.exit_code == 2 and "give a --sweep PATH=SPEC first" in first.output


@pytest.mark.parametrize(
    "spec, text",
    [
        ("links.*.amplitud=0.1", "unknown key 'amplitud'; did you mean 'amplitude'"),
        ("links.9.phase=0", "index 9 is out of range"),
        ("friction.backward=0,-1", "no point of the grid is a valid gait: all 4 are refused"),
    ],
)
def test_bad_paths_and_grids_without_a_valid_point_are_refused_before_any_work(tmp_path, spec, text):
    out = tmp_path / "out.csv"
    r = vel(P4, *FAST, "--sweep", "period=1,2", "--sweep", spec, "-o", out)
    assert r.exit_code == 2
    assert text in r.output and "Traceback" not in r.output
    assert list(tmp_path.iterdir()) == []  # no table, no journal


INCHING_FAST = """\
name: inching-fast
blocks: 2
period: 1.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3}
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 20, max_periods: 20}
"""


def inching_v0(backward, k, amplitude=0.3, period=1.0):
    """v0 of the two-block inching gait, L = 1 + A cos(2 pi t / T), forward friction 1.

    The stress sigma = k (L - z) moves the front block forward at sigma = mu^+ = 1 and the rear
    block at sigma = -1; backward at sigma = -b (front) and b (rear). With b > 1 only forward
    slips happen: each period the link extends by 2A against the front block and contracts by
    2A against the rear one, less the elastic play 2 mu^+ / k each way, so the displacement is
    2A - 2/k (tests/test_closed_forms.py). With b < 1 only backward slips happen, and by the
    mirror x -> -x (which swaps mu^+ and mu^-) the displacement is -(2A - 2b/k). The grid has
    the extremes of L (t = 0, T/2 with an even number of steps), so this holds on the grid.
    """
    sign, mu = (1, 1.0) if backward > 1 else (-1, backward)
    return sign * (2 * amplitude - 2 * mu / k) / period


def test_300_point_sweep_with_10_invalid_points(tmp_path):
    """30 backward frictions (one of them 1.0 = the forward friction: the uniqueness condition
    fails) x 10 log-spaced stiffnesses: the 10 points of friction 1.0 are recorded as invalid
    with the reason, the 290 others run, and each v0 is the closed form (`inching_v0`)."""
    gait = tmp_path / "inching.yaml"
    gait.write_text(INCHING_FAST)
    backward = [round(0.5 + 0.1 * i, 10) for i in range(30)]  # 0.5 .. 3.4, with 1.0
    assert backward.count(1.0) == 1
    out = tmp_path / "s.h5"
    r = vel(
        gait,
        "--sweep",
        f"friction.backward=[{','.join(map(str, backward))}]",
        "--sweep",
        "stiffness=log:5:50:10",
        "-o",
        out,
    )
    assert r.exit_code == 0, r.output
    assert "300 points: 290 ok, 10 invalid, 0 failed, 0 not converged" in r.output
    table = read_table(out)
    counts = table.counts()
    assert counts["ok"] == 290 and counts["invalid"] == 10 and len(table.rows) == 300
    b, k = table.coordinates()
    for bi, ki, row in zip(b, k, table.rows):
        if bi == 1.0:
            assert row.status == "invalid" and row.v0 is None
            assert "uniqueness" in row.message and "friction.backward=1.0, " in row.message
        else:
            assert row.status == "ok" and row.integrator == "exact" and row.limit == "iterate"
            assert row.v0 == pytest.approx(inching_v0(bi, ki), abs=1e-12)
            assert row.v0_error_estimate is not None and row.v0_error_estimate < 1e-12
            assert row.convergence == "finite-time"
    assert not sweeps.journal_path(out).exists()


# -- agreement with single runs ----------------------------------------------------------------
def test_sweep_points_equal_single_velocity_runs(tmp_path):
    """Every point of a 5 x 3 sweep (batched) equals `crawlsim velocity` on that point's gait
    file (single run) to 1e-12, with the same convergence and period count."""
    gait = base()
    grid = sweeps.make_grid(gait, [parse_axis(AMP), parse_axis(LAG)])
    table = sweeps.sweep(gait, [AMP, LAG])
    assert table.counts()["ok"] == 15
    for i in (0, 4, 7, 11, 14):
        path = tmp_path / f"point-{i}.yaml"
        path.write_text(yaml.safe_dump(grid.document(i)))
        single = json.loads(vel(path, "--json").output)
        row = table.rows[i]
        assert row.v0 == pytest.approx(single["v0"], abs=1e-12, rel=0)
        assert row.convergence == single["convergence"]
        assert row.periods == single["periods"] + single["limit_periods"]
        assert row.limit == single["limit_method"]
        assert abs(float(vel(path).output) - single["v0"]) <= single["v0_error_estimate"]


def test_velocity_single_run_output_and_exit_codes():
    r = vel(P4, *FAST)
    assert r.exit_code == 0 and len(r.output.splitlines()) == 1
    v0 = float(r.output)
    s = json.loads(vel(P4, *FAST, "--json").output)
    assert s["convergence"] in ("finite-time", "asymptotic")
    # the digits its error estimate supports (the printed v0 is the JSON's rounded to them, so
    # not equal to it bit for bit); --json has the full precision
    assert r.output.strip() == supported(s["v0"], s["v0_error_estimate"])[0]
    assert abs(v0 - s["v0"]) <= s["v0_error_estimate"]
    slow = vel(
        GAITS / "peristalsis-4.yaml",
        "--steps-per-period",
        "40",
        "--sweep",
        "links.*.amplitude=0.1",
        "--max-periods",
        "2",
    )
    assert slow.exit_code == 0 and ",not-converged,2,exact,iterate,0,not-converged," in slow.output
    assert vel(P4, "--steps-per-period", "40", "--max-periods", "1", "--tolerance", "1e-15").exit_code == 3
    dash = vel(P4, *FAST, "-o", "-")  # stdout, as without -o
    assert dash.exit_code == 0 and dash.stdout == r.stdout


@pytest.mark.parametrize("extra", [[], ["--json"], ["--sweep", "period=1,2"], ["--sweep", "period=1,2", "-o", "OUT"]])
def test_velocity_of_a_sweeping_process_is_refused(tmp_path, extra):
    """A sweeping process (kind: sweeping-process) has no velocity: exit code 2, one line naming
    the file and pointing to `crawlsim run`, no traceback, no file written, with or without a
    sweep."""
    triangle = GAITS / "paper" / "triangle.yaml"
    out = tmp_path / "t.csv"
    r = CliRunner().invoke(main, ["velocity", str(triangle), *[str(out) if a == "OUT" else a for a in extra]])
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output and len(r.output.strip().splitlines()) == 1
    assert str(triangle) in r.output and "no velocity" in r.output
    assert f"crawlsim run {triangle}" in r.output
    assert not out.exists() and not sweeps.journal_path(out).exists()


def test_failed_points_are_recorded_not_fatal(tmp_path):
    """A point whose grid hits an instant of a uniqueness violation is refused with its reason
    (status invalid, see tests/test_points.py); the others run and the exit code is 0."""
    from tests.test_points import LICQ_GAIT

    path = tmp_path / "licq.yaml"
    path.write_text(LICQ_GAIT)
    r = vel(
        path, "--integrator", "catch-up", "--sweep", "simulation.steps_per_period=100,101,102", "-o", tmp_path / "t.csv"
    )
    assert r.exit_code == 0
    assert "3 points: 2 ok, 1 invalid, 0 failed, 0 not converged" in r.output
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert rows[0] == (
        "simulation.steps_per_period,v0,v0_error_estimate,displacement_per_period,"
        "dissipation_per_period,cost_of_transport,convergence,periods,integrator,"
        "limit,newton_steps,status,message"
    )
    assert rows[1].startswith('100,,,,,,,0,catch-up,,,invalid,"the model does not determine the motion at t = 0.25')
    for row in rows[2:]:  # no time-step error measured in a catch-up sweep: no estimate
        fields = row.split(",")
        assert fields[2] == "" and ",finite-time,2,catch-up,iterate,0,ok," in row


def test_a_point_that_raises_does_not_sink_its_neighbours(monkeypatch):
    """A point whose run raises is recorded as failed (an unexpected exception, named) and its
    neighbours keep their values."""
    import crawlsim.study.points as points

    gait = with_simulation(base(), integrator="catch-up")
    reference = sweeps.sweep(gait, [AMP])
    original = points.settle

    def flaky(process, **options):
        if abs(process.crawler.lengths[0, 0] - (1 + 0.2)) < 1e-12:
            raise FloatingPointError("boom")
        return original(process, **options)

    monkeypatch.setattr(points, "settle", flaky)
    table = sweeps.sweep(gait, [AMP])
    assert [r.status for r in table.rows] == ["ok", "ok", "failed", "ok", "ok"]
    assert table.rows[2].message == "FloatingPointError: boom"
    for i in (0, 1, 3, 4):
        assert table.rows[i].v0 == reference.rows[i].v0


def test_more_columns_agree_with_single_runs():
    """dissipation_per_period, cost_of_transport, v0_error_estimate and the integrator of each
    point equal those of a single run of its gait (`crawlsim.api.run`), for either
    integrator."""
    from crawlsim import api

    for integrator in ("catch-up", "exact"):
        gait = with_simulation(load_gait(P4), steps_per_period=40, integrator=integrator)
        table = sweeps.sweep(gait, ["links.*.amplitude=0.2,0.3"])
        grid = sweeps.make_grid(gait, ["links.*.amplitude=0.2,0.3"])
        for i, row in enumerate(table.rows):
            single = api.run(grid.gait(i))
            assert row.integrator == integrator == single.integrator
            if integrator == "catch-up":  # the time-step error is not measured in sweeps
                assert row.v0_error_estimate is None and single.estimate.time_step is not None
            names = ("dissipation_per_period", "cost_of_transport") + (
                ("v0_error_estimate",) if integrator == "exact" else ()
            )
            for name in names:
                assert getattr(row, name) == pytest.approx(single.summary()[name], rel=1e-9, abs=1e-15), name
            assert row.dissipation_per_period > 0


# -- outputs ------------------------------------------------------------------------------------
def test_csv_and_hdf5_hold_the_same_table(tmp_path):
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", tmp_path / "s.csv").exit_code == 0
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", tmp_path / "s.h5").exit_code == 0
    stdout = vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG).stdout
    dash = vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", "-").stdout
    csv_text = (tmp_path / "s.csv").read_text()
    assert stdout == csv_text == dash
    assert not (tmp_path / "-").exists() and not Path("-").exists()
    table = read_table(tmp_path / "s.h5")
    assert table.to_csv() == csv_text
    with h5py.File(tmp_path / "s.h5") as f:
        assert f.attrs["kind"] == "sweep"
        assert f.attrs["integrator"] == "exact"  # what the rows ran, the gait's default
        assert json.loads(f.attrs["paths"]) == ["links.*.amplitude", "links.1.phase"]
        assert json.loads(f.attrs["dimensions"]) == [0, 1]
        assert yaml.safe_load(f.attrs["gait_yaml"])["simulation"]["steps_per_period"] == 40
        np.testing.assert_array_equal(f["grid/links_1_phase"][()], [0.2, 0.33, 0.4])
        assert f["grid/links_1_phase"].attrs["path"] == "links.1.phase"
        assert len(f["results/v0"]) == 15
        np.testing.assert_array_equal(f["results/links_all_amplitude"][()], np.repeat([0.1, 0.15, 0.2, 0.25, 0.3], 3))
        np.testing.assert_array_equal(f["grid/v0"][()].ravel(), f["results/v0"][()])
        assert list(f["results/status"].asstr()[()]) == ["ok"] * 15
        assert list(f["results/integrator"].asstr()[()]) == ["exact"] * 15
        for name in ("dissipation_per_period", "cost_of_transport", "v0_error_estimate"):
            assert np.all(np.isfinite(f[f"results/{name}"][()])), name
    data = np.genfromtxt(tmp_path / "s.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    np.testing.assert_array_equal(data["v0"], table.columns()["v0"])  # repr round-trips
    np.testing.assert_array_equal(data["cost_of_transport"], table.columns()["cost_of_transport"])


def test_linked_sweep_round_trips_through_hdf5_and_merge(tmp_path):
    args = [
        P4,
        *FAST,
        "--sweep",
        "links.1.phase=0.2:0.4:4",
        "--link",
        "links.2.phase=0.5:0.7:4",
        "--sweep",
        "period=1,2",
    ]
    assert vel(*args, "-o", tmp_path / "full.h5").exit_code == 0
    full = read_table(tmp_path / "full.h5")
    assert full.dimensions == (0, 0, 1) and full.shape == (4, 2) and len(full.rows) == 8
    assert full.dimension_paths() == [["links.1.phase", "links.2.phase"], ["period"]]
    phase1, phase2, period = full.coordinates()
    np.testing.assert_allclose(phase2 - phase1, 0.3, atol=1e-15)  # linked: always 0.3 apart
    for i in (1, 2):
        assert vel(*args, "--shard", f"{i}/2", "-o", tmp_path / f"p{i}.h5").exit_code == 0
    merged = cli("merge", tmp_path / "p1.h5", tmp_path / "p2.h5", "-o", "-")
    assert merged.exit_code == 0 and merged.stdout == full.to_csv()


def test_older_sweep_files_are_read(tmp_path):
    """A sweep file of crawlsim 0.1 (no dimensions attribute, no v0_error_estimate,
    dissipation_per_period, cost_of_transport or integrator) reads with those missing."""
    out = tmp_path / "old.h5"
    assert vel(P4, *FAST, "--sweep", AMP, "-o", out).exit_code == 0
    new = read_table(out)
    with h5py.File(out, "a") as f:
        del f.attrs["dimensions"]
        for name in LATER_COLUMNS:
            del f[f"results/{name}"]
    old = read_table(out)
    assert old.dimensions == (0,) and [r.v0 for r in old.rows] == [r.v0 for r in new.rows]
    assert all(r.integrator == "" and r.dissipation_per_period is None for r in old.rows)
    header, first = old.to_csv().splitlines()[:2]
    fields = dict(zip(header.split(","), first.split(",")))
    assert fields["status"] == "ok" and fields["v0"] == repr(new.rows[0].v0)
    for name in LATER_COLUMNS:
        assert fields[name] == "", name


@pytest.fixture
def workers_always(monkeypatch):
    """Local workers start whatever the measured cost and the load of the machine (a small
    sweep would run here), after the two tasks of MIN_CHUNK points that run here first."""
    from crawlsim.study import executors

    monkeypatch.setattr(executors, "worth_workers", lambda seconds, jobs, warm_up=0.0: jobs > 1)
    monkeypatch.setattr(executors, "free_cores", lambda jobs: jobs)
    monkeypatch.setattr(executors, "TASK_SECONDS", 1e-9)  # every task MIN_CHUNK points


@pytest.mark.parametrize("integrator", ["exact", "catch-up"])
def test_jobs_give_the_same_table(integrator, workers_always):
    """The rows on two workers are those of one process, bit for bit (the same arithmetic)."""
    gait = with_simulation(base(), integrator=integrator)
    axes = [AMP, "links.1.phase=0.2,0.33,0.4,0.5,0.6"]
    one = sweeps.sweep(gait, axes)
    two = sweeps.sweep(gait, axes, jobs=2)
    assert two.to_csv() == one.to_csv()
    assert [r.v0 for r in two.rows] == [r.v0 for r in one.rows] and len(one.rows) == 25


def test_workers_start_only_when_they_pay():
    """Two workers on 2 cores halve the serial time at best, after their start-up: they start
    only when that saves at least POOL_MIN_GAIN of the serial time; one job never starts any."""
    from crawlsim.study import executors

    start, gain = executors.POOL_START_SECONDS, executors.POOL_MIN_GAIN
    # break-even: start + t / 2 = (1 - gain) t  <=>  t = start / (1/2 - gain)
    even = start / (0.5 - gain)
    assert not executors.worth_workers(0.9 * even, 2)
    assert executors.worth_workers(1.1 * even, 2)
    assert not executors.worth_workers(1e6, 1)
    assert executors.worth_workers(1.1 * start / (0.75 - gain), 4)
    # each worker pays the warm-up the first task here paid beyond its points
    assert not executors.worth_workers(1.1 * even, 2, warm_up=1.0)
    assert executors.worth_workers(1.1 * (start + 1.0) / (0.5 - gain), 2, warm_up=1.0)
    assert 1 <= executors.free_cores(8) <= (os.cpu_count() or 1)
    assert executors.free_cores(1) == 1


def test_a_small_sweep_runs_here_with_jobs(monkeypatch):
    """A sweep whose measured cost does not pay for the workers' start-up starts no pool, and
    gives the same rows."""
    from crawlsim.study import executors

    started = []
    monkeypatch.setattr(executors, "WorkerPool", lambda jobs: started.append(jobs))
    one = sweeps.sweep(base(), [LAG])
    two = sweeps.sweep(base(), [LAG], jobs=2)
    assert started == [] and two.to_csv() == one.to_csv()


def test_velocity_builds_the_grid_once(monkeypatch):
    """`crawlsim velocity --sweep` makes one grid (checks, memory estimate and the sweep share
    it) and `crawlsim.study.sweep.sweep` takes it as it is."""
    from crawlsim.study import grid as grids

    made = []
    post_init = grids.SweepGrid.__post_init__

    def spy(self):
        made.append(self)
        post_init(self)

    monkeypatch.setattr(grids.SweepGrid, "__post_init__", spy)
    r = vel(P4, *FAST, "--sweep", LAG, "--sweep", "links.2.phase=0,0.5")
    assert r.exit_code == 0, r.output
    assert len(made) == 1 and made[0].shape == (3, 2)
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert len(rows) == 6 and all(row["status"] == "ok" for row in rows)


def test_sweep_takes_a_grid_or_a_gait_and_axes():
    grid = sweeps.make_grid(base(), [LAG])
    by_grid = sweeps.sweep(grid)
    by_axes = sweeps.sweep(base(), [LAG])
    assert by_grid.to_csv() == by_axes.to_csv()
    with pytest.raises(TypeError, match="has its axes"):
        sweeps.sweep(grid, [LAG])


def test_extra_columns_of_a_grid():
    """A `PointQuantity` adds a column to every row that runs, to the CSV and to the journal:
    here the displacement per period again, as v0 T (T = 1 for this gait)."""

    class Displacement:
        name = "v0_times_period"

        def __call__(self, gait, row):
            return row.v0 * gait.period

    grid = sweeps.make_grid(base(), ["friction.backward=[0,2,2.5]"], quantities=[Displacement()])
    table = sweeps.sweep(grid)
    cols = table.columns()
    ok = cols["status"] == "ok"
    assert list(ok) == [False, True, True]
    np.testing.assert_allclose(cols["v0_times_period"][ok], cols["displacement_per_period"][ok], rtol=1e-12, atol=0)
    assert np.isnan(cols["v0_times_period"][0])
    assert table.to_csv().splitlines()[0].endswith(",message,v0_times_period")
    row = table.rows[1]
    assert PointResult.from_json(row.to_json()) == row
    assert "extra" not in sweeps.sweep(base(), [LAG]).rows[0].to_json()  # journals unchanged
    assert grid.fingerprint(None) != sweeps.make_grid(base(), ["friction.backward=[0,2,2.5]"]).fingerprint(None)


def test_workers_report_every_point(tmp_path, workers_always):
    """With --jobs 2 the progress moves point by point (each worker reports a finished point at
    once), including invalid points, and adds up to the grid."""
    calls = []
    table = sweeps.sweep(base(), ["friction.backward=[0,2,2.5,3.5]", AMP], jobs=2, progress=calls.append)
    assert sum(calls) == 20 and max(calls) <= sweeps.MIN_CHUNK and len(calls) >= 8
    assert table.counts() == {"ok": 15, "not-converged": 0, "invalid": 5, "failed": 0}


def test_chunks_grow_with_the_measured_rate_and_shrink_at_the_end():
    """Tasks start at MIN_CHUNK points (progress and the journal move at once), then take about
    TASK_SECONDS at the measured rate (capped at MAX_CHUNK); the last ones split what is left
    among the workers."""
    chunker = Chunker(np.arange(1000), workers=2)
    sizes = [len(chunker.take())]
    assert sizes == [sweeps.MIN_CHUNK]
    chunker.record(8, 8 / 20.0)  # 20 points per second
    sizes.append(len(chunker.take()))
    assert sizes[-1] == round(20 * TASK_SECONDS)
    chunker.record(1000, 0.1)  # very fast now: capped
    sizes.append(len(chunker.take()))
    assert sizes[-1] == MAX_CHUNK
    while (chunk := chunker.take()) is not None:
        left = 1000 - sum(sizes)
        assert len(chunk) == min(max(sweeps.MIN_CHUNK, min(MAX_CHUNK, -(-left // 2))), left)
        sizes.append(len(chunk))
    assert sum(sizes) == 1000 and sizes[-1] <= sweeps.MIN_CHUNK


def test_shards_merge_into_the_unsharded_file(tmp_path):
    full = tmp_path / "full.h5"
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", full).exit_code == 0
    parts = []
    for i in (1, 2, 3, 4):
        part = tmp_path / f"part-{i}.h5"
        assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "--shard", f"{i}/4", "-o", part).exit_code == 0
        assert len(read_table(part).rows) == len(range(i - 1, 15, 4))
        parts.append(part)
    merged = tmp_path / "merged.h5"
    r = cli("merge", *reversed(parts), "-o", merged)
    assert r.exit_code == 0, r.output
    with h5py.File(full) as a, h5py.File(merged) as b:
        assert a.attrs["integrator"] == b.attrs["integrator"] == "exact"
        assert dict(a.attrs).keys() == dict(b.attrs).keys()
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
    csv_merge = cli("merge", *parts, "-o", tmp_path / "merged.csv")
    assert csv_merge.exit_code == 0
    assert (tmp_path / "merged.csv").read_text() == read_table(full).to_csv()
    missing = cli("merge", *parts[:3], "-o", tmp_path / "bad.h5")
    assert missing.exit_code == 2 and "missing [4]" in missing.output
    assert not (tmp_path / "bad.h5").exists()
    assert cli("merge", full, "-o", tmp_path / "bad.h5").exit_code == 2
    assert cli("merge", *parts, "-o", tmp_path / "bad.txt").exit_code == 2
    assert vel(P4, *FAST, "--sweep", AMP, "--shard", "1/2").exit_code == 2
    assert vel(P4, *FAST, "--sweep", AMP, "--shard", "3/2", "-o", tmp_path / "x.h5").exit_code == 2


# -- the journal and resume -----------------------------------------------------------------------
def test_journal_flushes_on_a_clock_not_per_chunk(tmp_path):
    """The first rows reach the file at once; later ones (flushed and fsynced) only once the
    interval has passed since the last flush, and at close; a reader sees every flushed row."""
    now = [0.0]
    journal = sweeps.Journal(tmp_path / "j", "fp", interval=3.0, clock=lambda: now[0])
    rows = [PointResult(i, "ok", v0=0.1 * i, periods=2) for i in range(5)]
    assert not journal.path.exists()
    journal.append(rows[:1])
    assert sorted(journal.load()) == [0]
    journal.append(rows[1:2])
    now[0] = 2.9
    journal.append(rows[2:3])
    assert sorted(journal.load()) == [0]
    now[0] = 3.0
    journal.append(rows[3:4])
    assert sorted(journal.load()) == [0, 1, 2, 3]
    now[0] = 4.0
    journal.append(rows[4:])
    assert sorted(journal.load()) == [0, 1, 2, 3]
    journal.close()
    assert journal.load() == {r.index: r for r in rows}
    # a torn last line (a kill mid-write) is skipped; a journal of an older crawlsim (rows
    # without the later columns) is read with them missing
    with open(journal.path, "a") as f:
        f.write(
            json.dumps(
                {
                    "index": 7,
                    "v0": 1.0,
                    "displacement_per_period": 1.0,
                    "convergence": "finite-time",
                    "periods": 2,
                    "status": "ok",
                    "message": "",
                    "steps": 80,
                }
            )
            + "\n"
            + '{"index": 9, "v0"'
        )
    loaded = journal.load()
    assert sorted(loaded) == [0, 1, 2, 3, 4, 7] and loaded[7].integrator == ""


def test_interrupted_sweep_resumes_without_recomputing(tmp_path):
    """Interrupt (KeyboardInterrupt from inside the stepping, as Ctrl-C) after 20 points: the
    journal keeps every point whose batch finished, equal to an uninterrupted run's rows; the
    rerun simulates only the others and writes the same file."""
    axes = ["links.*.amplitude=0.1:0.3:8", "links.1.phase=0.2:0.45:5"]  # 40 points
    gait = base()
    reference = sweeps.sweep(gait, axes)
    out = tmp_path / "s.csv"
    count = [0]

    def interrupt(k):
        count[0] += k
        if count[0] >= 20:
            raise KeyboardInterrupt

    with pytest.raises(sweeps.SweepInterrupted) as stopped:
        sweeps.sweep(gait, axes, output=out, progress=interrupt)
    assert not out.exists()
    kept = sweeps.Journal(sweeps.journal_path(out), "").path.read_text().count("\n") - 1
    grid = sweeps.make_grid(gait, axes)
    rows = sweeps.Journal(sweeps.journal_path(out), grid.fingerprint(None)).load()
    assert stopped.value.done == len(rows) == kept and 0 < kept < 20
    assert stopped.value.total == 40 and stopped.value.journal == sweeps.journal_path(out)
    for index, row in rows.items():
        assert row == reference.rows[index]
    resumed_rows = []
    resumed = sweeps.sweep(gait, axes, output=out, on_rows=lambda r, resumed: resumed and resumed_rows.extend(r))
    assert resumed.computed == 40 - kept and len(resumed_rows) == kept
    assert out.read_text() == reference.to_csv()
    assert not sweeps.journal_path(out).exists()
    other = sweeps.Journal(sweeps.journal_path(out), "another sweep")
    sweeps.journal_path(out).write_text(json.dumps({"fingerprint": "x"}) + "\n")
    with pytest.raises(GaitError, match="belongs to a different sweep"):
        other.load()


# catch-up: the batched stepper makes 400 points quick (these tests are about interrupts)
SWEEP_ARGS = [
    sys.executable,
    "-m",
    "crawlsim",
    "velocity",
    P4,
    "--steps-per-period",
    "40",
    "--integrator",
    "catch-up",
    "--sweep",
    "links.*.amplitude=0.1:0.3:20",
    "--sweep",
    "links.1.phase=0.2:0.45:20",
]


def _start(out, *extra):
    """A sweep process whose progress lines (stderr is a pipe: log mode) come every 0.05 s."""
    env = {**os.environ, "CRAWLSIM_PROGRESS_INTERVAL": "0.05"}
    return subprocess.Popen(
        SWEEP_ARGS + ["-o", str(out), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )


def _wait_for_points(proc, at_least):
    """Read progress lines until one reports ``at_least`` points done; the lines read."""
    lines = []
    for line in proc.stderr:
        lines.append(line)
        m = re.match(r"velocity: (\d+)/400 points", line)
        if m and int(m.group(1)) >= at_least:
            return lines
    raise AssertionError(f"the sweep ended before {at_least} points: {lines}")


@pytest.mark.slow  # sweeps in subprocesses, signalled and run again
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_exits_130_and_the_rerun_resumes(tmp_path, sig, code):
    """Ctrl-C (SIGINT) exits 130 and SIGTERM (a batch system's stop) 143; either way every
    finished point is in the journal, the message says how many, and the rerun of the same
    command reads them back (--verbose says so), computes the rest and writes the table a
    fresh run writes."""
    out = tmp_path / "s.h5"
    journal = sweeps.journal_path(out)
    proc = _start(out)
    seen = _wait_for_points(proc, 16)
    proc.send_signal(sig)
    rest = proc.stderr.read()
    assert proc.wait(30) == code, seen + [rest]
    m = re.search(
        r"Interrupted: (\d+) of 400 points finished, kept in (\S+); run the same "
        r"command again to resume",
        rest,
    )
    assert m, rest
    assert "Traceback" not in rest and not out.exists()
    kept = int(m.group(1))
    # progress counts points as they finish inside a batch; a batch's rows are kept when it
    # ends, so at least the first batch (MIN_CHUNK points) is in the journal
    assert sweeps.MIN_CHUNK <= kept < 400 and m.group(2) == f"{journal}"
    assert journal.read_text().count("\n") - 1 == kept
    if sig != signal.SIGINT:
        return
    again = _start(out, "--verbose")
    stdout, stderr = again.communicate(timeout=120)
    assert again.returncode == 0, stderr
    assert f"resuming: {kept} of 400 points read from {journal}" in stderr
    assert not journal.exists()
    fresh = sweeps.sweep(with_simulation(base(), integrator="catch-up"), [SWEEP_ARGS[-3], SWEEP_ARGS[-1]])
    table = read_table(out)
    assert [r.status for r in table.rows] == [r.status for r in fresh.rows]
    np.testing.assert_allclose(table.columns()["v0"], fresh.columns()["v0"], rtol=0, atol=1e-12)


@pytest.mark.slow  # a sweep in a subprocess, killed and run again
def test_killed_process_resumes(tmp_path):
    """SIGKILL a sweep process once its journal holds finished points; the rerun of the same
    command completes the table, equal to an uninterrupted run's."""
    args = [
        sys.executable,
        "-m",
        "crawlsim",
        "velocity",
        P4,
        "--steps-per-period",
        "40",
        "--integrator",
        "catch-up",
        "--sweep",
        "links.*.amplitude=0.1:0.3:30",
        "--sweep",
        "links.1.phase=0.2:0.45:20",
    ]
    out = tmp_path / "s.h5"
    journal = sweeps.journal_path(out)
    proc = subprocess.Popen(args + ["-o", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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
    assert read_table(out).to_csv() == read_table(fresh).to_csv()


# -- plot ---------------------------------------------------------------------------------------
def test_plot_one_and_two_paths(tmp_path):
    import matplotlib.image as mpimg

    for axes, name in (([AMP], "one"), ([AMP, LAG], "two")):
        args = [P4, *FAST] + [x for a in axes for x in ("--sweep", a)] + ["-o", tmp_path / f"{name}.h5", "--plot"]
        r = vel(*args)
        assert r.exit_code == 0 and r.output == f"{tmp_path / name}-sweep.png\n"
        image = mpimg.imread(tmp_path / f"{name}-sweep.png")
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 300
        assert image[..., :3].std() > 0.05  # not blank
    three = ["--sweep", AMP, "--sweep", LAG, "--sweep", "period=1,2", "-o", tmp_path / "three.h5", "--plot"]
    r = vel(P4, *FAST, *three)
    assert r.exit_code == 2 and "one or two swept dimensions" in r.output
    assert not list(tmp_path.glob("three*"))


def test_sweep_figures_of_files_mark_invalid_points_as_invalid(tmp_path, monkeypatch):
    """The figure of a sweep file (`crawlsim plot SWEEP.h5`, `velocity --plot`) marks each point
    without a v0 by its own status: the three gaits that break uniqueness are "invalid gait"
    (+), never "failed" (x), as docs/figures.md says (they used to be drawn as failed)."""
    import crawlsim.plotting.output as output

    one = tmp_path / "one.h5"
    assert (
        vel(
            P4,
            *FAST,
            "--sweep",
            "friction.backward=[0.5,1,2,3,4]",
            "--link",
            "friction.forward=[0.5,1,1,1,1]",
            "-o",
            one,
        ).exit_code
        == 0
    )
    drawn = []
    monkeypatch.setattr(output, "save_figure", lambda fig, path, **kw: drawn.append(fig))
    for args in (
        ["plot", one, "-o", tmp_path / "s.png"],
        [
            "velocity",
            P4,
            *FAST,
            "--sweep",
            "friction.backward=[0.5,1,2,3,4]",
            "--link",
            "friction.forward=[0.5,1,1,1,1]",
            "-o",
            tmp_path / "v.csv",
            "--plot",
        ],
    ):
        assert cli(*args).exit_code == 0
    assert len(drawn) == 2
    for fig in drawn:
        marks = {
            line.get_label(): line.get_xdata().tolist()
            for line in fig.axes[0].get_lines()
            if line.get_marker() in ("x", "+")
        }
        assert marks == {"invalid gait": [0.5, 1.0, 3.0]}
        assert fig.axes[0].get_ylabel() == "displacement per period $v_0T/\\ell$"


def test_v0_jumps_at_equal_friction_are_walls_not_contours(tmp_path):
    """peristalsis-4 with forward friction 1: v0 changes sign where the backward friction crosses
    1 (two blocks forward, two backward: the uniqueness condition fails exactly there, and the
    set of slipping blocks flips). Sampled at 0.5, 0.68, ..., 1.4, v0 jumps between 0.86 and
    1.04 (by 0.18 to 0.39) where the intervals beside change by 0.03 to 0.07: the figure draws a
    wall on that cell boundary for every amplitude, and no v0 = 0 contour, which would be
    interpolated across the jump."""
    from matplotlib.collections import LineCollection

    from crawlsim.io.sweepfile import read_sweep
    from crawlsim.plotting import sweep_data_figure

    out = tmp_path / "jump.h5"
    assert (
        vel(
            P4, *FAST, "--sweep", "friction.backward=0.5:1.4:6", "--sweep", "links.*.amplitude=0.2:0.3:4", "-o", out
        ).exit_code
        == 0
    )
    data = read_sweep(out)
    v0 = np.asarray(data["columns"]["v0"], dtype=float).reshape(6, 4)
    assert np.all(v0[:3] < 0) and np.all(v0[3:] > 0)
    ax = sweep_data_figure(data).axes[0]
    (walls,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    points = np.concatenate(walls.get_segments())
    np.testing.assert_allclose(points[:, 0], 0.95, rtol=0, atol=1e-12)
    assert points[:, 1].min() == pytest.approx(0.2 - 0.05 / 3)
    assert points[:, 1].max() == pytest.approx(0.3 + 0.05 / 3)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["jump of $v_0$"]


def test_crawlsim_plot_draws_sweep_files(tmp_path):
    """`crawlsim plot SWEEP.h5` dispatches on the file's kind: <stem>-sweep.<fmt> with v0 over
    one dimension (linked paths count once) or a heat map over two, the points without a v0
    (invalid and failed) marked; 3-D sweeps, shards and --only are refused (exit 2)."""
    import matplotlib.image as mpimg

    from crawlsim.plotting import sweep_data_figure

    one = tmp_path / "one.h5"
    assert (
        vel(
            P4,
            *FAST,
            "--sweep",
            "friction.backward=[0.5,1,2,3,4]",
            "--link",
            "friction.forward=[0.5,1,1,1,1]",
            "-o",
            one,
        ).exit_code
        == 0
    )
    table = read_table(one)
    ax = sweep_data_figure(sweeps.table_payload(table)).axes[0]  # linked paths count once
    assert ax.get_xlabel() == "friction.backward ($F$)" and len(ax.get_lines()[0].get_xdata()) >= 5
    # backward 1 = forward 1 and backward 3 (= 3 x forward 1 on 4 blocks) break uniqueness;
    # backward 0.5 = forward 0.5 too
    (invalid,) = [line for line in ax.get_lines() if line.get_label() == "invalid gait"]
    assert invalid.get_xdata().tolist() == [0.5, 1.0, 3.0]
    r = cli("plot", one, "-o", tmp_path / "fig")
    assert r.exit_code == 0, r.output
    image = mpimg.imread(tmp_path / "fig" / "one-sweep.png")
    assert image.shape[0] > 200 and image[..., :3].std() > 0.05
    two = tmp_path / "two.h5"
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "-o", two).exit_code == 0
    r = cli("plot", two, "--format", "svg")
    assert r.exit_code == 0 and (tmp_path / "two-sweep.svg").read_text().startswith("<?xml")
    assert cli("plot", two, "--only", "motion").exit_code == 2
    three = tmp_path / "three.h5"
    assert vel(P4, *FAST, "--sweep", AMP, "--sweep", LAG, "--sweep", "period=1,2", "-o", three).exit_code == 0
    r = cli("plot", three)
    assert r.exit_code == 2 and "this sweep has 3" in r.output
    part = tmp_path / "part.h5"
    assert vel(P4, *FAST, "--sweep", AMP, "--shard", "1/2", "-o", part).exit_code == 0
    assert cli("plot", part).exit_code == 2
    assert sorted(p.name for p in tmp_path.glob("*.png")) == []


def test_sweeping_a_waves_numbers_and_its_links():
    """On a wave (links: {wave: ..., phase_step: ...}) a sweep of links.phase_step moves the lag
    of every link at once (link i at i x step, modulo 1), one of links.wave.amplitude every
    link's amplitude, and one of links.1.phase that generated link alone (the point's document
    holds the links written out), as docs/gait-files.md defines them."""
    import yaml

    from crawlsim.gait.document import gait_from_document

    doc = yaml.safe_load(Path(P4).read_text())
    doc["links"] = {"wave": {"kind": "cosine", "mean": 1.0, "amplitude": 0.3}, "phase_step": 0.3333333333333333}
    wave = gait_from_document(doc, "wave.yaml")
    lags = sweeps.make_grid(wave, ["links.phase_step=0:0.5:3"])
    assert [[s.phase for s in lags.gait(i).links] for i in range(3)] == [
        [0.0, 0.0, 0.0],
        [0.0, 0.25, 0.5],
        [0.0, 0.5, 0.0],
    ]
    grid = sweeps.make_grid(wave, ["links.wave.amplitude=0.1,0.2", "links.1.phase=0.5"])
    point = grid.gait(1)
    assert [s.amplitude for s in point.links] == [0.2] * 3 and [s.phase for s in point.links] == [
        0.0,
        0.5,
        0.6666666666666666,
    ]
    assert isinstance(grid.document(1)["links"], list) and isinstance(grid.base.document["links"], dict)
