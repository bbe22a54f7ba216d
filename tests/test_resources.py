"""Memory estimated before a run (crawlsim.integrate.resources) and the --max-memory refusal.

The estimate must bound the peak memory a run really allocates: measured here with
tracemalloc (which sees numpy's allocations; Clarabel's own are outside the Python heap and
small) on crawlers of several shapes, with both integrators, and on a sweep batch.
"""

import resource
import subprocess
import sys
import tracemalloc

import pytest
from click.testing import CliRunner

from crawlsim import api
from crawlsim.cli import main
from crawlsim.errors import ResourceError
from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.resources import (
    DEFAULT_CAP,
    check_memory,
    default_limit,
    format_size,
    gait_memory,
    parse_size,
    run_memory,
)
from crawlsim.study import sweep as sweeps


def crawler(n, steps, periods=4, integrator="catch-up"):
    return gait_from_document(
        {
            "blocks": n,
            "period": 1.0,
            "stiffness": 10.0,
            "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": (0.37 * i) % 1} for i in range(n - 1)],
            "friction": {"forward": 1.0, "backward": 2.5 + 1e-3 * n},
            "simulation": {"steps_per_period": steps, "max_periods": periods, "integrator": integrator},
        },
        "memory.yaml",
    )


def peak_of(action):
    tracemalloc.start()
    try:
        action()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.fixture(scope="module", autouse=True)
def warm(tmp_path_factory):
    """Import everything a run uses before measuring, so imports are not counted."""
    folder = tmp_path_factory.mktemp("warm")
    api.run(crawler(3, 20, 2, "exact"), output=folder / "w.h5")
    sweeps.sweep(crawler(3, 20, 2), ["period=1,2"])


@pytest.mark.parametrize(
    "n, steps, integrator",
    [
        (2, 1000, "catch-up"),
        (4, 20000, "catch-up"),
        (50, 200, "catch-up"),
        (200, 20, "catch-up"),
        (4, 2000, "exact"),
        (10, 200, "exact"),
    ],
)
def test_estimate_bounds_the_measured_peak_of_a_run(n, steps, integrator, tmp_path):
    gait = crawler(n, steps, integrator=integrator)
    measured = peak_of(lambda: api.run(gait, output=tmp_path / "r.h5", save_every=3))
    estimate = gait_memory(gait, save_every=3)
    assert measured <= estimate.total, (measured, estimate)
    assert estimate.total <= 40 * max(measured, 1 << 20)  # an upper bound, not a wild one


def test_estimate_bounds_the_measured_peak_of_a_sweep_batch():
    gait = crawler(4, 500, periods=6)
    points = 64
    measured = peak_of(lambda: sweeps.sweep(gait, [f"period=0.5:2:{points}"]))
    assert measured <= gait_memory(gait, batch=points).total


def test_estimate_grows_as_the_arrays_do():
    """(G+1) x N tables, and the dense n^2 matrices of a generic process: doubling G doubles
    the per-period part, doubling the dimension quadruples the dense part. A crawler has no
    N^2 part (the chain kernel is O(N))."""
    small, long_, wide = run_memory(10, 1000), run_memory(10, 2000), run_memory(20, 1000)
    offsets = "tabulated offsets c(t)"
    assert dict(long_.parts)[offsets] == 2 * dict(small.parts)[offsets]
    dense = "dense matrices of the projector"
    assert dense not in dict(small.parts)
    # O(N): 20 blocks against 10 is at most (20 - 1) / (10 - 1) ~ 2.1 times any part, but the
    # periodic-limit solver's Jacobian, dense (N^2) up to crawlsim.integrate.limit.DENSE_JACOBIAN unknowns
    jacobian = "the periodic-limit solver's Jacobian"
    for name, size in wide.parts:
        ratio = size / dict(small.parts)[name]
        assert ratio <= 2.2 or (name == jacobian and ratio == pytest.approx((19 / 9) ** 2)), name
    generic, twice = run_memory(10, 1000, dense=True), run_memory(20, 1000, dense=True)
    assert dict(twice.parts)[dense] == 4 * dict(generic.parts)[dense]
    assert run_memory(10, 1001, integrator="exact").total > small.total
    assert run_memory(10, 1001, batch=100).total > small.total


