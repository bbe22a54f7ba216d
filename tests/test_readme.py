"""The README's code blocks run as printed, and the outputs it shows are what crawlsim prints.

Every fenced block of README.md is one of:

* a **command block** (no language): lines ``$ COMMAND`` each followed by the output it shows,
  or, without ``$``, commands alone (each line starting with ``crawlsim``). Each command runs
  in a shell, in a scratch folder holding a copy of ``gaits/``, with the ``crawlsim`` console
  script of this interpreter's environment first on PATH; it must exit 0 (or the code of an
  ``exit N`` marker), and its stdout then stderr must match the lines shown: exactly, except
  that a line ``...`` stands for any lines and a JSON object is compared key by key without its
  ``wall_time`` (the one number that changes from run to run);
* a **YAML block**: a gait file. With a ``file NAME`` marker it is written as NAME for the
  commands after it (which must use it); without one it must pass ``crawlsim validate``;
* a **Python block**: run with this interpreter in the same folder;
* an **illustration**, marked ``skip: REASON`` (the set-up commands, which install the package;
  synopses of options; a line for ``~/.bashrc``; an example progress line of a long sweep).

A marker is an HTML comment on the last non-blank line before the block's opening fence:
``<!-- readme-test: skip: REASON -->``, ``<!-- readme-test: file NAME -->`` or
``<!-- readme-test: exit N -->``. A block that fits no kind and has no marker fails the test:
nothing is skipped silently. No cost override is applied: every command runs as printed.

The blocks run in document order in one folder (a later block may read what an earlier one
wrote, as a reader following the page would).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MARKER = re.compile(r"^<!--\s*readme-test:\s*(.*?)\s*-->$")
FENCE = re.compile(r"^(\s*)```(\w*)\s*$")
#: Keys of JSON output whose values change from run to run.
VOLATILE_KEYS = {"wall_time"}


@dataclass
class Block:
    line: int  # 1-based line of the opening fence
    language: str
    text: str  # dedented by the fence's indentation
    marker: str | None

    @property
    def id(self) -> str:
        return f"line-{self.line}-{self.language or 'text'}"


def parse_blocks(text: str) -> list[Block]:
    blocks: list[Block] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        match = FENCE.match(lines[i])
        if not match:
            i += 1
            continue
        indent, language = match.group(1), match.group(2)
        before = [line.strip() for line in lines[:i] if line.strip()]
        marker = MARKER.match(before[-1]) if before else None
        body = []
        j = i + 1
        while j < len(lines) and lines[j].strip() != "```":
            line = lines[j]
            body.append(line[len(indent):] if line.startswith(indent) else line.lstrip())
            j += 1
        assert j < len(lines), f"README.md:{i + 1}: unclosed code block"
        blocks.append(Block(i + 1, language, "\n".join(body) + "\n",
                            marker.group(1) if marker else None))
        i = j + 1
    return blocks


BLOCKS = parse_blocks(README.read_text(encoding="utf-8"))


def commands(block: Block) -> list[tuple[str, list[str] | None]]:
    """(command, expected output lines or None) of a command block."""
    lines = block.text.rstrip("\n").splitlines()
    if any(line.startswith("$ ") for line in lines):
        assert lines[0].startswith("$ "), f"README.md:{block.line}: output before a command"
        out: list[tuple[str, list[str] | None]] = []
        for line in lines:
            if line.startswith("$ "):
                out.append((line[2:], []))
            else:
                expected = out[-1][1]
                assert expected is not None
                expected.append(line.rstrip())
        return out
    assert all(line.startswith("crawlsim ") for line in lines if line.strip()), (
        f"README.md:{block.line}: a block that is neither commands ($ ... or crawlsim ...) nor "
        "marked `<!-- readme-test: skip: REASON -->`")
    return [(line, None) for line in lines if line.strip()]


def _same_line(expected: str, actual: str) -> bool:
    if expected.startswith("{") and actual.startswith("{"):
        try:
            want, got = json.loads(expected), json.loads(actual)
        except json.JSONDecodeError:
            return expected == actual
        if isinstance(want, dict) and isinstance(got, dict):
            return ({k: v for k, v in want.items() if k not in VOLATILE_KEYS}
                    == {k: v for k, v in got.items() if k not in VOLATILE_KEYS}
                    and want.keys() == got.keys())
    return expected == actual


def output_matches(expected: list[str], actual: list[str]) -> bool:
    """Line by line, ``...`` matching any run of lines (possibly none)."""
    if not expected:
        return not actual
    if expected[0] == "...":
        return any(output_matches(expected[1:], actual[k:]) for k in range(len(actual) + 1))
    return bool(actual) and _same_line(expected[0], actual[0]) and \
        output_matches(expected[1:], actual[1:])


def test_output_matching_rules():
    assert output_matches(["a", "..."], ["a", "b", "c"])
    assert output_matches(["a", "...", "c"], ["a", "c"])
    assert not output_matches(["a", "b"], ["a", "b", "c"])
    assert not output_matches(["a"], ["b"])
    assert output_matches(['{"v0": 0.4, "wall_time": 1.0}'], ['{"v0": 0.4, "wall_time": 2.5}'])
    assert not output_matches(['{"v0": 0.4, "wall_time": 1}'], ['{"v0": 0.5, "wall_time": 1}'])
    assert not output_matches(['{"v0": 0.4}'], ['{"v0": 0.4, "extra": 1}'])


def test_every_block_is_run_or_marked_as_an_illustration():
    assert BLOCKS, "README.md has no code blocks"
    first = BLOCKS[0]
    assert first.marker and first.marker.startswith("skip:") and "pip install" in first.text, \
        "the first block (set-up: pip install) is marked as not run"
    for block in BLOCKS:
        if block.marker is None:
            continue
        kind, _, rest = block.marker.partition(" ")
        assert kind in ("skip:", "file", "exit"), f"README.md:{block.line}: marker {block.marker!r}"
        if kind == "skip:":
            assert rest.strip(), f"README.md:{block.line}: a skip marker says why"
        if kind == "file":
            assert block.language == "yaml", f"README.md:{block.line}: `file` marks a gait"
            later = " ".join(cmd for b in BLOCKS if b.line > block.line and b.language == ""
                             and not (b.marker or "").startswith("skip:")
                             for cmd, _ in commands(b))
            assert rest.strip() in later, f"README.md:{block.line}: {rest} is never used"
        if kind == "exit":
            assert block.language == "" and rest.strip().isdigit()
    runnable = [b for b in BLOCKS if not (b.marker or "").startswith("skip:")]
    assert {b.language for b in runnable} <= {"", "yaml", "python"}, \
        "a block in another language needs a runner here or a skip marker"
    assert sum(1 for b in runnable if b.language == "") >= 5


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "gaits", folder / "gaits")
    return folder


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["CRAWLSIM_PROGRESS_INTERVAL"] = "3600"  # no progress line in a shown output
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _run(block: Block, folder: Path) -> None:
    env = _environment()
    marker = block.marker or ""
    if marker.startswith("skip:"):
        return
    where = f"README.md:{block.line}"
    if block.language == "yaml":
        if marker.startswith("file "):
            (folder / marker.split(None, 1)[1]).write_text(block.text)
            return
        path = folder / f"readme-block-{block.line}.yaml"
        path.write_text(block.text)
        done = subprocess.run(["crawlsim", "validate", path.name], cwd=folder, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{where}: {done.stdout}{done.stderr}"
        return
    if block.language == "python":
        done = subprocess.run([sys.executable, "-c", block.text], cwd=folder, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{where}: {done.stderr}"
        return
    code = int(marker.split()[1]) if marker.startswith("exit ") else 0
    for command, expected in commands(block):
        done = subprocess.run(command, shell=True, cwd=folder, env=env, capture_output=True,
                              text=True, timeout=600)
        assert done.returncode == code, \
            f"{where}: `{command}` exited {done.returncode}\n{done.stdout}{done.stderr}"
        if expected is not None:
            actual = [line.rstrip() for line in (done.stdout + done.stderr).splitlines()]
            assert output_matches(expected, actual), (
                f"{where}: `{command}` printed\n" + "\n".join(actual)
                + "\nbut the README shows\n" + "\n".join(expected))


_DONE: set[int] = set()


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[b.id for b in BLOCKS])
def test_block(index, workdir):
    """Block ``index``, after every earlier block (a later block may use an earlier one's
    files, as a reader following the page would)."""
    for earlier in range(index + 1):
        if earlier not in _DONE:
            _DONE.add(earlier)  # an earlier failure is reported by its own test
            if earlier == index:
                _run(BLOCKS[earlier], workdir)
            else:
                try:
                    _run(BLOCKS[earlier], workdir)
                except AssertionError:
                    pass
