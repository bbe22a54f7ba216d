"""The README's code blocks run as printed, and the outputs it shows are what crawlsim prints.

The same rules hold for every page of docs/ (tests/test_docs.py runs them with the functions
below). Every fenced block of a page is one of:

* a **command block** (no language): lines ``$ COMMAND`` each followed by the output it shows,
  or, without ``$``, commands alone (each line starting with ``crawlsim``). Each command runs
  in a shell, in a scratch folder holding a copy of ``gaits/``, with the ``crawlsim`` console
  script of this interpreter's environment first on PATH; it must exit 0 (or the code of an
  ``exit N`` marker), and its stdout then stderr must match the lines shown (see
  ``_same_line``): the text exactly, a line ``...`` standing for any lines, and the numbers to
  the digits their estimate supports (never bit for bit: the last bits of a roundoff-level
  result change with the numpy/scipy release, the BLAS and the CPU); a JSON object is compared
  key by key without its ``wall_time`` (the one number that changes from run to run);
* a **YAML block**: a gait file. With a ``file NAME`` marker it is written as NAME for the
  commands after it (which must use it); without one it must pass ``crawlsim validate``;
* a **Python block**: run with this interpreter in the same folder; a block right after it
  marked ``output`` holds what it prints, compared as a command's output is;
* an **illustration**, marked ``skip: REASON`` (the set-up commands, which install the package;
  synopses of options; a line for ``~/.bashrc``; an example progress line of a long sweep).

A marker is an HTML comment on the last non-blank line before the block's opening fence:
``<!-- readme-test: skip: REASON -->``, ``<!-- readme-test: file NAME -->`` or
``<!-- readme-test: exit N -->`` or ``<!-- readme-test: output -->``. A block that fits no
kind and has no marker fails the test: nothing is skipped silently. No cost override is applied:
every command runs as printed.

The blocks run in document order in one folder (a later block may read what an earlier one
wrote, as a reader following the page would).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from .conftest import console_env

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
    page: str = "README.md"

    @property
    def id(self) -> str:
        return f"line-{self.line}-{self.language or 'text'}"

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def parse_blocks(text: str, page: str = "README.md") -> list[Block]:
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
            body.append(line[len(indent) :] if line.startswith(indent) else line.lstrip())
            j += 1
        assert j < len(lines), f"{page}:{i + 1}: unclosed code block"
        blocks.append(Block(i + 1, language, "\n".join(body) + "\n", marker.group(1) if marker else None, page))
        i = j + 1
    return blocks


BLOCKS = parse_blocks(README.read_text(encoding="utf-8"))


def commands(block: Block) -> list[tuple[str, list[str] | None]]:
    """(command, expected output lines or None) of a command block; a line ending in a
    backslash continues on the next, as in a shell."""
    lines: list[str] = []
    for line in block.text.rstrip("\n").splitlines():
        if lines and lines[-1].endswith("\\"):
            lines[-1] = lines[-1][:-1].rstrip() + " " + line.strip()
        else:
            lines.append(line)
    if any(line.startswith("$ ") for line in lines):
        assert lines[0].startswith("$ "), f"{block.where}: output before a command"
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
        f"{block.where}: a block that is neither commands ($ ... or crawlsim ...) nor "
        "marked `<!-- readme-test: skip: REASON -->`"
    )
    return [(line, None) for line in lines if line.strip()]


#: A number printed without an estimate (a count, a rate, a bound) must agree to this relative
#: tolerance: to every digit but roundoff in the last of ~12 printed digits. Counts are integers
#: and so must be equal.
NUMBER_RTOL = 1e-9
#: Two estimates of one error ("± 7e-15" and "± 8e-15") are one order of magnitude, not a value:
#: they must agree within this factor.
ESTIMATE_FACTOR = 10.0
#: Lines of roundoff residuals, by label -> the label of the line whose estimate bounds them. The
#: energy balance residual W - D - J of a run is roundoff below the estimate of the actuator work
#: W (crawlsim prints it as computed: 0 on one machine, 4.44e-16 on another); its first number
#: is absolute, its second relative to W. The JSON key -> the key of its bound.
ROUNDOFF_LINES = {"energy balance residual": "actuator work per period"}
ROUNDOFF_KEYS = {"energy_balance_residual": "dissipation_error_estimate"}
NUMBER = re.compile(r"(?<![\w.\-+])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.]*\w)")
PLUS_MINUS = " ± "
#: The text before an estimate: ``a ± e``, or ``a per period (± e, ...)`` where the estimate is
#: written in parentheses after its value's unit.
ESTIMATE_BEFORE = re.compile(r"^(?: ± |[^\d]*\(± )$")


def _split(line: str) -> tuple[list[str], list[float]]:
    """The text between the numbers of ``line``, and its numbers (a number inside a name such as
    ``peristalsis-4.h5`` is text)."""
    texts, numbers, start = [], [], 0
    for match in NUMBER.finditer(line):
        texts.append(line[start : match.start()])
        numbers.append(float(match.group()))
        start = match.end()
    texts.append(line[start:])
    return texts, numbers


@dataclass
class Roundoff:
    """One output's bound on its roundoff residuals: the estimate ``bound`` of the quantity of
    value ``scale`` that the residual balances."""

    bound: float
    scale: float


def _roundoff(lines: list[str]) -> dict[str, Roundoff]:
    out = {}
    for line in lines:
        texts, numbers = _split(line)
        for residual, bounding in ROUNDOFF_LINES.items():
            if texts[0].strip() == bounding and len(numbers) >= 2 and texts[1] == PLUS_MINUS:
                out[residual] = Roundoff(numbers[1], abs(numbers[0]))
    return out


def _same_number(want: float, got: float) -> bool:
    return want == got or abs(want - got) <= NUMBER_RTOL * max(abs(want), abs(got))


def _same_estimate(want: float, got: float) -> bool:
    if want == 0 or got == 0:
        return want == got
    return max(want, got) <= ESTIMATE_FACTOR * min(want, got)


def _same_text_line(expected: str, actual: str, bounds: tuple[dict[str, Roundoff], dict[str, Roundoff]]) -> bool:
    """The text equal, and the numbers: ``a ± e`` matches ``b ± e'`` when ``|a - b| <= e + e'``
    (both bound their true error; ``a per period (± e`` too, `ESTIMATE_BEFORE`) and ``e``, ``e'``
    agree within ESTIMATE_FACTOR; the numbers of a roundoff residual line match when both outputs'
    are within their own output's bound; any other number within NUMBER_RTOL."""
    want_text, want = _split(expected)
    got_text, got = _split(actual)
    if want_text != got_text:
        return False
    label = want_text[0].strip()
    if label in ROUNDOFF_LINES:
        limits = []
        for bound in bounds:
            if label not in bound:
                return expected == actual
            b = bound[label]
            # the absolute residual, then the relative one (printed to one digit: 1.5x)
            limits.append([b.bound, 1.5 * b.bound / max(b.scale, 1e-300)])
        return all(
            abs(value) <= limit[min(i, 1)]
            for values, limit in zip((want, got), limits)
            for i, value in enumerate(values)
        )
    i = 0
    while i < len(want):
        if i + 1 < len(want) and ESTIMATE_BEFORE.match(want_text[i + 1]):
            (a, e), (b, f) = want[i : i + 2], got[i : i + 2]
            if not (abs(a - b) <= e + f and _same_estimate(e, f)):
                return False
            i += 2
            continue
        if not _same_number(want[i], got[i]):
            return False
        i += 1
    return True


def _same_json(want: dict, got: dict) -> bool:
    """Key by key without VOLATILE_KEYS: a ``*_error_*`` estimate within ESTIMATE_FACTOR, a
    roundoff residual (ROUNDOFF_KEYS) within each object's bound, other floats within the estimate
    of their quantity when the object has one (``v0`` and ``v0_error_estimate``) or NUMBER_RTOL,
    anything else equal."""
    if want.keys() != got.keys():
        return False
    estimate_of = {
        "displacement_per_period": "v0_error_estimate",
        "actuator_work_per_period": "dissipation_error_estimate",
    }
    for key in want.keys() - VOLATILE_KEYS:
        a, b = want[key], got[key]
        if not (isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool)):
            if a != b:
                return False
            continue
        error = estimate_of.get(key, f"{key}_error_estimate")
        if "_error_" in key:
            ok = _same_estimate(a, b)
        elif key in ROUNDOFF_KEYS:
            bound = ROUNDOFF_KEYS[key]
            ok = abs(a) <= want.get(bound, 0.0) and abs(b) <= got.get(bound, 0.0)
        elif isinstance(want.get(error), float) and isinstance(got.get(error), float):
            ok = abs(a - b) <= want[error] + got[error]
        else:
            ok = _same_number(a, b)
        if not ok:
            return False
    return True


