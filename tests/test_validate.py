"""`crawlsim validate`: every error of every file, each with file and key path; exit 0 or 2."""

import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.gait.document import validation_errors

from .conftest import GAITS

GOOD = """\
blocks: 3
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}, 1.0]
friction: {forward: 1.0, backward: 2.5}
"""

#: Five independent structural errors: each must be listed.
BROKEN = """\
blocks: 3
period: -1
stiffness: [1, .inf]
links: [{kind: cosine, mean: 1.0, amplitud: 0.3}, {kind: steps, times: [0, 0.5], values: [1]}]
friction: {forward: 1.0, backwrad: 2.5}
simulation: {steps_per_period: 0}
"""

#: Structure valid; three semantic errors that do not depend on each other.
SEMANTIC = """\
blocks: 3
period: 1.0
stiffness: [1, 2, 3]
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}, 1.0]
friction:
  - {forward: -1.0, backward: 2.5}
  - {forward: 1.0, backward: {kind: cosine, mean: 0.5, amplitude: 1.0}}
  - {forward: 1.0, backward: 2.5}
"""


def write(folder, name, text):
    path = folder / name
    path.write_text(text)
    return str(path)


def test_every_structural_error_is_listed(tmp_path):
    path = write(tmp_path, "broken.yaml", BROKEN)
    found = {(e.keypath, e.message.split(",")[0]) for e in validation_errors(path)}
    keys = {k for k, _ in found}
    assert {
        "period",
        "stiffness[1]",
        "links[0].amplitud",
        "links[0].amplitude",
        "links[1].values",
        "friction.backwrad",
        "friction.backward",
        "simulation.steps_per_period",
    } <= keys, found
    result = CliRunner().invoke(main, ["validate", path])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.startswith(path)]
    assert len(lines) == len(validation_errors(path)) >= 8
    assert all(line.startswith(f"{path}: ") for line in lines)
    assert "1 of 1 gait files invalid" in result.output


def test_semantic_errors_that_can_run_are_all_listed(tmp_path):
    path = write(tmp_path, "semantic.yaml", SEMANTIC)
    errors = validation_errors(path)
    assert [e.keypath for e in errors] == ["stiffness", "friction[0].forward", "friction[1].backward"]
    assert "expected 2 stiffness values (one per link), got 3" in errors[0].message
    assert "its minimum is -1" in errors[1].message and "its minimum is -0.5" in errors[2].message


def test_valid_files_and_mixed_lists(tmp_path):
    good = write(tmp_path, "good.yaml", GOOD)
    bad = write(tmp_path, "bad.yaml", GOOD.replace("backward: 2.5", "backward: 2.0"))
    result = CliRunner().invoke(main, ["validate", good])
    assert result.exit_code == 0 and result.output == f"{good}: valid\n"
    result = CliRunner().invoke(main, ["validate", good, bad, str(tmp_path / "missing.yaml"), "/dev/zero"])
    assert result.exit_code == 2
    assert f"{good}: valid" in result.output
    assert f"{bad}: friction: uniqueness condition violated: for J = {{1, 2}}" in result.output
    assert "missing.yaml: no such gait file" in result.output
    assert "/dev/zero: is a device, not a gait file" in result.output
    assert "3 of 4 gait files invalid" in result.output


@pytest.mark.parametrize("path", sorted(GAITS.rglob("*.yaml")), ids=lambda p: p.name)
def test_every_example_gait_is_valid(path):
    assert validation_errors(path) == []


def test_yaml_errors_are_one_error(tmp_path):
    path = write(tmp_path, "syntax.yaml", "blocks: [3\n")
    errors = validation_errors(path)
    assert len(errors) == 1 and "YAML syntax error at line" in errors[0].message
