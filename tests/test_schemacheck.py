"""The compiled schema check (`crawlsim.gait.schemacheck`) decides exactly what jsonschema decides.

`crawlsim.gait.schemaerrors.check_schema` accepts a document on the compiled check's word alone, without
jsonschema, so validation stays as strict as before only if the compiled check never accepts a
document that jsonschema's Draft202012Validator refuses. These tests compare the two, as
predicates, on every schema of the project and on every one of their sub-schemas: on the
repository's gaits, on broken variants of them, and on random JSON-like values built from the
schemas' own keys, enum values and bounds (Hypothesis, derandomized). They also check that the
compiled check refuses to compile what it does not implement.
"""

import copy

import jsonschema
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from crawlsim.errors import GaitError
from crawlsim.gait import document as gait_module
from crawlsim.gait import signals, units
from crawlsim.gait.schemacheck import UnsupportedSchema, compile_schema
from crawlsim.gait.validation import structure
from crawlsim.gait.yamlsafe import load_yaml

from .conftest import GAITS, ROOT

SCHEMAS = {
    "crawler": gait_module.CRAWLER_SCHEMA,
    "crawler structure": structure(gait_module.CRAWLER_SCHEMA),
    "process": gait_module.PROCESS_SCHEMA,
    "process structure": structure(gait_module.PROCESS_SCHEMA),
    "signal": signals.SIGNAL_SCHEMA,
    "simulation": gait_module.SIMULATION_SCHEMA,
    "units": units.UNITS_SCHEMA,
}


def _subschemas(schema, out):
    """Every schema nested in ``schema`` (by the keywords that hold schemas), itself included."""
    if not isinstance(schema, dict) or any(s is schema for s in out):
        return out
    out.append(schema)
    for key, value in schema.items():
        if key == "properties":
            for sub in value.values():
                _subschemas(sub, out)
        elif key == "allOf":
            for sub in value:
                _subschemas(sub, out)
        elif key in ("items", "if", "then", "else", "additionalProperties"):
            _subschemas(value, out)
    return out


SUBSCHEMAS: list[dict] = []
for _schema in SCHEMAS.values():
    _subschemas(_schema, SUBSCHEMAS)


def _collect(schema, keys, strings, numbers):
    """The property names, string constants and bounds of a schema: the values near which the
    two validators could disagree."""
    if isinstance(schema, dict):
        for key, value in schema.items():
            if key in ("properties",):
                keys.update(value)
            if key in ("enum",):
                strings.update(v for v in value if isinstance(v, str))
            if key == "const" and isinstance(value, str):
                strings.add(value)
            if key in ("minimum", "maximum", "exclusiveMinimum", "minItems", "maxItems", "minLength") and isinstance(
                value, (int, float)
            ):
                numbers.update({value, value - 1, value + 1, float(value)})
            _collect(value, keys, strings, numbers)
    elif isinstance(schema, list):
        for value in schema:
            _collect(value, keys, strings, numbers)


KEYS: set[str] = set()
STRINGS: set[str] = set()
NUMBERS: set = set()
for _schema in SCHEMAS.values():
    _collect(_schema, KEYS, STRINGS, NUMBERS)
BOUNDARY_NUMBERS = sorted(n for n in NUMBERS if abs(n) < 1e300)

# Whitespace is where regular-expression dialects differ (`\S` in the units' pattern): \x1c to
# \x1f are whitespace to Python's re but not to Unicode's White_Space property.
_text = st.text(alphabet=st.sampled_from(list("ab mN\t\n\x1c\x1f\u00a0\u2003\u180e")), max_size=4)
_leaves = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(BOUNDARY_NUMBERS),
    st.sampled_from(sorted(STRINGS)),
    _text,
)
_values = st.recursive(
    _leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(st.one_of(st.sampled_from(sorted(KEYS)), _text, st.integers(0, 2)), inner, max_size=5),
    ),
    max_leaves=12,
)


def reference(schema, instance) -> bool:
    return jsonschema.Draft202012Validator(schema).is_valid(instance)


def test_every_schema_of_the_project_compiles():
    assert len(SUBSCHEMAS) > 30  # the walk reached the nested schemas
    for schema in SUBSCHEMAS:
        compile_schema(schema)


@pytest.mark.parametrize(
    "schema",
    [
        {"anyOf": [{"type": "number"}]},
        {"patternProperties": {"a": True}},
        {"type": "object", "properties": {"a": {"oneOf": [True]}}},
        {"enum": [1, 2]},  # non-string constants compare with jsonschema's bool-aware ==
        {"const": 0},
        {"type": "decimal"},
        {"minimum": "0"},
        {"items": [{"type": "number"}]},
        "not a schema",
    ],
)
def test_what_is_not_implemented_is_refused_at_compile_time(schema):
    """A keyword the compiled check would otherwise ignore must not make it more lenient."""
    with pytest.raises(UnsupportedSchema):
        compile_schema(schema)


def _documents():
    paths = sorted(GAITS.rglob("*.yaml")) + sorted((ROOT / "tests" / "hostile").glob("*.yaml"))
    out = []
    for path in paths:
        try:
            document = load_yaml(path.read_text(), str(path))
        except GaitError:
            continue  # YAML bombs and the like: the YAML guards refuse those before any schema
        if isinstance(document, dict):
            out.append((path.name, document))
    return out


DOCUMENTS = _documents()


