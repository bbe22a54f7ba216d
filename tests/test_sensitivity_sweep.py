"""``crawlsim velocity --sweep ... --sensitivity PATH`` (issue 22): a ``dv0/dPATH`` column per
number, met against the two-block crawler's closed forms at every grid point, with units in the
sweep file and the xarray Dataset, kept through shards, merges and the journal.

The two-block crawler (tests/test_sensitivity.py): d = 2 a - (mu_1^+ + mu_2^+)/k, v0 = d/T, so
dv0/dk = (mu_1^+ + mu_2^+)/(k^2 T), dv0/dmu_1^+ = -1/(k T), dv0/da = 2/T and dv0/dT = -v0/T.
"""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.gait.document import gait_from_document
from crawlsim.study import sweep as sweeps
from crawlsim.study.points import PointResult
from crawlsim.study.table import merge_tables, read_table

PATHS = ("stiffness", "friction.0.forward", "links.*.amplitude", "period")


def _doc(units: bool = False, integrator: str = "exact") -> dict:
    doc = {
        "name": "two-block",
        "blocks": 2,
        "period": 2.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3}],
        "friction": [{"forward": 1.0, "backward": 5.0}, {"forward": 0.5, "backward": 5.0}],
        "simulation": {"steps_per_period": 200, "max_periods": 50, "tolerance": 1e-12, "integrator": integrator},
    }
    if units:
        doc["units"] = {"length": "mm", "time": "s", "force": "N"}
    return doc


def _gait(**kw):
    return gait_from_document(_doc(**kw), "two-block")


def _expected(k: float, T: float = 2.0, a: float = 0.3, mus: float = 1.5) -> dict[str, float]:
    v0 = (2 * a - mus / k) / T
    return {
        "dv0/dstiffness": mus / (k * k * T),
        "dv0/dfriction.0.forward": -1 / (k * T),
        "dv0/dlinks.0.amplitude": 2 / T,
        "dv0/dperiod": -v0 / T,
    }


def _yaml(tmp_path, doc) -> str:
    import yaml

    path = tmp_path / "two-block.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def _cli(*args):
    from click.testing import CliRunner

    from crawlsim.cli import main

    return CliRunner().invoke(main, ["velocity", *args])


def test_cli_csv_columns_meet_closed_forms(tmp_path):
    gait = _yaml(tmp_path, _doc())
    args = [gait, "--sweep", "stiffness=[5,10,20]"]
    for p in PATHS:
        args += ["--sensitivity", p]
    res = _cli(*args)
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    assert len(rows) == 3
    for row in rows:
        k = float(row["stiffness"])
        for column, value in _expected(k).items():
            assert float(row[column]) == pytest.approx(value, abs=1e-10), (k, column)
    header = res.stdout.splitlines()[0].split(",")
    assert header[-4:] == list(_expected(1.0))


def test_hdf5_and_xarray_carry_units(tmp_path):
    """mm, s, N: v0 in mm/s, so dv0/dk in mm/s over N/mm, dv0/dmu in mm/s over N, dv0/da in
    1/s, dv0/dT in mm/s^2; the columns read back through `read_table`."""
    import h5py

    import crawlsim

    out = tmp_path / "s.h5"
    gait = _gait(units=True)
    table = sweeps.sweep(gait, ["stiffness=[5,10]"], output=out, sensitivity=PATHS)
    expected_units = {
        "dv0_dstiffness": "mm^2/(N s)",
        "dv0_dfriction_0_forward": "mm/(N s)",
        "dv0_dlinks_0_amplitude": "1/s",
        "dv0_dperiod": "mm/s^2",
    }
    with h5py.File(out) as f:
        for group in ("grid", "results"):
            for name, unit in expected_units.items():
                ds = f[group][name]
                assert ds.attrs["units"] == unit, (group, name)
                assert (
                    ds.attrs["column"]
                    == "dv0/d"
                    + {
                        "dv0_dstiffness": "stiffness",
                        "dv0_dfriction_0_forward": "friction.0.forward",
                        "dv0_dlinks_0_amplitude": "links.0.amplitude",
                        "dv0_dperiod": "period",
                    }[name]
                )
        assert f["grid"]["dv0_dstiffness"][()] == pytest.approx(
            [_expected(5.0)["dv0/dstiffness"], _expected(10.0)["dv0/dstiffness"]], abs=1e-10
        )
    back = read_table(out)
    for a, b in zip(back.rows, table.rows):
        assert a.derivatives == b.derivatives
    ds = crawlsim.sweep(gait, {"stiffness": [5.0, 10.0]}, sensitivity=["stiffness"])
    assert ds["dv0_dstiffness"].attrs["units"] == "mm^2/(N s)"
    assert ds["dv0_dstiffness"].values == pytest.approx(
        [_expected(k)["dv0/dstiffness"] for k in (5.0, 10.0)], abs=1e-10
    )


