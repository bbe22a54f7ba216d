"""Reading gait files safely: a size limit, and YAML whose cost is bounded before it is built.

A gait file is a small text file, but the path a user gives may be anything: `/dev/zero`, a FIFO,
a file of gigabytes, or YAML written to exhaust the reader (an alias bomb, "billion laughs", or
nesting thousands deep). Each of these is refused here with a `GaitError` naming the file, after
reading at most `MAX_GAIT_BYTES` + 1 bytes and before anything is expanded:

* devices, sockets and folders are refused without being opened; a FIFO (a pipe such as
  ``<(sed ... gait.yaml)``) is read like a file, up to the size limit;
* YAML is first read as a stream of parser events (libyaml's parser when it is installed), and
  refused there when it nests deeper than `MAX_DEPTH` or holds more than `MAX_NODES` values with
  every alias expanded, or when an alias is used inside its own anchor. Only then is it composed
  and constructed: aliases stay shared in the result, but the first consumer that copies the
  document (validation does) expands them, so their expansion must be bounded beforehand;
* YAML 1.2 floats without a dot (``1e-3``) are floats, and duplicate keys are refused.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml
from yaml.constructor import ConstructorError, SafeConstructor
from yaml.events import (
    AliasEvent,
    DocumentStartEvent,
    MappingEndEvent,
    MappingStartEvent,
    ScalarEvent,
    SequenceEndEvent,
    SequenceStartEvent,
)
from yaml.nodes import MappingNode, ScalarNode
from yaml.parser import Parser
from yaml.reader import Reader
from yaml.resolver import Resolver
from yaml.scanner import Scanner

from crawlsim.errors import GaitError

MAX_GAIT_BYTES = 1 << 20
"""Largest gait file read (1 MiB). The largest crawler the schema allows (100,000 blocks) with
shared friction and anchored link signals fits in well under that; PyYAML needs about two
seconds per MiB, so the limit also bounds the time spent reading."""

MAX_DEPTH = 32
"""Deepest nesting of YAML collections. A gait needs 5 (friction list, mapping, signal, times);
deeper documents are refused before Python's recursion limit is reached."""

MAX_INT_DIGITS = 4300
"""Longest integer literal read (Python's own limit on converting text to int)."""

MAX_NODES = 2_000_000
"""Most YAML nodes (keys, values, list items) a document may hold once every alias is expanded.
A 100,000-block crawler with per-block friction holds about 800,000; an alias bomb holds 10^9."""


class _Refused(yaml.composer.ComposerError):
    """A document refused by a guard (depth, expanded size, recursion), not a syntax error."""


def _guard(text: str) -> None:
    """Refuse, from the parser's events alone, YAML that is too deep or too big once expanded.

    One pass over the events (no node is built): the open collections are a stack of counters,
    an anchor records the expanded size of what it names when that is complete, and an alias
    adds that size to its collection. An alias to an anchor still open is a recursive alias.

    libyaml's scanner reads ahead of the events and, from PyYAML 6.0.3, refuses deep nesting
    itself (its own limit and wording) before this guard sees the 33rd level. A document libyaml
    refuses is therefore read again by PyYAML's pure-Python parser, which reads no further than
    it must: crawlsim's own refusal (`MAX_DEPTH`) speaks when it applies, libyaml's error
    otherwise.
    """
    try:
        _guard_events(text, _Parser)
    except _Refused:
        raise
    except yaml.YAMLError:
        if _Parser is _PythonParser:
            raise
        try:
            _guard_events(text, _PythonParser)
        except _Refused:
            raise
        except (yaml.YAMLError, RecursionError):
            pass
        raise


def _guard_events(text: str, parser_class: Any) -> None:
    parser = parser_class(text)
    stack: list[list[Any]] = []  # [anchor, expanded size] of each open collection
    sizes: dict[str, int] = {}
    open_anchors: set[str] = set()
    try:
        while parser.check_event():
            event = parser.get_event()
            added = 0
            if isinstance(event, (SequenceStartEvent, MappingStartEvent)):
                if len(stack) >= MAX_DEPTH:
                    raise _Refused(
                        None,
                        None,
                        f"nesting deeper than {MAX_DEPTH} levels; a gait file needs at most 5",
                        event.start_mark,
                    )
                stack.append([event.anchor, 1])
                if event.anchor is not None:
                    open_anchors.add(event.anchor)
            elif isinstance(event, (SequenceEndEvent, MappingEndEvent)):
                anchor, added = stack.pop()
                if anchor is not None:
                    sizes[anchor] = added
                    open_anchors.discard(anchor)
            elif isinstance(event, ScalarEvent):
                added = 1
                if event.anchor is not None:
                    sizes[event.anchor] = 1
            elif isinstance(event, AliasEvent):
                if event.anchor in open_anchors:
                    raise _Refused(
                        None,
                        None,
                        f"recursive alias *{event.anchor}: the anchor is used inside itself",
                        event.start_mark,
                    )
                added = sizes.get(event.anchor, 1)  # an undefined alias is the composer's error
            elif isinstance(event, DocumentStartEvent):
                sizes.clear()
            if added and stack:
                stack[-1][1] += added
                if stack[-1][1] > MAX_NODES:
                    raise _Refused(
                        None,
                        None,
                        f"the document holds more than {MAX_NODES:,} values "
                        "once its aliases are expanded (an alias bomb?)",
                        event.start_mark,
                    )
    finally:
        parser.dispose()


