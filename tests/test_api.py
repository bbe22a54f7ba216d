"""The Python API for studies: load_gait, Gait.replace (the --sweep path syntax), simulate with
the trajectory in memory and to_xarray, sweep to an xarray Dataset, and docs/study.md."""

import dataclasses
import io
import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import crawlsim
import crawlsim.study.sweep
from crawlsim import api
from crawlsim.errors import GaitError, SweepSpecError
from crawlsim.io.runread import read_results
from crawlsim.study.grid import Axis, make_grid

from .conftest import GAITS, ROOT

P4 = GAITS / "peristalsis-4.yaml"
INCHING = GAITS / "inching-2.yaml"


# -- gaits ----------------------------------------------------------------------------------------
def test_load_gait_is_immutable_and_replace_returns_a_new_validated_gait():
    gait = crawlsim.load_gait(P4)
    assert isinstance(gait, crawlsim.Gait)
    with pytest.raises(dataclasses.FrozenInstanceError):
        gait.period = 2.0
    before = [dict(link) for link in gait.document["links"]]
    wider = gait.replace("links.*.amplitude", 0.2)
    assert isinstance(wider, crawlsim.Gait) and wider is not gait
    assert [link["amplitude"] for link in wider.document["links"]] == [0.2, 0.2, 0.2]
    assert gait.document["links"] == before  # the original is untouched
    np.testing.assert_allclose(wider.lengths(np.array([0.0]))[0], [1.2, 0.9, 0.9])
    pairs = gait.replace("period", 2.0, "links.1.phase", 0.25)
    mapping = gait.replace({"period": 2.0, "links.1.phase": 0.25})
    assert pairs.document == mapping.document and pairs.period == 2.0
    assert pairs.document["links"][1]["phase"] == 0.25
    steps = gait.replace("simulation.steps_per_period", 300.0)
    assert steps.simulation.steps_per_period == 300 and isinstance(
        steps.document["simulation"]["steps_per_period"], int
    )


def test_a_gait_and_the_package_show_what_a_user_looks_for():
    """repr(gait) was 2 kB (its whole document and file text); dir(crawlsim) listed the module's
    own imports (TYPE_CHECKING, annotations, importlib)."""
    assert repr(crawlsim.load_gait(P4)) == "<Gait peristalsis-4: 4 blocks, period 1, from " + str(P4) + ">"
    triangle = crawlsim.load_gait(GAITS / "paper" / "triangle.yaml")
    assert repr(triangle).startswith("<ProcessSpec triangle: 3 faces in R^2, period 1, from ")
    names = dir(crawlsim)
    assert not {"TYPE_CHECKING", "annotations", "importlib"} & set(names)
    assert set(crawlsim.__all__) <= set(names) and "plotting" in names


def test_replace_edits_exactly_as_a_sweep_point():
    """The same path syntax, the same edit: the document of a one-point sweep grid."""
    gait = crawlsim.load_gait(P4)
    for path, value in (
        ("links.*.amplitude", 0.25),
        ("friction.backward", 2.5),
        ("links.2.phase", 0.5),
        ("stiffness", 12),
    ):
        grid = make_grid(gait, [Axis(path, (value,))])
        assert gait.replace(path, value).document == grid.document(0)


@pytest.mark.parametrize(
    "args, error, message",
    [
        (("links.*.amplitud", 0.2), GaitError, "did you mean 'amplitude'"),
        (("links.7.phase", 0.2), GaitError, "index 7 is out of range"),
        (("links", 0.2), GaitError, "not a number"),
        (("friction.forward", -1.0), GaitError, "friction must be positive"),
        (("links.*.amplitude", 0.2, "links.1.amplitude", 0.3), GaitError, "set each value once"),
        (("period",), TypeError, "path, value pairs"),
        ((3, 0.2), TypeError, "dotted string"),
    ],
)
def test_replace_refuses_bad_changes_naming_them(args, error, message):
    gait = crawlsim.load_gait(P4)
    with pytest.raises(error, match=re.escape(message)) as info:
        gait.replace(*args)
    if error is GaitError:
        assert str(info.value).startswith(f"{P4} with {args[0]}=")