def _same_line(expected: str, actual: str, bounds: tuple[dict[str, Roundoff], dict[str, Roundoff]] = ({}, {})) -> bool:
    if expected.startswith("{") and actual.startswith("{"):
        try:
            want, got = json.loads(expected), json.loads(actual)
        except json.JSONDecodeError:
            return expected == actual
        if isinstance(want, dict) and isinstance(got, dict):
            return _same_json(want, got)
    return _same_text_line(expected, actual, bounds)


def output_matches(expected: list[str], actual: list[str]) -> bool:
    """Line by line, ``...`` matching any run of lines (possibly none)."""
    return _matches(expected, actual, (_roundoff(expected), _roundoff(actual)))


def _matches(expected: list[str], actual: list[str], bounds) -> bool:
    if not expected:
        return not actual
    if expected[0] == "...":
        return any(_matches(expected[1:], actual[k:], bounds) for k in range(len(actual) + 1))
    return bool(actual) and _same_line(expected[0], actual[0], bounds) and _matches(expected[1:], actual[1:], bounds)


def test_output_matching_rules():
    assert output_matches(["a", "..."], ["a", "b", "c"])
    assert output_matches(["a", "...", "c"], ["a", "c"])
    assert not output_matches(["a", "b"], ["a", "b", "c"])
    assert not output_matches(["a"], ["b"])
    assert output_matches(['{"v0": 0.4, "wall_time": 1.0}'], ['{"v0": 0.4, "wall_time": 2.5}'])
    assert not output_matches(['{"v0": 0.4, "wall_time": 1}'], ['{"v0": 0.5, "wall_time": 1}'])
    assert not output_matches(['{"v0": 0.4}'], ['{"v0": 0.4, "extra": 1}'])


