"""Gait files: reading a YAML document and validating it into a `Gait` or a `ProcessSpec`
(docs/model.md §1, §5).

The file is read safely (`crawlsim.gait.yamlsafe`: a size limit, bounded YAML); documents are
dispatched on their `kind` key (`_KINDS`): `crawler` (the default) builds a `Gait`
(`crawlsim.gait.crawler_spec`), `sweeping-process` a `ProcessSpec`
(`crawlsim.gait.process_spec`). jsonschema checks structure, types and bounds (the schemas state
every bound and why), then each kind's semantic checks run.

`validation_errors` lists every error of a file instead of stopping at the first
(``crawlsim validate``).

``from crawlsim.gait.document import Gait, load_gait`` is the one import a user needs.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import warnings
from pathlib import Path
from typing import Any, TypeVar

import yaml

from crawlsim.errors import GaitError, GaitWarning
from crawlsim.gait.crawler_spec import CRAWLER_SCHEMA, Gait, build_crawler, negative_length, uniqueness_report
from crawlsim.gait.process_spec import PROCESS_SCHEMA, ProcessSpec, build_process
from crawlsim.gait.schemaerrors import check_schema, finite_errors, schema_errors
from crawlsim.gait.settings import SIMULATION_SCHEMA, simulation_from
from crawlsim.gait.signals import SIGNAL_SCHEMA, parse_signal
from crawlsim.gait.validation import Builder, ErrorSink, plain, structure, validated
from crawlsim.gait.yamlsafe import load_yaml, read_limited

__all__ = [  # and the two kinds of document, so that one import gives a gait and its type
    "Gait",
    "ProcessSpec",
    "document_errors",
    "gait_from_document",
    "load_gait",
    "parse_gait",
    "uniqueness_explanation",
    "validation_errors",
    "with_simulation",
]
_KINDS: dict[str, tuple[dict, Builder]] = {
    "crawler": (CRAWLER_SCHEMA, build_crawler),
    "sweeping-process": (PROCESS_SCHEMA, build_process),
}
"""Gait kinds: the value of the document's `kind` key -> (schema, builder)."""

Spec = TypeVar("Spec", bound=Gait | ProcessSpec)


def load_gait(path: str | Path) -> Gait | ProcessSpec:
    """Read and validate a gait file; the name defaults to the file's stem.

    The file is read by `crawlsim.gait.yamlsafe`: at most `MAX_GAIT_BYTES`, devices refused, YAML
    depth and alias expansion bounded.
    """
    text = read_limited(path)
    spec = parse_gait(text, source=str(path), default_name=Path(path).stem)
    _warn_negative_length(spec)
    return spec


def _warn_negative_length(spec: Any) -> None:
    """A `GaitWarning` when a link's actuator length goes negative (`negative_length`): a file
    read, or validated, says so once; the gaits of a sweep's points do not."""
    problem = negative_length(spec) if isinstance(spec, Gait) else None
    if problem is not None:
        warnings.warn(problem, GaitWarning, stacklevel=3)


def parse_gait(text: str, source: str = "<string>", default_name: str = "gait") -> Gait | ProcessSpec:
    """Parse and validate gait YAML; syntax errors are reported with line and column."""
    document = load_yaml(text, source)
    return gait_from_document(document, source, source_text=text, default_name=default_name)