def test_shards_merge_and_journal_keep_the_columns(tmp_path):
    gait = _gait()
    parts = []
    for i in (1, 2):
        part = tmp_path / f"part-{i}.h5"
        sweeps.sweep(gait, ["stiffness=[5,10,20]"], output=part, shard=(i, 2), sensitivity=["stiffness"])
        parts.append(read_table(part))
    merged = merge_tables(parts)
    column = merged.columns()["dv0/dstiffness"]
    assert column == pytest.approx([1.5 / (k * k * 2.0) for k in (5, 10, 20)], abs=1e-10)
    row = merged.rows[0]
    assert PointResult.from_json(json.loads(json.dumps(row.to_json()))) == row
    # a journal of the same grid without --sensitivity is another sweep
    grid = sweeps.make_grid(gait, ["stiffness=[5,10,20]"])
    with_paths = sweeps.make_grid(gait, ["stiffness=[5,10,20]"], sensitivity=["stiffness"])
    assert grid.fingerprint(None) != with_paths.fingerprint(None)


def test_catch_up_points_differentiate_their_own_map():
    """A catch-up sweep's column is the derivative of the catch-up map at that point, the
    value `sensitivity` gives for that gait (method catch-up), and for the two-block crawler
    whose grid holds the extremes of L (u = 0 and 1/2), the closed form itself. (At k = 5 the
    stress meets the friction limit exactly at a grid time, u = 1/4: a kink of the catch-up
    map, reported as such; 6 and 12 avoid it.)"""
    gait = _gait(integrator="catch-up")
    table = sweeps.sweep(gait, ["stiffness=[6,12]"], sensitivity=["stiffness", "period"])
    for row, k in zip(table.rows, (6.0, 12.0)):
        assert row.integrator == "catch-up"
        r = sensitivity(gait.replace("stiffness", k), ["stiffness"])
        assert r["stiffness"].method == "catch-up"
        assert row.derivatives["stiffness"] == pytest.approx(r["stiffness"].v0.value, abs=1e-12)
        assert row.derivatives["stiffness"] == pytest.approx(_expected(k)["dv0/dstiffness"], abs=1e-10)
        assert row.derivatives["period"] == pytest.approx(-row.v0 / 2.0, abs=1e-12)


def test_unconverged_and_kinked_points_have_no_value(tmp_path):
    """At the threshold of motion (2 a k = mu_1^+ + mu_2^+: a = 0.075 with k = 10) the point
    sits on a kink: its cell is missing; the others have their closed form."""
    gait = _gait().replace("links.0.amplitude", 0.075)
    table = sweeps.sweep(gait, ["stiffness=[10,20]"], sensitivity=["stiffness"])
    column = table.columns()["dv0/dstiffness"]
    assert np.isnan(column[0])
    assert column[1] == pytest.approx(1.5 / (400 * 2.0), abs=1e-10)
    text = table.to_csv().splitlines()
    assert text[1].endswith(",")  # the missing cell is empty


def test_column_is_the_point_sensitivity():
    """On peristalsis-4 (no closed form) each cell is `crawlsim.sensitivity` of that point's
    gait, walked on the limit period the point's own run found."""
    import crawlsim

    gait = crawlsim.load_gait("gaits/peristalsis-4.yaml")
    table = sweeps.sweep(gait, ["links.1.phase=[0.2,0.3]"], sensitivity=["links.*.phase"])
    cols = table.columns()
    assert [c for c in cols if c.startswith("dv0/d")] == [
        "dv0/dlinks.0.phase",
        "dv0/dlinks.1.phase",
        "dv0/dlinks.2.phase",
    ]
    for n, lag in enumerate((0.2, 0.3)):
        r = sensitivity(gait.replace("links.1.phase", lag), ["links.*.phase"])
        for p in r.parameters:
            assert p.smooth
            assert cols["dv0/d" + p.path][n] == pytest.approx(p.v0.value, abs=10 * p.v0.error_estimate + 1e-12), (
                lag,
                p.path,
            )
        # a common phase shift: the three derivatives sum to zero
        assert abs(sum(cols[f"dv0/dlinks.{i}.phase"][n] for i in range(3))) <= 1e-10