def test_numbers_match_to_the_digits_their_estimate_supports():
    """The two lines that a fresh install on numpy 2.4/scipy 1.17 printed differently from the
    README (issue 19), and what must still fail."""
    # a ± e and b ± e' match when |a - b| <= e + e' (1e-15 <= 1.5e-14 here)
    v0 = "  v0                       0.069483045557860 ± 7e-15 (period iteration)"
    assert output_matches([v0], ["  v0                       0.069483045557859 ± 8e-15 (period iteration)"])
    assert not output_matches([v0], ["  v0                       0.069483045557890 ± 8e-15 (period iteration)"])
    assert not output_matches([v0], ["  v0                       0.069483045557860 ± 7e-13 (period iteration)"])
    assert not output_matches([v0], ["  v0                       0.069483045557860 ± 7e-15 (period iteration!)"])
    assert not output_matches([v0], ["  v0                       0.069483045557860 (period iteration)"])
    # a roundoff residual: 0 and 4.44e-16 are both below the work's estimate 7e-13 (and
    # 2e-16 relative below 7e-13 / 2.08)
    work = "  actuator work per period 2.0762064933864 ± 7e-13"
    zero = "  energy balance residual  0 (work - dissipation - jump losses; 0 relative)"
    small = "  energy balance residual  4.44e-16 (work - dissipation - jump losses; 2e-16 relative)"
    large = "  energy balance residual  4.44e-12 (work - dissipation - jump losses; 2e-12 relative)"
    assert output_matches([work, zero], [work, small])
    assert not output_matches([work, zero], [work, large])
    assert not output_matches([zero], [small])  # no stated bound: exact
    # an estimate in parentheses after its value (docs/paper.md printed "± 7e-09", numpy 2.4
    # "± 6e-09"): the rate within e + e', not to NUMBER_RTOL; the count after it still exactly
    rate = "  convergence              asymptotic, contraction rate 0.125 per period (± 7e-09, fitted on 8 periods)"
    assert output_matches([rate], [rate.replace("7e-09", "6e-09").replace("0.125 ", "0.125000001 ")])
    assert not output_matches([rate], [rate.replace("0.125 ", "0.12501 ")])
    assert not output_matches([rate], [rate.replace("7e-09", "7e-07")])
    assert not output_matches([rate], [rate.replace("8 periods", "9 periods")])
    # numbers without an estimate: within NUMBER_RTOL; counts exactly; names are text
    assert output_matches(["rate 0.9828, 3 steps"], ["rate 0.9828, 3 steps"])
    assert not output_matches(["rate 0.9828, 3 steps"], ["rate 0.9829, 3 steps"])
    assert not output_matches(["rate 0.9828, 3 steps"], ["rate 0.9828, 4 steps"])
    assert not output_matches(["written peristalsis-4.h5"], ["written peristalsis-5.h5"])
    # JSON: a value within its estimate, a roundoff residual within its bound
    want = {
        "v0": 0.3999999999999998,
        "v0_error_estimate": 8.9e-14,
        "dissipation_error_estimate": 1.8e-13,
        "energy_balance_residual": -1.1e-16,
        "periods": 2,
    }
    assert output_matches(
        [json.dumps(want)], [json.dumps(want | {"v0": 0.4000000000000001, "energy_balance_residual": 0.0})]
    )
    assert not output_matches([json.dumps(want)], [json.dumps(want | {"v0": 0.4000001})])
    assert not output_matches([json.dumps(want)], [json.dumps(want | {"energy_balance_residual": 1e-12})])
    assert not output_matches([json.dumps(want)], [json.dumps(want | {"periods": 3})])


