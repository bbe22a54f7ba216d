"""Feedback anywhere: progress lines on stderr when it is not a terminal (a batch job's log), a
bar on a terminal, nothing with --quiet; the estimate of a run's periods from the contraction
of its Poincare steps. Log lines are driven by a fake clock or a short interval, never by
sleeping."""

import io
import json
import math
import os
import re
import subprocess
import sys

import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.cli.progress import Progress, RunProgress, choose_mode, log_interval, periods_to_tolerance

from .conftest import GAITS

LINE = re.compile(
    r"^(?P<label>[\w.-]+): (?P<done>\d+)/(?P<about>~?)(?P<total>\d+) "
    r"(?P<unit>\w+)s \((?P<pct>\d+)%\), (?P<rate>[\d.e+-]+) \w+s/s, "
    r"elapsed \d+:\d\d:\d\d(, ETA \d+:\d\d:\d\d)?"
)


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_log_lines_follow_the_clock():
    """No line before the interval; then done/total, rate and ETA from the clock; a final line
    when the log printed anything; none at all for work shorter than the interval."""
    clock, out = Clock(), io.StringIO()
    p = Progress("velocity", "point", 10, mode="log", stream=out, interval=10, clock=clock, heartbeat=False)
    p.update(3)
    clock.now += 9.9
    assert not p.tick() and out.getvalue() == ""
    clock.now += 0.1  # 10 s: 3 points -> 0.3 points/s, 7 left -> ETA 23.3 s
    assert p.tick()
    line = out.getvalue().splitlines()[-1]
    m = LINE.match(line)
    assert m and (m["done"], m["total"], m["pct"], m["unit"]) == ("3", "10", "30", "point")
    assert float(m["rate"]) == pytest.approx(0.3) and line.endswith("ETA 0:00:23")
    assert not p.tick()  # not again until 10 s later
    clock.now += 10
    p.update(7)  # an update past the interval writes its own line
    assert len(out.getvalue().splitlines()) == 2
    p.close(complete=True)
    last = out.getvalue().splitlines()[-1]
    assert last.startswith("velocity: 10/10 points (100%)") and last.endswith(", done")

    quiet = io.StringIO()
    short = Progress("velocity", "point", 10, mode="log", stream=quiet, interval=10, clock=Clock(), heartbeat=False)
    short.update(10)
    short.close(complete=True)
    assert quiet.getvalue() == ""


def test_resumed_points_count_as_done_but_not_in_the_rate():
    clock, out = Clock(), io.StringIO()
    p = Progress("velocity", "point", 100, mode="log", stream=out, interval=5, clock=clock, heartbeat=False)
    p.skip(60)
    p.update(4)
    clock.now += 5
    p.tick()
    m = LINE.match(out.getvalue())
    assert m["done"] == "64" and float(m["rate"]) == pytest.approx(0.8)
    assert out.getvalue().strip().endswith("ETA 0:00:45")  # 36 left at 0.8 per second


def test_heartbeat_writes_while_a_unit_is_slow():
    """A unit that takes longer than the interval (one long period) still gets log lines: the
    heartbeat thread checks the clock between updates. The fake clock says a second has passed;
    the test waits for the thread's write, not for time."""
    import threading

    written = threading.Event()

    class Stream(io.StringIO):
        def write(self, text):
            n = super().write(text)
            written.set()
            return n

    clock, out = Clock(), Stream()
    p = Progress("run", "period", None, mode="log", stream=out, interval=1e-3, clock=clock)
    clock.now += 1.0
    assert written.wait(30)
    p.close()
    assert out.getvalue().startswith("run: 0 periods, 0 periods/s, elapsed 0:00:01")


def test_modes_and_interval(monkeypatch):
    class Tty(io.StringIO):
        def isatty(self):
            return True

    assert choose_mode(False, Tty()) == "bar" and choose_mode(False, io.StringIO()) == "log"
    assert choose_mode(True, Tty()) == "off"
    monkeypatch.setenv("CRAWLSIM_PROGRESS_INTERVAL", "2.5")
    assert log_interval() == 2.5
    for bad in ("0", "-1", "x", "nan"):
        monkeypatch.setenv("CRAWLSIM_PROGRESS_INTERVAL", bad)
        assert log_interval() == 10.0


