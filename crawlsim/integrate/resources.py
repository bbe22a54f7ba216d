"""Memory a run needs, estimated before anything big is allocated, and the limit it must fit in.

A gait file can ask for more than a machine has: 10^7 steps per period make every tabulated
column 80 MB, and a generic process of many faces has dense matrices of size n m. Rather
than fail half-way with a MemoryError (or be killed), a run is refused up front with a
`ResourceError` (exit code 2) naming the estimate, what dominates it, and the limit.

The estimate follows the arrays a run holds at its peak (G + 1 grid points per period, N
blocks; every entry a double):

* the process tabulated on one period's grid: offsets c(t) (G+1) x 2N, friction (G+1) x 2N,
  lengths L(t) and stress offsets K L(t) (G+1) x (N-1) each;
* one period of stepping: states w (G+1) x (N-1), multipliers G x 2N, positions (G+1) x N;
* for a crawler, the KKT kernel's structures are O(N) (`crawlsim.projection.kkt.ChainPolyhedron`): the
  cache of factored active sets is bounded (`crawlsim.projection.kkt.CACHE_NUMBERS`), and the periodic-limit
  solver's dense Jacobian (N-1)^2 is used only up to `crawlsim.integrate.limit.DENSE_JACOBIAN` links;
* for a generic process, its dense normals, metric and the cache of active sets, about
  `DENSE_SQUARES` n^2;
* temporaries (blocks of telescoped steps, the analysis of the limit period, the HDF5 rows):
  `TEMPORARIES` times the per-period arrays, more for the event-driven integrator;

plus `BASE_BYTES` for the interpreter's own working set. A sweep holds the tabulated process
of every gait of a batch besides. The constants are calibrated against tracemalloc's peak
(tests/test_resources.py asserts the estimate bounds it).

The default limit is the smaller of `DEFAULT_CAP` and `DEFAULT_FRACTION` of the memory
available: MemAvailable of /proc/meminfo, the headroom under RLIMIT_AS, and the headroom under
a cgroup's memory.max, whichever is least.

Time is bounded the same way where it can be predicted: the cost of evaluating the signals
(`signal_work`). The exact integrator finds each event of a Fourier gait by certified sampling,
`crawlsim.integrate.exact.CELLS_PER_CYCLE` samples per cycle of the highest harmonic H, each sample
evaluating the 2H + 1 basis functions and the m = 2N gap and rate functions: a cost of order
H^2 (TRIG_COST + m) per event search (catch-up runs the exact integrator for its reference too).
The estimate counts `SEARCHES_PER_PERIOD` searches a period, the fewest a moving gait has, so
it is a lower bound (a gait of many events a period, a wave of many blocks, takes longer and is
not refused for it); a gait whose two first periods would cost more than `MAX_SIGNAL_WORK` even
so is refused up front with a `ResourceError` naming the signal.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

from crawlsim.errors import ResourceError

if TYPE_CHECKING:
    from crawlsim.gait.crawler_spec import Gait
    from crawlsim.gait.process_spec import ProcessSpec

BYTES = 8  # a double
BASE_BYTES = 8 << 20
TEMPORARIES = 2.0
TEMPORARIES_EXACT = 5.0
DENSE_SQUARES = 64
DEFAULT_CAP = 8 << 30
DEFAULT_FRACTION = 0.5

_UNITS = {
    "": 1,
    "b": 1,
    "k": 1 << 10,
    "m": 1 << 20,
    "g": 1 << 30,
    "t": 1 << 40,
    "kib": 1 << 10,
    "mib": 1 << 20,
    "gib": 1 << 30,
    "tib": 1 << 40,
    "kb": 10**3,
    "mb": 10**6,
    "gb": 10**9,
    "tb": 10**12,
}


@dataclass(frozen=True)
class MemoryEstimate:
    """Estimated peak bytes of a run, and the parts it is made of (largest first)."""

    total: int
    parts: tuple[tuple[str, int], ...]

    def describe(self) -> str:
        top = ", ".join(f"{name} {format_size(size)}" for name, size in self.parts[:3])
        return f"about {format_size(self.total)} ({top})"


def run_memory(
    blocks: int,
    grid_points: int,
    *,
    save_every: int = 1,
    integrator: str = "catch-up",
    batch: int = 1,
    dense: bool = False,
) -> MemoryEstimate:
    """Estimated peak memory of simulating a crawler of ``blocks`` blocks on a period grid of
    ``grid_points`` points (G + 1: the steps per period plus the breakpoints, plus one).

    ``batch`` > 1 is a sweep that steps that many gaits together (each keeps its tabulated
    process); ``save_every`` thins the rows written to the results file; ``dense`` counts the
    dense matrices of a generic process.
    """
    from crawlsim.integrate.limit import DENSE_JACOBIAN  # start-up: the commands check memory before numpy
    from crawlsim.projection.kkt import CACHE_NUMBERS  # (idem: this module is light, the solvers are not)

    n, p = int(blocks), int(grid_points)
    tabulated = [
        ("tabulated offsets c(t)", p * 2 * n),
        ("tabulated friction", p * 2 * n),
        ("lengths and stress offsets", 2 * p * (n - 1)),
    ]
    period = [
        ("one period's states w", p * (n - 1)),
        ("one period's multipliers", (p - 1) * 2 * n),
        ("one period's positions", p * n),
        ("rows written to the results file", (p // max(1, save_every) + 1) * 3 * n),
    ]
    factor = TEMPORARIES_EXACT if integrator == "exact" else TEMPORARIES
    parts = [(name, int(BYTES * size * factor)) for name, size in tabulated + period]
    if dense:
        parts.append(("dense matrices of the projector", BYTES * DENSE_SQUARES * n * n))
    else:
        # a set per step at most, until the cache's bound
        parts.append(("the cache of factored active sets", BYTES * min(CACHE_NUMBERS, 2 * p * (6 * n + 8))))
        if n - 1 <= DENSE_JACOBIAN:
            parts.append(("the periodic-limit solver's Jacobian", BYTES * 4 * (n - 1) ** 2))
    if batch > 1:
        per_gait = sum(size for _, size in tabulated) + 12 * n
        parts.append((f"the tabulated processes of a batch of {batch}", BYTES * batch * per_gait))
    parts.append(("the interpreter's working set", BASE_BYTES))
    parts.sort(key=lambda part: -part[1])
    return MemoryEstimate(sum(size for _, size in parts), tuple(parts))


def process_memory(
    dimension: int, faces: int, grid_points: int, *, save_every: int = 1, integrator: str = "catch-up"
) -> MemoryEstimate:
    """As `run_memory`, for a generic process of ``faces`` constraints in ``dimension``
    variables: a crawler of N blocks has 2N faces in N - 1 variables, so the same arrays are
    counted with N the larger of n + 1 and m / 2."""
    return run_memory(
        max(dimension + 1, (faces + 1) // 2), grid_points, save_every=save_every, integrator=integrator, dense=True
    )


def gait_memory(
    gait: Gait | ProcessSpec,
    *,
    save_every: int = 1,
    batch: int = 1,
    steps_per_period: int | None = None,
    blocks: int | None = None,
) -> MemoryEstimate:
    """`run_memory` of a validated `Gait` or `ProcessSpec` with its simulation settings (the
    grid is its steps per period plus its breakpoints); ``steps_per_period`` and ``blocks``
    override the gait's, for the largest point of a sweep."""
    steps = steps_per_period or gait.simulation.steps_per_period
    points = steps + len(gait.breakpoints()) + 1
    integrator = gait.simulation.integrator
    if hasattr(gait, "normals"):
        faces, dimension = gait.normals.shape
        return process_memory(dimension, faces, points, save_every=save_every, integrator=integrator)
    return run_memory(blocks or gait.blocks, points, save_every=save_every, integrator=integrator, batch=batch)