def check_markers(blocks: list[Block]) -> None:
    """Every marker is known and used as it says: a skip says why, a ``file`` gait is read by a
    later command, ``exit N`` marks a command block, ``output`` follows a Python block."""
    for k, block in enumerate(blocks):
        if block.marker is None:
            continue
        kind, _, rest = block.marker.partition(" ")
        assert kind in ("skip:", "file", "exit", "output"), f"{block.where}: marker {block.marker!r}"
        if kind == "skip:":
            assert rest.strip(), f"{block.where}: a skip marker says why"
        if kind == "file":
            assert block.language == "yaml", f"{block.where}: `file` marks a gait"
            later = " ".join(
                cmd
                for b in blocks
                if b.line > block.line and b.language == "" and not (b.marker or "").startswith(("skip:", "output"))
                for cmd, _ in commands(b)
            )
            assert rest.strip() in later, f"{block.where}: {rest} is never used"
        if kind == "exit":
            assert block.language == "" and rest.strip().isdigit()
        if kind == "output":
            assert (
                block.language == "" and k > 0 and blocks[k - 1].language == "python" and blocks[k - 1].marker is None
            ), f"{block.where}: `output` follows a Python block that runs"
    runnable = [b for b in blocks if not (b.marker or "").startswith("skip:")]
    assert {b.language for b in runnable} <= {"", "yaml", "python"}, (
        "a block in another language needs a runner here or a skip marker"
    )


