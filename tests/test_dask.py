"""Sweeps on a real Dask distributed cluster (scheduler and two worker processes on 127.0.0.1)
give the same table as a local run. CI installs the ``dask`` extra, so this is not skipped."""

import distributed
import h5py
import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.study import executors
from crawlsim.study import sweep as sweeps
from crawlsim.study.table import read_table
from tests.test_sweep import AMP, LAG, P4

#: Dask clusters start in seconds, and an unreachable scheduler is waited for: .ci/run runs them in its slow step
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scheduler():
    with distributed.LocalCluster(
        host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        yield cluster.scheduler_address


def test_dask_sweep_equals_local_run(scheduler):
    gait = with_simulation(load_gait(P4), steps_per_period=40)
    axes = ["links.*.amplitude=0.1:0.3:9", LAG]
    local = sweeps.sweep(gait, axes)
    remote = sweeps.sweep(gait, axes, scheduler=scheduler)
    assert remote.to_csv() == local.to_csv()
    assert remote.counts()["ok"] == 27


def test_dask_reports_progress_as_tasks_finish(scheduler, tmp_path):
    """Small tasks, collected as each finishes (distributed.as_completed): progress comes in
    steps of at most MIN_CHUNK points, not whole quarters of the grid; invalid points are
    recorded on the workers like locally; the journal is written as tasks come back."""
    gait = with_simulation(load_gait(P4), steps_per_period=40)
    axes = ["friction.backward=[0,2,2.5]", "links.*.amplitude=0.1:0.3:9"]
    calls, journaled = [], []
    out = tmp_path / "d.csv"
    table = sweeps.sweep(
        gait,
        axes,
        scheduler=scheduler,
        output=out,
        progress=calls.append,
        on_rows=lambda rows, resumed: journaled.append(len(rows)),
    )
    assert sum(calls) == 27 and max(calls) <= sweeps.MIN_CHUNK and len(calls) >= 4
    assert journaled == calls
    assert table.counts() == {"ok": 18, "not-converged": 0, "invalid": 9, "failed": 0}
    assert out.read_text() == sweeps.sweep(gait, axes).to_csv()


def test_dask_cli_writes_the_local_file(scheduler, tmp_path):
    run = CliRunner()
    args = ["velocity", P4, "--steps-per-period", "40", "--sweep", AMP, "--sweep", LAG]
    assert run.invoke(main, args + ["-o", str(tmp_path / "local.h5")]).exit_code == 0
    r = run.invoke(main, args + ["--scheduler", scheduler, "-o", str(tmp_path / "dask.h5")])
    assert r.exit_code == 0, r.output
    assert read_table(tmp_path / "dask.h5").to_csv() == read_table(tmp_path / "local.h5").to_csv()
    with h5py.File(tmp_path / "dask.h5") as f:
        assert f.attrs["integrator"] == "exact"  # what the rows ran


def test_unreachable_scheduler_is_bad_input(tmp_path, monkeypatch):
    monkeypatch.setattr(executors, "SCHEDULER_TIMEOUT", "1s")
    r = CliRunner().invoke(
        main,
        [
            "velocity",
            P4,
            "--steps-per-period",
            "40",
            "--sweep",
            AMP,
            "--scheduler",
            "tcp://127.0.0.1:1",
            "-o",
            str(tmp_path / "x.csv"),
        ],
    )
    assert r.exit_code == 2 and "cannot reach the Dask scheduler" in r.output
    assert not (tmp_path / "x.csv").exists()
