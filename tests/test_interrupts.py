"""Where the command line raises Ctrl-C and SIGTERM (crawlsim.interrupts).

A signal that arrives in another library's code (here: a function of this test file, called
back by h5py's file driver the way libhdf5 calls `GuardedFile.write`) is noted and raised at the
next safe point; one that arrives in crawlsim's own code is raised at once; a second one is
raised at once wherever it arrives. An interrupted command publishes no file.
"""

import glob
import os
import signal
import sys

import pytest
from click.testing import CliRunner

from crawlsim import interrupts
from crawlsim.cli import main
from crawlsim.io import atomic

GAIT = """\
blocks: 2
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}]
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 50, max_periods: 20}
"""


def load_gait(text):
    import yaml

    from crawlsim.gait.document import gait_from_document

    return gait_from_document(yaml.safe_load(text), "g.yaml")


def _frame_in(filename):
    code = compile("import sys\nframe = sys._getframe()", filename, "exec")
    scope = {}
    exec(code, scope)
    return scope["frame"]


@pytest.fixture
def handlers():
    with interrupts.installed():
        yield
    assert interrupts.pending() is None


@pytest.mark.parametrize(
    "signum, raised", [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, interrupts.Terminated)]
)
def test_a_signal_in_another_librarys_code_waits_for_the_next_safe_point(handlers, signum, raised):
    interrupts._handler(signum, sys._getframe())  # this test file: not crawlsim's code
    assert interrupts.pending() == signum
    with pytest.raises(raised) as caught:
        interrupts.check()
    assert caught.type is raised
    assert interrupts.pending() is None
    interrupts.check()  # raised once only


def test_a_signal_in_crawlsims_own_code_is_raised_at_once(handlers):
    with pytest.raises(interrupts.Terminated):
        interrupts._handler(
            signal.SIGTERM, _frame_in(os.path.join(os.path.dirname(interrupts.__file__), "analysis", "run.py"))
        )
    assert interrupts.pending() is None


def test_the_write_callback_counts_as_another_librarys_code(handlers):
    interrupts._handler(signal.SIGINT, _frame_in(atomic.__file__))
    assert interrupts.pending() == signal.SIGINT
    with pytest.raises(KeyboardInterrupt):
        interrupts.check()


def test_a_second_signal_is_raised_at_once_and_stays_noted_in_another_librarys_code(handlers):
    interrupts._handler(signal.SIGINT, sys._getframe())
    with pytest.raises(KeyboardInterrupt):
        interrupts._handler(signal.SIGINT, sys._getframe())
    assert interrupts.pending() == signal.SIGINT  # should that library swallow it
    with pytest.raises(KeyboardInterrupt):
        interrupts.check()


def test_a_second_signal_in_crawlsims_own_code_is_raised_once(handlers):
    interrupts._handler(signal.SIGINT, sys._getframe())
    with pytest.raises(KeyboardInterrupt):
        interrupts._handler(
            signal.SIGINT, _frame_in(os.path.join(os.path.dirname(interrupts.__file__), "analysis", "run.py"))
        )
    assert interrupts.pending() is None


def test_no_signal_is_ever_raised_inside_the_write_callback(handlers):
    """Not even a second one: libhdf5 would swallow it and crash on the way out."""
    for _ in range(3):
        interrupts._handler(signal.SIGINT, _frame_in(atomic.__file__))
    assert interrupts.pending() == signal.SIGINT
    with pytest.raises(KeyboardInterrupt):
        interrupts.check()


@pytest.mark.parametrize("ending", [SystemExit(3), RuntimeError("a failure")])
def test_a_noted_signal_wins_over_how_the_command_ends(ending):
    with pytest.raises(interrupts.Terminated) as caught:
        with interrupts.installed():
            interrupts._handler(signal.SIGTERM, sys._getframe())
            raise ending
    assert caught.value.__cause__ is ending
    assert interrupts.pending() is None


def test_a_catch_up_sweep_point_stops_at_a_noted_signal(handlers):
    """Sweep points (crawlsim.study.points) run period by period: each period looks."""
    from crawlsim.gait.document import with_simulation
    from crawlsim.study.points import evaluate

    gait = with_simulation(load_gait(GAIT), integrator="catch-up", max_periods=5)
    assert evaluate([gait], [0])[0].status == "ok"
    interrupts._handler(signal.SIGINT, sys._getframe())
    with pytest.raises(KeyboardInterrupt):
        evaluate([gait], [0])
    assert interrupts.pending() is None


