"""The documentation holds together: every relative link and image in README.md and docs/*.md
points to a file of the repository, and every ``#anchor`` to a heading of its target, with
GitHub's rule for heading anchors (mkdocs.yml gives the site the same slugs, and
``mkdocs build --strict`` checks the site's links again). Every code block of docs/*.md runs as
printed, with the rules of tests/test_readme.py. The site's navigation holds every page, the
layout page names every package, and every path ``crawlsim/...`` a page names exists. The model
documentation keeps the section numbers that code and messages cite as ``docs/model.md §N``."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.test_readme import Block, check_markers, parse_blocks, run_in_order

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _prose(text: str) -> str:
    """The text outside fenced code blocks and inline code."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation other than '-' and '_' dropped,
    spaces to '-'.

    >>> anchor("2. The sweeping process on K(t)")
    '2-the-sweeping-process-on-kt'
    """
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.S | re.M)
    return {anchor(m.group(1)) for m in re.finditer(r"^#{1,6} (.+)$", text, flags=re.M)}


def links(path: Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(_prose(path.read_text(encoding="utf-8")))]


def test_anchor_rule():
    assert anchor("`crawlsim run`") == "crawlsim-run"
    assert anchor("Correction 2: the acute angle on [T/2, T]") == "correction-2-the-acute-angle-on-t2-t"
    assert anchor("3. Catch-up stepping, slips and uniqueness") == "3-catch-up-stepping-slips-and-uniqueness"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(page):
    found = links(page)
    assert found or page.name in ("model.md", "study.md")  # pages without links
    for target in found:
        if re.match(r"^[a-z]+:", target):
            continue  # an external address: not checked here
        file, _, fragment = target.partition("#")
        resolved = (page.parent / file).resolve() if file else page
        assert resolved.exists(), f"{page.name}: {target} points to a missing file"
        assert ROOT in resolved.parents or resolved == ROOT, f"{page.name}: {target} leaves the repository"
        if fragment:
            assert resolved.suffix == ".md", f"{page.name}: {target}"
            assert fragment in anchors(resolved), f"{page.name}: no heading for #{fragment} in {file or page.name}"


def test_no_page_points_outside_the_project():
    """Nothing user-facing names the shared folder the project was written from."""
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        assert "../shared" not in text, page.name


def test_model_sections():
    """docs/model.md keeps §1 ... §7 in order, the two corrections to the paper, and cites the
    paper by its authors and title."""
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    numbered = re.findall(r"^## (\d)\. ", text, flags=re.M)
    assert numbered == ["1", "2", "3", "4", "5", "6", "7"]
    assert "Colombo, P. Gidoni and E. Vilches" in text
    assert "Stabilization of periodic sweeping processes" in text
    assert "Correction 1: the translation is k L" in text
    assert "l(t) = (0, t)  on [0, T/2],      l(t) = (0, T - t)  on [T/2, T]" in text


def test_every_figure_is_shown():
    """Each image the figure scripts make is shown in docs/figures.md or docs/paper.md (the
    README shows one of them), and each image shown exists (test_links_resolve)."""
    made = {p.name for p in (DOCS / "figures").glob("*.png")}
    readme = {Path(t).name for t in links(ROOT / "README.md") if t.endswith(".png")}
    docs = {Path(t).name for page in ("figures.md", "paper.md") for t in links(DOCS / page) if t.endswith(".png")}
    assert made == docs
    assert len(readme) == 1 and readme <= made


# -- the site ----------------------------------------------------------------------------------
def _nav_pages(nav) -> list[str]:
    out: list[str] = []
    for item in nav:
        for value in item.values() if isinstance(item, dict) else [item]:
            out.extend(_nav_pages(value) if isinstance(value, list) else [value])
    return out


def test_the_site_navigation_holds_every_page():
    """mkdocs.yml lists every page of docs/ (the notebooks of docs/examples/ included) once,
    and only pages that exist: the issue's pages (the model, gait files, each command, the HDF5
    layout, integrators, sweeps, optimize, the paper, benchmarks, the API, the examples) among
    them."""
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    nav = _nav_pages(config["nav"])
    assert len(nav) == len(set(nav))
    pages = {
        p.relative_to(DOCS).as_posix()
        for p in DOCS.rglob("*")
        if p.suffix in (".md", ".ipynb")
        and not p.name.startswith("_")
        and "_hooks" not in p.parts
        and ".ipynb_checkpoints" not in p.parts
    }
    assert set(nav) == pages
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
        "layout.md",
    } <= pages
    assert sum(p.endswith(".ipynb") for p in pages) >= 2


def test_the_commands_page_has_every_command():
    """docs/commands.md has a section per command of `crawlsim --help`."""
    from crawlsim.cli import main

    headings = anchors(DOCS / "commands.md")
    for name in main.list_commands(None):  # type: ignore[arg-type]
        assert f"crawlsim-{name}" in headings, name


def test_the_layout_page_names_every_package_and_only_paths_that_exist():
    """docs/layout.md names every package folder of crawlsim/ (``gait/``, ``kernel/``, ...) and
    every module, and every ``crawlsim/...`` path named on any page exists: a module that is
    added, moves or splits cannot leave the page behind."""
    layout = (DOCS / "layout.md").read_text(encoding="utf-8")
    for package in sorted(p.parent.name for p in (ROOT / "crawlsim").glob("*/__init__.py")):
        assert f"{package}/" in layout, package
    for module in sorted((ROOT / "crawlsim").glob("**/*.py")):  # a new module is described
        if module.name not in ("__init__.py", "__main__.py"):
            assert f"`{module.name}`" in layout, f"docs/layout.md does not describe {module.relative_to(ROOT)}"
    for page in PAGES:
        for path in re.findall(r"crawlsim/[\w/]+\.py|crawlsim/[\w/]+/(?=[\s`),])", page.read_text(encoding="utf-8")):
            assert (ROOT / path).exists(), f"{page.name}: {path} does not exist"


# -- every code block of docs/ runs --------------------------------------------------------------
DOC_BLOCKS = {page.name: parse_blocks(page.read_text(encoding="utf-8"), f"docs/{page.name}") for page in PAGES[1:]}
#: The blocks that run (an illustration marked ``skip: REASON`` is checked by its marker alone).
CASES = [
    (name, i)
    for name, blocks in DOC_BLOCKS.items()
    for i, block in enumerate(blocks)
    if not (block.marker or "").startswith("skip:")
]


@pytest.mark.parametrize("name", sorted(DOC_BLOCKS))
def test_every_docs_block_is_run_or_marked_as_an_illustration(name):
    check_markers(DOC_BLOCKS[name])


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """One scratch folder per page, holding a copy of gaits/, and what each page ran."""
    state: dict[str, tuple[Path, set[int], dict[str, str]]] = {}

    def folder(name: str) -> tuple[Path, set[int], dict[str, str]]:
        if name not in state:
            path = tmp_path_factory.mktemp(name.removesuffix(".md"))
            shutil.copytree(ROOT / "gaits", path / "gaits")
            state[name] = (path, set(), {})
        return state[name]

    return folder


def _block_id(case: tuple[str, int]) -> str:
    block: Block = DOC_BLOCKS[case[0]][case[1]]
    return f"{case[0]}-{block.id}"


@pytest.mark.parametrize("case", CASES, ids=[_block_id(c) for c in CASES])
def test_docs_block(case, folders):
    """Block ``index`` of a docs page, after every earlier block of the page."""
    name, index = case
    if DOC_BLOCKS[name][index].language == "python" and "xarray" in DOC_BLOCKS[name][index].text:
        pytest.importorskip("xarray")
        pytest.importorskip("h5netcdf")
    path, done, printed = folders(name)
    run_in_order(DOC_BLOCKS[name], index, path, done, printed)


# -- the API reference -------------------------------------------------------------------------
def _hook():
    import importlib.util

    spec = importlib.util.spec_from_file_location("api_docstrings", DOCS / "_hooks" / "api_docstrings.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_object_of_the_api_reference_has_a_docstring():
    """The check that fails `mkdocs build --strict` (docs/_hooks/api_docstrings.py) finds every
    object docs/api.md renders, each documented with its public methods, and finds a missing
    docstring where there is one."""
    hook = _hook()
    paths = hook.DIRECTIVE.findall((DOCS / "api.md").read_text(encoding="utf-8"))
    assert {
        "crawlsim.api.simulate",
        "crawlsim.api.sweep",
        "crawlsim.api.SimulationResult",
        "crawlsim.gait.document.Gait",
    } <= set(paths)
    assert [name for path in paths for name in hook.undocumented(path)] == []
    assert hook.undocumented("tests.test_docs._hook") == ["tests.test_docs._hook"]
    assert hook.undocumented("tests.test_readme.Block") == [
        "tests.test_readme.Block",
        "tests.test_readme.Block.id",
        "tests.test_readme.Block.where",
    ]


@pytest.mark.slow  # mkdocs build; .ci/run builds the site in its own step too
def test_the_site_builds_strictly(tmp_path):
    """`mkdocs build --strict` (as .ci/run runs it): no broken link or anchor, no page outside
    the navigation, no undocumented object in the API reference, and the notebooks rendered
    with their stored figures."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    pytest.importorskip("mkdocstrings_handlers.python")
    pytest.importorskip("mkdocs_jupyter")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert "WARNING" not in done.stderr, done.stderr
    notebook = (tmp_path / "site" / "examples" / "first-run" / "index.html").read_text(encoding="utf-8")
    assert notebook.count("data:image/png") >= 3
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    assert "keep_trajectory" in api  # a signature rendered from the code