class _Constructor(SafeConstructor):
    """Safe construction that refuses duplicate keys."""

    def construct_mapping(self, node: MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: SafeConstructor says so below
                continue
            if duplicate:
                raise ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: ScalarNode) -> int:
        """An integer of at most `MAX_INT_DIGITS` digits (Python refuses to convert longer ones;
        no number of a gait needs more than a few)."""
        digits = sum(c.isalnum() for c in str(node.value))
        if digits > MAX_INT_DIGITS:
            raise _Refused(
                None, None, f"an integer of {digits:,} digits; at most {MAX_INT_DIGITS:,} are read", node.start_mark
            )
        return super().construct_yaml_int(node)


_Constructor.add_constructor("tag:yaml.org,2002:int", _Constructor.construct_yaml_int)


class _Resolver(Resolver):
    """YAML 1.1 resolution, plus YAML 1.2 floats without a dot (``1e-3``).

    Plain scalars are resolved once per distinct text: a list of 10^5 equal numbers costs one
    round of regular expressions, not 10^5 (there are no path resolvers, so the tag depends on
    the text alone).
    """

    def resolve(self, kind: Any, value: Any, implicit: Any) -> Any:
        if kind is not ScalarNode or not implicit[0]:
            return super().resolve(kind, value, implicit)
        cache = self.__dict__.setdefault("_tags", {})
        tag = cache.get(value)
        if tag is None:
            tag = cache[value] = super().resolve(kind, value, implicit)
        return tag


_Resolver.yaml_implicit_resolvers = {k: list(v) for k, v in Resolver.yaml_implicit_resolvers.items()}
_Resolver.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


class _PythonParser(Reader, Scanner, Parser):
    """PyYAML's pure-Python event parser (no nesting limit of its own, reads only as far as it
    must)."""

    def __init__(self, stream: str) -> None:
        Reader.__init__(self, stream)
        Scanner.__init__(self)
        Parser.__init__(self)

    def dispose(self) -> None:
        pass


try:  # libyaml parses and composes about ten times faster than pure Python
    from yaml._yaml import CParser as _Parser  # type: ignore[import-not-found,unused-ignore]

    class _Loader(_Parser, _Constructor, _Resolver):  # type: ignore[misc,valid-type,unused-ignore]
        def __init__(self, stream: str) -> None:
            _Parser.__init__(self, stream)
            _Constructor.__init__(self)
            _Resolver.__init__(self)
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    from yaml.composer import Composer

    _Parser = _PythonParser  # type: ignore[misc,assignment,unused-ignore]

    class _Loader(Reader, Scanner, Parser, Composer, _Constructor, _Resolver):  # type: ignore[no-redef]
        def __init__(self, stream: str) -> None:
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)
            Composer.__init__(self)
            _Constructor.__init__(self)
            _Resolver.__init__(self)


def load_yaml(text: str, source: str) -> Any:
    """One YAML document from ``text``; every way it can fail is a `GaitError` naming ``source``.

    The events are checked first (`_guard`), so nothing is composed from a document that is too
    deep or too big. Syntax errors name the line and column.
    """
    try:
        _guard(text)
        loader = _Loader(text)
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        what = "YAML refused" if isinstance(error, _Refused) else "YAML syntax error"
        raise GaitError(source, "", f"{what}{where}: {error.problem}") from None
    except yaml.YAMLError as error:
        raise GaitError(source, "", f"YAML syntax error: {error}") from None
    except (ValueError, OverflowError, RecursionError, MemoryError) as error:
        # int() of an integer literal of more than 4300 digits, for one
        reason = str(error).split("; use sys.set_int_max_str_digits")[0]
        raise GaitError(source, "", f"YAML refused: {reason}") from None


def read_limited(path: str | Path, limit: int = MAX_GAIT_BYTES) -> str:
    """The text of a gait file, refusing what is not a small UTF-8 file before reading it all.

    Devices, sockets and folders are refused without being opened (`/dev/zero` would never
    end). Regular files larger than ``limit`` are refused from their size; anything else
    readable (a FIFO, ``/proc`` files that report size 0) is read up to ``limit`` + 1 bytes.
    """
    source = str(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise GaitError(source, "", "no such gait file") from None
    except OSError as error:
        raise GaitError(source, "", f"cannot read the gait file: {error.strerror}") from None
    mode = info.st_mode
    if stat.S_ISDIR(mode):
        raise GaitError(source, "", "is a folder, not a gait file")
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        raise GaitError(source, "", "is a device, not a gait file")
    if stat.S_ISSOCK(mode):
        raise GaitError(source, "", "is a socket, not a gait file")
    too_big = GaitError(
        source,
        "",
        f"is larger than {limit:,} bytes: a gait file is a small text file (see the size limits in the gait schema)",
    )
    if stat.S_ISREG(mode) and info.st_size > limit:
        raise too_big
    try:
        # O_NONBLOCK: opening a FIFO without a writer would wait for one; reading it then sees
        # end of file at once. The descriptor is made blocking again to read a live writer.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as error:
        raise GaitError(source, "", f"cannot read the gait file: {error.strerror}") from None
    try:
        os.set_blocking(fd, True)
        chunks: list[bytes] = []
        size = 0
        while size <= limit:
            chunk = os.read(fd, limit + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise GaitError(source, "", f"cannot read the gait file: {error.strerror}") from None
    finally:
        os.close(fd)
    if size > limit:
        raise too_big
    try:
        return b"".join(chunks).decode("utf-8")
    except UnicodeDecodeError as error:
        raise GaitError(source, "", f"is not UTF-8 text (byte {error.start}): a gait file is YAML text") from None
