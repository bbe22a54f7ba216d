"""Results files, format_version 2: netCDF-4 files that xarray opens with named dimensions,
every dataset with units and long_name, CF flags for enumerations, sweep numbers on their grid;
format_version 1 files still read as before."""

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.errors import GaitError, ResultsFileError
from crawlsim.gait.units import Units, path_quantity
from crawlsim.io.layout import FORMAT_VERSION, NOT_A_VARIABLE
from crawlsim.io.runread import read_results
from crawlsim.io.sweepfile import axis_name, read_sweep
from crawlsim.plotting import plot_results
from crawlsim.study.table import read_table

from .conftest import GAITS, make_gait

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

DATA = Path(__file__).resolve().parent / "data"
NETCDF_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

UNITS_GAIT = {
    "name": "units-3",
    "blocks": 3,
    "period": 2.0,
    "stiffness": [10.0, 12.0],
    "links": [
        {"kind": "cosine", "mean": 1.0, "amplitude": 0.3},
        {"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 0.4},
    ],
    "friction": [
        {"forward": 1.0, "backward": 2.0},
        {"forward": 1.5, "backward": 2.5},
        {"forward": {"kind": "cosine", "mean": 1.2, "amplitude": 0.5}, "backward": 3.0},
    ],
    "simulation": {"steps_per_period": 60},
    "units": {"length": "mm", "time": "s", "force": "N"},
}


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A crawler run with units, an exact run (with /events), a generic process, a sweep and a
    shard of it."""
    d = tmp_path_factory.mktemp("files")
    (d / "units.yaml").write_text(yaml.safe_dump(UNITS_GAIT, sort_keys=False))
    runs = {
        "units": ["run", d / "units.yaml"],
        "exact": ["run", GAITS / "inching-2.yaml", "--integrator", "exact", "--steps-per-period", "40"],
        "process": ["run", GAITS / "paper" / "triangle.yaml", "--steps-per-period", "60"],
        "sweep": ["velocity", d / "units.yaml", "--sweep", "links.*.amplitude=0.2,0.3", "--sweep", "period=1,2,4"],
        "shard": [
            "velocity",
            d / "units.yaml",
            "--sweep",
            "links.*.amplitude=0.2,0.3",
            "--sweep",
            "period=1,2,4",
            "--shard",
            "2/4",
        ],
    }
    out = {}
    for name, args in runs.items():
        out[name] = d / f"{name}.h5"
        r = cli(*args, "-o", out[name])
        assert r.exit_code == 0, r.output
    return out


def _datasets(path):
    found = {}
    with h5py.File(path) as f:
        f.visititems(
            lambda name, obj: (
                found.setdefault(name, obj.attrs.keys().__len__()) if isinstance(obj, h5py.Dataset) else None
            )
        )
    return found


@pytest.mark.parametrize("name", ["units", "exact", "process", "sweep", "shard"])
def test_xarray_opens_every_group_with_named_dimensions_and_units(files, name):
    """open_datatree fails on a dataset with an unscaled axis (h5netcdf's default refuses
    "phony" dimensions), so opening is itself the check; then no dimension is phony and every
    variable, coordinates included, has units and a long_name."""
    with xr.open_datatree(files[name], engine="h5netcdf") as tree:
        for node in tree.subtree:
            ds = node.to_dataset()
            for dim in ds.dims:
                assert not str(dim).startswith("phony_dim"), (node.path, dim)
                assert NETCDF_NAME.match(str(dim)), dim
            for var in ds.variables.values():
                assert "units" in var.attrs and var.attrs["long_name"], (node.path, var.name)
    with h5py.File(files[name]) as f:

        def check(path, obj):
            if isinstance(obj, h5py.Dataset):
                assert "units" in obj.attrs and "long_name" in obj.attrs, path
                for axis, dim in enumerate(obj.dims):
                    assert len(dim) == 1 or obj.attrs.get("CLASS") == b"DIMENSION_SCALE", (path, axis)

        f.visititems(check)


def test_run_file_dimensions(files):
    with xr.open_datatree(files["units"], engine="h5netcdf") as tree:
        assert dict(tree["trajectory"].to_dataset().w.sizes) == {"time": len(tree["trajectory"]["t"]), "state": 2}
        limit = tree["limit"].to_dataset()
        G = limit.sizes["step"]
        assert limit.sizes["limit_time"] == G + 1
        assert limit.slip.dims == ("step", "block") and limit.multipliers.dims == ("step", "constraint")
        assert limit.friction.dims == ("limit_time", "constraint")
        assert tree["convergence"]["velocity"].dims == ("period",)
        assert tree["process"]["stiffness"].dims == ("link",)  # B and M follow from k
        root = tree.to_dataset()
        np.testing.assert_array_equal(root.block, [1, 2, 3])
        np.testing.assert_array_equal(root.link, [1, 2])
        np.testing.assert_array_equal(root.constraint_block, [1, 2, 3, 1, 2, 3])
        np.testing.assert_array_equal(root.constraint_limit, [1, 1, 1, -1, -1, -1])
    with xr.open_datatree(files["exact"], engine="h5netcdf") as tree:
        assert tree["events"]["w"].dims == ("event_time", "state")
        assert tree["events"]["x"].dims == ("event_time", "block")


def test_friction_columns_are_labelled_by_block_and_limit(files):
    """/limit/friction[:, i] is mu^+ of block constraint_block[i] where constraint_limit is +1,
    and mu^- where it is -1, at the limit period's times (friction is T-periodic, so the
    relative times of /limit/t give the same values)."""
    gait = make_gait(UNITS_GAIT)
    data = read_results(files["units"])
    t, friction = data["limit"]["t"], data["limit"]["friction"]
    block, limit = data["coordinates"]["constraint_block"], data["coordinates"]["constraint_limit"]
    for i in range(friction.shape[1]):
        mu = gait.mu_plus(t) if limit[i] == 1 else gait.mu_minus(t)
        np.testing.assert_allclose(friction[:, i], mu[:, block[i] - 1], rtol=1e-15)


def test_slip_is_a_cf_flag_variable_consistent_with_the_slip_rates(files):
    with h5py.File(files["units"]) as f:
        slip = f["limit/slip"]
        np.testing.assert_array_equal(slip.attrs["flag_values"], [-1, 0, 1])
        assert slip.attrs["flag_values"].dtype == slip.dtype
        assert slip.attrs["flag_meanings"] == "backward_slip stick forward_slip"
        rate = f["limit/slip_rate"][()]
        s = slip[()]
        assert set(np.unique(s)) <= {-1, 0, 1} and (s == 1).any() and (s == 0).any()
        assert np.all(rate[s == 1] > 0) and np.all(rate[s == -1] < 0)
        assert np.all(np.abs(rate[s == 0]) <= 1e-12 * np.abs(rate).max())


def test_units_of_the_datasets_follow_the_units_block(files):
    expected = {
        "trajectory/t": "s",
        "trajectory/x": "mm",
        "trajectory/w": "N",
        "trajectory/stress": "N",
        "trajectory/shape": "mm",
        "convergence/velocity": "mm/s",
        "convergence/displacement": "mm",
        "convergence/dissipation": "N mm",
        "convergence/poincare_step": "N",
        "convergence/slip_l2_distance": "mm/s^(1/2)",
        "convergence/period": "1",
        "limit/slip": "1",
        "limit/slip_rate": "mm/s",
        "limit/multipliers": "mm",
        "limit/friction": "N",
        "limit/lengths": "mm",
        "limit/offsets": "N",
        "process/stiffness": "N/mm",
    }
    with h5py.File(files["units"]) as f:
        for path, unit in expected.items():
            assert f[path].attrs["units"] == unit, path
        assert json.loads(f.attrs["units_json"]) == UNITS_GAIT["units"]
        attribute_units = json.loads(f.attrs["attribute_units_json"])
        assert attribute_units["v0"] == "mm/s" and attribute_units["period"] == "s"
        assert attribute_units["dissipation_per_period"] == "N mm"
    with h5py.File(files["exact"]) as f:  # no units block: dimensionless
        assert json.loads(f.attrs["units_json"]) == {}
        for path in ("trajectory/t", "trajectory/x", "convergence/velocity", "events/t"):
            assert f[path].attrs["units"] == "1", path
    with h5py.File(files["process"]) as f:
        assert f.attrs["kind"] == "sweeping-process"
        assert f["process/metric"].attrs["units"] == "1"
        assert f["process/metric"].dims[0][0].name == "/state"
        assert "constraint_block" not in f and "block" not in f


def test_units_in_json_and_summary_text(tmp_path):
    (tmp_path / "u.yaml").write_text(yaml.safe_dump(UNITS_GAIT))
    r = cli("run", tmp_path / "u.yaml", "--json", "-o", tmp_path / "u.h5")
    assert json.loads(r.output)["units"] == UNITS_GAIT["units"]
    r = cli("run", tmp_path / "u.yaml", "-o", tmp_path / "u.h5")
    v0_line = next(line for line in r.output.splitlines() if line.strip().startswith("v0"))
    assert re.search(r"v0\s+[-0-9.e]+ mm/s ± [0-9.e-]+ mm/s \(", v0_line), v0_line
    assert "dissipation per period" in r.output and " N mm" in r.output
    r = cli("run", GAITS / "inching-2.yaml", "--steps-per-period", "20", "--json", "-o", tmp_path / "i.h5")
    assert json.loads(r.output)["units"] == {}


@pytest.mark.parametrize(
    "block, message",
    [
        ({"lenght": "mm"}, "unknown key 'lenght'"),
        ({"length": 3}, "units.length"),
        ({"time": ""}, "units.time"),
        ("mm", "units"),
    ],
)
def test_units_block_is_validated(block, message):
    with pytest.raises(GaitError, match=re.escape(message)):
        make_gait({**UNITS_GAIT, "units": block})


@pytest.mark.parametrize(
    "block, message",
    [
        (
            {"force": "Newtons"},
            "units.force: expected a unit of force, one of N, kN, mN, uN, µN, "
            "nN, dyn, lbf; got 'Newtons': write its symbol, 'N'",
        ),
        ({"length": "millimetres"}, "got 'millimetres': write its symbol, 'mm'"),
        ({"time": "sec"}, "units.time: expected a unit of time"),
        (
            {"length": "s"},
            "units.length: expected a unit of length, one of m, km, dm, cm, mm, um, "
            "µm, nm, in, ft; got 's', a unit of time",
        ),
        ({"force": "mm"}, "got 'mm', a unit of length"),
        ({"length": "MM"}, "did you mean 'mm'"),
        ({"force": "kgf"}, "got 'kgf'"),
    ],
)
def test_unit_names_are_checked(block, message):
    """A unit string is one of `crawlsim.gait.units.UNIT_NAMES` for its dimension; a spelled-out name
    gets its symbol, a unit of another dimension is named as such, a typo gets the closest
    names."""
    with pytest.raises(GaitError, match=re.escape(message)):
        make_gait({**UNITS_GAIT, "units": {**UNITS_GAIT["units"], **block}})


def test_every_listed_unit_is_accepted():
    from crawlsim.gait.units import UNIT_NAMES, unit_problem

    for base, names in UNIT_NAMES.items():
        for name in names:
            assert unit_problem(base, name) is None
            make_gait({**UNITS_GAIT, "units": {base: name}})


def test_a_misspelt_unit_exits_2_naming_file_and_key(tmp_path):
    """`units: {force: Newtons}` used to pass silently: now run and validate exit 2 with the
    file, the key path and what was expected, and no results file."""
    import yaml

    path = tmp_path / "u.yaml"
    path.write_text(yaml.safe_dump({**UNITS_GAIT, "units": {"length": "mm", "force": "Newtons"}}))
    for args in (["run", path, "-o", tmp_path / "u.h5"], ["validate", path]):
        r = cli(*args)
        assert r.exit_code == 2, r.output
        assert f"{path}: units.force: expected a unit of force" in r.output
        assert "'N'" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "u.h5").exists()


def test_unit_composition():
    u = Units(length="mm", time="s", force="N")
    assert [u.of(q) for q in ("velocity", "stiffness", "dissipation", "compliance", "force", "velocity_l2", "1")] == [
        "mm/s",
        "N/mm",
        "N mm",
        "mm/N",
        "N",
        "mm/s^(1/2)",
        "1",
    ]
    assert Units(length="mm").of("velocity") == "mm"  # time without a unit: dimensionless
    assert Units(time="s").of("velocity") == "1/s"
    assert Units(length="0.1 mm", time="s").of("velocity") == "(0.1 mm)/s"
    assert Units().of("dissipation") == "1" and Units().suffix("velocity") == ""
    assert Units(force="N", time="s").compose({"force": -1, "time": -1}) == "1/(N s)"


def test_quantities_of_swept_paths():
    from crawlsim.gait.docpaths import path_keys as keys

    assert path_quantity("crawler", keys("links.*.amplitude")) == "length"
    assert path_quantity("crawler", keys("links.1.phase")) == "1"
    assert path_quantity("crawler", keys("friction.0.backward")) == "force"
    assert path_quantity("crawler", keys("period")) == "time"
    assert path_quantity("crawler", keys("stiffness")) == "stiffness"
    assert path_quantity("crawler", keys("simulation.steps_per_period")) == "1"
    assert path_quantity("sweeping-process", keys("offsets.0.mean")) == "length"


def test_axis_names_are_safe_and_unique():
    assert axis_name("links.*.amplitude") == "links_all_amplitude"
    assert axis_name("links.1.phase") == "links_1_phase"
    assert axis_name("a.b_c", ["a_b_c"]) == "a_b_c_2"
    assert axis_name("v0") == "v0_2"  # never a variable's name
    for path in ("friction.*.backward", "simulation.steps_per_period", "links.0.values.1"):
        assert NETCDF_NAME.match(axis_name(path))


def test_sweep_grid_holds_the_table_on_the_grid(files):
    """Point i of the table sits at np.unravel_index(i, shape) on the grid (C order); the axes
    carry their paths and units; the shard's grid has only its own points."""
    table = read_table(files["sweep"])
    with xr.open_datatree(files["sweep"], engine="h5netcdf") as tree:
        grid = tree["grid"].to_dataset()
        assert grid.v0.dims == ("links_all_amplitude", "period")
        assert grid.links_all_amplitude.attrs["path"] == "links.*.amplitude"
        assert grid.links_all_amplitude.attrs["units"] == "mm"
        assert grid.period.attrs["units"] == "s"
        assert grid.v0.attrs["units"] == "mm/s"
        np.testing.assert_array_equal(grid.v0.values.ravel(), table.columns()["v0"])
        np.testing.assert_array_equal(grid.periods.values.ravel(), table.columns()["periods"])
        assert (grid.status.values == 0).all()  # ok
        assert set(grid.convergence.attrs["flag_meanings"].split()) >= {"finite_time", "asymptotic"}
        assert tree["results"]["v0"].dims == ("point",)
        np.testing.assert_array_equal(tree["results"]["links_all_amplitude"].values, [0.2, 0.2, 0.2, 0.3, 0.3, 0.3])
    shard = read_table(files["shard"])
    with xr.open_datatree(files["shard"], engine="h5netcdf") as tree:
        status = tree["grid"]["status"].values.ravel()
        v0 = tree["grid"]["v0"].values.ravel()
        mine = np.zeros(6, dtype=bool)
        mine[shard.points] = True
        assert np.all(status[~mine] == -1) and np.all(np.isnan(v0[~mine]))
        np.testing.assert_array_equal(v0[mine], table.columns()["v0"][mine])


