"""Where the points of a sweep run: in this process, on local worker processes, or on a Dask
cluster, in tasks sized to take about `TASK_SECONDS` each (`Chunker`); ``collect(rows)``
receives each finished task's rows, in the order tasks finish."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from crawlsim import interrupts
from crawlsim.errors import SweepSpecError
from crawlsim.study.points import run_points

#: Points per task handed to a worker. Small tasks keep progress and the journal moving; large
#: ones pay a task's overhead once for many points. Task sizes adapt between the two to take
#: about `TASK_SECONDS` each.
MIN_CHUNK = 8
MAX_CHUNK = 256
TASK_SECONDS = 2.0
#: How often the wait for workers (local or Dask) looks for a Ctrl-C noted meanwhile
#: (`crawlsim.interrupts`, `_collect_as_ready`).
WAIT_SECONDS = 0.2
#: How long to wait for a Dask scheduler before giving up (exit code 2).
SCHEDULER_TIMEOUT = "20s"
#: Modules a fresh local worker imports before its first task.
_PRELOAD = ["crawlsim.study.points"]


class Chunker:
    """Hands out the points still to do as tasks sized to take about `TASK_SECONDS` on one
    worker, at the rate measured so far (`MIN_CHUNK` until the first task is back); the last
    tasks shrink so that the workers finish together."""

    def __init__(self, todo: np.ndarray, workers: int):
        self.todo = np.asarray(todo, dtype=np.int64)
        self.workers = max(1, int(workers))
        self.pos = 0
        self.points = 0
        self.seconds = 0.0

    def record(self, points: int, seconds: float) -> None:
        self.points += points
        self.seconds += seconds

    def take(self) -> np.ndarray | None:
        left = len(self.todo) - self.pos
        if left <= 0:
            return None
        size = MIN_CHUNK
        if self.seconds > 0:
            size = round(self.points / self.seconds * TASK_SECONDS)
        size = max(MIN_CHUNK, min(MAX_CHUNK, size, math.ceil(left / self.workers)))
        chunk = self.todo[self.pos : self.pos + size]
        self.pos += len(chunk)
        return chunk


#: What starting local workers costs besides their warm-up, in seconds (the forkserver imports
#: numpy and crawlsim, then forks), and the least share of the serial time that the workers
#: must save beyond it and their warm-up: below, a sweep runs here (`run_local`).
POOL_START_SECONDS = 1.0
POOL_MIN_GAIN = 0.2


def _run_chunk(grid, chunk, chunker: Chunker, collect, progress) -> float:
    """Run one task here; its seconds."""
    began = time.perf_counter()
    rows = run_points(grid, chunk, progress=progress)
    seconds = time.perf_counter() - began
    chunker.record(len(chunk), seconds)
    collect(rows)
    return seconds


def free_cores(jobs: int) -> int:
    """Workers that can run at once: at most ``jobs``, the cores, and the cores not busy with
    other processes (the load average of the last minute, this process counted out); at
    least 1."""
    cores = os.cpu_count() or 1
    try:
        busy = max(os.getloadavg()[0] - 1.0, 0.0)
    except (AttributeError, OSError):  # no load average on this platform
        busy = 0.0
    return max(1, min(int(jobs), cores, math.floor(cores - busy + 0.5)))


def worth_workers(seconds_left: float, jobs: int, warm_up: float = 0.0) -> bool:
    """Do ``jobs`` local workers finish ``seconds_left`` of serial work sooner than this
    process, by at least `POOL_MIN_GAIN` of it, once they have started (`POOL_START_SECONDS`)
    and warmed up (``warm_up``: what this process's first task cost beyond its points, the
    kernel loaded once per process)? The ideal parallel time is ``seconds_left / jobs``."""
    if jobs <= 1:
        return False
    parallel = POOL_START_SECONDS + warm_up + seconds_left / jobs
    return parallel <= (1 - POOL_MIN_GAIN) * seconds_left


def run_local(grid, todo, jobs: int, collect, progress) -> None:
    """The points ``todo`` in this process or on local workers, whichever is sooner (so a small
    sweep, or one of cheap points, never runs slower with ``-j 2`` than with ``-j 1``): the
    first two tasks run here, the first pays the warm-up of a process and the second measures
    the steady cost of a point; the rest goes to a pool only when `worth_workers` says it pays
    for its start-up and warm-up, on `free_cores` workers. The rows are the same either way."""
    chunker = Chunker(todo, 1)
    first = chunker.take()
    if first is None:
        return
    warm = _run_chunk(grid, first, chunker, collect, progress)
    second = chunker.take()
    if second is None:
        return
    each = _run_chunk(grid, second, chunker, collect, progress) / len(second)
    warm = max(warm - each * len(first), 0.0)
    left = len(chunker.todo) - chunker.pos
    workers = free_cores(jobs) if jobs > 1 and left else 1
    if worth_workers(left * each, workers, warm):
        with WorkerPool(workers) as pool:
            run_on_pool(
                grid, chunker.todo[chunker.pos :], pool, collect, progress, rate=(len(second), each * len(second))
            )
    else:
        while (chunk := chunker.take()) is not None:
            _run_chunk(grid, chunk, chunker, collect, progress)


_WORKER: dict[str, Any] = {}


def _init_worker(queue) -> None:
    """Ctrl-C is the parent's to handle (it stops the pool), so a local worker ignores SIGINT
    rather than dying with a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _WORKER["queue"] = queue


