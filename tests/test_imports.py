"""The import graph of the command line: start-up is part of the interface (shell loops call
`crawlsim velocity` thousands of times; `crawlsim --help` and completion must answer at once).

Each check runs a fresh interpreter and lists the modules loaded after the command. The timing
itself is a benchmark (scripts/bench-startup.py), never a test.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "gaits" / "inching-2.yaml"
HEAVY = ("numpy", "scipy", "h5py", "jsonschema", "matplotlib", "yaml", "tqdm", "clarabel")

DRIVER = """\
import json, sys
args, out = json.loads(sys.argv[1]), sys.argv[2]
if args is None:
    import crawlsim, crawlsim.cli
else:
    from crawlsim.cli import main
    try:
        main(args, prog_name="crawlsim")
    except SystemExit:
        pass
with open(out, "w") as f:
    json.dump(sorted(sys.modules), f)
"""


def modules_after(args, tmp_path) -> set[str]:
    """The modules a fresh interpreter holds after ``crawlsim ARGS`` (None: after importing
    crawlsim and crawlsim.cli only)."""
    out = tmp_path / "modules.json"
    subprocess.run(
        [sys.executable, "-c", DRIVER, json.dumps(args), str(out)], check=True, cwd=tmp_path, capture_output=True
    )
    return set(json.loads(out.read_text()))


def loaded(modules: set[str], name: str) -> bool:
    return name in modules or any(m.startswith(name + ".") for m in modules)


@pytest.mark.parametrize(
    "args",
    [
        None,
        ["--version"],
        ["--help"],
        ["velocity", "--help"],
        ["run", "--help"],
        ["info", "--help"],
        ["plot", "--help"],
    ],
)
def test_import_and_help_load_no_numerical_module(args, tmp_path):
    modules = modules_after(args, tmp_path)
    assert not [m for m in HEAVY if loaded(modules, m)]


def test_only_the_invoked_command_module_is_imported(tmp_path):
    modules = modules_after(["velocity", "--help"], tmp_path)
    assert "crawlsim.cli.velocity" in modules
    assert not {"crawlsim.cli.run", "crawlsim.cli.plot", "crawlsim.cli.info", "crawlsim.cli.merge"} & modules
    every = modules_after(["--help"], tmp_path)  # the listing needs each command's help line
    assert {"crawlsim.cli.run", "crawlsim.cli.velocity", "crawlsim.cli.info"} <= every


@pytest.mark.parametrize("integrator", ["catch-up", "exact"])
def test_velocity_loads_what_it_needs_and_no_more(integrator, tmp_path):
    """v0 of a gait needs numpy, YAML, the schema validation and the KKT kernel; not h5py
    (nothing is written), matplotlib, tqdm (stderr is not a terminal), Dask or the sweep
    machinery. Clarabel is loaded only when the kernel's own updates do not settle a step (the
    two-block gait never needs it), and scipy.optimize not at all: the exact integrator's events
    of a cosine gait have closed forms. jsonschema is not loaded for a valid gait (the compiled
    check of `crawlsim.gait.schemacheck` accepts it)."""
    modules = modules_after(["velocity", str(GAIT), "--integrator", integrator], tmp_path)
    for name in ("numpy", "yaml", "crawlsim.projection.adapter", "crawlsim.projection.kkt"):
        assert loaded(modules, name), name
    for name in (
        "h5py",
        "matplotlib",
        "tqdm",
        "distributed",
        "dask",
        "crawlsim.study.sweep",
        "crawlsim.io.runfile",
        "crawlsim.plotting.output",
        "clarabel",
        "scipy.optimize",
        "jsonschema",
    ):
        assert not loaded(modules, name), name


def test_velocity_reads_no_distribution_metadata(tmp_path):
    """The library versions (`crawlsim.io.provenance.versions`, 20-30 ms of metadata reading) are
    recorded in results files; printing v0 does not look them up, ``--json`` (whose summary
    holds no versions) neither."""
    code = (
        "import sys\nfrom crawlsim.cli import main\n"
        "for extra in ([], ['--json']):\n"
        "    try:\n        main(['velocity', sys.argv[1], *extra], prog_name='crawlsim')\n"
        "    except SystemExit:\n        pass\n"
        "from crawlsim.io.provenance import _versions\n"
        "info = _versions.cache_info()\nprint('LOOKUPS', info.hits + info.misses)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(GAIT)], capture_output=True, text=True, check=True, cwd=tmp_path
    ).stdout
    assert out.splitlines()[-1] == "LOOKUPS 0"


def test_validate_of_a_valid_gait_loads_no_jsonschema(tmp_path):
    modules = modules_after(["validate", str(GAIT)], tmp_path)
    assert loaded(modules, "crawlsim.gait.document") and not loaded(modules, "jsonschema")


def test_validate_of_crawler_gaits_loads_neither_scipy_nor_the_kernel(tmp_path):
    """Checking a crawler's gait file (structure, friction, admissible start, uniqueness) is
    numpy's work: scipy (its LPs check generic process files only), numba and the compiled
    kernel are for running."""
    modules = modules_after(["validate", str(GAIT), str(ROOT / "gaits" / "earthworm-100.yaml")], tmp_path)
    for name in ("scipy", "numba", "crawlsim.kernel", "crawlsim.projection.kkt", "clarabel", "h5py"):
        assert not loaded(modules, name), name


def test_an_invalid_gait_loads_jsonschema_for_its_message(tmp_path):
    """jsonschema, the reference validator, phrases the error of a refused gait."""
    bad = tmp_path / "bad.yaml"
    bad.write_text(GAIT.read_text() + "\nsimulaton: {}\n")
    modules = modules_after(["velocity", str(bad)], tmp_path)
    assert loaded(modules, "jsonschema")


def test_version_of_the_console_script_loads_no_click(tmp_path):
    """``crawlsim --version`` (the console script, `crawlsim.console`) answers before importing
    click, with click's own answer."""
    code = (
        "import sys, json; sys.argv = ['crawlsim', '--version']\n"
        "from crawlsim.console import main\n"
        "try:\n    main()\nexcept SystemExit as e:\n    code = e.code\n"
        "print(json.dumps([code, sorted(sys.modules)]))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    first, last = out.splitlines()[0], out.splitlines()[-1]
    code_, modules = json.loads(last)
    assert code_ == 0 and not loaded(set(modules), "click")
    assert not [m for m in HEAVY if loaded(set(modules), m)]
    via_click = subprocess.run(
        [sys.executable, "-m", "crawlsim", "--version"], cwd=tmp_path, capture_output=True, text=True, check=True
    ).stdout
    assert first == via_click.strip()


def test_help_of_the_console_script_is_clicks_and_loads_no_click(tmp_path):
    """``crawlsim --help`` (the console script) prints the stored text, byte for byte what click
    renders at 80 columns, without importing click; narrower, click renders it itself."""
    from click.testing import CliRunner

    from crawlsim._help import TEXT
    from crawlsim.cli import main as cli

    rendered = CliRunner().invoke(cli, ["--help"], prog_name="crawlsim", terminal_width=78)
    assert rendered.exit_code == 0
    assert TEXT == rendered.output, "crawlsim/_help.py is stale: its TEXT must be\n" + rendered.output
    code = (
        "import sys, json; sys.argv = ['crawlsim', '--help']\n"
        "from crawlsim.console import main\n"
        "try:\n    main()\nexcept SystemExit as e:\n    code = e.code\n"
        "print(json.dumps([code, sorted(sys.modules)]))"
    )
    for columns, stored in (("120", True), ("80", True), ("60", False)):
        done = subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            check=True,
            cwd=tmp_path,
            env={**os.environ, "COLUMNS": columns},
        )
        *text, last = done.stdout.splitlines(keepends=True)
        code_, modules = json.loads(last)
        assert code_ == 0 and loaded(set(modules), "click") != stored, columns
        if stored:
            assert "".join(text) == TEXT


def test_console_script_passes_everything_else_to_the_command_group(tmp_path):
    code = "import sys; sys.argv = ['crawlsim', 'validate', sys.argv[1]]\nfrom crawlsim.console import main\nmain()"
    done = subprocess.run([sys.executable, "-c", code, str(GAIT)], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr


def test_run_and_info_load_no_plotting(tmp_path):
    modules = modules_after(["run", str(GAIT), "-o", str(tmp_path / "r.h5")], tmp_path)
    assert loaded(modules, "h5py") and not loaded(modules, "matplotlib")
    modules = modules_after(["info", str(tmp_path / "r.h5")], tmp_path)
    assert loaded(modules, "h5py")
    for name in ("matplotlib", "scipy", "jsonschema", "clarabel"):
        assert not loaded(modules, name), name