def test_v2_readers_keep_the_v1_keys(files):
    """read_results returns the keys format 1 had, with the same dataset names; format 2 only
    adds keys (limit/step, the root coordinates)."""
    old, new = read_results(DATA / "v1-run.h5"), read_results(files["units"])
    for key, value in old.items():
        assert key in new
        if isinstance(value, dict) and key != "attrs":
            assert set(value) <= set(new[key]), key
    assert set(new["limit"]) - set(old["limit"]) == {"step"}
    # events: the exact integrator; energy: the energy ledger of crawlers; limit_solver:
    # /limit/solver, how the limit was found
    assert set(new) - set(old) <= {"coordinates", "events", "energy", "limit_solver", "limit_solver_attrs"}
    assert set(old["attrs"]) <= set(new["attrs"])
    assert new["attrs"]["format_version"] == FORMAT_VERSION == 2
    old_sweep, new_sweep = read_sweep(DATA / "v1-sweep.h5"), read_sweep(files["sweep"])
    assert set(old_sweep) <= set(new_sweep)
    assert set(old_sweep["columns"]) == {
        "links.*.amplitude",
        "v0",
        "displacement_per_period",
        "convergence",
        "periods",
        "status",
        "message",
    }
    assert set(new_sweep["columns"]) == {
        "links.*.amplitude",
        "period",
        "v0",
        "displacement_per_period",
        "convergence",
        "periods",
        "status",
        "message",
        "v0_error_estimate",
        "dissipation_per_period",
        "cost_of_transport",
        "integrator",
        "limit",
        "newton_steps",
    }


