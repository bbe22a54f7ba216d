"""Outputs never destroy data (crawlsim.io.outputs, crawlsim.io.atomic, the commands' -o/--force).

A command replaces only a crawlsim output of the same kind, never its input nor a special
file, nor an output another command is writing; temporary files are removed on failure, SIGINT
and SIGTERM, and stale ones of dead processes by the next write of the same target.
"""

import glob
import os
import signal
import stat
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.errors import OutputError
from crawlsim.io import atomic, outputs
from crawlsim.io.outputs import FIGURE, RUN, SWEEP, check_target, classify

GAIT = """\
blocks: 2
period: 1.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3}
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 50, max_periods: 20}
"""

#: A gait that runs for seconds with --check-every-step (Clarabel at every step, asymptotic
#: convergence at rate 1/2 to a tolerance it never reaches: about 40 periods, until the Poincare
#: step is at roundoff, 10 s on the CI machine).
SLOW = """\
blocks: 3
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.12}, 1.0]
friction: {forward: 1.0, backward: 1.5}
simulation: {steps_per_period: 2000, max_periods: 100000, tolerance: 1.0e-300}
"""


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(GAIT)
    return tmp_path


def invoke(*args):
    return CliRunner().invoke(main, list(args))


def refused(result, *phrases):
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for phrase in phrases:
        assert phrase in result.output, result.output


def test_the_gait_file_is_never_an_output(folder):
    for args in (
        ["run", "g.yaml", "-o", "g.yaml"],
        ["run", "g.yaml", "-o", "g.yaml", "--force"],
        ["velocity", "g.yaml", "--sweep", "period=1,2", "-o", "g.yaml", "--force"],
    ):
        refused(invoke(*args), "is the input file g.yaml", "even with --force")
    assert (folder / "g.yaml").read_text() == GAIT


def test_a_yaml_file_named_h5_is_not_overwritten_by_its_own_run(folder):
    """`crawlsim run gait.h5`: the default output <stem>.h5 is the input itself."""
    (folder / "gait.h5").write_text(GAIT)
    refused(invoke("run", "gait.h5"), "is the input file gait.h5")
    refused(invoke("run", "gait.h5", "--force"), "is the input file gait.h5")
    assert (folder / "gait.h5").read_text() == GAIT