def check_memory(estimate: MemoryEstimate, limit: int, source: str, what: str = "this run") -> None:
    """Refuse with a `ResourceError` when ``estimate`` exceeds ``limit`` bytes."""
    if estimate.total > limit:
        raise ResourceError(
            source,
            "",
            f"{what} would need {estimate.describe()}, more than the "
            f"memory limit of {format_size(limit)} (--max-memory; "
            "fewer steps per period or blocks need less)",
        )


def parse_size(text: str) -> int:
    """Bytes from ``4GiB``, ``500MB``, ``1.5G`` or ``1000000``: kB, MB, GB, TB are powers of
    1000; KiB, MiB, GiB, TiB and the bare letters K, M, G, T are powers of 1024."""
    match = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*([a-zA-Z]*)\s*", str(text))
    unit = match.group(2).lower() if match else ""
    if match is None or unit not in _UNITS:
        raise ValueError(f"expected a size such as 4GiB, 500MB or 2G, got {text!r}")
    size = float(match.group(1)) * _UNITS[unit]
    if not 0 < size < 2**62:
        raise ValueError(f"expected a positive size below 4 EiB, got {text!r}")
    return int(size)


def format_size(size: float) -> str:
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{int(size)} B"


def available_memory() -> int | None:
    """Bytes this process could still allocate, from what the system says: the least of
    MemAvailable, the headroom under RLIMIT_AS and under the cgroup's memory.max; None when
    none of them can be read."""
    candidates = []
    meminfo = _read("/proc/meminfo")
    found = re.search(r"^MemAvailable:\s+(\d+) kB", meminfo or "", re.MULTILINE)
    if found:
        candidates.append(int(found.group(1)) * 1024)
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            status = _read("/proc/self/status") or ""
            used = re.search(r"^VmSize:\s+(\d+) kB", status, re.MULTILINE)
            candidates.append(max(0, soft - (int(used.group(1)) * 1024 if used else 0)))
    except (ImportError, OSError, ValueError):  # pragma: no cover - not POSIX
        pass
    cgroup_max = (_read("/sys/fs/cgroup/memory.max") or "").strip()
    if cgroup_max.isdigit():
        current = (_read("/sys/fs/cgroup/memory.current") or "0").strip()
        candidates.append(max(0, int(cgroup_max) - (int(current) if current.isdigit() else 0)))
    return min(candidates) if candidates else None