# -- simulate -------------------------------------------------------------------------------------
def test_simulate_keeps_the_trajectory_and_matches_the_closed_form():
    """Two-block inching (tests/test_closed_forms.py): v0 = 2A - (mu_1^+ + mu_2^+)/k, exact on a
    grid holding t = 0 and T/2; the trajectory's stress is k (L - (x_2 - x_1))."""
    gait = crawlsim.load_gait(INCHING).replace("links.0.amplitude", 0.25)
    r = crawlsim.simulate(gait, integrator="catch-up", steps_per_period=40, save_every=2)
    assert r.v0 == pytest.approx(2 * 0.25 - 2 / 10, abs=1e-13)
    assert r.steps_per_period == 40 and r.integrator == "catch-up"
    tr = r.trajectory
    assert tr.t.shape == (r.periods * 20 + 1,) and tr.x.shape == (len(tr.t), 2)
    np.testing.assert_allclose(np.diff(tr.t), 0.05, rtol=1e-12)
    L = 1 + 0.25 * np.cos(2 * np.pi * tr.t)
    np.testing.assert_allclose(tr.stress[:, 0], 10 * (L - (tr.x[:, 1] - tr.x[:, 0])), atol=1e-12)
    np.testing.assert_allclose(tr.shape[:, 0], tr.x[:, 1] - tr.x[:, 0], atol=1e-15)
    assert tr.reaction is None and tr.events is None
    exact = crawlsim.simulate(gait, integrator="exact", steps_per_period=40)
    assert exact.integrator == "exact" and exact.trajectory.events is not None
    assert exact.v0 == pytest.approx(0.3, abs=1e-13)


def test_keeping_the_trajectory_changes_no_number():
    gait = crawlsim.load_gait(P4)
    kept = crawlsim.simulate(gait, steps_per_period=100)
    lean = crawlsim.simulate(gait, steps_per_period=100, keep_trajectory=False)
    # one computation with and without keeping the trajectory, on one machine: bit for bit
    assert lean.trajectory is None and kept.v0 == lean.v0
    np.testing.assert_array_equal(kept.history.poincare_step, lean.history.poincare_step)
    np.testing.assert_array_equal(kept.limit.x, lean.limit.x)
    cli = api.run(gait.replace("simulation.steps_per_period", 100))
    assert cli.v0 == kept.v0


@pytest.mark.parametrize(
    "path, save_every, integrator",
    [
        (GAITS / "smooth-friction-3.yaml", 1, "exact"),  # /events
        (GAITS / "paper" / "triangle.yaml", 3, "catch-up"),  # reactions summed over 3 steps
    ],
)
def test_simulate_writes_no_hdf5_until_asked(monkeypatch, path, save_every, integrator):
    """`simulate` keeps its results in memory: no HDF5 file is opened while it runs, and the
    file written later, when `image` is asked for, holds exactly the trajectory (and events)
    the result already has."""
    import h5py

    def refuse(*args, **kwargs):
        raise AssertionError("simulate opened an HDF5 file")

    opened = h5py.File
    monkeypatch.setattr(h5py, "File", refuse)
    result = crawlsim.simulate(path, steps_per_period=60, integrator=integrator, save_every=save_every)
    monkeypatch.setattr(h5py, "File", opened)
    data = read_results(io.BytesIO(result.image))
    t = result.trajectory
    for name in ("t", "w", "x", "stress", "shape", "reaction"):
        mine = getattr(t, name)
        assert (mine is None) == (name not in data["trajectory"]), name
        if mine is not None:
            np.testing.assert_array_equal(mine, data["trajectory"][name])
    assert (t.events is None) == ("events" not in data)
    if t.events is not None:
        for name, values in t.events.items():
            np.testing.assert_array_equal(values, data["events"][name])
    assert data["attrs"]["command_line"].startswith("crawlsim.simulate(")