@pytest.mark.parametrize(
    "text, size",
    [
        ("4GiB", 4 << 30),
        ("500MB", 500_000_000),
        ("2G", 2 << 30),
        ("1.5 MiB", 3 << 19),
        ("1000000", 1_000_000),
        ("64k", 65536),
        ("3kb", 3000),
    ],
)
def test_parse_size(text, size):
    assert parse_size(text) == size


@pytest.mark.parametrize("text", ["", "lots", "-1GB", "4 GiBs", "0", "1e3MB", "inf"])
def test_parse_size_refuses(text):
    with pytest.raises(ValueError):
        parse_size(text)


def test_check_memory_names_estimate_and_limit():
    estimate = run_memory(100_000, 1001)
    with pytest.raises(ResourceError) as info:
        check_memory(estimate, 500 << 20, "big.yaml")
    message = str(info.value)
    assert message.startswith("big.yaml: this run would need about")
    assert "tabulated offsets c(t)" in message
    assert f"more than the memory limit of {format_size(500 << 20)}" in message


def test_default_limit_is_capped_and_follows_the_address_space_limit():
    assert 0 < default_limit() <= DEFAULT_CAP

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (600 << 20, 600 << 20))

    code = "from crawlsim.integrate.resources import default_limit; print(default_limit())"
    out = subprocess.run([sys.executable, "-c", code], preexec_fn=limit, capture_output=True, text=True, check=True)
    assert 0 < int(out.stdout) <= 300 << 20  # half the headroom under 600 MB at most


