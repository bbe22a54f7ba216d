"""The netCDF-4 layout every crawlsim HDF5 file follows, and the helpers that write and read it.

Every axis of every dataset is attached to a named dimension scale (`Scales`), every dataset
carries ``units`` (UDUNITS syntax, "1" when dimensionless) and ``long_name`` (`describe_var`),
enumerations carry the CF ``flag_values`` and ``flag_meanings``, and the root carries
``Conventions``. Writes are atomic (`crawlsim.io.atomic`): a failed write leaves no file behind.
The run, sweep and optimisation files build on these (`crawlsim.io.runfile`,
`crawlsim.io.sweepfile`, `crawlsim.io.optfile`).
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from crawlsim import __version__
from crawlsim.errors import ResultsFileError
from crawlsim.io import atomic
from crawlsim.io.atomic import atomic_path, discard, guarded, temporary_beside

FORMAT_VERSION = 2
#: Format versions the readers accept.
READABLE_VERSIONS = (1, 2)

#: netCDF-4 marks a dimension scale that is not a variable by this NAME (followed by its size).
NOT_A_VARIABLE = b"This is a netCDF dimension but not a netCDF variable."

SLIP_FLAGS = ((-1, "backward_slip"), (0, "stick"), (1, "forward_slip"))
LIMIT_FLAGS = ((-1, "backward_limit"), (1, "forward_limit"))
CONVERGENCE_FLAGS = ((-1, "none"), (0, "finite_time"), (1, "asymptotic"), (2, "not_converged"))
SOLVER_PERIOD_FLAGS = ((-1, "rejected_newton"), (0, "plain"), (1, "newton"))
STATUS_FLAGS = ((-1, "not_computed"), (0, "ok"), (1, "not_converged"), (2, "invalid"), (3, "failed"))

#: The metadata conventions the files follow (the root attribute ``Conventions``): netCDF's
#: dimension scales and the CF attributes (units, long_name, flag_values and flag_meanings).
CONVENTIONS = "CF-1.10"


@dataclass(frozen=True)
class Var:
    """A dataset of the layout: its dimensions, description, the quantity its units follow
    (a key of `crawlsim.gait.units.QUANTITIES`, or a role resolved per kind by `_ROLES`), and the CF
    flags of an enumeration."""

    dims: tuple[str, ...]
    long_name: str
    quantity: str
    flags: tuple[tuple[int, str], ...] = ()
    comment: str = ""


#: Quantities that depend on the kind of run: (crawler, generic sweeping process). A crawler's w
#: is -K z, a force; a generic process's state z is taken as a length, with dimensionless


class Scales:
    """The dimension scales of one file, by name, with their netCDF dimension ids."""

    def __init__(self) -> None:
        self.scales: dict[str, h5py.Dataset] = {}

    def _register(self, name: str, ds: h5py.Dataset) -> None:
        ds.attrs["_Netcdf4Dimid"] = np.int32(len(self.scales))
        self.scales[name] = ds

    def coordinate(self, group: h5py.Group, name: str, data: Any) -> h5py.Dataset:
        """A coordinate variable: a dataset named like its dimension, holding its values."""
        if np.asarray(data).dtype.kind in "OU":  # names (the files of `crawlsim velocity A.yaml B.yaml`)
            data = np.asarray(data, dtype=object).astype(str).tolist()
            ds = group.create_dataset(name, data=data, dtype=h5py.string_dtype(), track_order=True)
        else:
            ds = group.create_dataset(name, data=data, track_order=True)
        ds.make_scale(name)
        self._register(name, ds)
        return ds

    def attach(self, ds: h5py.Dataset, dims: Sequence[str]) -> None:
        for axis, dim in enumerate(dims):
            if self.scales[dim] != ds:
                ds.dims[axis].attach_scale(self.scales[dim])


def describe_var(ds: h5py.Dataset, var: Var, unit: str, coordinates: str = "") -> None:
    """The CF attributes of a dataset: units, long_name, flags, coordinates."""
    ds.attrs["long_name"] = var.long_name
    ds.attrs["units"] = unit
    if var.flags:
        ds.attrs["flag_values"] = np.array([v for v, _ in var.flags], dtype=ds.dtype)
        ds.attrs["flag_meanings"] = " ".join(m for _, m in var.flags)
    if var.comment:
        ds.attrs["comment"] = var.comment
    if coordinates:
        ds.attrs["coordinates"] = coordinates


def target_file(target: Any) -> tuple[h5py.File, Path | None, atomic.GuardedFile | None]:
    """Open a results target: a path (a temporary file beside it, written through
    `crawlsim.io.atomic.GuardedFile` and renamed at the end) or a binary file object (an in-memory
    image: `io.BytesIO`)."""
    if isinstance(target, io.IOBase):
        return h5py.File(target, "w", track_order=True), None, None
    tmp = temporary_beside(Path(target))
    try:
        raw = atomic.GuardedFile(tmp, "w+")  # looked up now: tests fill the disk
        return h5py.File(raw, "w", track_order=True), tmp, raw
    except BaseException:
        discard(tmp)
        raise


@contextmanager
def atomic_h5(path: Any) -> Iterator[h5py.File]:
    """A new HDF5 file written atomically (`crawlsim.io.atomic`), a full disk an `OutputError`."""
    with atomic_path(path) as tmp, guarded(tmp) as raw, h5py.File(raw, "w", track_order=True) as f:
        yield f


def json_ready(summary: Mapping[str, Any]) -> dict[str, Any]:
    """NaN and infinities (not JSON) become null."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in summary.items()}