def test_to_xarray_is_the_results_file(tmp_path):
    """The tree of a result and the tree of the file the CLI writes for the same run have the
    same groups, variables, dimensions and values."""
    xr = pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    gait = crawlsim.load_gait(GAITS / "smooth-friction-3.yaml")
    result = crawlsim.simulate(gait, steps_per_period=50)
    out = tmp_path / "r.h5"
    api.run(gait.replace("simulation.steps_per_period", 50), output=out)
    memory = result.to_xarray()
    with xr.open_datatree(out, engine="h5netcdf", decode_timedelta=False) as disk:
        assert [n.path for n in memory.subtree] == [n.path for n in disk.subtree]
        for node in disk.subtree:
            a, b = memory[node.path].to_dataset(), node.to_dataset()
            assert set(a.variables) == set(b.variables), node.path
            for name, var in b.variables.items():
                assert a[name].dims == var.dims, (node.path, name)
                np.testing.assert_array_equal(a[name].values, var.values)
                assert a[name].attrs.keys() == var.attrs.keys()
                for key, value in var.attrs.items():
                    assert np.array_equal(a[name].attrs[key], value), (name, key)
    np.testing.assert_array_equal(memory["trajectory"]["x"].values, result.trajectory.x)
    assert memory.attrs["command_line"].startswith("crawlsim.simulate(")
    assert result.save(tmp_path / "saved.h5").exists()
    assert read_results(tmp_path / "saved.h5")["attrs"]["v0"] == result.v0


def test_generic_processes_run_through_the_same_api():
    spec = crawlsim.load_gait(GAITS / "paper" / "triangle.yaml")
    assert isinstance(spec, crawlsim.ProcessSpec)
    r = crawlsim.simulate(spec, steps_per_period=60)
    assert r.v0 is None and r.trajectory.x is None and r.trajectory.reaction is not None
    assert r.rate.rate == pytest.approx(1 / 8, rel=1e-3)  # the paper's phi^3
    assert spec.replace("period", 2.0).period == 2.0


# -- sweep ----------------------------------------------------------------------------------------
def test_sweep_returns_a_dataset_on_the_grid():
    """v0 on the grid equals single runs of the same gaits (the batched stepper agrees with
    single runs to 1e-12, docs/sweeps.md#scale)."""
    pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    gait = crawlsim.load_gait(P4)
    amplitudes, phases = [0.2, 0.3], [0.25, 0.5, 0.75]
    grid = crawlsim.sweep(gait, {"links.*.amplitude": amplitudes, "links.1.phase": phases}, steps_per_period=80)
    assert grid.v0.dims == ("links.*.amplitude", "links.1.phase")  # the paths passed (issue 35)
    assert grid["links.1.phase"].attrs["path"] == "links.1.phase"
    np.testing.assert_array_equal(grid["links.*.amplitude"].values, amplitudes)
    assert float(grid.v0.sel({"links.*.amplitude": 0.3, "links.1.phase": 0.5})) == float(grid.v0[1, 1])
    assert (grid.status.values == 0).all() and (grid.message.values == "").all()
    for i, a in enumerate(amplitudes):
        for j, p in enumerate(phases):
            single = crawlsim.simulate(
                gait.replace("links.*.amplitude", a, "links.1.phase", p), steps_per_period=80, keep_trajectory=False
            )
            assert float(grid.v0[i, j]) == pytest.approx(single.v0, abs=1e-12)
    assert grid.attrs["command_line"].startswith("crawlsim.sweep(")
    assert "steps_per_period: 80" in grid.attrs["gait_yaml"]
    assert grid.attrs["integrator"] == "exact"  # the integrator every point ran
    catch_up = crawlsim.sweep(gait, {"links.*.amplitude": amplitudes}, steps_per_period=80, integrator="catch-up")
    assert catch_up.attrs["integrator"] == "catch-up"


def test_sweep_without_xarray_returns_the_table(monkeypatch, tmp_path):
    def missing():
        raise ImportError("no xarray")

    monkeypatch.setattr(crawlsim.study.sweep, "_xarray", missing)
    out = tmp_path / "s.h5"
    table = crawlsim.sweep(
        crawlsim.load_gait(INCHING), {"links.0.amplitude": [0.2, 0.3]}, steps_per_period=20, output=out
    )
    assert isinstance(table, crawlsim.study.sweep.SweepTable)
    np.testing.assert_allclose(table.columns()["v0"], [0.2, 0.4], atol=1e-13)
    assert out.exists()