def test_format_1_files_still_read_and_plot(tmp_path):
    """The committed files were written by crawlsim before format 2 (inching-2, 8 steps): the
    closed form v0 = 2A - (mu_1^+ + mu_2^+)/k holds exactly on that grid (it holds the extremes
    of L at t = 0 and T/2), for A = 0.3 and 0.2."""
    data = read_results(DATA / "v1-run.h5")
    assert data["attrs"]["format_version"] == 1
    assert data["attrs"]["v0"] == pytest.approx(0.4, abs=1e-13)
    assert data["trajectory"]["t"].shape == (17,) and data["limit"]["slip"].shape == (8, 2)
    written = plot_results(DATA / "v1-run.h5", tmp_path)
    assert len(written) == 5 and all(p.stat().st_size > 1000 for p in written)
    table = read_table(DATA / "v1-sweep.h5")
    assert table.paths == ("links.*.amplitude",)
    np.testing.assert_allclose([r.v0 for r in table.rows], [0.2, 0.4], atol=1e-13)


def test_newer_format_is_refused_clearly(tmp_path):
    newer = tmp_path / "newer.h5"
    shutil.copy(DATA / "v1-run.h5", newer)
    with h5py.File(newer, "a") as f:
        f.attrs["format_version"] = 3
    with pytest.raises(ResultsFileError, match="format_version 3 was written by a newer"):
        read_results(newer)
    r = cli("plot", newer)
    assert r.exit_code == 2 and "upgrade crawlsim" in r.output


