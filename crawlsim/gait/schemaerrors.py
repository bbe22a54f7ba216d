"""Checking a gait document's numbers and structure, with errors that name the key path
(``friction[2].backward``) and what was expected: every document kind and every signal is
checked by these helpers, so errors read alike wherever they are found.

A valid document (the common case) is accepted by the compiled check of
`crawlsim.gait.schemacheck` without importing jsonschema; jsonschema, the reference, decides
every document that check refuses and finds its error.
"""

from __future__ import annotations

import difflib
import itertools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from crawlsim.errors import GaitError
from crawlsim.gait.schemacheck import Check, compile_schema

if TYPE_CHECKING:
    import jsonschema

LARGEST = 1e100
"""Largest magnitude of any number in a gait document. The model multiplies a few of them
(stiffness x length x blocks, squared in the projections' norms); within 1e100 none of these
products overflows a double, and no physical quantity in any unit system comes near it."""


def join_keypath(base: str, *parts: str | int) -> str:
    """Append keys (`.key`) and 0-based indices (`[i]`) to a key path like `friction[2].backward`."""
    path = base
    for part in parts:
        if isinstance(part, int):
            path += f"[{part}]"
        elif part.startswith("[") or not path:
            path += part
        elif part:
            path += f".{part}"
    return path


def _describe(instance: Any) -> str:
    if isinstance(instance, bool):
        return f"a boolean ({str(instance).lower()})"
    if instance is None:
        return "nothing (null)"
    if isinstance(instance, int) and abs(instance) > LARGEST:
        return f"an integer of {instance.bit_length()} bits"
    if isinstance(instance, (int, float)):
        return f"the number {instance!r}"
    if isinstance(instance, str):
        return f"a string ({instance!r})"
    if isinstance(instance, list):
        return f"a list of {len(instance)} entries"
    if isinstance(instance, dict):
        return "a mapping"
    return f"a {type(instance).__name__}"


_TYPE_NAMES = {
    "number": "a number",
    "integer": "an integer",
    "object": "a mapping",
    "array": "a list",
    "string": "a string",
    "boolean": "a boolean",
    "null": "null",
}


