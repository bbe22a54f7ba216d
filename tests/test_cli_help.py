"""The help texts tell the truth: every example in every ``--help`` runs as written, the
defaults they state are the gait file's defaults, and shell completion works as documented."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from crawlsim import __version__
from crawlsim.cli import (
    DEFAULT_INTEGRATOR,
    DEFAULT_MAX_PERIODS,
    DEFAULT_STEPS_PER_PERIOD,
    DEFAULT_TOLERANCE,
    main,
)
from crawlsim.gait.settings import Simulation

from .conftest import console_env

ROOT = Path(__file__).resolve().parents[1]


def commands():
    ctx = main.make_context("crawlsim", ["--help"], resilient_parsing=True)
    return [("crawlsim", main)] + [(name, main.get_command(ctx, name)) for name in main.list_commands(ctx)]


def examples(help_text: str) -> list[str]:
    """The shell lines of the ``Examples:`` block of a help text, continuations joined."""
    block = re.split(r"\n\s*Examples?:\n", help_text, maxsplit=1)
    if len(block) < 2:
        return []
    lines, current = [], ""
    for raw in block[1].splitlines():
        line = raw.strip()
        if not line:
            if current:
                break
            continue
        current += line
        if current.endswith("\\"):
            current = current[:-1].rstrip() + " "
            continue
        lines.append(current)
        current = ""
    return lines


@pytest.mark.slow  # every example of every command, each a fresh process: about 100 s
@pytest.mark.parametrize("name, command", commands(), ids=lambda c: c if isinstance(c, str) else "")
def test_every_help_example_runs(name, command, tmp_path):
    """Each command's examples run in order in an empty folder holding the example gaits, with
    the installed `crawlsim` on PATH, each with exit code 0."""
    lines = examples(command.help)
    assert lines, f"{name} --help has no examples"
    (tmp_path / "gaits").symlink_to(ROOT / "gaits")
    env = console_env()
    for line in lines:
        assert line.startswith(("crawlsim ", "for ")), line
        r = subprocess.run(
            ["bash", "-c", f"set -eo pipefail; {line}"],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert r.returncode == 0, (line, r.stdout[-2000:], r.stderr[-2000:])


def test_the_examples_are_found():
    found = {name: examples(command.help) for name, command in commands()}
    assert any("--shard $i/3" in line and "crawlsim merge" in line for line in found["velocity"])
    assert any("--link" in line for line in found["velocity"])
    assert all(found.values())


def test_defaults_in_the_help_are_the_gait_files_defaults():
    """The help says what wins: the gait file's value, else crawlsim's default, which is the
    default of `crawlsim.gait.settings.Simulation`."""
    s = Simulation()
    assert (DEFAULT_STEPS_PER_PERIOD, DEFAULT_MAX_PERIODS, DEFAULT_TOLERANCE, str(DEFAULT_INTEGRATOR)) == (
        s.steps_per_period,
        s.max_periods,
        s.tolerance,
        s.integrator,
    )
    for command in ("run", "velocity"):
        text = " ".join(
            CliRunner().invoke(main, [command, "--help"], terminal_width=1000, max_content_width=1000).output.split()
        )
        for value in (s.steps_per_period, s.max_periods, f"{s.tolerance:g}", s.integrator):
            assert f"(default: the gait file's value, else {value})" in text, (command, value)


def test_version_and_short_options():
    assert CliRunner().invoke(main, ["--version"]).output == f"crawlsim, version {__version__}\n"
    text = CliRunner().invoke(main, ["velocity", "--help"]).output
    assert "-j, --jobs" in text and "-q, --quiet" in text and "-v, --verbose" in text
    assert "_CRAWLSIM_COMPLETE=bash_source crawlsim" in CliRunner().invoke(main, ["--help"]).output


def _complete(words: str, cword: int, shell="bash"):
    env = {**os.environ, "_CRAWLSIM_COMPLETE": f"{shell}_complete", "COMP_WORDS": words, "COMP_CWORD": str(cword)}
    return subprocess.run(
        [sys.executable, "-m", "crawlsim"], env=env, capture_output=True, text=True, check=True
    ).stdout


def test_shell_completion_as_documented():
    """The documented line makes a bash completion function, and completing answers with the
    commands, options and choices."""
    env = {**os.environ, "_CRAWLSIM_COMPLETE": "bash_source"}
    source = subprocess.run(
        [sys.executable, "-m", "crawlsim"], env=env, capture_output=True, text=True, check=True
    ).stdout
    assert "_crawlsim_completion()" in source and "complete -o nosort -F" in source
    assert _complete("crawlsim ve", 1).split() == ["plain,velocity"]
    assert "plain,--integrator" in _complete("crawlsim run g.yaml --int", 3).split()
    assert set(_complete("crawlsim run g.yaml --integrator ", 4).split()) == {"plain,catch-up", "plain,exact"}


def test_citation_file():
    """CITATION.cff is valid CFF 1.2.0 in its required keys, carries the package's version, and
    cites the paper crawlsim implements."""
    import yaml

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["message"] and cff["title"].startswith("crawlsim") and cff["authors"]
    assert cff["version"] == __version__
    (paper,) = cff["references"]
    assert paper["type"] == "article"
    assert " ".join(paper["title"].split()) == (
        "Stabilization of periodic sweeping processes and asymptotic average velocity for soft "
        "locomotors with dry friction"
    )
    assert [a["family-names"] for a in paper["authors"]] == ["Colombo", "Gidoni", "Vilches"]
