"""crawlsim: exact simulation of soft crawlers with dry friction.

The folders are the path from a gait file to an answer:

    gait/        YAML gait file -> validated `Gait`: schema, signals, units, dotted paths,
                 loads, the uniqueness condition
    kernel/      the compiled kernel (interpreted or numba): the tolerance policy, the catch-up
                 step and the exact event loop
    io/          HDF5 (netCDF-4) results files, provenance, atomic writes
    projection/  exact, certified projections in Python: the KKT certificate, the polyhedra,
                 the one Clarabel adapter
    model/       `Gait` -> shape-space sweeping process: offsets, the `Crawler`'s quantities
    integrate/   stepping a process period by period: catch-up, exact, the periodic limit, the
                 exact energy ledger
    analysis/    a run to its periodic regime and what it measures: v0, energy, sensitivities
    plotting/    figures and animations of a run
    study/       one gait's run, sweeps, the paper's checks
    design/      gait design: optimize (evolution or gradient search), the stall search
    api.py       the entry points for Python studies: load_gait, simulate, sweep, sensitivity,
                 and the typed readers open_run, open_sweep,
                 open_optimization
    cli/         the `crawlsim` command, one module per command

Each package imports only those listed above it (`lint-imports`, pyproject.toml).

The names below are imported on first use, so ``import crawlsim`` stays light (no numpy).
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False  # typing itself is not imported: `crawlsim --version` needs none of it
if TYPE_CHECKING:
    from typing import Any

__version__ = "0.1.0"

#: Public names -> the module that defines them.
_EXPORTS = {
    "load_gait": "crawlsim.api",
    "simulate": "crawlsim.api",
    "run": "crawlsim.api",
    "sweep": "crawlsim.api",
    "sensitivity": "crawlsim.api",
    "rigid_limit": "crawlsim.api",
    "open_run": "crawlsim.api",
    "open_sweep": "crawlsim.api",
    "open_optimization": "crawlsim.api",
    "RunStatus": "crawlsim.status",
    "Convergence": "crawlsim.status",
    "SimulationResult": "crawlsim.api",
    "Trajectory": "crawlsim.api",
    "Gait": "crawlsim.gait.document",
    "ProcessSpec": "crawlsim.gait.document",
    "Units": "crawlsim.gait.units",
    "CertificateError": "crawlsim.errors",
    "CrawlsimError": "crawlsim.errors",
    "GaitError": "crawlsim.errors",
    "InputError": "crawlsim.errors",
    "GaitWarning": "crawlsim.errors",
    "stall": "crawlsim.design.stall",
}

_SUBPACKAGES = {
    "analysis",
    "api",
    "cli",
    "design",
    "errors",
    "gait",
    "integrate",
    "io",
    "kernel",
    "model",
    "plotting",
    "projection",
    "status",
    "study",
}

__all__ = [
    "load_gait",
    "simulate",
    "sweep",
    "run",
    "sensitivity",
    "rigid_limit",
    "open_run",
    "open_sweep",
    "open_optimization",
    "SimulationResult",
    "Trajectory",
    "RunStatus",
    "Convergence",
    "Gait",
    "ProcessSpec",
    "Units",
    "CertificateError",
    "CrawlsimError",
    "GaitError",
    "InputError",
    "GaitWarning",
    "stall",
    "__version__",
]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    if name in _SUBPACKAGES:  # crawlsim.api, crawlsim.io, ... without importing them first
        return importlib.import_module(f"crawlsim.{name}")
    raise AttributeError(f"module 'crawlsim' has no attribute {name!r}")


def __dir__() -> list[str]:  # the public names, not this module's own imports
    return sorted(set(__all__) | _SUBPACKAGES)
