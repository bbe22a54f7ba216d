"""The documentation holds together: every relative link and image in README.md and docs/*.md
points to a file of the repository, and every ``#anchor`` to a heading of its target, with
GitHub's rule for heading anchors. The model documentation keeps the section numbers that code
and messages cite as ``docs/model.md §N``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
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
    assert anchor("Correction 2: the acute angle on [T/2, T]") == \
        "correction-2-the-acute-angle-on-t2-t"
    assert anchor("3. Catch-up stepping, slips and uniqueness") == \
        "3-catch-up-stepping-slips-and-uniqueness"


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
    """docs/model.md keeps §1 ... §6 in order, the two corrections to the paper, and cites the
    paper by its authors and title."""
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    numbered = re.findall(r"^## (\d)\. ", text, flags=re.M)
    assert numbered == ["1", "2", "3", "4", "5", "6"]
    assert "Colombo, P. Gidoni and E. Vilches" in text
    assert "Stabilization of periodic sweeping processes" in text
    assert "Correction 1: the translation is k L" in text
    assert "l(t) = (0, t)  on [0, T/2],      l(t) = (0, T - t)  on [T/2, T]" in text


def test_every_figure_is_shown():
    """Each image the figure scripts make is shown in the README and in docs/figures.md or
    docs/paper.md, and each image shown exists."""
    made = {p.name for p in (ROOT / "docs" / "figures").glob("*.png")}
    readme = {Path(t).name for t in links(ROOT / "README.md") if t.endswith(".png")}
    docs = {Path(t).name for page in ("figures.md", "paper.md")
            for t in links(ROOT / "docs" / page) if t.endswith(".png")}
    assert made == docs
    assert made - readme <= {"paper-acute-angle.png", "paper-triangle.png"}
