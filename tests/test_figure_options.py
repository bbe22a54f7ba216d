"""How figures are written: ``--dpi``, ``--figsize``, ``--style`` and the format by the output
file's extension, on ``crawlsim plot`` and ``crawlsim run --plot``; bad options exit 2 with a
message, no traceback and no file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from crawlsim import api
from crawlsim.cli import main
from crawlsim.gait.document import load_gait, with_simulation

GAITS = Path(__file__).resolve().parents[1] / "gaits"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def run_h5(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "p4.h5"
    gait = with_simulation(load_gait(GAITS / "peristalsis-4.yaml"), steps_per_period=100)
    api.run(gait, output=out)
    return out


@pytest.mark.parametrize(
    "suffix, magic", [(".pdf", b"%PDF-"), (".svg", b"<?xml"), (".png", b"\x89PNG\r\n\x1a\n"), (".PDF", b"%PDF-")]
)
def test_one_figure_by_the_extension_of_its_file(run_h5, tmp_path, suffix, magic):
    target = tmp_path / f"motion{suffix}"
    r = cli("plot", run_h5, "--only", "motion", "-o", target)
    assert r.exit_code == 0, r.output
    assert r.output.strip() == str(target)
    head = target.read_bytes()[:64]
    assert head.startswith(magic)
    if suffix == ".svg":
        assert b"<svg" in target.read_bytes()[:2048]
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_figsize_and_dpi_give_the_pixels(run_h5, tmp_path):
    """--figsize W,H is the whole figure: a PNG of W x dpi by H x dpi pixels (4 x 100 by 3 x
    100, 2.5 x 300 by 1.5 x 300). Without --figsize the figure is cropped to its content, and
    its pixel size scales with the dpi: 300 dpi is twice 150 dpi, to the pixel of rounding."""
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    assert cli("plot", run_h5, "--only", "motion", "-o", a, "--figsize", "4,3", "--dpi", "100").exit_code == 0
    assert Image.open(a).size == (400, 300)
    assert cli("plot", run_h5, "--only", "convergence", "-o", b, "--figsize", "2.5,1.5", "--dpi", "300").exit_code == 0
    assert Image.open(b).size == (750, 450)
    low, high = tmp_path / "low.png", tmp_path / "high.png"
    assert cli("plot", run_h5, "--only", "motion", "-o", low).exit_code == 0
    assert cli("plot", run_h5, "--only", "motion", "-o", high, "--dpi", "300").exit_code == 0
    small, large = np.array(Image.open(low).size), np.array(Image.open(high).size)
    assert np.all(np.abs(large - 2 * small) <= 2), (small, large)


def test_pdf_page_is_the_figsize(run_h5, tmp_path):
    """A PDF's page (MediaBox, in points of 1/72 in) is --figsize exactly: 3.5 x 2.6 in is
    252 x 187.2 pt."""
    import re

    target = tmp_path / "m.pdf"
    assert cli("plot", run_h5, "--only", "motion", "-o", target, "--figsize", "3.5,2.6").exit_code == 0
    box = re.search(rb"/MediaBox \[\s*0 0 ([0-9.]+) ([0-9.]+)\s*\]", target.read_bytes())
    assert box is not None
    assert (float(box[1]), float(box[2])) == pytest.approx((252.0, 187.2))


def test_style_sheet_is_applied(run_h5, tmp_path):
    """A named style (dark_background: a black figure) and a style file (a red figure face)
    change the pixels; crawlsim's own figures are otherwise white."""
    plain, dark, own = tmp_path / "plain.png", tmp_path / "dark.png", tmp_path / "own.png"
    sheet = tmp_path / "red.mplstyle"
    sheet.write_text("figure.facecolor: red\nsavefig.facecolor: red\n")
    assert cli("plot", run_h5, "--only", "motion", "-o", plain).exit_code == 0
    assert cli("plot", run_h5, "--only", "motion", "-o", dark, "--style", "dark_background").exit_code == 0
    assert cli("plot", run_h5, "--only", "motion", "-o", own, "--style", sheet).exit_code == 0
    corner = [Image.open(p).convert("RGB").getpixel((1, 1)) for p in (plain, dark, own)]
    assert corner == [(255, 255, 255), (0, 0, 0), (255, 0, 0)]


