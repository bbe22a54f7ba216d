"""What every kind of gait document shares on its way to a validated object: a plain copy, the
structure checked by its schema, and the collection of its errors (`crawlsim validate` lists
them all, a load stops at the first).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np
import yaml

from crawlsim.errors import GaitError
from crawlsim.gait.schemaerrors import check_finite, check_schema
from crawlsim.gait.signals import without_signals
from crawlsim.gait.units import unit_problems

Builder = Callable[..., Any]
"""``build(document, source, source_text, default_name, errors)``: a kind's semantic checks and
its validated object (None when ``errors`` collects and found some)."""


def plain(value: Any) -> Any:
    """A deep copy with numpy scalars and arrays turned into Python numbers and lists."""
    if type(value) in _SCALARS:  # immutable: its own copy (a sweep copies a document a point)
        return value
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {key: plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        if all(type(item) in _SCALARS for item in value):
            return list(value)  # a list of numbers (the common long list) needs no deeper copy
        return [plain(item) for item in value]
    return copy.deepcopy(value)


_SCALARS = frozenset({float, int, str, bool, type(None)})


def structure(schema: dict) -> dict:
    """The schema with every signal accepted as is: signals are validated one by one (and only
    once each) by `parse_signal`, which keeps a document of 10^5 links fast to check."""
    skeleton = _SKELETONS.get(id(schema))
    if skeleton is None:
        skeleton = _SKELETONS[id(schema)] = without_signals(schema)
    return skeleton


_SKELETONS: dict[int, dict] = {}


def validated(
    document: dict,
    schema: dict,
    build: Builder,
    source: str,
    source_text: str | None = None,
    default_name: str = "gait",
) -> Any:
    """A plain document checked (finite numbers, then the structure of ``schema``) and built by
    ``build``, whose first error is raised."""
    check_finite(document, source)
    check_schema(document, structure(schema), source)
    if source_text is None:
        source_text = yaml.safe_dump(document, sort_keys=False)
    return build(document, source, source_text, default_name, ErrorSink())


class ErrorSink:
    """Where a builder's checks report: by default the first error is raised; with
    ``collect=True`` each is recorded and the checks that do not depend on it go on."""

    def __init__(self, collect: bool = False):
        self.collect = collect
        self.found: list[GaitError] = []

    def add(self, error: GaitError) -> None:
        if not self.collect:
            raise error
        self.found.append(error)

    def attempt(self, check: Callable[..., Any], *args: Any) -> Any:
        """``check(*args)``, or None after reporting its GaitError."""
        try:
            return check(*args)
        except GaitError as error:
            self.add(error)
            return None


def readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def check_units(document: dict, source: str, errors: ErrorSink) -> None:
    """Each unit name of the ``units:`` block is one of `crawlsim.gait.units.UNIT_NAMES`."""
    for keypath, problem in unit_problems(document.get("units")):
        errors.add(GaitError(source, keypath, problem))


def count_error(source: str, keypath: str, expected: int, what: str, got: int) -> GaitError:
    return GaitError(source, keypath, f"expected {expected} {what}, got {got}")
