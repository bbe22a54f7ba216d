"""Dotted paths into a gait document: the one syntax of ``--sweep PATH=...`` and `Gait.replace`.

A path is keys joined by dots: mapping keys, integer list indices, and ``*`` for every element of
a list (``links.*.amplitude``, ``friction.1.backward``, ``period``). Every key but the last must
exist; the last may be an optional key the document leaves out (a signal's ``phase``), and the
schema then decides whether it is allowed. A path names numbers (or other scalars), never a
whole mapping or list.

A wave of links, ``links: {wave: SIGNAL, phase_step: CYCLES}`` (`wave_links`), has two kinds of
paths. ``links.wave.amplitude`` and ``links.phase_step`` are the wave's own numbers: setting one
sets it for every link, the phases staying in step. ``links.3.phase`` and ``links.*.amplitude``
name the links the wave generates, as if they were written out: setting one writes the links out
(the document then holds the list) and sets that link's number alone. Several changes at once set
the wave's own numbers first (`set_values`), so a generated link's number overrides the wave's.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping, Sequence
from decimal import Decimal
from typing import Any

from crawlsim.errors import GaitError
from crawlsim.gait.schemaerrors import did_you_mean

Key = str | int
#: Top-level keys that are not continuous parameters of a gait.
STRUCTURAL = ("blocks", "simulation", "name", "description", "units", "kind")


def wave_links(links: dict, count: int) -> list:
    """The ``count`` link signals of a wave ``{wave: SIGNAL, phase_step: CYCLES}``: link i
    (0-based) is the wave's signal with phase ``phase + i * phase_step`` modulo 1 (in [0, 1)),
    computed in decimal from the numbers as written, so that a step of -0.1 gives link 7 the
    phase 0.3 as it would be typed, not 0.29999999999999993; a constant wave is that constant on
    every link."""
    wave = links["wave"]
    if not isinstance(wave, dict):
        return [wave] * count
    start, step = (Decimal(repr(float(v))) for v in (wave.get("phase", 0.0), links.get("phase_step", 0.0)))
    phases = ((start + i * step) % 1 for i in range(count))
    return [{**wave, "phase": float(p + 1 if p < 0 else p) + 0.0} for p in phases]


def explicit(document: dict) -> dict:
    """``document`` with a wave's links written out (`wave_links`); the document itself when its
    links are a list already."""
    links = document.get("links")
    if isinstance(links, dict) and "wave" in links:
        return {**document, "links": wave_links(links, int(document["blocks"]) - 1)}
    return document


def value_at(document: dict, keys: Sequence[Key]) -> Any:
    """The value at concrete ``keys`` (a generated link's, through its wave); None for a last key
    the document leaves out."""
    node: Any = explicit(document) if len(keys) > 1 and isinstance(keys[1], int) else document
    for key in keys:
        node = node.get(key) if isinstance(node, dict) else node[key]
    return node


def path_keys(path: str) -> tuple[Key, ...]:
    """The keys of a dotted path, list indices as integers."""
    return tuple(int(p) if p.isdigit() else p for p in path.split("."))


def resolve_path(document: dict, path: Any, source: str) -> list[tuple[Key, ...]]:
    """The concrete key tuples ``path`` names in ``document`` (``*`` expanded).

    ``path`` is the dotted string or anything with a ``path`` attribute (a sweep `Axis`). A path
    that does not fit the document is a `GaitError` naming ``source``, the path and why.
    """
    path = str(getattr(path, "path", path))
    if not path or any(part == "" for part in path.split(".")):
        raise GaitError(source, path, "empty key in the dotted path")
    found: list[tuple[tuple[Key, ...], Any]] = [((), document)]
    keys = path_keys(path)
    for depth, key in enumerate(keys):
        last = depth == len(keys) - 1
        nxt: list[tuple[tuple[Key, ...], Any]] = []
        for prefix, node in found:
            if prefix == ("links",) and (key == "*" or isinstance(key, int)):
                node = explicit(document)["links"]  # the links a wave generates
            if key == "*":
                if not isinstance(node, list):
                    raise GaitError(source, path, f"'*' needs a list, but {_where(prefix)} is {_kind(node)}")
                nxt.extend((prefix + (i,), item) for i, item in enumerate(node))
            elif isinstance(node, list):
                if not isinstance(key, int):
                    hint = f"; use {'.'.join(map(str, prefix))}.*.{key} or an index 0..{len(node) - 1}"
                    raise GaitError(
                        source, path, f"{_where(prefix)} is a list, so the key {key!r} must be an index or '*'{hint}"
                    )
                if not 0 <= key < len(node):
                    raise GaitError(
                        source,
                        path,
                        f"index {key} is out of range: {_where(prefix)} has {len(node)} elements (0..{len(node) - 1})",
                    )
                nxt.append((prefix + (key,), node[key]))
            elif isinstance(node, dict):
                if str(key) not in node and not last:
                    names = list(map(str, node))
                    hint = f"{did_you_mean(key, names)} (keys: {', '.join(names)})"
                    raise GaitError(source, path, f"{_where(prefix)} has no key {str(key)!r}{hint}")
                nxt.append((prefix + (str(key),), node.get(str(key))))
            else:
                raise GaitError(source, path, f"{_where(prefix)} is {_kind(node)}, it has no key {key!r}")
        found = nxt
    for prefix, node in found:
        if isinstance(node, (dict, list)):
            raise GaitError(
                source, path, f"{'.'.join(map(str, prefix))} is {_kind(node)}, not a number: sweep a number inside it"
            )
    return [prefix for prefix, _ in found]


def _where(prefix: tuple[Key, ...]) -> str:
    """A key prefix as the messages name it (formed only for a message)."""
    return ".".join(str(k) for k in prefix) or "the document"


def _kind(node: Any) -> str:
    if isinstance(node, dict):
        return "a mapping"
    if isinstance(node, list):
        return "a list"
    return f"the value {node!r}"


def set_value(document: dict, keys: Sequence[Key], value: Any) -> None:
    """Set ``value`` at the concrete key tuple ``keys`` of ``document``, in place.

    An integral value replacing an integer stays an integer (``blocks``, ``steps_per_period``),
    so that the schema, which wants integers there, accepts a swept 3.0. A generated link's number
    writes the wave's links out first (module docstring).
    """
    if len(keys) > 1 and keys[0] == "links" and isinstance(keys[1], int):
        document["links"] = explicit(document)["links"]
    node: Any = document
    for key in keys[:-1]:
        node = node[key]
    old = node.get(keys[-1]) if isinstance(node, dict) else node[keys[-1]]
    node[keys[-1]] = typed(value, old)


def set_values(document: dict, changes: Iterable[tuple[Sequence[Key], Any]]) -> None:
    """Each ``(keys, value)`` set in place (`set_value`), a wave's own numbers before those of the
    links it generates (module docstring)."""
    for keys, value in sorted(changes, key=lambda change: len(change[0]) > 1 and isinstance(change[0][1], int)):
        set_value(document, keys, value)


def typed(value: Any, old: Any) -> Any:
    """``value``, as an int when it is integral and replaces an int."""
    if (
        isinstance(old, int)
        and not isinstance(old, bool)
        and isinstance(value, (int, float))
        and not isinstance(value, bool)
        and float(value).is_integer()
    ):
        return int(value)
    return value


def changes_of(args: Sequence[Any]) -> list[tuple[str, Any]]:
    """``(path, value)`` pairs from ``replace``'s arguments: ``path, value[, path, value ...]``
    or a single mapping ``{path: value}``."""
    if len(args) == 1 and isinstance(args[0], Mapping):
        pairs = list(args[0].items())
    elif len(args) % 2 == 0 and args:
        pairs = [(args[i], args[i + 1]) for i in range(0, len(args), 2)]
    else:
        raise TypeError(
            "replace() takes path, value pairs (replace('period', 2.0, "
            "'links.1.phase', 0.25)) or one mapping (replace({'period': 2.0}))"
        )
    for path, _ in pairs:
        if not isinstance(path, str):
            raise TypeError(f"replace(): a path is a dotted string such as 'links.*.amplitude', got {path!r}")
    return pairs


def edited(document: dict, pairs: Sequence[tuple[str, Any]], source: str) -> dict:
    """A deep copy of ``document`` with each ``(path, value)`` applied; a path that does not fit,
    or two paths that set the same number, are a `GaitError`."""
    doc = copy.deepcopy(document)
    seen: dict[tuple[Key, ...], str] = {}
    changes = []
    for path, value in pairs:
        for keys in resolve_path(document, path, source):
            if keys in seen:
                raise GaitError(
                    source,
                    path,
                    f"this path sets {'.'.join(map(str, keys))}, which {seen[keys]} sets too: set each value once",
                )
            seen[keys] = path
            changes.append((keys, value))
    set_values(doc, changes)
    return doc


def replacement(source: str, document: dict, args: Sequence[Any]) -> tuple[str, dict]:
    """The label and the edited document of ``replace(*args)`` on a gait read from ``source``:
    errors of the rebuilt gait name the gait and the changes (``gait.yaml with
    links.*.amplitude=0.5``), as a sweep names its point."""
    pairs = changes_of(args)
    label = f"{source} with " + ", ".join(f"{p}={v!r}" for p, v in pairs)
    return label, edited(document, pairs, label)


def check_number_paths(gait: Any, paths: Sequence[str], continuous: bool = False) -> tuple[str, ...]:
    """``paths``, each checked to name a number of ``gait`` (``--sensitivity``: a `GaitError`
    naming the path when one names nothing, or with ``continuous`` no continuous parameter such
    as ``blocks``: exit code 2 before any point runs). A path to a key the document leaves out
    (but a signal's phase) is put to the schema with a value, so that a misspelt key
    (``links.*.phse``) gets the did-you-mean of a gait file and of ``--sweep``."""
    for path in paths:
        keys = resolve_path(gait.document, path, gait.source)[0]
        if continuous and keys[0] in STRUCTURAL:
            raise GaitError(gait.source, path, "not a continuous parameter of the gait: v0 has no derivative in it")
        node = value_at(gait.document, keys[:-1])
        if keys[-1] != "phase" and isinstance(node, dict) and keys[-1] not in node:
            try:
                gait.replace(path, 1.0)
            except GaitError as error:
                if error.message.startswith("unknown key"):
                    raise GaitError(gait.source, error.keypath, error.message) from None
    return tuple(paths)
