"""A compiled yes/no check of crawlsim's own JSON Schemas, so that a valid gait file does not pay
for importing jsonschema.

Importing jsonschema (with attrs, referencing and the bundled metaschemas) costs about 60-110 ms,
a quarter of what `crawlsim velocity` on a small gait needs, and a shell loop calls it thousands
of times. Almost every file such a loop reads is valid, and a valid file needs only the answer
"valid". So `compile_schema` turns a schema into a predicate built from closures, once per
process; `crawlsim.gait.schemaerrors.check_schema` asks it first and calls jsonschema, the reference, only
when the predicate says "invalid": jsonschema then finds the error and phrases the message (file,
key path, expectation), exactly as before. Validation is not weakened as long as the predicate
never accepts what jsonschema refuses; tests/test_schemacheck.py checks that the two agree on
valid gaits, on every kind of broken gait and on random documents.

The predicate implements the Draft 2020-12 keywords crawlsim's schemas use, with jsonschema's
own Python semantics (its type checker: a bool is not a number, 2.0 is an integer; `pattern` by
`re.search`; lengths in code points). A schema using any other keyword is refused at compile
time (`UnsupportedSchema`) rather than half-checked: a new keyword in a schema fails the tests
at once instead of being silently ignored.

Why not a library: fastjsonschema supports drafts 4-7 only and compiles with ``exec`` at run
time (70 ms and more for the gait schema, more than importing jsonschema saves); jsonschema-rs
is a compiled dependency of its own whose regular expressions follow Rust's (ECMA's) notion of
``\\S``, not Python's, so it would disagree with jsonschema on some unit names.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from numbers import Number
from typing import Any

Check = Callable[[Any], bool]

#: Keywords that only annotate (no effect on validity).
_ANNOTATIONS = frozenset({"$schema", "description", "title", "x-expected", "default", "examples"})

#: jsonschema's type checker for Draft 2020-12, keyword by keyword.
_TYPES: dict[str, Check] = {
    "number": lambda x: isinstance(x, Number) and not isinstance(x, bool),
    "integer": lambda x: (isinstance(x, int) and not isinstance(x, bool)) or (isinstance(x, float) and x.is_integer()),
    "object": lambda x: isinstance(x, dict),
    "array": lambda x: isinstance(x, list),
    "string": lambda x: isinstance(x, str),
    "boolean": lambda x: isinstance(x, bool),
    "null": lambda x: x is None,
}


class UnsupportedSchema(ValueError):
    """A schema uses a keyword (or a form of one) that `compile_schema` does not implement."""


def _is_number(x: Any) -> bool:
    return isinstance(x, Number) and not isinstance(x, bool)


def compile_schema(schema: Any) -> Check:
    """A predicate that is True exactly when jsonschema's Draft202012Validator finds ``instance``
    valid against ``schema``; raises `UnsupportedSchema` for keywords it does not implement."""
    if schema is True:
        return lambda x: True
    if schema is False:
        return lambda x: False
    if not isinstance(schema, dict):
        raise UnsupportedSchema(f"a schema is a mapping or a boolean, got {schema!r}")
    unknown = set(schema) - _ANNOTATIONS - _KEYWORDS.keys() - {"then", "else"}
    if unknown:
        raise UnsupportedSchema(f"keywords not implemented: {', '.join(sorted(unknown))}")
    built = [_KEYWORDS[key](value, schema) for key, value in schema.items() if key in _KEYWORDS]
    checks = [check for check in built if check is not None]
    if not checks:
        return lambda x: True
    if len(checks) == 1:
        return checks[0]
    return lambda x: all(check(x) for check in checks)


def _type(value: Any, schema: dict) -> Check:
    names = value if isinstance(value, list) else [value]
    if any(name not in _TYPES for name in names):
        raise UnsupportedSchema(f"type {value!r}")
    tests = [_TYPES[name] for name in names]
    return lambda x: any(test(x) for test in tests)


def _strings(value: Any, what: str) -> frozenset[str]:
    # jsonschema compares a string with anything by ==, which is False for every non-string:
    # membership of a str in a set of strings is the same test. Other constants compare with
    # jsonschema's bool-aware equality, which this module does not implement.
    if not all(isinstance(v, str) for v in value):
        raise UnsupportedSchema(f"{what} with values other than strings: {value!r}")
    return frozenset(value)


def _enum(value: Any, schema: dict) -> Check:
    allowed = _strings(value, "enum")
    return lambda x: isinstance(x, str) and x in allowed


def _const(value: Any, schema: dict) -> Check:
    allowed = _strings([value], "const")
    return lambda x: isinstance(x, str) and x in allowed


def _bound(test: Callable[[Any, Any], bool]) -> Callable[[Any, dict], Check]:
    def build(value: Any, schema: dict) -> Check:
        if not _is_number(value):
            raise UnsupportedSchema(f"a bound that is not a number: {value!r}")
        return lambda x: not _is_number(x) or test(x, value)

    return build


def _count(kind: type[list] | type[str], test: Callable[[int, int], bool]) -> Callable[[Any, dict], Check]:
    def build(value: Any, schema: dict) -> Check:  # jsonschema: len(), code points for strings
        return lambda x: not isinstance(x, kind) or test(len(x), value)

    return build


def _items(value: Any, schema: dict) -> Check | None:
    if value is True:
        return None
    item = compile_schema(value)
    return lambda x: not isinstance(x, list) or all(item(entry) for entry in x)


def _required(value: Any, schema: dict) -> Check:
    keys = tuple(value)
    return lambda x: not isinstance(x, dict) or all(key in x for key in keys)


def _properties(value: Any, schema: dict) -> Check | None:
    checks = [(key, compile_schema(sub)) for key, sub in value.items() if sub is not True]
    if not checks:
        return None
    return lambda x: not isinstance(x, dict) or all(check(x[key]) for key, check in checks if key in x)


def _additional(value: Any, schema: dict) -> Check | None:
    if value is True:
        return None
    declared = frozenset(schema.get("properties", {}))
    if value is False:
        return lambda x: not isinstance(x, dict) or all(key in declared for key in x)
    extra = compile_schema(value)
    return lambda x: not isinstance(x, dict) or all(extra(x[key]) for key in x if key not in declared)


def _all_of(value: Any, schema: dict) -> Check:
    checks = [compile_schema(sub) for sub in value]
    return lambda x: all(check(x) for check in checks)


def _if(value: Any, schema: dict) -> Check:
    condition = compile_schema(value)
    then = compile_schema(schema.get("then", True))
    otherwise = compile_schema(schema.get("else", True))
    return lambda x: then(x) if condition(x) else otherwise(x)


def _pattern(value: Any, schema: dict) -> Check:
    regex = re.compile(value)  # jsonschema: re.search(pattern, instance)
    return lambda x: not isinstance(x, str) or regex.search(x) is not None


_KEYWORDS: dict[str, Callable[[Any, dict], Check | None]] = {
    "type": _type,
    "enum": _enum,
    "const": _const,
    # each bound refuses what jsonschema refuses (`x < m` for minimum, ...), so that a value no
    # comparison holds for (nan) is treated alike
    "minimum": _bound(lambda x, m: not x < m),
    "maximum": _bound(lambda x, m: not x > m),
    "exclusiveMinimum": _bound(lambda x, m: not x <= m),
    "exclusiveMaximum": _bound(lambda x, m: not x >= m),
    "minItems": _count(list, lambda n, m: not n < m),
    "maxItems": _count(list, lambda n, m: not n > m),
    "minLength": _count(str, lambda n, m: not n < m),
    "maxLength": _count(str, lambda n, m: not n > m),
    "items": _items,
    "required": _required,
    "properties": _properties,
    "additionalProperties": _additional,
    "allOf": _all_of,
    "if": _if,
    "pattern": _pattern,
}
"""Keyword -> builder of its check. A keyword's check passes any instance of a type it does not
apply to, as in JSON Schema. `then` and `else` are read by `if` (alone they do nothing)."""