def test_max_memory_option(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(
        "blocks: 3\nperiod: 1.0\nstiffness: 10.0\nlinks: [{kind: cosine, mean: 1.0, amplitude: 0.3}, 1.0]\n"
        "friction: {forward: 1.0, backward: 2.5}\nsimulation: {steps_per_period: 100000}\n"
    )
    runner = CliRunner()
    for args in (
        ["run", "g.yaml", "--max-memory", "10MB"],
        ["velocity", "g.yaml", "--max-memory", "10MB"],
        ["velocity", "g.yaml", "--sweep", "period=1,2", "--max-memory", "10MB"],
        ["velocity", "g.yaml", "--sweep", "simulation.steps_per_period=10,10000000", "--max-memory", "1GiB"],
    ):
        result = runner.invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        assert "g.yaml: this" in result.output and "more than the memory limit" in result.output
    assert not (tmp_path / "g.h5").exists()
    result = runner.invoke(main, ["run", "g.yaml", "--max-memory", "lots"])
    assert result.exit_code == 2 and "expected a size such as 4GiB" in result.output
    result = runner.invoke(
        main, ["velocity", "g.yaml", "--max-memory", "2GiB", "--steps-per-period", "100", "--max-periods", "5"]
    )
    assert result.exit_code in (0, 3), result.output


@pytest.mark.parametrize("option", ["--tolerance"])
@pytest.mark.parametrize("value", ["inf", "nan", "-inf", "1e999"])
def test_float_options_refuse_non_finite_values(option, value, tmp_path):
    (tmp_path / "g.yaml").write_text(
        "blocks: 2\nperiod: 1.0\nstiffness: 10.0\nlinks: [1.0]\nfriction: {forward: 1.0, backward: 2.0}\n"
    )
    for command in ("run", "velocity"):
        result = CliRunner().invoke(main, [command, str(tmp_path / "g.yaml"), option, value])
        assert result.exit_code == 2, result.output
        assert "Traceback" not in result.output


# -- time: the cost of the signals (issue 19, item 12) ----------------------------------------
def fourier_gait(blocks, harmonics, integrator="exact"):
    """Every link a Fourier series of ``harmonics`` equal cosine terms (amplitude 0.3 in all)."""
    link = {"kind": "fourier", "mean": 1.0, "cos": [0.3 / harmonics] * harmonics}
    return {
        "blocks": blocks,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [link] * (blocks - 1),
        "friction": {"forward": 1.0, "backward": 2.5},
        "simulation": {"integrator": integrator},
    }


def test_signal_work_grows_with_harmonics_and_blocks():
    """The estimate is of order H^2 (TRIG_COST + 2N) a period: doubling H multiplies it by about
    4 (exactly 2 (4H + 1) / (2H + 1)); signals of at most one harmonic (closed-form events) cost
    only their tabulation."""
    from crawlsim.integrate.resources import TRIG_COST, signal_work

    one, two = signal_work(100, 4, 1001), signal_work(200, 4, 1001)
    assert two.per_period / one.per_period == pytest.approx(2 * 401 / 201)
    more = signal_work(100, 80, 1001)
    assert more.per_period / one.per_period == pytest.approx((TRIG_COST + 80) / (TRIG_COST + 4))
    assert signal_work(1, 2000, 1001).per_period == 0.0
    assert signal_work(1, 2000, 1001).tabulation == 1001 * 3 * (TRIG_COST + 2000)


@pytest.mark.parametrize("blocks, integrator", [(2, "exact"), (2, "catch-up"), (40, "exact")])
def test_a_gait_whose_signals_would_not_finish_is_refused_before_it_runs(tmp_path, monkeypatch, blocks, integrator):
    """The issue's gaits: 2 blocks with a Fourier link of 1000 harmonics ran for over a minute
    with either integrator, 40 such blocks finished no period in 2 minutes. Both are refused by
    the estimate (exit 2, the signal's key, how to reduce the cost) before anything runs: the
    simulation and the sweep fail this test if they start."""
    import yaml

    from crawlsim.gait.document import load_gait
    from crawlsim.integrate.resources import MAX_SIGNAL_WORK, gait_signal_work

    monkeypatch.chdir(tmp_path)
    (tmp_path / "f.yaml").write_text(yaml.safe_dump(fourier_gait(blocks, 1000, integrator)))
    assert gait_signal_work(load_gait(tmp_path / "f.yaml")).run > MAX_SIGNAL_WORK

    def computed(*args, **kwargs):
        raise AssertionError("the run started")

    import crawlsim.design.optimize

    monkeypatch.setattr(api, "run", computed)
    monkeypatch.setattr(sweeps, "run_sweep", computed)
    monkeypatch.setattr(crawlsim.design.optimize, "optimize", computed)
    for args in (
        ["run", "f.yaml"],
        ["velocity", "f.yaml"],
        ["velocity", "f.yaml", "--sweep", "period=1,2", "-o", "s.csv"],
        ["optimize", "f.yaml", "--free", "period=1:2", "--max-evaluations", "2"],
    ):
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 2, result.output
        message = result.output.strip()
        assert len(message.splitlines()) == 1 and "Traceback" not in message
        assert "f.yaml: links[0]: a signal of 1,000 harmonics" in message
        assert "use fewer harmonics" in message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.yaml"]


def test_gaits_of_few_harmonics_are_not_refused():
    """A Fourier link of 50 harmonics on 2 blocks, and 1000 blocks of cosine links (closed-form
    events; docs/large-crawlers.md), are within the estimate."""
    from crawlsim.integrate.resources import MAX_SIGNAL_WORK, gait_signal_work

    small = gait_from_document(fourier_gait(2, 50), "small.yaml")
    assert gait_signal_work(small).run < MAX_SIGNAL_WORK / 100
    assert gait_signal_work(crawler(1000, 1000)).run < MAX_SIGNAL_WORK / 100


def test_a_journal_that_is_not_a_regular_file_is_refused(tmp_path):
    """OUT.journal a FIFO: the sweep opened it and waited for a reader forever. Now exit 2
    before any point runs (in a subprocess with a time limit, so that a regression fails
    instead of hanging the suite)."""
    import os

    gait = tmp_path / "g.yaml"
    gait.write_text(
        "blocks: 2\nperiod: 1.0\nstiffness: 10.0\nlinks: [{kind: cosine, mean: 1.0, "
        "amplitude: 0.3}]\nfriction: {forward: 1.0, backward: 2.5}\n"
    )
    os.mkfifo(tmp_path / "s.csv.journal")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "crawlsim",
            "velocity",
            str(gait),
            "--sweep",
            "period=1,2",
            "-o",
            str(tmp_path / "s.csv"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.strip() == (
        f"Error: {tmp_path / 's.csv.journal'}: is a FIFO (named pipe), "
        "not a regular file: the journal of a sweep must be a regular "
        "file; remove it, or choose another output name"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.yaml", "s.csv.journal"]