def open_h5(path: Path, what: str) -> h5py.File:
    """Open an HDF5 file for reading, or raise `ResultsFileError` saying why it can't be."""
    if not path.exists():
        raise ResultsFileError(f"{path}: no such {what}")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise ResultsFileError(f"{path}: not an HDF5 file ({exc})") from None


def check_version(f: h5py.File, path: Any) -> int:
    if "format_version" not in f.attrs:
        raise ResultsFileError(f"{path}: not a crawlsim results file (no format_version attribute)")
    version = int(plain(f.attrs["format_version"]))
    if version not in READABLE_VERSIONS:
        raise ResultsFileError(
            f"{path}: format_version {version} was written by a newer crawlsim "
            f"({plain(f.attrs.get('crawlsim_version', '?'))}); this crawlsim "
            f"({__version__}) reads format_version "
            f"{', '.join(map(str, READABLE_VERSIONS))}: upgrade crawlsim"
        )
    return version


def variables(group: h5py.Group, skip: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """The group's datasets, without the netCDF dimensions that are not variables (nor those
    named in ``skip``)."""
    out = {}
    for name, ds in group.items():
        if not isinstance(ds, h5py.Dataset) or name in skip:
            continue
        name_attr = ds.attrs.get("NAME", b"")
        if isinstance(name_attr, str):
            name_attr = name_attr.encode()
        if NOT_A_VARIABLE in bytes(name_attr):
            continue
        out[name] = ds[()]
    return out


def plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def number(value: Any) -> Any:
    """NaN and -1 (null in the attributes) become None."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return None
    return value


def write_column(group: h5py.Group, name: str, values: Any) -> h5py.Dataset:
    """A one-dimensional dataset of numbers, or of strings (variable-length UTF-8) when
    ``values`` holds text."""
    values = np.asarray(values)
    if values.dtype == object or values.dtype.kind in "US":
        return group.create_dataset(
            name, data=values.astype(str).tolist(), dtype=h5py.string_dtype(), shape=values.shape, track_order=True
        )
    return group.create_dataset(name, data=values, track_order=True)


def read_column(ds: h5py.Dataset) -> np.ndarray:
    """A dataset's values, strings as an object array of Python str."""
    if h5py.check_string_dtype(ds.dtype):
        return np.array(ds.asstr()[()], dtype=object)
    return np.asarray(ds[()])


def write_header(f: h5py.File, *, title: str, comment: str, kind: str) -> None:
    """The root attributes every file starts with."""
    a = f.attrs
    a["title"] = title
    a["comment"] = comment
    a["crawlsim_version"] = __version__
    a["format_version"] = FORMAT_VERSION
    a["Conventions"] = CONVENTIONS
    a["kind"] = kind


def write_file(target: Any, write: Any) -> None:
    """Call ``write(h5py.File)`` on a new file at ``target``, written atomically; a binary file
    object (an in-memory image) is written in place."""
    if isinstance(target, io.IOBase):
        with h5py.File(target, "w", track_order=True) as f:
            write(f)
        return
    with atomic_h5(target) as f:
        write(f)


def counts(values: Sequence[str]) -> dict[str, int]:
    """How often each status occurs, in order of first occurrence."""
    out: dict[str, int] = {}
    for s in values:
        out[s] = out.get(s, 0) + 1
    return out


def root_attrs(f: h5py.File) -> dict[str, Any]:
    """The root attributes as plain Python values."""
    return {k: plain(v) for k, v in f.attrs.items()}
