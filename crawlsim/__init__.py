"""crawlsim: exact simulation of soft crawlers with dry friction.

The path from a gait file to an answer, one module per stage:

    gait.py        YAML gait file -> validated `Gait` (docpaths.py: dotted paths into it)
    model.py       `Gait` -> tabulated shape-space sweeping process (docs/model.md §2)
    projection.py  exact, certified projections (the only user of Clarabel)
    stepping.py    catch-up stepping, period by period
    analysis.py    convergence, v0, limit period
    h5io.py        HDF5 (netCDF-4) results files; provenance.py and units.py: what they record
    api.py         the entry points for Python studies: load_gait, simulate, sweep
    cli/           the `crawlsim` command

The names below are imported on first use, so ``import crawlsim`` stays light (no numpy).

``crawlsim.sweep`` is also the module `crawlsim/sweep.py`: the package makes that module
callable, so ``crawlsim.sweep(gait, {...})`` runs `crawlsim.api.sweep` while
``from crawlsim import sweep`` still gives the module (a type checker sees the module only:
typed code calls `crawlsim.api.sweep`). ``crawlsim.sensitivity`` is made callable the same way.
"""

from __future__ import annotations

import importlib
import sys
import types

TYPE_CHECKING = False  # typing itself is not imported: `crawlsim --version` needs none of it
if TYPE_CHECKING:
    from typing import Any

__version__ = "0.1.0"

#: Public names -> the module that defines them.
_EXPORTS = {
    "load_gait": "crawlsim.api",
    "simulate": "crawlsim.api",
    "run": "crawlsim.api",
    "sensitivity": "crawlsim.api",
    "SimulationResult": "crawlsim.api",
    "Trajectory": "crawlsim.api",
    "Gait": "crawlsim.gait",
    "ProcessSpec": "crawlsim.gait",
    "Units": "crawlsim.units",
    "CertificateError": "crawlsim.errors",
    "CrawlsimError": "crawlsim.errors",
    "GaitError": "crawlsim.errors",
    "InputError": "crawlsim.errors",
    "stall": "crawlsim.stall",
}

_SUBMODULES = {"analysis", "api", "atomic", "batch", "corpus", "docpaths", "errors", "exact",
               "gait", "h5io", "kkt", "model", "offsets", "paper", "projection", "provenance",
               "sensitivity", "signals", "stall", "status", "stepping", "sweep", "units"}

__all__ = ["load_gait", "simulate", "sweep", "run", "sensitivity", "SimulationResult", "Trajectory",
           "Gait", "ProcessSpec", "Units", "CertificateError", "CrawlsimError", "GaitError", "InputError",
           "stall", "__version__"]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:  # crawlsim.api, crawlsim.h5io, ... without importing them first
        return importlib.import_module(f"crawlsim.{name}")  # sweep: made callable on import
    raise AttributeError(f"module 'crawlsim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _CallableSweepModule(types.ModuleType):
    """The module crawlsim.sweep, callable as `crawlsim.api.sweep`."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from .api import sweep

        return sweep(*args, **kwargs)


class _CallableSensitivityModule(types.ModuleType):
    """The module crawlsim.sensitivity, callable as `crawlsim.api.sensitivity`."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from .api import sensitivity

        return sensitivity(*args, **kwargs)


_CALLABLE_MODULES = {"sweep": _CallableSweepModule, "sensitivity": _CallableSensitivityModule}


class _Package(types.ModuleType):
    """The package: importing the submodule ``sweep`` (``sensitivity``) sets the attribute of
    that name here, and that is where the module becomes callable (whatever imports it
    first)."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _CALLABLE_MODULES and type(value) is types.ModuleType:
            value.__class__ = _CALLABLE_MODULES[name]
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