def _pool_task(grid, indices):
    """A local worker's task: rows of ``indices`` and the seconds they took. Each finished
    point is reported on the progress queue at once."""
    queue = _WORKER["queue"]
    began = time.perf_counter()
    rows = run_points(grid, indices, progress=None if queue is None else queue.put)
    return rows, time.perf_counter() - began


def _dask_task(grid, indices):
    """A Dask worker's task (``grid`` is scattered once to every worker)."""
    began = time.perf_counter()
    rows = run_points(grid, indices)
    return rows, time.perf_counter() - began


def _relay(queue, progress) -> None:
    """Progress counts from the workers' queue, until the None that ends the pool."""
    while (k := queue.get()) is not None:
        progress(k)


class WorkerPool:
    """``jobs`` local worker processes, kept for as many sweeps as the caller runs (an
    optimisation runs one per generation of its search: starting a pool for each, about a
    second, would cost more than the workers save). Use as a context manager and pass it to
    `crawlsim.study.sweep.run_sweep` as ``pool``; each task carries its grid. Progress reports
    from the workers go to the ``progress`` of the sweep that is running."""

    def __init__(self, jobs: int):
        import multiprocessing
        import threading
        from concurrent.futures import ProcessPoolExecutor

        self.jobs = int(jobs)
        context = multiprocessing.get_context("forkserver" if os.name == "posix" else "spawn")
        if os.name == "posix":
            context.set_forkserver_preload(_PRELOAD)
        self.progress: Callable[[int], None] | None = None
        self._queue = context.SimpleQueue()
        self._relay = threading.Thread(
            target=_relay, args=(self._queue, self._report), name="crawlsim-relay", daemon=True
        )
        self._relay.start()
        self.executor = ProcessPoolExecutor(
            self.jobs, mp_context=context, initializer=_init_worker, initargs=(self._queue,)
        )

    def _report(self, k: int) -> None:
        if self.progress is not None:
            self.progress(k)

    def stop(self) -> None:
        """End the workers now (an interrupt, a failure)."""
        _stop_pool(self.executor, {})
        self._queue.put(None)

    def close(self) -> None:
        """End the workers after their last task; the relay drains their last reports."""
        self.executor.shutdown(wait=True)
        self._queue.put(None)
        self._relay.join(5)

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.stop()
        else:
            self.close()