@pytest.mark.parametrize("values", [[], [math.nan], ["a"], "0.1"])
def test_sweep_refuses_bad_values(values):
    with pytest.raises(SweepSpecError, match="finite numbers"):
        crawlsim.sweep(crawlsim.load_gait(INCHING), {"period": values})


def test_crawlsim_sweep_and_sensitivity_are_functions_with_signatures():
    """``crawlsim.sweep`` and ``crawlsim.sensitivity`` are the API's functions (real signatures,
    their own docstrings), whichever of the package and the module `crawlsim.study.sweep` was
    imported first (checked in a fresh interpreter for each order)."""
    for first in ("import crawlsim.study.sweep", "import crawlsim"):
        code = (
            f"{first}\nimport crawlsim, inspect, types\n"
            "import crawlsim.api as api\n"
            "assert crawlsim.sweep is api.sweep and crawlsim.sensitivity is api.sensitivity\n"
            "import importlib\n"
            "assert isinstance(importlib.import_module('crawlsim.study.sweep'), types.ModuleType)\n"
            "for f in (crawlsim.sweep, crawlsim.sensitivity):\n"
            "    params = inspect.signature(f).parameters\n"
            "    assert 'gait' in params, params\n"
            "    assert not any(p.kind is p.VAR_POSITIONAL for p in params.values())\n"
            "    assert f.__doc__ and 'module' not in f.__doc__.splitlines()[0]\n"
        )
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stderr


def test_import_crawlsim_stays_light():
    code = "import sys, crawlsim\nassert 'numpy' not in sys.modules, 'numpy'\nprint(crawlsim.__all__)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert "simulate" in done.stdout and "load_gait" in done.stdout


def test_py_typed_marker_ships():
    assert (ROOT / "crawlsim" / "py.typed").exists()
    assert '"py.typed"' in (ROOT / "pyproject.toml").read_text()


# -- docs/study.md --------------------------------------------------------------------------------
def test_the_study_in_the_docs_runs_and_says_what_it_finds(tmp_path, monkeypatch):
    """Run the Python blocks of docs/study.md in order, in a scratch folder holding the gaits,
    then check the claims its text makes about the table it prints."""
    pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    pytest.importorskip("pandas")
    text = (ROOT / "docs" / "study.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 3 and sum(b.count("\n") for b in blocks) <= 40
    os.symlink(GAITS, tmp_path / "gaits")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    out = io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    for block in blocks:
        exec(compile(block, "docs/study.md", "exec"), namespace)
    monkeypatch.undo()
    printed = {" ".join(line.split()) for line in out.getvalue().splitlines()}
    shown = re.findall(r"```\n(links\.\*\.amplitude.*?)```", text, flags=re.S)[0]
    for line in shown.strip().splitlines():  # the output the page shows is the output
        assert " ".join(line.split()) in printed, line
    v0 = namespace["v0"]
    amp = v0["links.*.amplitude"].values
    still = v0.sel(lag=0.0, method="nearest").values
    assert np.all(np.abs(still[amp <= 0.2 + 1e-12]) < 1e-12)
    np.testing.assert_allclose(still[amp > 0.2 + 1e-12], 2 * amp[amp > 0.2 + 1e-12] - 0.4, atol=1e-9)
    moving = v0.sel(lag=v0.lag[v0.lag > 0])
    assert np.all(moving.sel({"links.*.amplitude": amp[amp >= 0.15]}).values > 1e-3)
    assert abs(float(v0.sel({"lag": 0.1, "links.*.amplitude": 0.1}, method="nearest"))) < 5e-5
    assert np.all(v0.sel({"lag": v0.lag[v0.lag >= 0.2], "links.*.amplitude": 0.1}).values > 1e-3)
    assert np.all(np.diff(v0.values, axis=1) >= -1e-12)  # never decreases with the amplitude
    at = v0.sel({"links.*.amplitude": 0.4}, method="nearest").values  # lags 0, 0.1, ..., 0.5
    assert at[2] > at[3] and at[2] > at[4] and at[5] > at[2]
    assert (tmp_path / "peristalsis-4.h5").exists()