def test_other_files_are_replaced_only_with_force(folder):
    (folder / "notes.txt").write_text("my notes\n")
    refused(invoke("run", "g.yaml", "-o", "notes.txt"), "exists and is not a crawlsim output", "--force")
    refused(invoke("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "notes.txt"), "not a crawlsim sweep table")
    assert (folder / "notes.txt").read_text() == "my notes\n"
    assert invoke("run", "g.yaml", "-o", "notes.txt", "--force").exit_code == 0
    assert classify(folder / "notes.txt") == RUN


def test_outputs_of_the_same_kind_are_replaced_and_other_kinds_refused(folder):
    assert invoke("run", "g.yaml", "-o", "r.h5").exit_code == 0
    assert invoke("run", "g.yaml", "-o", "r.h5").exit_code == 0  # a run over a run
    assert invoke("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "s.csv").exit_code == 0
    assert invoke("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "s.csv").exit_code == 0
    assert invoke("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "s.h5").exit_code == 0
    assert (classify(folder / "r.h5"), classify(folder / "s.csv"), classify(folder / "s.h5")) == (RUN, SWEEP, SWEEP)
    refused(invoke("run", "g.yaml", "-o", "s.h5"), "is a crawlsim sweep table")
    refused(invoke("run", "g.yaml", "-o", "s.csv"), "is a crawlsim sweep table")
    refused(invoke("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "r.h5"), "is a crawlsim run results file")
    with h5py.File(folder / "plain.h5", "w") as f:
        f["x"] = [1.0]
    refused(invoke("run", "g.yaml", "-o", "plain.h5"), "not a crawlsim output")
    (folder / "empty.h5").write_bytes(b"")
    assert invoke("run", "g.yaml", "-o", "empty.h5").exit_code == 0  # nothing to lose


def test_figures_replace_images_of_their_format_only(folder):
    assert invoke("run", "g.yaml", "-o", "r.h5").exit_code == 0
    (folder / "r-motion.png").write_text("not an image")
    refused(invoke("plot", "r.h5", "--only", "motion"), "r-motion.png", "not a figure")
    assert invoke("plot", "r.h5", "--only", "motion", "--force").exit_code == 0
    assert classify(folder / "r-motion.png") == "figure:png"
    assert invoke("plot", "r.h5", "--only", "motion").exit_code == 0  # an image over an image
    (folder / "g-sweep.png").write_text("not an image")  # velocity --plot's figure, beside the gait
    refused(invoke("velocity", "g.yaml", "--sweep", "period=1,2", "--plot"), "g-sweep.png", "not a figure")


def test_special_files_are_refused_even_with_force(folder):
    refused(invoke("run", "g.yaml", "-o", "/dev/null", "--force"), "is a device")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    os.mkfifo(folder / "pipe.h5")
    refused(invoke("run", "g.yaml", "-o", "pipe.h5", "--force"), "is a FIFO")
    assert stat.S_ISFIFO(os.stat(folder / "pipe.h5").st_mode)
    refused(invoke("run", "g.yaml", "-o", str(folder)), str(folder))  # click refuses a folder


def test_publish_refuses_a_target_that_became_special(folder):
    """The rename itself checks again: a FIFO made after the command's check survives."""
    with pytest.raises(OutputError, match="FIFO"):
        with atomic.atomic_path(folder / "late.h5") as tmp:
            tmp.write_text("data")
            os.mkfifo(folder / "late.h5")
    assert stat.S_ISFIFO(os.stat(folder / "late.h5").st_mode)
    assert not glob.glob(str(folder / ".late.h5.*"))


def test_missing_or_unwritable_folder_is_exit_2_naming_it(folder, monkeypatch):
    refused(invoke("run", "g.yaml", "-o", "no/such/out.h5"), f"the folder {folder / 'no' / 'such'} does not exist")
    refused(invoke("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "no/s.csv"), "does not exist")
    locked = folder / "locked"
    locked.mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: os.path.abspath(path) != str(locked))
    with pytest.raises(OutputError, match="is not writable"):
        check_target(locked / "out.h5", RUN)


def test_a_folder_that_refuses_the_temporary_file_is_an_output_error(folder, monkeypatch):
    """Root passes os.access everywhere; a read-only file system still fails at mkstemp."""

    def read_only(*args, **kwargs):
        raise OSError(30, "Read-only file system")

    monkeypatch.setattr(atomic.tempfile, "mkstemp", read_only)
    with pytest.raises(OutputError, match="cannot write in the folder .*Read-only file system"):
        atomic.temporary_beside(folder / "out.h5")


def dead_pid():
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_temporary_files_of_dead_processes_are_removed(folder):
    host = atomic._HOST
    stale = folder / f".r.h5.{host}.{dead_pid()}.abcd1234.tmp"
    live = folder / f".r.h5.{host}.{os.getpid()}.abcd1234.tmp"
    elsewhere = folder / f".r.h5.otherhost.{dead_pid()}.abcd1234.tmp"
    other_target = folder / f".x.h5.{host}.{dead_pid()}.abcd1234.tmp"
    for path in (stale, live, elsewhere, other_target):
        path.write_bytes(b"partial")
    assert invoke("run", "g.yaml", "-o", "r.h5").exit_code == 0
    assert not stale.exists()
    assert live.exists() and elsewhere.exists() and other_target.exists()


def start_slow_run(folder):
    (folder / "slow.yaml").write_text(SLOW)
    # the same run for two periods first, so that the compiled kernel is in numba's cache and
    # the signal below arrives while periods are written, not during the first compilation
    subprocess.run(
        [
            sys.executable,
            "-m",
            "crawlsim",
            "run",
            "slow.yaml",
            "-o",
            "warm.h5",
            "--check-every-step",
            "--max-periods",
            "2",
            "--quiet",
        ],
        cwd=folder,
        capture_output=True,
        timeout=900,
        check=False,
    )
    child = subprocess.Popen(
        [sys.executable, "-m", "crawlsim", "run", "slow.yaml", "-o", "slow.h5", "--check-every-step"],
        cwd=folder,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    began = time.monotonic()
    while not glob.glob(str(folder / ".slow.h5.*.tmp")):
        assert child.poll() is None, child.communicate()
        assert time.monotonic() - began < 60, "no temporary file appeared"
        time.sleep(0.05)
    time.sleep(0.3)  # well into writing periods
    return child


@pytest.mark.slow  # a slow run, signalled, in a subprocess
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_no_temporary_file_survives_sigterm_or_sigint(folder, signum):
    child = start_slow_run(folder)
    child.send_signal(signum)
    _, err = child.communicate(timeout=60)
    # the shell conventions for a process ended by a signal: 128 + 15 and 128 + 2
    assert child.returncode == {signal.SIGTERM: 143, signal.SIGINT: 130}[signum], err[-3000:]
    assert b"Traceback" not in err
    assert not glob.glob(str(folder / ".slow.h5*"))
    assert not (folder / "slow.h5").exists()


def test_unchecked_uniqueness_is_warned_and_recorded(folder):
    """50 blocks of distinct friction are beyond the exact check; the file opts in."""
    n = 50
    rng = np.random.default_rng(3)
    friction = "".join(
        f"  - {{forward: {float(f)!r}, backward: {float(b)!r}}}\n"
        for f, b in zip(rng.uniform(1, 2, n), rng.uniform(2, 3, n))
    )
    text = (
        f"blocks: {n}\nperiod: 1.0\nstiffness: 10.0\nlinks: ["
        + ", ".join(["1.0"] * (n - 1))
        + "]\nfriction:\n"
        + friction
        + "simulation: {steps_per_period: 4, max_periods: 3, unchecked_uniqueness: true}\n"
    )
    (folder / "wide.yaml").write_text(text)
    result = CliRunner().invoke(main, ["run", "wide.yaml", "-o", "wide.h5"])
    assert result.exit_code == 0, result.output
    assert "Warning: wide.yaml: the uniqueness condition" in result.output
    with h5py.File(folder / "wide.h5") as f:
        assert f.attrs["unchecked_uniqueness"] == 1
    assert invoke("run", "g.yaml", "-o", "r.h5").exit_code == 0
    with h5py.File(folder / "r.h5") as f:
        assert f.attrs["unchecked_uniqueness"] == 0
    refused(invoke("run", "wide.yaml", "-o", "no.h5", "--max-periods", "0"), "max-periods")


def test_check_target_kinds_directly(folder):
    assert check_target(folder / "new.h5", RUN) == folder / "new.h5"
    (folder / "old.png").write_bytes(b"\x89PNG\r\n\x1a\n....")
    assert check_target(folder / "old.png", FIGURE) == folder / "old.png"
    with pytest.raises(OutputError, match="a PNG image, not a crawlsim sweep table"):
        check_target(folder / "old.png", SWEEP)
    (folder / "table.csv").write_text(
        "period,v0,displacement_per_period,convergence,periods,status,message\n1,0.4,0.4,finite-time,2,ok,\n"
    )
    assert classify(folder / "table.csv") == SWEEP
    (folder / "other.csv").write_text("a,b\n1,2\n")
    assert classify(folder / "other.csv") is None


def test_write_best_replaces_only_a_gait_crawlsim_optimize_wrote(folder):
    """``optimize --write-best`` follows the rule of every output: a text file of notes, or a
    run's results file, is refused before any work (it used to become a gait); a gait file
    crawlsim optimize wrote, an empty file, or any file with --force may be replaced."""
    (folder / "notes.txt").write_text("my notes\n")
    assert invoke("run", "g.yaml", "-o", "r.h5").exit_code == 0
    for target, what in (("notes.txt", "not a crawlsim output"), ("r.h5", "a crawlsim run results file")):
        result = invoke("optimize", "g.yaml", "--free", "links.1.phase=0:1", "-o", "o.h5", "--write-best", target)
        refused(result, f"--write-best {target}", what, "not a gait file written by crawlsim optimize", "--force")
    assert (folder / "notes.txt").read_text() == "my notes\n" and classify(folder / "r.h5") == RUN
    assert not (folder / "o.h5").exists()
    (folder / "best.yaml").write_text("# written by crawlsim optimize: maximise v0\n" + GAIT)
    assert classify(folder / "best.yaml") == outputs.GAIT
    assert check_target(folder / "best.yaml", outputs.GAIT) == folder / "best.yaml"
    assert check_target(folder / "notes.txt", outputs.GAIT, force=True) == folder / "notes.txt"
    outputs.release()


def test_a_second_process_writing_the_same_output_is_refused_at_once(folder):
    """Two real processes: while a run writes slow.h5, another command given the same output
    exits 2 at once, naming the first (its process id), and writes nothing; the claim (a lock
    file beside the target) goes with the first command, on SIGTERM too, and the output can be
    written again after."""
    child = start_slow_run(folder)
    began = time.monotonic()
    second = subprocess.run(
        [sys.executable, "-m", "crawlsim", "run", "g.yaml", "-o", "slow.h5"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert time.monotonic() - began < 30  # refused at once: no run
    assert second.returncode == 2, second.stderr
    assert "--output slow.h5: is being written by another crawlsim command" in second.stderr
    assert f"process {child.pid} on " in second.stderr and "Traceback" not in second.stderr
    assert (folder / ".slow.h5.lock").exists() and not (folder / "slow.h5").exists()
    child.send_signal(signal.SIGTERM)
    assert child.wait(timeout=60) == 143
    assert not glob.glob(str(folder / ".slow.h5*"))  # the lock file with the temporary one
    assert invoke("run", "g.yaml", "-o", "slow.h5").exit_code == 0
    assert classify(folder / "slow.h5") == RUN and not (folder / ".slow.h5.lock").exists()