def run_on_pool(grid, todo, pool: WorkerPool, collect, progress, rate: tuple[int, float] = (0, 0.0)) -> None:
    """The points ``todo`` on the workers of ``pool``, two tasks in flight per worker, sized at
    the measured ``rate`` (points, seconds) while the workers have reported none."""
    from concurrent.futures import FIRST_COMPLETED, wait

    chunker = Chunker(todo, pool.jobs)
    chunker.record(*rate)
    pool.progress = progress
    pending: dict = {}

    def submit() -> None:
        chunk = chunker.take()
        if chunk is not None:
            pending[pool.executor.submit(_pool_task, grid, chunk)] = chunk

    try:
        for _ in range(2 * pool.jobs):
            submit()
        _collect_as_ready(
            pending, lambda fs: wait(fs, timeout=WAIT_SECONDS, return_when=FIRST_COMPLETED)[0], chunker, collect, submit
        )  # the workers report progress through the relay
    except BaseException:
        for fut in pending:
            fut.cancel()
        pool.stop()
        raise


def _collect_as_ready(
    pending: dict,
    ready_within: Callable[[list], Any],
    chunker: Chunker,
    collect,
    submit: Callable[[], None],
    progress=None,
) -> None:
    """Collect the tasks ``pending`` (future -> chunk) as they finish, submitting one more for
    each: ``ready_within(futures)`` returns those done within `WAIT_SECONDS` (perhaps none), and
    a Ctrl-C noted meanwhile, while this thread waited in another library's code, is raised
    between waits (`crawlsim.interrupts`), not only when a task ends (or never, on a stalled
    cluster). ``progress(k)`` is told of each task's rows, where the workers do not report."""
    while pending:
        ready = ready_within(list(pending))
        interrupts.check()
        for fut in ready:
            chunk = pending.pop(fut)
            rows, seconds = fut.result()
            chunker.record(len(chunk), seconds)
            collect(rows)
            if progress is not None:
                progress(len(rows))
            submit()


def _stop_pool(ex, pending) -> None:
    """Cancel what has not started and end the workers now (an interrupt, a failure)."""
    for fut in pending:
        fut.cancel()
    processes = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(5)


def check_scheduler(address: str) -> None:
    """Refuse (`SweepSpecError`, exit code 2), before anything is computed, a ``--scheduler``
    that is not the address of a Dask scheduler (SCHEME://HOST:PORT or HOST:PORT) or when Dask
    is not installed."""
    source = f"--scheduler {address}"
    try:
        from distributed.comm.addressing import get_address_host_port
    except ImportError:
        raise SweepSpecError(source, "", "Dask is not installed: pip install 'crawlsim[dask]'") from None
    try:
        host, port = get_address_host_port(address)
        valid = bool(host) and 0 < int(port) < 65536
    except (ValueError, TypeError):
        valid = False
    if not valid:
        raise SweepSpecError(
            source, "", "expected the address of a Dask scheduler, SCHEME://HOST:PORT such as tcp://127.0.0.1:8786"
        )


def run_dask(grid, todo, scheduler, collect, progress) -> None:
    """Tasks on a Dask cluster, two in flight per worker thread, collected as each finishes
    (`distributed.wait`, first completed): progress and the journal move with every task."""
    try:
        from distributed import Client, wait
    except ImportError:
        raise SweepSpecError("--scheduler", "", "Dask is not installed: pip install 'crawlsim[dask]'") from None
    check_scheduler(scheduler)
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
    except OSError as exc:
        raise SweepSpecError(f"--scheduler {scheduler}", "", f"cannot reach the Dask scheduler ({exc})") from None
    pending: dict = {}
    try:
        workers = _workers(client)
        chunker = Chunker(todo, workers)
        shared = client.scatter(grid, broadcast=True)

        def submit() -> None:
            chunk = chunker.take()
            if chunk is not None:
                pending[client.submit(_dask_task, shared, chunk, pure=False)] = chunk

        def ready_within(futures):
            try:
                return wait(futures, timeout=WAIT_SECONDS, return_when="FIRST_COMPLETED").done
            except TimeoutError:  # none finished meanwhile
                return ()

        for _ in range(2 * workers):
            submit()
        _collect_as_ready(pending, ready_within, chunker, collect, submit, progress)
    except BaseException:
        if pending:
            client.cancel(list(pending))
        raise
    finally:
        client.close()


def _workers(client) -> int:
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:
        return 1