@pytest.mark.parametrize(
    "args, words",
    [
        (["--only", "motion", "-o", "{tmp}/m.jpg"], "extension .jpg"),
        (["--only", "motion", "-o", "{tmp}/m.eps"], "a figure is written as .png, .pdf or .svg"),
        (["-o", "{tmp}/all.pdf"], "names one figure"),
        (["--only", "motion", "-o", "{tmp}/m.svg", "--format", "pdf"], "--format pdf"),
        (["--only", "motion", "-o", "{tmp}/m.png", "--style", "{typo}"], "did you mean '{style}'"),
        (
            ["--only", "motion", "-o", "{tmp}/m.png", "--style", "{tmp}/missing.mplstyle"],
            "no such matplotlib style sheet or file",
        ),
        (["--only", "motion", "-o", "{tmp}/m.png", "--style", "{tmp}/bad.mplstyle"], "not a matplotlib style sheet"),
        (["--only", "motion", "-o", "{tmp}/m.png", "--figsize", "3"], "--figsize"),
        (["--only", "motion", "-o", "{tmp}/m.png", "--figsize", "0,2"], "--figsize"),
        (["--only", "motion", "-o", "{tmp}/m.png", "--figsize", "nan,2"], "--figsize"),
        (["--only", "motion", "-o", "{tmp}/m.png", "--dpi", "0"], "--dpi"),
        (["--only", "motion", "-o", "{tmp}/m.png", "--dpi", "inf"], "--dpi"),
    ],
)
def test_bad_figure_options_exit_2_and_write_nothing(run_h5, tmp_path, args, words):
    out = tmp_path / "out"
    out.mkdir()
    (out / "bad.mplstyle").write_text("this is not: a valid: style\nlines.linewidth: wide\n")
    from matplotlib import style as sheets

    # A style sheet matplotlib has, misspelt by one letter (the names are matplotlib's).
    style = "ggplot" if "ggplot" in sheets.available else sorted(sheets.available)[0]
    fill = {"tmp": out, "typo": style[:-1] + "x", "style": style}
    r = cli("plot", run_h5, *[a.format(**fill) for a in args])
    assert r.exit_code == 2, r.output
    assert words.format(**fill) in r.output, r.output
    assert "Traceback" not in r.output
    assert sorted(p.name for p in out.iterdir()) == ["bad.mplstyle"]


def test_run_plot_takes_the_figure_options(tmp_path):
    """run --plot --plot-format svg --figsize writes SVG figures of that size; the figure
    options without --plot are refused (exit 2) before the run, with no results file."""
    gait = GAITS / "inching-2.yaml"
    out = tmp_path / "i.h5"
    r = cli(
        "run",
        gait,
        "-o",
        out,
        "--steps-per-period",
        "20",
        "--plot",
        "--plot-format",
        "svg",
        "--figsize",
        "4,3",
        "--quiet",
    )
    assert r.exit_code == 0, r.output
    figures = sorted(p.name for p in tmp_path.glob("i-*"))
    assert figures == [
        "i-convergence.svg",
        "i-gait-diagram.svg",
        "i-kymograph.svg",
        "i-motion.svg",
        "i-shape-space.svg",
    ]
    head = (tmp_path / "i-motion.svg").read_text()[:1000]
    assert 'width="288pt" height="216pt"' in head  # 4 x 3 in, 72 pt to the inch
    for option in (["--dpi", "200"], ["--plot-format", "pdf"], ["--style", "ggplot"]):
        target = tmp_path / "no.h5"
        r = cli("run", gait, "-o", target, "--steps-per-period", "20", *option)
        assert r.exit_code == 2 and "add --plot" in r.output and "Traceback" not in r.output
        assert not target.exists()
    r = cli("run", gait, "-o", tmp_path / "no.h5", "--plot", "--style", "nonesuch")
    assert r.exit_code == 2 and "--style nonesuch" in r.output
    assert not (tmp_path / "no.h5").exists()


def test_plot_means_the_same_in_run_and_velocity(tmp_path, monkeypatch):
    """--plot is a flag in both (it took a file in velocity): the figures next to the results, as
    `crawlsim plot RESULTS` names them, in --plot-format with the figure options; without -o,
    velocity's next to the gait's name in this folder, its path on stderr (the table is on
    stdout). The paths are printed as the results path is, relative (run printed them absolute)."""
    monkeypatch.chdir(tmp_path)
    sweep = ["--sweep", "friction.backward=2,3", "--steps-per-period", "20"]
    r = cli("velocity", GAITS / "inching-2.yaml", *sweep, "-o", "s.h5", "--plot", "--plot-format", "pdf", "--dpi", "99")
    assert r.exit_code == 0 and r.stdout == "s-sweep.pdf\n", r.output
    assert (tmp_path / "s-sweep.pdf").read_bytes()[:5] == b"%PDF-"
    r = cli("velocity", GAITS / "inching-2.yaml", *sweep, "--plot", "--figsize", "4,3")
    assert r.exit_code == 0 and r.stderr == "inching-2-sweep.png\n" and r.stdout.startswith("friction.backward,v0")
    assert Image.open(tmp_path / "inching-2-sweep.png").size == (600, 450)  # 4 x 3 in at 150 dpi
    r = cli("velocity", GAITS / "inching-2.yaml", "--plot")
    assert r.exit_code == 2 and "crawlsim run GAIT --plot" in r.output
    r = cli("run", GAITS / "inching-2.yaml", "-o", "r.h5", "--steps-per-period", "20", "--plot")
    assert r.exit_code == 0 and "  figure                   r-motion.png" in r.output.splitlines()