def test_sweep_file_is_not_a_run_file(files):
    with pytest.raises(ResultsFileError, match="a sweep file"):
        read_results(files["sweep"])


def test_time_dimensions_are_indexed_by_their_times(files):
    """time, limit_time and event_time are coordinate variables (dimension scales) holding the
    group's t, so xarray indexes them: ``sel(time=...)`` picks a saved grid point by its time."""
    with h5py.File(files["exact"]) as f:
        for path in ("trajectory/time", "limit/limit_time", "events/event_time"):
            ds = f[path]
            assert ds.attrs["CLASS"] == b"DIMENSION_SCALE"
            assert not bytes(ds.attrs["NAME"]).startswith(NOT_A_VARIABLE)
            np.testing.assert_array_equal(ds[()], f[path.rsplit("/", 1)[0] + "/t"][()])
        assert f.attrs["Conventions"] == "CF-1.10"
    with xr.open_datatree(files["exact"], engine="h5netcdf") as tree:
        trajectory = tree["trajectory"].to_dataset()
        t = trajectory.t.values
        picked = trajectory.sel(time=t[7])
        np.testing.assert_array_equal(picked.w.values, trajectory.w.values[7])
        assert "time" in trajectory.indexes and "event_time" in tree["events"].to_dataset().indexes