def test_every_block_is_run_or_marked_as_an_illustration():
    assert BLOCKS, "README.md has no code blocks"
    first = BLOCKS[0]
    assert first.marker and first.marker.startswith("skip:") and "pip install" in first.text, (
        "the first block (set-up: pip install) is marked as not run"
    )
    assert "python -m pytest tests" in first.text, "the set-up runs the tests as .ci/run does"
    check_markers(BLOCKS)
    shown = [cmd for b in BLOCKS if b.language == "" and b.marker is None for cmd, expected in commands(b) if expected]
    assert "crawlsim run gaits/peristalsis-4.yaml" in shown, "the first run's output is shown"


def test_readme_fits_a_newcomer():
    """Issue 23: at most 200 lines, one figure, and links into the documentation site."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert len(images) == 1 and images[0].startswith("docs/figures/")
    linked = set(re.findall(r"\]\(docs/([\w\-/]+\.(?:md|ipynb))", text))
    assert {
        "model.md",
        "gait-files.md",
        "commands.md",
        "hdf5.md",
        "integrators.md",
        "sweeps.md",
        "optimize.md",
        "paper.md",
        "benchmarks.md",
        "api.md",
        "exact-step.md",
        "layout.md",
    } <= linked


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "gaits", folder / "gaits")
    return folder


def _environment() -> dict[str, str]:
    env = console_env()
    env["CRAWLSIM_PROGRESS_INTERVAL"] = "3600"  # no progress line in a shown output
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def run_block(block: Block, folder: Path, printed: dict[str, str]) -> None:
    """Run one block in ``folder``; ``printed`` keeps the stdout of the last Python block for
    the ``output`` block after it."""
    env = _environment()
    marker = block.marker or ""
    if marker.startswith("skip:"):
        return
    where = block.where
    if marker == "output":
        assert "python" in printed, f"{where}: no Python block ran before this output"
        actual = [line.rstrip() for line in printed.pop("python").splitlines()]
        expected = block.text.rstrip("\n").splitlines()
        assert output_matches(expected, actual), (
            f"{where}: the Python block above printed\n"
            + "\n".join(actual)
            + f"\nbut {block.page} shows\n"
            + "\n".join(expected)
        )
        return
    if block.language == "yaml":
        if marker.startswith("file "):
            (folder / marker.split(None, 1)[1]).write_text(block.text)
            return
        path = folder / f"readme-block-{block.line}.yaml"
        path.write_text(block.text)
        done = subprocess.run(
            ["crawlsim", "validate", path.name], cwd=folder, env=env, capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, f"{where}: {done.stdout}{done.stderr}"
        return
    if block.language == "python":
        done = subprocess.run(
            [sys.executable, "-c", block.text], cwd=folder, env=env, capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, f"{where}: {done.stderr}"
        printed["python"] = done.stdout
        return
    code = int(marker.split()[1]) if marker.startswith("exit ") else 0
    for command, expected in commands(block):
        done = subprocess.run(command, shell=True, cwd=folder, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == code, f"{where}: `{command}` exited {done.returncode}\n{done.stdout}{done.stderr}"
        if expected is not None:
            actual = [line.rstrip() for line in (done.stdout + done.stderr).splitlines()]
            assert output_matches(expected, actual), (
                f"{where}: `{command}` printed\n"
                + "\n".join(actual)
                + f"\nbut {block.page} shows\n"
                + "\n".join(expected)
            )


def run_in_order(blocks: list[Block], index: int, folder: Path, done: set[int], printed: dict[str, str]) -> None:
    """Block ``index``, after every earlier block not yet run (a later block may use an earlier
    one's files, as a reader following the page would); an earlier failure is reported by its
    own test."""
    for earlier in range(index + 1):
        if earlier not in done:
            done.add(earlier)
            if earlier == index:
                run_block(blocks[earlier], folder, printed)
            else:
                try:
                    run_block(blocks[earlier], folder, printed)
                except AssertionError:
                    pass


_DONE: set[int] = set()
_PRINTED: dict[str, str] = {}


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[b.id for b in BLOCKS])
def test_block(index, workdir):
    """Block ``index`` of the README, after every earlier block."""
    run_in_order(BLOCKS, index, workdir, _DONE, _PRINTED)