def _broken_variants(document):
    """The document with one value at a time replaced by a wrong one of another type, a key
    misspelt, a required key removed."""
    wrong = [None, True, "x", -1, 0, 0.5, 1e101, [], {}, [1.0], {"kind": "cosine"}]
    paths = []

    def walk(node, path):
        if isinstance(node, dict):
            for key, value in node.items():
                paths.append((*path, key))
                walk(value, (*path, key))
        elif isinstance(node, list):
            for index, value in enumerate(node[:3]):
                paths.append((*path, index))
                walk(value, (*path, index))

    walk(document, ())
    for path in paths:
        for value in wrong:
            broken = copy.deepcopy(document)
            node = broken
            for part in path[:-1]:
                node = node[part]
            node[path[-1]] = value
            yield broken
        broken = copy.deepcopy(document)
        node = broken
        for part in path[:-1]:
            node = node[part]
        if isinstance(node, dict):
            node[str(path[-1]) + "s"] = node.pop(path[-1])
            yield broken


@pytest.mark.parametrize("name,document", DOCUMENTS, ids=[n for n, _ in DOCUMENTS])
def test_agrees_on_the_repository_gaits_and_their_broken_variants(name, document):
    kind = document.get("kind", "crawler")
    if kind not in ("crawler", "sweeping-process"):
        return
    schemas = (
        [gait_module.CRAWLER_SCHEMA, SCHEMAS["crawler structure"]]
        if kind == "crawler"
        else [gait_module.PROCESS_SCHEMA, SCHEMAS["process structure"]]
    )
    checks = [(schema, compile_schema(schema)) for schema in schemas]
    validators = [jsonschema.Draft202012Validator(schema) for schema in schemas]
    compared = 0
    for variant in [document, *_broken_variants(document)]:
        for check, validator in zip([c for _, c in checks], validators):
            assert check(variant) == validator.is_valid(variant), (name, variant)
            compared += 1
    assert compared > 2


@pytest.mark.parametrize("index", range(len(SUBSCHEMAS)))
@settings(max_examples=40)  # per sub-schema; over 60 of them
@given(instance=_values)
@example(instance={"length": "\x1c"})  # whitespace to Python's re, not to Unicode
@example(instance=" mm")  # `pattern` searches: a match need not start the string
@example(instance={"time": "\t s"})
@example(instance={"kind": "cosine", "mean": 1, "amplitude": True})
@example(instance={"kind": "steps", "times": [0.5], "values": [1.0]})
@example(instance=float("nan"))
@example(instance=2.0)
def test_agrees_with_jsonschema_on_random_values(index, instance):
    schema = SUBSCHEMAS[index]
    assert compile_schema(schema)(instance) == reference(schema, instance)


@given(
    instance=st.fixed_dictionaries(
        {
            "blocks": st.sampled_from([1, 2, 3.0, 2.5, True, 100_001]),
            "period": st.sampled_from([1, 1e-10, 0, 1e9, 2e9, "1"]),
            "stiffness": st.sampled_from([10, [10, 20], [0], [], -1, [True]]),
            "links": st.lists(
                st.sampled_from(
                    [
                        1.0,
                        {"kind": "cosine", "mean": 1, "amplitude": 0.2},
                        {"kind": "cosine", "mean": 1},
                        {"kind": "sine"},
                        {"kind": "steps", "times": [0], "values": [1]},
                        "x",
                    ]
                ),
                max_size=3,
            ),
            "friction": st.sampled_from(
                [
                    {"forward": 1, "backward": 2},
                    {"forward": 1},
                    [{"forward": 1, "backward": 2}],
                    {"forward": 1, "backwrd": 2},
                    {"forward": {"kind": "cosine", "mean": 1, "amplitude": 0.5}, "backward": 1},
                ]
            ),
        },
        optional={
            "simulation": st.dictionaries(
                st.sampled_from(
                    [
                        "steps_per_period",
                        "max_periods",
                        "tolerance",
                        "integrator",
                        "limit",
                        "unchecked_uniqueness",
                        "step",
                    ]
                ),
                st.sampled_from([1, 0, 1e-12, "exact", "catch-up", "newton", "euler", True, 2.0]),
            ),
            "units": st.dictionaries(
                st.sampled_from(["length", "time", "force", "mass"]), st.sampled_from(["mm", "", " ", "\x1c", 3])
            ),
        },
    )
)
def test_agrees_on_near_valid_crawler_documents(instance):
    for schema in (gait_module.CRAWLER_SCHEMA, SCHEMAS["crawler structure"]):
        assert compile_schema(schema)(instance) == reference(schema, instance)


def test_a_valid_gait_is_accepted_without_importing_jsonschema():
    """`check_schema` on a valid document asks the compiled check only (a fresh interpreter:
    this one has imported jsonschema above)."""
    import subprocess
    import sys

    code = (
        "import sys; from crawlsim.gait.document import load_gait; "
        f"load_gait({str(GAITS / 'peristalsis-4.yaml')!r}); "
        "print('jsonschema' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_an_invalid_gait_still_gets_jsonschemas_message():
    """The compiled check says only "invalid"; the message (file, key path, expectation) is
    jsonschema's best match, as before."""
    text = (GAITS / "inching-2.yaml").read_text() + "\nsimulaton: {}\n"
    with pytest.raises(GaitError) as info:
        gait_module.parse_gait(text, source="inching.yaml")
    message = str(info.value)
    assert "inching.yaml" in message and "simulaton" in message
    assert "did you mean 'simulation'" in message
