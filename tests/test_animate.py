"""``crawlsim animate``: a GIF of the blocks and links in motion, written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.colors import to_hex
from PIL import Image, ImageSequence

from crawlsim import api
from crawlsim.cli import main
from crawlsim.errors import OutputError
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.io.runread import read_results
from crawlsim.plotting import animation
from crawlsim.plotting.animation import (
    ANIMATION_DPI,
    ANIMATION_SIZE,
    animation_frames,
    limit_positions,
    parse_periods,
    write_animation,
)
from crawlsim.plotting.style import FAINT, SLIP_COLOURS

GAITS = Path(__file__).resolve().parents[1] / "gaits"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def p4(tmp_path_factory):
    """peristalsis-4 at 200 steps a period, plain iteration: 2 periods stored whole."""
    out = tmp_path_factory.mktemp("run") / "p4.h5"
    gait = with_simulation(load_gait(GAITS / "peristalsis-4.yaml"), steps_per_period=200)
    api.run(gait, output=out)
    return out


def frames_of(path: Path) -> list[np.ndarray]:
    with Image.open(path) as image:
        assert image.format == "GIF"
        return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(image)]


def test_gif_of_peristalsis_4(p4, tmp_path):
    """40 frames a period by default, 8 x 5.6 in at 80 dpi (640 x 448 pixels), 50 ms a frame
    (20 frames a second); the frames differ (the crawler moves), and the blocks' slip colours
    are in them."""
    target = tmp_path / "crawl.gif"
    r = cli("animate", p4, "-o", target)
    assert r.exit_code == 0, r.output
    assert r.output.strip() == f"{target} (40 frames, 2 s)"
    assert target.read_bytes()[:6] == b"GIF89a"
    frames = frames_of(target)
    assert len(frames) == 40
    size = (round(ANIMATION_SIZE[0] * ANIMATION_DPI), round(ANIMATION_SIZE[1] * ANIMATION_DPI))
    assert frames[0].shape == (size[1], size[0], 3)
    with Image.open(target) as image:
        assert image.info["duration"] == 50 and image.info.get("loop") == 0
    changed = [np.mean(np.any(a != b, axis=-1)) for a, b in zip(frames, frames[1:])]
    assert min(changed) > 0, "two consecutive frames are the same"
    forward = np.array(Image.new("RGB", (1, 1), SLIP_COLOURS[1]).getpixel((0, 0)))
    assert any(np.any(np.all(np.abs(f.astype(int) - forward) <= 8, axis=-1)) for f in frames)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["crawl.gif"]


def test_limit_positions_are_the_trajectory(p4):
    """The positions the animation draws over the limit period are the trajectory's over its
    last period (peristalsis-4 is periodic from period 1, and every step is stored): the body
    from the link lengths, the barycentre from the running frame and y(t0), to roundoff."""
    r = read_results(p4)
    x = limit_positions(r)
    t, xt = r["trajectory"]["t"], r["trajectory"]["x"]
    start = np.searchsorted(t, r["limit_attrs"]["start"])
    np.testing.assert_allclose(x, xt[start:], rtol=0, atol=1e-12)


def test_periods_and_frames(p4, tmp_path):
    """--periods 0:2 with 5 frames a period: 10 frames at t/T = 0, 0.2, ..., 1.8, from the
    trajectory, each with the slip state of the step that follows it."""
    r = read_results(p4)
    frames = animation_frames(r, (0, 2), 5)
    np.testing.assert_allclose(frames.t, np.arange(10) / 5, atol=1e-12)
    index = np.searchsorted(r["trajectory"]["t"], frames.t - 1e-12)
    np.testing.assert_array_equal(frames.x, r["trajectory"]["x"][index])
    dx = r["trajectory"]["x"][index + 1] - r["trajectory"]["x"][index]
    np.testing.assert_array_equal(frames.slip, np.sign(np.where(np.abs(dx) > 1e-9, dx, 0)))
    target = tmp_path / "two.gif"
    r = cli("animate", p4, "--periods", "0:2", "--frames-per-period", "5", "-o", target)
    assert r.exit_code == 0, r.output
    assert len(frames_of(target)) == 10
    assert parse_periods("3:7") == (3, 7)


@pytest.mark.parametrize(
    "args, words",
    [
        (["--periods", "0:9"], "the run holds 2 periods"),
        (["--periods", "2:1"], "0 <= A < B"),
        (["--periods", "a:b"], "expected A:B"),
        (["-o", "{tmp}/crawl.avi"], "written as .gif or .mp4"),
        (["--fps", "0"], "--fps"),
        (["--frames-per-period", "1"], "--frames-per-period"),
    ],
)
def test_bad_requests_exit_2_and_write_nothing(p4, tmp_path, args, words):
    args = [a.format(tmp=tmp_path) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "crawl.gif")]
    r = cli("animate", p4, *args)
    assert r.exit_code == 2 and words in r.output and "Traceback" not in r.output, r.output
    assert list(tmp_path.iterdir()) == []


def test_mp4_without_ffmpeg_is_refused(p4, tmp_path, monkeypatch):
    from matplotlib import animation as mpl_animation

    monkeypatch.setattr(mpl_animation.writers, "is_available", lambda name: False)
    r = cli("animate", p4, "-o", tmp_path / "crawl.mp4")
    assert r.exit_code == 2 and "needs ffmpeg" in r.output
    assert list(tmp_path.iterdir()) == []


def test_an_error_while_writing_leaves_no_file(p4, tmp_path, monkeypatch):
    """A failure at frame 5 of 40 (a full disk, say) leaves neither the GIF nor a temporary
    file; an existing animation at the target is kept as it was."""
    target = tmp_path / "crawl.gif"
    real = animation.animation_figure

    def failing(results, frames, **options):
        fig, draw = real(results, frames, **options)

        def draw_or_fail(k):
            if k == 5:
                raise OSError(28, "No space left on device")
            return draw(k)

        return fig, draw_or_fail

    monkeypatch.setattr(animation, "animation_figure", failing)
    # a full disk is crawlsim's own refusal, naming the target (crawlsim.io.atomic.disk_error)
    with pytest.raises(OutputError, match=f"no space left on device: {target}"):
        write_animation(read_results(p4), target)
    assert list(tmp_path.iterdir()) == []
    Image.new("RGB", (4, 4)).save(target)
    before = target.read_bytes()
    with pytest.raises(OutputError):
        write_animation(read_results(p4), target)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["crawl.gif"]


def test_help_has_an_example():
    r = cli("animate", "--help")
    assert r.exit_code == 0
    assert "crawlsim animate p4.h5 -o crawl.gif" in r.output
    assert "--periods A:B" in r.output


def _length_legend(results) -> list[str]:
    """The legend of the lengths panel; its link lengths are grey (blue and vermilion are
    tension and compression in the stress panel)."""
    fig, _ = animation.animation_figure(results, animation_frames(results, None, 4))
    lengths = fig.axes[1]
    first = lengths.patches[0] if lengths.patches else lengths.get_lines()[0]
    colour = first.get_facecolor() if lengths.patches else first.get_color()
    assert to_hex(colour) == FAINT.lower()
    return [text.get_text() for text in lengths.get_legend().get_texts()]


def test_length_panel_legend_names_its_artists(p4, tmp_path):
    """The lengths panel's legend reads "link $z_i$" and "actuator $L_i$", for the bars of a
    4-block crawler (it read "_nolegend_": the label is the bar container's, not a bar's) and
    for the curve along the body of a 41-block one."""
    from .test_plotting import wave_file

    assert _length_legend(read_results(p4)) == ["link $z_i$", "actuator $L_i$"]
    assert _length_legend(read_results(wave_file(tmp_path, 41))) == ["link $z_i$", "actuator $L_i$"]


def test_animation_of_a_result_object(p4, tmp_path):
    """write_animation takes the result of crawlsim.simulate: the frames are those of the
    results file of the same run (positions, stresses, slips to 1e-12), and the GIF has them
    all."""
    from crawlsim.plotting import run_data

    gait = with_simulation(load_gait(GAITS / "peristalsis-4.yaml"), steps_per_period=200)
    result = api.simulate(gait)
    ours, stored = (animation_frames(run_data(result), None, 8), animation_frames(read_results(p4), None, 8))
    for name in ("t", "x", "stress", "lengths", "slip"):
        np.testing.assert_allclose(getattr(ours, name), getattr(stored, name), rtol=1e-12, atol=1e-12, err_msg=name)
    path, count = write_animation(result, tmp_path / "r.gif", frames_per_period=8)
    assert count == 8 and len(frames_of(path)) == 8


def test_the_last_periods_in_a_frame_that_follows_the_crawler(p4, tmp_path):
    """--last K animates the last K stored periods with the positions taken from the barycentre:
    in every frame the blocks' centres average 0, the ground's marks pass by as the barycentre
    advances, and its trace from the first frame is as long as it has come (peristalsis-4: v0 T
    a period in its periodic regime)."""
    from crawlsim.plotting.animation import animation_figure

    r = read_results(p4)
    frames = animation_frames(r, (1, 2), 8)
    fig, draw = animation_figure(r, frames, follow=True)
    body = fig.axes[0]
    boxes = next(c for c in body.collections if c.__class__.__name__ == "PolyCollection")
    ground = [c for c in body.collections if c.__class__.__name__ == "LineCollection"][-1]  # after the links
    y = frames.x.mean(axis=1)
    first = None
    for k in (0, 4, 7):
        draw(k)
        centres = np.array([np.mean(v[:, 0]) for v in [p.vertices[:4] for p in boxes.get_paths()]])
        assert abs(centres.mean()) <= 1e-12
        marks = np.array([seg[0][0] for seg in ground.get_segments()])
        first = marks if first is None else first
        np.testing.assert_allclose(marks, first - (y[k] - y[0]), atol=1e-12)
        trace = next(line for line in body.get_lines() if line.get_label() == "barycentre's trace")
        np.testing.assert_allclose(trace.get_xdata(), [y[0] - y[k], 0.0], atol=1e-12)
    assert body.get_xlabel() == "position from the barycentre $(x_j - y)/\\ell$"
    target = tmp_path / "follow.gif"
    r = cli("animate", p4, "--last", 1, "--frames-per-period", 8, "-o", target)
    assert r.exit_code == 0 and r.output.strip() == f"{target} (8 frames, 0.4 s)", r.output
    r = cli("animate", p4, "--last", 1, "--periods", "0:1", "-o", tmp_path / "no.gif")
    assert r.exit_code == 2 and "give one of the two" in r.output and not (tmp_path / "no.gif").exists()