def test_periods_to_tolerance_on_a_geometric_decay():
    """Poincare steps s_q = s_0 r^q reach the tolerance at the first q with s_0 r^q <= tol, so
    a run takes Q + 1 = ceil(log(tol / s_0) / log r) + 1 periods; the estimate made after any
    three periods is exactly that (the fitted rate is r to roundoff)."""
    r, s0, tol = 0.5, 1.0, 1e-12
    total = math.ceil(math.log(tol / s0) / math.log(r)) + 1  # 41
    steps = [s0 * r**q for q in range(total)]
    assert steps[total - 1] <= tol < steps[total - 2]
    for done in range(3, total + 1):
        assert periods_to_tolerance(steps[:done], tol, 1000) == total, done
    assert periods_to_tolerance(steps[:3], tol, 30) == 30  # capped by max_periods
    assert periods_to_tolerance(steps[:1], tol, 1000) is None  # no rate from one step
    assert periods_to_tolerance([1.0, 1.0, 1.0], tol, 77) == 77  # no contraction
    assert periods_to_tolerance([0.3, 0.0], tol, 77) == 2  # finite-time: converged


def test_run_progress_bar_total_follows_the_estimate():
    """On a terminal the bar's total is the estimate, updated every period, and a finite-time
    run that stops early ends with its count as the total."""

    class Tty(io.StringIO):
        def isatty(self):
            return True

    stream = Tty()
    run = RunProgress("gait", 1e-12, 1000, mode="bar", stream=stream)
    totals = []
    for q in range(5):
        run(q, 0.5**q)
        totals.append(run.progress.total)
    assert totals[0] is None and totals[2:] == [41, 41, 41]
    run(5, 0.0)  # the step falls to 0: periodic from here
    assert run.progress.total == 6
    run.close(complete=True)
    assert "gait" in stream.getvalue() and "41" in stream.getvalue()


SLOW = """\
name: slow
blocks: 3
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.12}, 1.0]
friction: {forward: 1.0, backward: 1.5}
simulation: {steps_per_period: 100, max_periods: 120}
"""


def _crawlsim(*args, interval="0.02"):
    env = {**os.environ, "CRAWLSIM_PROGRESS_INTERVAL": interval}
    return subprocess.run([sys.executable, "-m", "crawlsim", *map(str, args)], capture_output=True, text=True, env=env)


def test_a_run_without_a_terminal_logs_progress_lines(tmp_path):
    """stderr is a pipe (a SLURM log): lines with period counts against the estimated total
    (`~`), the Poincare step, and a final line; --quiet prints none, and stdout is the JSON."""
    gait = tmp_path / "slow.yaml"
    gait.write_text(SLOW)
    r = _crawlsim("run", gait, "--json", "-o", tmp_path / "slow.h5")
    assert r.returncode in (0, 3), r.stderr
    periods = json.loads(r.stdout)["periods"]
    lines = [m for m in map(LINE.match, r.stderr.splitlines()) if m]
    assert len(lines) >= 2, r.stderr
    assert all(m["label"] == "slow" and m["unit"] == "period" for m in lines)
    assert any(m["about"] == "~" for m in lines[:-1]) and "Poincare step" in r.stderr
    assert r.stderr.splitlines()[-1].endswith(", done")
    assert lines[-1]["done"] == lines[-1]["total"] == str(periods)
    quiet = _crawlsim("run", gait, "--json", "-q", "-o", tmp_path / "quiet.h5")
    assert quiet.stderr == "" and json.loads(quiet.stdout)["periods"] == periods


def test_a_sweep_without_a_terminal_logs_points(tmp_path):
    r = _crawlsim(
        "velocity",
        GAITS / "peristalsis-4.yaml",
        "--steps-per-period",
        "40",
        "--sweep",
        "links.*.amplitude=0.1:0.3:40",
        "-o",
        tmp_path / "s.csv",
    )
    assert r.returncode == 0, r.stderr
    lines = [m for m in map(LINE.match, r.stderr.splitlines()) if m]
    assert lines and all(m["total"] == "40" and m["unit"] == "point" for m in lines)
    done = [int(m["done"]) for m in lines]
    assert done == sorted(done) and done[-1] == 40
    assert r.stderr.splitlines()[-1].endswith(", done")


def test_verbose_and_quiet_exclude_each_other(tmp_path):
    r = CliRunner().invoke(main, ["velocity", str(GAITS / "inching-2.yaml"), "-q", "-v"])
    assert r.exit_code == 2 and "--quiet and --verbose" in r.output
