"""Progress on stderr wherever a command runs: a terminal, a batch job's log, or nowhere.

* **bar**: stderr is a terminal. A tqdm bar over a total that is known (points of a sweep) or
  estimated and refined as the run goes (periods of a run: `periods_to_tolerance`).
* **log**: stderr is not a terminal (a SLURM or PBS log, a pipe). One line at least every
  `interval` seconds (``CRAWLSIM_PROGRESS_INTERVAL``, default 10): done/total, rate, ETA. A run
  shorter than the interval prints nothing, so shell loops of short commands stay quiet; a run
  that printed lines ends with a final one.
* **off**: ``--quiet``. Warnings and errors are still printed.

This module imports nothing heavy: every command loads it.
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import IO, Any

from crawlsim.gait.settings import effective_tolerance

#: Seconds between two log lines when stderr is not a terminal.
DEFAULT_INTERVAL = 10.0
#: Environment variable that overrides `DEFAULT_INTERVAL` (seconds, > 0).
INTERVAL_ENV = "CRAWLSIM_PROGRESS_INTERVAL"


def log_interval() -> float:
    """The log interval: ``CRAWLSIM_PROGRESS_INTERVAL`` if it is a positive number, else 10 s."""
    text = os.environ.get(INTERVAL_ENV, "")
    try:
        value = float(text)
    except ValueError:
        return DEFAULT_INTERVAL
    return value if math.isfinite(value) and value > 0 else DEFAULT_INTERVAL


def choose_mode(quiet: bool, stream: IO[str] | None = None) -> str:
    """``off`` when quiet, ``bar`` on a terminal, ``log`` elsewhere."""
    stream = sys.stderr if stream is None else stream
    if quiet:
        return "off"
    isatty = getattr(stream, "isatty", None)
    return "bar" if isatty is not None and isatty() else "log"


def _clock_text(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"


class Progress:
    """Counts work done against a total that may be unknown (None) or change as it is estimated.

    Thread-safe: worker-pool progress arrives on a reader thread. ``clock`` and
    ``heartbeat=False`` let tests drive the log lines without sleeping (call `tick`).
    """

    def __init__(
        self,
        label: str,
        unit: str,
        total: int | None = None,
        *,
        mode: str = "log",
        stream: IO[str] | None = None,
        interval: float | None = None,
        clock: Callable[[], float] = time.monotonic,
        heartbeat: bool = True,
        estimated: bool = False,
    ):
        self.label, self.unit = label, unit
        self.total, self.estimated = total, estimated
        self.mode = mode
        self.stream = sys.stderr if stream is None else stream
        self.interval = log_interval() if interval is None else float(interval)
        self.clock = clock
        self.done = 0  # units finished, `initial` ones included
        self.initial = 0  # units finished before this run started (a resumed sweep)
        self.note = ""
        self.lines = 0  # log lines written
        self._lock = threading.RLock()
        self._start = self._last = clock()
        self._bar: Any = None  # a tqdm bar (untyped), made by _ensure_bar
        self._closed = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if mode == "log" and heartbeat:
            # A slow unit (a long period, a slow point) must not silence the log: a daemon
            # thread checks the clock between updates.
            self._thread = threading.Thread(target=self._beat, name="crawlsim-progress", daemon=True)
            self._thread.start()

    # -- counting ----------------------------------------------------------------------------
    def _ensure_bar(self):
        """The tqdm bar, made at the first event so that resumed units are its ``initial``
        count (tqdm's rate and ETA then count this run's work only)."""
        if self._bar is None and self.mode == "bar" and not self._closed:
            from tqdm import tqdm

            self._bar = tqdm(
                total=self.total,
                initial=self.done,
                unit=self.unit,
                file=self.stream,
                leave=False,
                dynamic_ncols=True,
                desc=self.label,
            )
            if self.note:
                self._bar.set_postfix_str(self.note)
        return self._bar

    def skip(self, n: int) -> None:
        """``n`` units were finished before this run (resumed from a journal): counted as done,
        not in the rate."""
        with self._lock:
            self.initial += n
            self.done += n
            if self._bar is not None:
                self._bar.update(n)

    def update(self, n: int = 1) -> None:
        with self._lock:
            self.done += n
            bar = self._ensure_bar()
            if bar is not None:
                bar.update(n)
            else:
                self.tick()

    def set_total(self, total: int | None, estimated: bool | None = None) -> None:
        with self._lock:
            if estimated is not None:
                self.estimated = estimated
            if total == self.total:
                return
            self.total = total
            bar = self._ensure_bar()
            if bar is not None:
                bar.total = total
                bar.refresh()

    def set_note(self, text: str) -> None:
        with self._lock:
            self.note = text
            if self._bar is not None:
                self._bar.set_postfix_str(text, refresh=False)

    def message(self, text: str) -> None:
        """A line for the user (``--verbose`` detail) that does not break the bar."""
        with self._lock:
            if self._bar is not None:
                self._bar.write(text, file=self.stream)
            else:
                print(text, file=self.stream, flush=True)

    # -- log lines ---------------------------------------------------------------------------
    def rate(self) -> float:
        """Units per second of this run (resumed units excluded)."""
        elapsed = self.clock() - self._start
        return (self.done - self.initial) / elapsed if elapsed > 0 else 0.0

    def line(self) -> str:
        """``label: done/total unit (pct%), rate unit/s, elapsed, ETA`` (the log line)."""
        with self._lock:
            elapsed = self.clock() - self._start
            rate = self.rate()
            parts = []
            if self.total:
                about = "~" if self.estimated else ""
                pct = 100.0 * self.done / self.total
                parts.append(f"{self.done}/{about}{self.total} {self.unit}s ({pct:.0f}%)")
            else:
                parts.append(f"{self.done} {self.unit}s")
            parts.append(f"{rate:.3g} {self.unit}s/s")
            parts.append(f"elapsed {_clock_text(elapsed)}")
            if self.total and rate > 0:
                left = max(self.total - self.done, 0) / rate
                parts.append(f"ETA {_clock_text(left)}")
            if self.note:
                parts.append(self.note)
            jit = sys.modules.get("crawlsim.kernel.jit")  # loaded by whatever runs the kernel
            if jit is not None and jit.compiling():
                parts.append(jit.compiling())
            return f"{self.label}: " + ", ".join(parts)

    def tick(self) -> bool:
        """Write a log line if `interval` has passed since the last one (or since the start)."""
        with self._lock:
            if self.mode != "log" or self.clock() - self._last < self.interval:
                return False
            self._last = self.clock()
            self.lines += 1
            print(self.line(), file=self.stream, flush=True)
            return True

    def _beat(self) -> None:
        while not self._stop.wait(min(self.interval / 4, 1.0)):
            self.tick()

    # -- the end -------------------------------------------------------------------------------
    def close(self, complete: bool = False) -> None:
        """Stop; a finished run's total becomes its count, and a log that printed lines ends
        with a final one."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        with self._lock:
            self._closed = True
            if complete:
                self.total, self.estimated = self.done, False
            if self._bar is not None:
                if complete:
                    self._bar.total = self.done
                    self._bar.refresh()
                self._bar.close()
                self._bar = None
            elif self.mode == "log" and self.lines:
                self.lines += 1
                print(self.line() + (", done" if complete else ", stopped"), file=self.stream, flush=True)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(complete=exc_type is None)


