"""Provenance of a results file: what ran, on what, with what, by which command, and when.

Every results file (runs and sweeps; optimisations later, through the same functions) records:

* ``gait_yaml``: the *effective* gait document, every override applied (``--steps-per-period``,
  ``--integrator``, ``Gait.replace``, ...): rerunning it reproduces the run
  (``crawlsim run --from RESULT.h5``);
* ``gait_file`` and ``gait_file_text``: where the gait was read from and its text as read,
  comments included;
* ``command_line``: ``sys.argv`` of the command, or the Python call when the library was called
  through `crawlsim.api` (see `recording`);
* ``integrator`` and ``integrator_json``: the integrator and every setting that can change its
  numbers;
* ``versions_json``: the versions of crawlsim, Python and the libraries that compute results;
* ``created``: the creation time, ISO 8601 in UTC.
"""

from __future__ import annotations

import functools
import json
import platform
import shlex
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from crawlsim import __version__
from crawlsim.gait.settings import effective_tolerance

#: The libraries whose versions are recorded (everything that computes or stores a number).
LIBRARIES = ("numpy", "scipy", "clarabel", "h5py")

_CALL: ContextVar[str | None] = ContextVar("crawlsim_call", default=None)


@contextmanager
def recording(call: str) -> Iterator[None]:
    """Record ``call`` (a Python call, say) as the command line of files written inside."""
    token = _CALL.set(call)
    try:
        yield
    finally:
        _CALL.reset(token)


def command_line() -> str:
    """The call being recorded, else this process's command line (``sys.argv``, shell-quoted)."""
    call = _CALL.get()
    return call if call is not None else shlex.join(sys.argv)


def versions() -> dict[str, str]:
    """Versions of crawlsim, Python and `LIBRARIES` ("unknown" for one not installed as a
    distribution)."""
    return dict(_versions())


@functools.cache
def _versions() -> tuple[tuple[str, str], ...]:
    """Looked up once per process (reading the distributions' metadata takes milliseconds)."""
    from importlib import metadata  # here: importing it costs milliseconds too

    out = {"crawlsim": __version__, "python": platform.python_version()}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "unknown"
    return tuple(out.items())


class _Versions(Mapping[str, str]):
    """`versions()`, read when first used: a run that writes no file (``crawlsim velocity``)
    never reads the distributions' metadata (20-30 ms, a tenth of that command's start-up)."""

    def _table(self) -> dict[str, str]:
        return dict(_versions())

    def __getitem__(self, key: str) -> str:
        return self._table()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._table())

    def __len__(self) -> int:
        return len(self._table())

    def __repr__(self) -> str:
        return repr(self._table())


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def session_attrs() -> dict[str, str]:
    """The attributes every results file records whatever it holds (runs, sweeps, and later
    optimisations): ``command_line``, ``versions_json`` and ``created``."""
    return {"command_line": command_line(), "versions_json": json.dumps(versions()), "created": now()}


def python_call(function: str, *args: Any, **kwargs: Any) -> str:
    """``crawlsim.simulate('gaits/x.yaml', integrator='exact')``: a call as text, for
    `recording`. A gait is shown by its source."""

    def show(value: Any) -> str:
        source = getattr(value, "source", None)
        if source is not None and hasattr(value, "document"):
            return f"<gait {source!r}>"
        return repr(value if not hasattr(value, "__fspath__") else str(value))

    parts = [show(a) for a in args] + [f"{k}={show(v)}" for k, v in kwargs.items() if v is not None]
    return f"{function}({', '.join(parts)})"


@dataclass(frozen=True, eq=False)
class Provenance:
    """The provenance attributes of one results file (see the module docstring).

    ``gait`` is the effective gait document, or its YAML as a file recorded it; ``gait_yaml``
    dumps a document when first read. A run that writes no file (``crawlsim velocity``, the
    library's ``run(..., history=False)``) never pays for the dump, which took 40 % of such a
    run (yaml's pure-Python emitter). A `Gait` is frozen and its document is never edited in
    place (`Gait.replace` makes a new one), so dumping it later gives the same text.
    """

    gait: Mapping[str, Any] | str
    gait_file: str
    gait_file_text: str
    integrator: str
    integrator_settings: Mapping[str, Any]
    command_line: str = field(default_factory=command_line)
    versions: Mapping[str, str] = field(default_factory=_Versions)
    created: str = field(default_factory=now)

    @functools.cached_property
    def gait_yaml(self) -> str:
        """The effective gait document as YAML (`effective_yaml`)."""
        return self.gait if isinstance(self.gait, str) else effective_yaml(self.gait)

    def __eq__(self, other: object) -> bool:
        """Equal when every recorded attribute is (a document equals its YAML)."""
        if not isinstance(other, Provenance):
            return NotImplemented
        return self.attrs() == other.attrs()

    __hash__ = None  # type: ignore[assignment]  # mutable mappings inside, as before

    def attrs(self) -> dict[str, str]:
        """The HDF5 root attributes, all strings (mappings as JSON)."""
        return {
            "gait_yaml": self.gait_yaml,
            "gait_file": self.gait_file,
            "gait_file_text": self.gait_file_text,
            "integrator": self.integrator,
            "integrator_json": json.dumps(dict(self.integrator_settings)),
            "command_line": self.command_line,
            "versions_json": json.dumps(dict(self.versions)),
            "created": self.created,
        }

    @classmethod
    def from_attrs(cls, attrs: Mapping[str, Any]) -> Provenance | None:
        """The provenance recorded in a results file's root attributes (`attrs`); None for a
        file written before provenance was recorded (format_version 1)."""
        if "gait_yaml" not in attrs or "integrator_json" not in attrs:
            return None
        return cls(
            gait=str(attrs["gait_yaml"]),
            gait_file=str(attrs.get("gait_file", "")),
            gait_file_text=str(attrs.get("gait_file_text", "")),
            integrator=str(attrs.get("integrator", "")),
            integrator_settings=json.loads(attrs["integrator_json"]),
            command_line=str(attrs.get("command_line", "")),
            versions=json.loads(attrs.get("versions_json", "{}")),
            created=str(attrs.get("created", "")),
        )


def for_gait(gait: Any, *, check_every_step: bool = False) -> Provenance:
    """The provenance of a run of ``gait`` (a `Gait` or `ProcessSpec`) with its own simulation
    settings, which `crawlsim.gait.document.with_simulation` keeps in step with its document."""
    s = gait.simulation
    settings = {
        "integrator": s.integrator,
        "steps_per_period": s.steps_per_period,
        "max_periods": s.max_periods,
        "tolerance": s.tolerance,
        "effective_tolerance": effective_tolerance(s.tolerance),
        "check_every_step": bool(check_every_step),
    }
    return Provenance(
        gait=gait.document,
        gait_file=str(gait.source),
        gait_file_text=str(gait.source_text),
        integrator=s.integrator,
        integrator_settings=settings,
    )


def effective_yaml(document: Mapping[str, Any]) -> str:
    """The document as YAML. Floats are written with ``repr``, so reading it back gives the same
    numbers bit for bit."""
    import yaml

    return str(yaml.safe_dump(dict(document), sort_keys=False))