def _prepare(doc: Any, source: str) -> tuple[dict, dict, Builder]:
    """A plain copy of the document, and its kind's schema and builder."""
    if doc is None:
        raise GaitError(source, "", "the document is empty; expected a gait mapping")
    document = plain(doc)
    if not isinstance(document, dict):
        raise GaitError(source, "", f"expected a gait mapping at the top level, got {type(document).__name__}")
    kind = document.get("kind", "crawler")
    if kind not in _KINDS:
        close = difflib.get_close_matches(str(kind), list(_KINDS), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise GaitError(source, "kind", f"expected one of {', '.join(map(repr, _KINDS))}, got {kind!r}{hint}")
    schema, build = _KINDS[kind]
    return document, schema, build


def gait_from_document(
    doc: dict, source: str, source_text: str | None = None, default_name: str = "gait"
) -> Gait | ProcessSpec:
    """Validate a parsed document (for instance one edited by a parameter sweep) into a Gait,
    or a ProcessSpec for ``kind: sweeping-process``."""
    document, schema, build = _prepare(doc, source)
    return validated(document, schema, build, source, source_text, default_name)


def validation_errors(path: str | Path) -> list[GaitError]:
    """Every error of a gait file, in document order (empty when the file is valid).

    Structure, types and bounds are all listed (jsonschema's iter_errors, and every signal
    checked on its own); the semantic checks then run as far as the structure allows, each
    check that can run on its own listing its error.
    """
    source = str(path)
    try:
        text = read_limited(path)
        document = load_yaml(text, source)
    except GaitError as error:
        return [error]
    return document_errors(document, source, text, Path(path).stem)


def uniqueness_explanation(path: str | Path) -> list[str]:
    """The whole uniqueness analysis of a crawler gait file (`crawlsim.gait.crawler_spec.
    uniqueness_report`), then what the gait says before a run (`crawlsim.gait.apriori`: the
    margin, the cell theorem's verdict); empty for a file that cannot be read."""
    from crawlsim.gait.apriori import apriori_lines

    source = str(path)
    try:
        document = load_yaml(read_limited(path), source)
        document, schema, build = _prepare(document, source)
    except GaitError:
        return []
    crawler = document.get("kind", "crawler") == "crawler"
    lines = uniqueness_report(document, source) if crawler else []
    try:
        spec = validated(plain(document), schema, functools.partial(build, unique=False) if crawler else build, source)
    except GaitError:
        return lines
    return lines + apriori_lines(spec)


def document_errors(
    doc: Any, source: str, source_text: str | None = None, default_name: str = "gait"
) -> list[GaitError]:
    """Every error of a parsed document (see `validation_errors`)."""
    try:
        document, schema, build = _prepare(doc, source)
    except GaitError as error:
        return [error]
    errors = finite_errors(document, source)
    reported = {e.keypath for e in errors}
    errors += [e for e in schema_errors(document, structure(schema), source) if e.keypath not in reported]
    for keypath, value in _signal_slots(document):
        found = [e for e in schema_errors(value, SIGNAL_SCHEMA, source, keypath) if e.keypath not in reported]
        if not found and not any(e.keypath.startswith(keypath) for e in errors):
            try:
                parse_signal(value, keypath, source)
            except GaitError as error:
                found = [error]
        errors += found
    if errors:
        return _distinct(errors)
    collected = ErrorSink(collect=True)
    try:
        spec = build(
            document, source, source_text or yaml.safe_dump(document, sort_keys=False), default_name, collected
        )
    except GaitError as error:  # a check whose failure stops the others
        collected.found.append(error)
    else:
        if not collected.found:
            _warn_negative_length(spec)
    return _distinct(collected.found)


def _distinct(errors: list[GaitError]) -> list[GaitError]:
    seen: set[str] = set()
    out = []
    for error in errors:
        if str(error) not in seen:
            seen.add(str(error))
            out.append(error)
    return out


def _signal_slots(document: dict):
    """(key path, value) of every place a signal goes, where the structure around it is right."""

    def items(key):
        value = document.get(key)
        return enumerate(value) if isinstance(value, list) else ()

    if document.get("kind", "crawler") == "sweeping-process":
        for i, value in items("offsets"):
            yield f"offsets[{i}]", value
        return
    for i, value in items("links"):
        yield f"links[{i}]", value
    if isinstance(document.get("links"), dict) and "wave" in document["links"]:
        yield "links.wave", document["links"]["wave"]
    friction = document.get("friction")
    entries = (
        [("friction", friction)]
        if isinstance(friction, dict)
        else [(f"friction[{j}]", f) for j, f in items("friction")]
    )
    for path, entry in entries:
        if isinstance(entry, dict):
            for direction in ("forward", "backward"):
                if direction in entry:
                    yield f"{path}.{direction}", entry[direction]
    loads = document.get("loads")
    if isinstance(loads, dict) and "force" in loads:
        force = loads["force"]
        if isinstance(force, list):
            for j, value in enumerate(force):
                yield f"loads.force[{j}]", value
        else:
            yield "loads.force", force


def with_simulation(gait: Spec, **overrides: Any) -> Spec:
    """A copy of `gait` with simulation settings replaced, validated like the file's.

    The document's `simulation` section is updated too, so a sweep that edits the document
    and rebuilds keeps the overrides; `source_text` stays the text that was read.
    """
    settings = {**dataclasses.asdict(gait.simulation), **plain(overrides)}
    check_schema(settings, SIMULATION_SCHEMA, gait.source, "simulation")
    simulation = simulation_from(settings)
    document = plain(gait.document)
    document["simulation"] = {**document.get("simulation", {}), **plain(overrides)}
    return dataclasses.replace(gait, simulation=simulation, document=document)