def periods_to_tolerance(rel_steps, tolerance: float, max_periods: int) -> int | None:
    """The total number of periods a run will take, estimated from its relative Poincare steps.

    Asymptotic convergence is geometric (docs/model.md §4): the steps contract as
    ``s_{q+1} ~ r s_q`` with the contraction rate r fitted by
    `crawlsim.analysis.run.contraction_rate`. The step after period q then falls to the tolerance
    after ``ceil(log(tol / s_q) / log r)`` more periods. None when there is no rate yet (fewer
    than two informative steps); ``max_periods`` when the steps do not contract.
    """
    import numpy as np

    from crawlsim.analysis.convergence import contraction_rate  # start-up: numpy once a run reports

    steps = np.asarray(rel_steps, dtype=float)
    done = len(steps)
    tol = effective_tolerance(tolerance)
    if done == 0:
        return None
    if steps[-1] <= tol:
        return done
    rate = contraction_rate(steps)
    if rate is None:
        return None
    if not rate < 1:
        return max_periods
    more = math.ceil(math.log(tol / steps[-1]) / math.log(rate) - 1e-9)
    return min(max_periods, done + max(more, 1))


class RunProgress:
    """Progress over the periods of one run: ``callback(q, rel_step)`` for
    `crawlsim.analysis.run.simulate`, with the total re-estimated after every period."""

    def __init__(self, label: str, tolerance: float, max_periods: int, *, mode: str, verbose: bool = False, **options):
        self.tolerance, self.max_periods, self.verbose = tolerance, max_periods, verbose
        self.steps: list[float] = []
        self.progress = Progress(label, "period", None, mode=mode, estimated=True, **options)

    def __call__(self, q: int, rel_step: float) -> None:
        self.steps.append(float(rel_step))
        self.progress.set_total(periods_to_tolerance(self.steps, self.tolerance, self.max_periods))
        self.progress.set_note(f"Poincare step {rel_step:.2e}")
        if self.verbose:
            self.progress.message(f"period {q}: relative Poincare step {rel_step:.3e}")
        self.progress.update(1)

    def close(self, complete: bool = False) -> None:
        self.progress.close(complete)

    def __enter__(self) -> RunProgress:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(complete=exc_type is None)