def default_limit() -> int:
    """The memory limit when --max-memory is not given: min(`DEFAULT_CAP`,
    `DEFAULT_FRACTION` x `available_memory`)."""
    available = available_memory()
    if available is None:
        return DEFAULT_CAP
    return int(min(DEFAULT_CAP, DEFAULT_FRACTION * available))


def _read(path: str) -> str | None:
    try:
        with open(path, encoding="ascii") as f:
            return f.read(1 << 16)
    except (OSError, UnicodeDecodeError):
        return None


#: Cost of one cos or sin in the units of `signal_work` (a multiply-add of numpy's matrix
#: product is 1; numpy's cos of an array element costs about 100 of them).
TRIG_COST = 100
#: Event searches a period at the fewest: a link that moves starts and stops slipping, forward
#: and backward.
SEARCHES_PER_PERIOD = 4
#: The largest `signal_work` of a run's first two periods (the fewest any run computes).
#: Measured (numpy 2.4, one core): a search of a 2-block gait with a Fourier link of 1000
#: harmonics, 1.3e10, takes 20 s, so 5e10 is a bit more than a minute, at the fewest events.
MAX_SIGNAL_WORK = 5e10


@dataclass(frozen=True)
class SignalWork:
    """The estimated cost of a gait's signals (`signal_work`) and what sets it."""

    per_period: float  # the event searches of one period
    tabulation: float  # the signals on the output grid, once a run
    harmonics: int
    faces: int
    key: str  # the signal with the most harmonics ("links[0]", "friction", ...)

    @property
    def run(self) -> float:
        """The two periods every run computes at least, and the tabulation."""
        return 2.0 * self.per_period + self.tabulation


def signal_work(harmonics: int, faces: int, grid_points: int, key: str = "") -> SignalWork:
    """The cost, in multiply-adds (a cos or sin counting `TRIG_COST`), of the signals of a
    gait whose largest number of harmonics is ``harmonics``, with ``faces`` constraints (2N for
    N blocks) on a grid of ``grid_points`` points a period. Signals of at most one harmonic
    (constants, piecewise-linear signals, cosines) have closed-form events: only their
    tabulation counts."""
    from crawlsim.integrate.exact import CELLS_PER_CYCLE  # start-up: the commands check the work before numpy

    h, m = int(harmonics), int(faces)
    per_sample = (2 * h + 1) * (TRIG_COST + m)
    per_period = 0.0 if h <= 1 else float(SEARCHES_PER_PERIOD) * CELLS_PER_CYCLE * h * per_sample
    return SignalWork(per_period, float(grid_points) * per_sample, h, m, key)


def gait_signal_work(gait: Gait | ProcessSpec, *, steps_per_period: int | None = None) -> SignalWork:
    """`signal_work` of a validated `Gait` or `ProcessSpec` with its simulation settings."""
    steps = steps_per_period or gait.simulation.steps_per_period
    points = steps + len(gait.breakpoints()) + 1
    if hasattr(gait, "normals"):
        process = cast("ProcessSpec", gait)  # a generic process: only it has normals
        named = [(f"offsets[{i}]", s) for i, s in enumerate(process.offsets)]
        faces = process.normals.shape[0]
    else:
        named = [(f"links[{i}]", s) for i, s in enumerate(gait.links)]
        named += [("friction", s) for s in gait.forward + gait.backward]
        faces = 2 * gait.blocks
    key, most = "", 0
    for name, signal in named:
        if signal.harmonics > most:
            key, most = name, signal.harmonics
    return signal_work(most, faces, points, key)


def check_signal_work(work: SignalWork, source: str) -> None:
    """Refuse with a `ResourceError` a gait whose signals would cost more than
    `MAX_SIGNAL_WORK` in its first two periods (a run that would not finish in reasonable
    time)."""
    if work.run <= MAX_SIGNAL_WORK:
        return
    raise ResourceError(
        source,
        work.key,
        (
            f"a signal of {work.harmonics:,} harmonics with {work.faces // 2:,} blocks would cost "
            f"at least {work.run:.1g} operations over the two periods a run needs (events are found "
            f"by sampling every cycle of the highest harmonic), more than crawlsim runs "
            f"({MAX_SIGNAL_WORK:.0e}, about a minute): use fewer harmonics (the cost grows as their "
            "square), fewer blocks or steps per period, or a piecewise-linear signal"
        ),
    )