def test_a_noted_signal_stops_publish_and_the_temporary_file_goes(handlers, tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(KeyboardInterrupt):
        with atomic.atomic_path(target) as tmp:
            tmp.write_text("finished")
            interrupts._handler(signal.SIGINT, sys._getframe())
    assert not target.exists()
    assert not glob.glob(str(tmp_path / ".out.txt.*"))


def test_a_signal_still_noted_when_the_block_ends_is_raised_then():
    with pytest.raises(interrupts.Terminated):
        with interrupts.installed():
            interrupts._handler(signal.SIGTERM, sys._getframe())
    assert interrupts.pending() is None


def test_the_previous_handlers_come_back():
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with interrupts.installed():
        assert signal.getsignal(signal.SIGINT) is interrupts._handler
        assert signal.getsignal(signal.SIGTERM) is interrupts._handler
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def test_without_the_command_line_nothing_is_noted():
    """The Python API keeps Python's own handlers: check is a no-op."""
    assert signal.getsignal(signal.SIGINT) is not interrupts._handler
    interrupts.check()


@pytest.mark.parametrize("times", [1, 2], ids=["once", "twice"])
@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_an_hdf5_write_stops_the_run_with_no_file(tmp_path, monkeypatch, signum, code, times):
    """The signal arrives inside the write libhdf5 calls back (where an exception would be
    swallowed, the run would go on and its file would be published, and a second one would
    leave libhdf5 broken): the run stops at the end of its period, with the signal's exit code
    and no file, temporary or final, whether the signal comes once or twice."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(GAIT)
    write = atomic.GuardedFile._write
    sent = []

    def write_then_signal(self, data):  # called by GuardedFile.write: the callback's frames
        n = write(self, data)
        if len(sent) < times and os.path.basename(self.name).startswith(".r.h5."):
            sent.append(signum)
            os.kill(os.getpid(), signum)  # handled here, inside the callback
            assert interrupts.pending() == signum
        return n

    monkeypatch.setattr(atomic.GuardedFile, "_write", write_then_signal)
    result = CliRunner().invoke(main, ["run", "g.yaml", "-o", "r.h5", "--quiet"])
    assert sent == [signum] * times
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "r.h5").exists()
    assert not glob.glob(str(tmp_path / ".r.h5*"))
    assert interrupts.pending() is None


def test_a_signal_after_the_file_is_in_place_leaves_the_exit_code(tmp_path, monkeypatch):
    """A SIGTERM just after the results file is renamed into place (`interrupts.settle`): the
    command finishes as it would have, exit code 0 and its summary, the file complete (it used
    to end with 143, or, past the handlers, be killed without a word)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(GAIT)
    settle = interrupts.settle
    sent = []

    def settle_then_signal():
        settle()
        if not sent:
            sent.append(signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(interrupts, "settle", settle_then_signal)
    result = CliRunner().invoke(main, ["run", "g.yaml", "-o", "r.h5"])
    assert sent and result.exit_code == 0, result.output
    assert "written" in result.output and "Terminated" not in result.output
    from crawlsim.io.outputs import RUN, classify

    assert classify(tmp_path / "r.h5") == RUN and interrupts.pending() is None


def test_an_interrupted_sweep_names_no_journal_it_has_not_written(tmp_path, monkeypatch):
    """Ctrl-C before any point of a sweep finishes: the message says nothing was kept, and
    names no journal (it used to name OUT.journal, which did not exist)."""
    import crawlsim.study.sweep

    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(GAIT)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(crawlsim.study.sweep, "run_local", interrupted)
    result = CliRunner().invoke(main, ["velocity", "g.yaml", "--sweep", "period=1,2", "-o", "s.csv", "--quiet"])
    assert result.exit_code == 130, result.output
    assert "Interrupted: 0 of 2 points finished, nothing to keep." in result.output
    assert "journal" not in result.output and sorted(p.name for p in tmp_path.iterdir()) == ["g.yaml"]