def did_you_mean(word: Any, choices: Sequence[str]) -> str:
    """The text '; did you mean ...?' with the choice nearest ``word``, or '' when none is near."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _schema_error(error: jsonschema.ValidationError, source: str, keypath: str) -> GaitError:
    path = join_keypath(keypath, *error.absolute_path)
    schema = error.schema if isinstance(error.schema, dict) else {}
    validator, instance = error.validator, error.instance
    if validator == "required":
        missing = next(key for key in error.validator_value if key not in instance)
        return GaitError(source, join_keypath(path, missing), "required key is missing")
    if validator == "additionalProperties":
        allowed = sorted(schema.get("properties", {}))
        extra = next(key for key in instance if key not in allowed)
        return GaitError(
            source,
            join_keypath(path, str(extra)),
            f"unknown key {extra!r}{did_you_mean(extra, allowed)} (allowed here: {', '.join(allowed)})",
        )
    if validator in ("enum", "const"):
        choices = error.validator_value if validator == "enum" else [error.validator_value]
        listed = ", ".join(repr(c) for c in choices)
        return GaitError(
            source, path, f"expected one of {listed}, got {_describe(instance)}{did_you_mean(instance, choices)}"
        )
    if validator == "minItems":
        return GaitError(source, path, f"expected at least {error.validator_value} entries, got {len(instance)}")
    if validator == "maxItems":
        what = f" ({schema['x-expected']})" if "x-expected" in schema else ""
        return GaitError(
            source, path, f"expected at most {error.validator_value:,} entries{what}, got {len(instance):,}"
        )
    expected = schema.get("x-expected")
    if expected is None and validator == "type":
        types = error.validator_value if isinstance(error.validator_value, list) else [error.validator_value]
        expected = " or ".join(str(_TYPE_NAMES.get(t, t)) for t in types)
    if expected is None and validator in ("minimum", "exclusiveMinimum"):
        expected = f"a number {'>=' if validator == 'minimum' else '>'} {error.validator_value}"
    if expected is None:
        return GaitError(source, path, error.message)
    return GaitError(source, path, f"expected {expected}, got {_describe(instance)}")


_BEST_OF = 64
"""Errors weighed by relevance to pick the one reported. Finding more errors means validating
the rest of the document, which for a huge list (refused by its maxItems, checked first) would
cost seconds."""


def _validator(schema: dict) -> jsonschema.Draft202012Validator:
    validator = _VALIDATORS.get(id(schema))
    if validator is None:
        import jsonschema  # only for a document the compiled check refuses (`_fast_check`)

        validator = _VALIDATORS[id(schema)] = jsonschema.Draft202012Validator(schema)
    return validator


def _fast_check(schema: dict) -> Check:
    check = _FAST_CHECKS.get(id(schema))
    if check is None:
        check = _FAST_CHECKS[id(schema)] = compile_schema(schema)
    return check


def check_schema(instance: Any, schema: dict, source: str, keypath: str = "") -> None:
    """Validate against a Draft 2020-12 schema; raise the most relevant error as a GaitError.

    An unknown key outranks a missing one at the same place: a misspelt key causes both, and
    only the unknown-key message can suggest the right spelling.

    A valid document (the common case) is accepted by the compiled check of
    `crawlsim.gait.schemacheck` without importing jsonschema; jsonschema, the reference, decides
    every document that check refuses and finds its error.
    """
    if _fast_check(schema)(instance):
        return
    from jsonschema.exceptions import best_match, by_relevance

    errors = _validator(schema).iter_errors(instance)
    first = next(errors, None)
    if first is None:  # the compiled check is stricter than jsonschema: never, by its tests
        return
    if first.validator == "maxItems":  # a list over its bound: its items are not worth checking
        raise _schema_error(first, source, keypath)
    relevance = by_relevance(strong={"additionalProperties"})
    error = best_match(itertools.chain([first], itertools.islice(errors, _BEST_OF - 1)), key=relevance)
    raise _schema_error(error if error is not None else first, source, keypath)


def schema_errors(instance: Any, schema: dict, source: str, keypath: str = "") -> list[GaitError]:
    """Every error of ``instance`` against ``schema`` (for `crawlsim validate`), in document
    order; an if/then branch reports its own errors rather than the failed branch."""
    if _fast_check(schema)(instance):
        return []  # valid: no need for jsonschema (`check_schema`)
    out: list[GaitError] = []
    seen: set[str] = set()
    for error in _validator(schema).iter_errors(instance):
        for leaf in _leaves(error):
            found = _schema_error(leaf, source, keypath)
            if str(found) not in seen:
                seen.add(str(found))
                out.append(found)
    return out


def _leaves(error: jsonschema.ValidationError):
    if error.context:
        for sub in error.context:
            yield from _leaves(sub)
    else:
        yield error


#: One validator per schema (the schemas are module constants): building one is costly, and
#: sweeps validate thousands of documents.
_VALIDATORS: dict[int, jsonschema.Draft202012Validator] = {}
_FAST_CHECKS: dict[int, Check] = {}


def check_finite(instance: Any, source: str, keypath: str = "") -> None:
    """Refuse inf, nan and magnitudes above `LARGEST` anywhere in a document: no quantity of the
    model is infinite, and products of larger ones overflow."""
    problem = _number_problem(instance)
    if problem is not None:
        raise GaitError(source, keypath, problem)
    if isinstance(instance, dict):
        for key, item in instance.items():
            check_finite(item, source, join_keypath(keypath, str(key)))
    elif isinstance(instance, list):
        if all(type(item) is float or type(item) is int for item in instance):
            # a list of numbers (the common long list): one pass without a call per entry
            bad = next(
                (i for i, item in enumerate(instance) if not -LARGEST <= item <= LARGEST), None
            )  # nan compares false too
            if bad is not None:
                check_finite(instance[bad], source, join_keypath(keypath, bad))
            return
        for index, item in enumerate(instance):
            check_finite(item, source, join_keypath(keypath, index))


def finite_errors(instance: Any, source: str, keypath: str = "") -> list[GaitError]:
    """Every number `check_finite` refuses, as errors (for `crawlsim validate`)."""
    problem = _number_problem(instance)
    if problem is not None:
        return [GaitError(source, keypath, problem)]
    out: list[GaitError] = []
    if isinstance(instance, dict):
        for key, item in instance.items():
            out += finite_errors(item, source, join_keypath(keypath, str(key)))
    elif isinstance(instance, list):
        for index, item in enumerate(instance):
            out += finite_errors(item, source, join_keypath(keypath, index))
    return out


def _number_problem(value: Any) -> str | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if isinstance(value, float) and not math.isfinite(value):
        return f"expected a finite number, got {value!r}"
    if abs(value) > LARGEST:
        return (
            f"expected a number of magnitude at most {LARGEST:g}, got {_describe(value)}: "
            "products of such numbers overflow (see the schema's descriptions)"
        )
    return None
