"""The grid of a sweep: its axes (``PATH=SPEC``), linked dimensions, and the edited gait
document of every grid point.

A sweep axis is ``PATH=SPEC``. ``PATH`` is a dotted path into the gait document (integer list
indices, ``*`` for every element: ``links.*.amplitude``, ``friction.1.backward``, ``period``).
``SPEC`` is one of

* ``START:STOP:NUM``: NUM evenly spaced values, both ends included, each the double nearest its
  exact value START + k (STOP - START) / (NUM - 1) with START and STOP as written, so that a
  value prints as the number asked for (``0:1:11`` gives 0.3, not 0.30000000000000004);
* ``log:LO:HI:NUM``: NUM log-spaced (geometric) values, LO and HI > 0, both ends included;
* ``[a,b,c]`` or ``a,b,c``: these values.

Axes are grouped into grid dimensions. A dimension is one axis, or several **linked** axes with
the same number of values that vary together (the command line's ``--link PATH=SPEC`` joins the
``--sweep`` before it): value k of every linked path belongs to index k of the dimension. The
grid is the Cartesian product of the dimensions in the order given, the last varying fastest (C
order): grid point i has the multi-index ``np.unravel_index(i, shape)``.

Every path is resolved against the base document when the grid is made (`make_grid`), so a bad
path is an `InputError` (exit code 2) before anything runs.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from crawlsim.errors import GaitError, InputError, SweepSpecError
from crawlsim.gait.crawler_spec import need_crawler
from crawlsim.gait.docpaths import check_number_paths, path_keys, resolve_path, set_values
from crawlsim.gait.document import Gait, gait_from_document
from crawlsim.gait.validation import plain

if TYPE_CHECKING:
    from crawlsim.study.points import PointQuantity

#: Most values of one axis (START:STOP:NUM, log:LO:HI:NUM), and most points of a grid. At the
#: fastest, some 10^3 points a second, a million points take hours; the values are made before
#: anything is checked, so a mistyped NUM must not allocate gigabytes.
MAX_AXIS_POINTS = 1_000_000


@dataclass(frozen=True)
class Axis:
    """One swept path and its values."""

    path: str
    values: tuple

    @property
    def keys(self) -> tuple:
        return path_keys(self.path)


_SPECS = "START:STOP:NUM, log:LO:HI:NUM, [a,b,c] or a,b,c"


def parse_axis(text: str, option: str = "--sweep") -> Axis:
    """``PATH=SPEC`` -> `Axis` (the specs of the module docstring); a malformed option is a
    `SweepSpecError` naming ``option``."""
    source = f"{option} {text}"
    path, sep, spec = text.partition("=")
    path, spec = path.strip(), spec.strip()
    if not sep or not path or not spec:
        raise SweepSpecError(
            source, "", f"expected PATH=SPEC with SPEC one of {_SPECS}, for example links.*.amplitude=0.1:0.4:7"
        )
    if any(part == "" for part in path.split(".")):
        raise SweepSpecError(source, path, "empty key in the dotted path")
    if spec.startswith("[") or spec.endswith("]"):
        if not (spec.startswith("[") and spec.endswith("]")) or not spec[1:-1].strip():
            raise SweepSpecError(source, path, f"expected a list [a,b,c] of numbers, got {spec!r}")
        values = _list(spec[1:-1], source, path)
    elif spec.lower().startswith("log:"):
        lo, hi, num = _range(spec[4:], source, path, "log:LO:HI:NUM")
        if not (lo > 0 and hi > 0):
            raise SweepSpecError(source, path, f"log-spaced values need LO > 0 and HI > 0, got {spec!r}")
        values = tuple(float(v) for v in np.geomspace(lo, hi, num))
        values = (lo, *values[1:-1], hi) if num > 1 else (lo,)  # both ends exactly as given
    elif ":" in spec:
        _, _, num = _range(spec, source, path, "START:STOP:NUM")
        start, stop = spec.split(":")[:2]
        values = _evenly(start, stop, num)
    else:
        values = _list(spec, source, path)
    if not all(math.isfinite(v) for v in values):
        raise SweepSpecError(source, path, f"values must be finite numbers, got {spec!r}")
    return Axis(path, values)


def _range(spec: str, source: str, path: str, form: str) -> tuple[float, float, int]:
    parts = spec.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise SweepSpecError(source, path, f"expected {form} with NUM an integer, got {spec!r}") from None
    if num < 1:
        raise SweepSpecError(source, path, f"NUM must be at least 1, got {num}")
    if num > MAX_AXIS_POINTS:
        raise SweepSpecError(
            source,
            path,
            f"NUM must be at most {MAX_AXIS_POINTS:,}, got {num:,}; "
            "a sweep that large would not finish: sweep fewer points",
        )
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise SweepSpecError(source, path, f"values must be finite numbers, got {spec!r}")
    return start, stop, num


def _evenly(start: str, stop: str, num: int) -> tuple[float, ...]:
    """``num`` values from ``start`` to ``stop`` (decimal strings), each correctly rounded from
    its exact value: integers over one denominator, whose true division Python rounds
    correctly."""
    a, b = Fraction(start), Fraction(stop)
    den = math.lcm(a.denominator, b.denominator)
    p, q, d = a.numerator * (den // a.denominator), b.numerator * (den // b.denominator), max(num - 1, 1)
    return tuple((p * (d - k) + q * k) / (den * d) for k in range(num))


def _list(text: str, source: str, path: str) -> tuple:
    try:
        return tuple(_number(v) for v in text.split(","))
    except ValueError:
        raise SweepSpecError(source, path, f"expected a comma list of numbers, got {text!r}") from None


def _number(text: str):
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        return float(text)


@dataclass(frozen=True, eq=False)
class SweepGrid:
    """A base gait and its axes: the grid of edited gait documents.

    ``dims[a]`` is the grid dimension of axis a; linked axes share one (`make_grid`).
    """

    base: Gait
    axes: tuple[Axis, ...]
    targets: tuple[tuple[tuple, ...], ...]  # concrete key tuples of each axis
    dims: tuple[int, ...] = ()
    #: Extra columns computed at every point that runs (`crawlsim.study.points.PointQuantity`).
    quantities: tuple[PointQuantity, ...] = ()
    sensitivity: tuple[str, ...] = ()  # --sensitivity paths: a dv0/dPATH column each
    point = "point of the grid"  # what a point is, in messages

    def __post_init__(self) -> None:
        if not self.dims:
            object.__setattr__(self, "dims", tuple(range(len(self.axes))))
        if self.size > MAX_AXIS_POINTS:
            raise SweepSpecError(
                "--sweep",
                "",
                f"the grid has {self.size:,} points (the product of "
                f"its axes), more than {MAX_AXIS_POINTS:,}; a sweep "
                "that large would not finish: sweep fewer points",
            )

    @property
    def shape(self) -> tuple[int, ...]:
        return grid_shape([len(a.values) for a in self.axes], self.dims)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def paths(self) -> tuple[str, ...]:
        return tuple(a.path for a in self.axes)

    @property
    def linked(self) -> bool:
        return len(set(self.dims)) < len(self.dims)

    @property
    def gait_yaml(self) -> str:
        """The base gait document as YAML, simulation overrides included."""
        return yaml.safe_dump(self.base.document, sort_keys=False)

    def values(self, index: int) -> tuple:
        """The value of every axis at grid point ``index``."""
        multi = np.unravel_index(index, self.shape) if self.axes else ()
        return tuple(a.values[multi[d]] for a, d in zip(self.axes, self.dims))

    def document(self, index: int) -> dict:
        """The base document with the point's values set: a copy (`crawlsim.gait.validation.
        plain`: the base document is plain data already, which copies faster than deepcopy)."""
        doc = plain(self.base.document)
        set_values(doc, [(keys, value) for targets, value in zip(self.targets, self.values(index)) for keys in targets])
        return doc

    def label(self, index: int) -> str:
        """The point in words, for error messages: ``file with path=value, ...``."""
        pairs = ", ".join(f"{a.path}={v!r}" for a, v in zip(self.axes, self.values(index)))
        return f"{self.base.source} with {pairs}" if pairs else self.base.source

    def gait(self, index: int) -> Gait:
        """Grid point ``index`` validated into a Gait (a GaitError names the point)."""
        gait = gait_from_document(
            self.document(index), self.label(index), source_text=self.base.source_text, default_name=self.base.name
        )
        assert isinstance(gait, Gait)  # the base is a crawler, and sweeps keep the kind
        return gait

    def fingerprint(self, shard) -> str:
        """Identity of a sweep: base document, axes, links and shard (journals from others are
        refused). Unlinked grids hash as before links existed, so their journals resume."""
        axes: list = [[a.path, list(a.values)] for a in self.axes]
        if self.linked:
            axes = [axes, list(self.dims)]
        parts: list = [self.gait_yaml, axes, list(shard) if shard else None]
        if self.quantities:
            parts.append([q.name for q in self.quantities])
        if self.sensitivity:
            parts.append(list(self.sensitivity))
        spec = json.dumps(parts)
        return hashlib.sha256(spec.encode()).hexdigest()

    def indices(self, shard=None) -> np.ndarray:
        """Grid indices of the shard ``(i, n)`` (1-based i: points i-1, i-1+n, ...), or all."""
        if shard is None:
            return np.arange(self.size)
        i, n = shard
        return np.arange(i - 1, self.size, n)

    @property
    def source(self) -> str:
        return self.base.source


@dataclass(frozen=True, eq=False)
class FileGrid(SweepGrid):
    """Gait files as a grid of one dimension, ``gait`` (``crawlsim velocity A.yaml B.yaml ...``):
    point i is file i with the simulation settings ``overrides`` (the command line's). A file
    that is not a valid crawler gait is an invalid point, as an invalid grid point is."""

    overrides: tuple[tuple[str, object], ...] = ()
    point = "gait file"

    @classmethod
    def of(cls, files: Sequence[str], overrides: dict | None = None) -> FileGrid:
        axis = Axis("gait", tuple(str(f) for f in files))
        return cls(None, (axis,), ((),), overrides=tuple(sorted((overrides or {}).items())))  # type: ignore[arg-type]

    @property
    def source(self) -> str:
        return f"{len(self.axes[0].values)} gait files"

    @property
    def gait_yaml(self) -> str:
        return ""

    def label(self, index: int) -> str:
        return str(self.axes[0].values[index])

    def gait(self, index: int) -> Gait:
        from crawlsim.gait.document import load_gait, with_simulation

        gait = load_gait(self.label(index))
        need_crawler(gait, "v0")
        return with_simulation(gait, **dict(self.overrides)) if self.overrides else gait  # type: ignore[return-value]

    def fingerprint(self, shard) -> str:
        """The files' paths and contents, the overrides and the shard: a journal of other or
        since edited files is refused."""
        digest = hashlib.sha256(json.dumps([list(self.axes[0].values), self.overrides, shard]).encode())
        for path in self.axes[0].values:
            try:
                digest.update(Path(path).read_bytes())
            except OSError:
                digest.update(b"unreadable")
        return digest.hexdigest()


def grid_shape(lengths, dims) -> tuple[int, ...]:
    """Values per grid dimension: the length of the first axis of each dimension."""
    first: dict[int, int] = {}
    for length, d in zip(lengths, dims):
        first.setdefault(d, int(length))
    return tuple(first[d] for d in sorted(first))


def _group(item) -> tuple[Axis, ...]:
    """One grid dimension: an `Axis` or ``PATH=SPEC``, or a sequence of them (linked paths)."""
    if isinstance(item, (Axis, str)):
        items: Sequence = [item]
    else:
        items = list(item)
        if not items:
            raise SweepSpecError("--sweep", "", "an empty group of linked paths")
    return tuple(
        a if isinstance(a, Axis) else parse_axis(a, "--sweep" if k == 0 else "--link") for k, a in enumerate(items)
    )


def make_grid(base: Gait, axes, quantities: Sequence[PointQuantity] = (), sensitivity: Sequence[str] = ()) -> SweepGrid:
    """The grid of ``base`` over ``axes``: each item is one dimension, an `Axis` (or its
    ``PATH=SPEC`` text) or a sequence of them that vary together (linked paths, the same
    number of values each). Every path is checked against the base document; overlapping or
    repeated paths are refused, and so is a base that is not a crawler
    (`crawlsim.gait.crawler_spec.need_crawler`). ``quantities`` are extra columns of the table
    (`crawlsim.study.points.PointQuantity`); ``sensitivity``, the ``--sensitivity`` paths, each
    number's ``dv0/dPATH`` column (`crawlsim.study.points.with_derivatives`)."""
    need_crawler(base, "a sweep of v0")
    groups = [_group(item) for item in axes]
    flat: list[Axis] = []
    dims: list[int] = []
    for d, group in enumerate(groups):
        for axis in group[1:]:
            if len(axis.values) != len(group[0].values):
                raise SweepSpecError(
                    f"--link {axis.path}",
                    axis.path,
                    f"has {len(axis.values)} values, but the path it is linked "
                    f"to ({group[0].path}) has {len(group[0].values)}: linked "
                    "paths vary together and need the same number of values",
                )
        flat.extend(group)
        dims.extend([d] * len(group))
    source = base.source
    targets = tuple(tuple(resolve_path(base.document, a, source)) for a in flat)
    seen: dict[tuple, str] = {}
    for k, (axis, keys) in enumerate(zip(flat, targets)):
        option = "--link" if k and dims[k] == dims[k - 1] else "--sweep"
        for key in keys:
            if key in seen:
                raise GaitError(
                    source,
                    axis.path,
                    f"this path sets {'.'.join(map(str, key))}, which {seen[key]} sets too: sweep each value once",
                )
            seen[key] = f"{option} {axis.path}"
    paths = check_number_paths(base, sensitivity, continuous=True)
    return SweepGrid(base, tuple(flat), targets, tuple(dims), tuple(quantities), paths)


def parse_shard(text: str) -> tuple[int, int]:
    """``I/N`` with 1 <= I <= N."""
    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise SweepSpecError(f"--shard {text}", "", "expected I/N, for example 3/16") from None
    if not 1 <= i <= n:
        raise SweepSpecError(f"--shard {text}", "", f"expected 1 <= I <= N, got I = {i}, N = {n}")
    return i, n


def check_some_point_runs(grid: SweepGrid) -> None:
    """Refuse a grid in which no point is a valid gait: nothing could run (a misspelt optional
    key, say, or a value that every point shares). Scans in grid order and stops at the first
    valid point, so a usual grid costs one validation."""
    first: InputError | None = None
    for index in range(grid.size):
        try:
            grid.gait(index)
        except InputError as exc:
            first = first or exc
        else:
            return
    if first is not None:
        raise SweepSpecError(
            first.source,
            first.keypath,
            f"{first.message} (no {grid.point} is a valid gait: all {grid.size} are refused, this is the first)",
        )
