import numpy as np
import pytest

from crawlsim.errors import GaitError
from crawlsim.gait.crawler_spec import admissibility_violation, uniqueness_violation
from crawlsim.gait.document import gait_from_document, load_gait, parse_gait, with_simulation
from crawlsim.gait.settings import Simulation
from crawlsim.gait.signals import Cosine, Steps

from .conftest import GAITS

EXAMPLE = """\
name: peristalsis-4
description: retrograde wave
blocks: 4
period: 1.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.0}
  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.25}
  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.5}
friction: {forward: 1.0, backward: 2.0}
initial: {positions: [0.0, 1.3, 2.3, 3.0]}
simulation: {steps_per_period: 1000, max_periods: 1000, tolerance: 1.0e-12, integrator: catch-up}
kind: crawler
"""


def refused(text, source="g.yaml"):
    with pytest.raises(GaitError) as info:
        parse_gait(text, source)
    assert info.value.source == source
    return info.value


def test_example_loads(tmp_path):
    path = tmp_path / "peri.yaml"
    path.write_text(EXAMPLE)
    gait = load_gait(path)
    assert gait.name == "peristalsis-4"
    assert gait.description == "retrograde wave"
    assert gait.source == str(path) and gait.source_text == EXAMPLE
    assert gait.blocks == 4 and gait.period == 1.0
    np.testing.assert_array_equal(gait.stiffness, [10.0, 10.0, 10.0])
    assert gait.links[1] == Cosine(mean=1.0, amplitude=0.3, phase=0.25)
    np.testing.assert_array_equal(gait.mu_plus([0.0, 0.5]), [[1.0] * 4] * 2)
    np.testing.assert_array_equal(gait.mu_minus([0.3])[0], [2.0] * 4)
    np.testing.assert_array_equal(gait.initial_positions, [0.0, 1.3, 2.3, 3.0])
    assert gait.simulation == Simulation(1000, 1000, 1e-12, "catch-up")
    assert gait.document["links"][2]["phase"] == 0.5
    assert gait.breakpoints().size == 0


def test_name_defaults_to_file_stem(tmp_path):
    path = tmp_path / "wave.yaml"
    path.write_text(EXAMPLE.replace("name: peristalsis-4\n", ""))
    assert load_gait(path).name == "wave"
    assert parse_gait(EXAMPLE.replace("name: peristalsis-4\n", "")).name == "gait"


def test_default_initial_positions_are_stress_free():
    gait = parse_gait(EXAMPLE.replace("initial: {positions: [0.0, 1.3, 2.3, 3.0]}\n", ""))
    np.testing.assert_allclose(gait.initial_positions, [0.0, 1.3, 2.3, 3.0], atol=1e-15)
    lengths = gait.lengths([0.0])[0]
    np.testing.assert_allclose(gait.stiffness * (lengths - np.diff(gait.initial_positions)), 0.0, atol=1e-14)


def test_per_block_friction_and_per_link_stiffness():
    text = EXAMPLE.replace("stiffness: 10.0", "stiffness: [1, 2, 3]").replace(
        "friction: {forward: 1.0, backward: 2.0}",
        "friction:\n"
        + "".join(
            f"  - {{forward: {f}, backward: {{kind: steps, times: [0, 0.5], values: [2, 3]}}}}\n"
            for f in (1, 1.25, 2.1, 2.7)
        ),
    )
    gait = parse_gait(text)
    np.testing.assert_array_equal(gait.stiffness, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(gait.mu_plus([0.0])[0], [1.0, 1.25, 2.1, 2.7])
    np.testing.assert_array_equal(gait.mu_minus([0.25, 0.5])[:, 0], [2.0, 3.0])
    assert gait.backward[3] == Steps(times=(0.0, 0.5), values=(2.0, 3.0))
    np.testing.assert_allclose(gait.breakpoints(), [0.0, 0.5])


def test_exponent_without_dot_is_a_float():
    assert parse_gait(EXAMPLE.replace("tolerance: 1.0e-12", "tolerance: 1e-9")).simulation.tolerance == 1e-9


def test_gait_from_document_and_with_simulation():
    gait = parse_gait(EXAMPLE)
    doc = dict(gait.document, period=np.float64(2.0), blocks=np.int64(4))
    again = gait_from_document(doc, "sweep")
    assert again.period == 2.0 and again.source == "sweep"
    assert "period: 2.0" in again.source_text
    faster = with_simulation(gait, steps_per_period=np.int64(50), integrator="exact")
    assert faster.simulation == Simulation(50, 1000, 1e-12, "exact")
    assert faster.document["simulation"]["steps_per_period"] == 50
    assert gait.simulation.steps_per_period == 1000
    with pytest.raises(GaitError) as info:
        with_simulation(gait, steps_per_period=0)
    assert info.value.keypath == "simulation.steps_per_period"
    with pytest.raises(GaitError) as info:
        with_simulation(gait, tolerence=1e-3)
    assert "did you mean 'tolerance'?" in info.value.message


def test_unknown_key_suggests_spelling():
    error = refused(EXAMPLE.replace("backward: 2.0", "backwrad: 2.0"))
    assert error.keypath == "friction.backwrad"
    assert "did you mean 'backward'?" in error.message
    error = refused(EXAMPLE.replace("period:", "periode:"))
    assert error.keypath == "periode" and "did you mean 'period'?" in error.message


def test_missing_key():
    error = refused(EXAMPLE.replace("stiffness: 10.0\n", ""))
    assert error.keypath == "stiffness" and "required" in error.message


def test_boolean_is_not_a_number():
    error = refused(EXAMPLE.replace("period: 1.0", "period: yes"))
    assert error.keypath == "period"
    assert "expected a positive number" in error.message and "boolean (true)" in error.message
    error = refused(EXAMPLE.replace("amplitude: 0.3, phase: 0.25", "amplitude: false, phase: 0.25"))
    assert error.keypath == "links[1].amplitude" and "expected a number" in error.message


def test_friction_entry_of_wrong_type():
    error = refused(EXAMPLE.replace("forward: 1.0", "forward: fast"))
    assert error.keypath == "friction.forward"
    assert "expected a number or a signal mapping with 'kind'" in error.message


@pytest.mark.parametrize(
    "old, new, keypath, phrase",
    [
        ("  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.5}\n", "", "links", "expected 3 link signals"),
        ("stiffness: 10.0", "stiffness: [10, 10]", "stiffness", "expected 3 stiffness values"),
        (
            "friction: {forward: 1.0, backward: 2.0}",
            "friction: [{forward: 1.0, backward: 2.0}]",
            "friction",
            "expected 4 friction mappings",
        ),
        ("positions: [0.0, 1.3, 2.3, 3.0]", "positions: [0.0, 1.3, 2.3]", "initial.positions", "expected 4 positions"),
    ],
)
def test_wrong_counts(old, new, keypath, phrase):
    error = refused(EXAMPLE.replace(old, new))
    assert error.keypath == keypath and phrase in error.message


@pytest.mark.parametrize(
    "old, new, keypath",
    [
        ("stiffness: 10.0", "stiffness: 0", "stiffness"),
        ("stiffness: 10.0", "stiffness: [10, -1, 10]", "stiffness[1]"),
        ("period: 1.0", "period: -1.0", "period"),
        ("blocks: 4", "blocks: 1", "blocks"),
    ],
)
def test_non_positive_parameters(old, new, keypath):
    error = refused(EXAMPLE.replace(old, new))
    assert error.keypath == keypath and "expected" in error.message


def test_non_positive_friction_names_minimum_and_time():
    error = refused(EXAMPLE.replace("forward: 1.0", "forward: {kind: cosine, mean: 1.0, amplitude: 1.2}"))
    assert error.keypath == "friction.forward"
    assert "friction must be positive (mu > 0" in error.message
    assert "its minimum is -0.2 at t = 0.5 T" in error.message
    text = EXAMPLE.replace(
        "friction: {forward: 1.0, backward: 2.0}",
        "friction:\n"
        + "  - {forward: 1.0, backward: 2.0}\n" * 2
        + "  - {forward: 1.0, backward: {kind: piecewise-linear, times: [0, 0.25, 1], values: [1, -0.2, 1]}}\n"
        + "  - {forward: 1.0, backward: 2.0}\n",
    )
    error = refused(text)
    assert error.keypath == "friction[2].backward"
    assert "its minimum is -0.2 at t = 0.25 T" in error.message
    error = refused(EXAMPLE.replace("backward: 2.0", "backward: 0"))
    assert error.keypath == "friction.backward" and "its minimum is 0 at t = 0 T" in error.message


def test_non_periodic_piecewise_linear():
    error = refused(
        EXAMPLE.replace(
            "{kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.0}",
            "{kind: piecewise-linear, times: [0, 0.5, 1], values: [1, 1.3, 1.1]}",
        )
    )
    assert error.keypath == "links[0].values" and "must be periodic" in error.message


@pytest.mark.parametrize(
    "times, keypath, phrase",
    [
        ("[0, 0.5, 0.4, 1]", "links[0].times[2]", "strictly increasing"),
        ("[0.1, 0.5, 0.7, 1]", "links[0].times[0]", "expected 0"),
        ("[0, 0.5, 0.7, 0.9]", "links[0].times[3]", "expected 1"),
    ],
)
def test_bad_piecewise_linear_times(times, keypath, phrase):
    error = refused(
        EXAMPLE.replace(
            "{kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.0}",
            f"{{kind: piecewise-linear, times: {times}, values: [1.3, 1, 1.2, 1.3]}}",
        )
    )
    assert error.keypath == keypath and phrase in error.message


def test_yaml_syntax_error_has_line_and_column():
    error = refused(EXAMPLE.replace("blocks: 4", "blocks: [4"))
    assert error.keypath == ""
    assert "YAML syntax error at line" in error.message and "column" in error.message


def test_duplicate_key_is_refused():
    error = refused(EXAMPLE + "period: 2.0\n")
    assert "duplicate key 'period'" in error.message and "line 14" in error.message


def test_missing_file(tmp_path):
    with pytest.raises(GaitError) as info:
        load_gait(tmp_path / "none.yaml")
    assert "no such gait file" in info.value.message


def test_inadmissible_initial_state_names_block_and_excess():
    error = refused(EXAMPLE.replace("positions: [0.0, 1.3, 2.3, 3.0]", "positions: [0.0, 1.3, 2.0, 3.0]"))
    assert error.keypath == "initial.positions"
    assert "block 2" in error.message and "at t = 0" in error.message
    assert "f_2 = -3 is below the backward friction limit -mu_2^- = -2 by 1" in error.message
    error = refused(EXAMPLE.replace("positions: [0.0, 1.3, 2.3, 3.0]", "positions: [0.0, 1.6, 2.3, 3.0]"))
    assert "block 1 is not held" in error.message
    assert "f_1 = 3 exceeds the forward friction limit mu_1^+ = 1 by 2" in error.message


def test_admissibility_violation_accepts_small_stress():
    gait = parse_gait(EXAMPLE)
    assert admissibility_violation(gait, [0.0, 1.35, 2.3, 3.0]) is None
    message = admissibility_violation(gait, [0.0, 1.45, 2.3, 3.0])
    assert "block 1" in message and "mu_1^+ = 1 by 0.5" in message


def test_uniqueness_isotropic_even_blocks_refused():
    text = EXAMPLE.replace("blocks: 4", "blocks: 2").replace("backward: 2.0", "backward: 1.0")
    text = text.replace("initial: {positions: [0.0, 1.3, 2.3, 3.0]}\n", "")
    text = text.replace("  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.25}\n", "")
    text = text.replace("  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.5}\n", "")
    error = refused(text.replace("period: 1.0", "period: 2.0"))
    assert error.keypath == "friction"
    assert "uniqueness condition violated: for J = {1} (forward) and the rest {2} (backward)" in error.message
    assert "for t in [0, 2] (a whole interval)" in error.message


def test_uniqueness_mu1_plus_equals_mu2_minus_on_part_of_the_period():
    doc = parse_gait(EXAMPLE).document
    doc = dict(
        doc,
        blocks=2,
        links=[1.0],
        initial={"positions": [0.0, 1.0]},
        friction=[
            {"forward": {"kind": "steps", "times": [0, 0.5], "values": [1.0, 3.0]}, "backward": 2.0},
            {"forward": 5.0, "backward": 1.0},
        ],
    )
    with pytest.raises(GaitError) as info:
        gait_from_document(dict(doc, period=4.0), "doc")
    assert info.value.keypath == "friction"
    assert "J = {1} (forward) and the rest {2} (backward)" in info.value.message
    assert "for t in [0, 2] (a whole interval)" in info.value.message


@pytest.mark.parametrize("blocks, forward, backward", [(4, 1.0, 2.0), (3, 1.0, 1.0)])
def test_uniqueness_passes(blocks, forward, backward):
    doc = {
        "blocks": blocks,
        "period": 1.0,
        "stiffness": 1.0,
        "links": [1.0] * (blocks - 1),
        "friction": {"forward": forward, "backward": backward},
    }
    gait = gait_from_document(doc, "doc")
    assert uniqueness_violation(gait) is None


def test_uniqueness_allows_isolated_zero_crossings():
    doc = {
        "blocks": 2,
        "period": 1.0,
        "stiffness": 1.0,
        "links": [1.0],
        "friction": [
            {"forward": {"kind": "cosine", "mean": 2.0, "amplitude": 1.0}, "backward": 1.0},
            {"forward": 1.5, "backward": 2.0},
        ],
    }
    assert uniqueness_violation(gait_from_document(doc, "doc")) is None


def test_uniqueness_twenty_blocks():
    doc = {
        "blocks": 20,
        "period": 1.0,
        "stiffness": 1.0,
        "links": [1.0] * 19,
        "friction": {"forward": 1.0, "backward": 1.0},
    }
    with pytest.raises(GaitError) as info:
        gait_from_document(doc, "doc")
    assert "J = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10} (forward)" in info.value.message


def test_unknown_gait_kind():
    error = refused(EXAMPLE.replace("kind: crawler", "kind: crawlr"))
    assert error.keypath == "kind" and "did you mean 'crawler'?" in error.message


def test_stiffness_ratios_too_wide_to_certify_are_refused_with_the_reason():
    """(k_max / k_min) N^2 bounds the condition number of the Gram matrices B_A K B_A^T."""
    error = refused(EXAMPLE.replace("stiffness: 10.0", "stiffness: [1e-8, 1e8, 1]"))
    assert error.keypath == "stiffness"
    assert "k_max / k_min = 1e+16" in error.message and "(k_max / k_min) N^2 = 1.6e+17" in error.message
    assert "above the 1e+12" in error.message and "uniqueness" not in error.message


def test_stiffness_ratio_1e6_with_40_blocks_is_accepted():
    n = 40
    doc = {
        "blocks": n,
        "period": 1.0,
        "stiffness": [10.0 ** (6 * i / (n - 2)) for i in range(n - 1)],
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.2, "phase": i / n} for i in range(n - 1)],
        "friction": {"forward": 1.0, "backward": 2.5},
    }
    gait = gait_from_document(doc, "doc")
    assert gait.stiffness.max() / gait.stiffness.min() == pytest.approx(1e6)


@pytest.mark.parametrize(
    "old, new, keypath, phrase",
    [
        ("blocks: 4", "blocks: 1e308", "blocks", "magnitude at most 1e+100"),
        ("blocks: 4", "blocks: 100001", "blocks", "an integer from 2 to 100,000"),
        ("period: 1.0", "period: 1e10", "period", "from 1e-09 to 1e+09"),
        ("period: 1.0", "period: 1e-12", "period", "from 1e-09 to 1e+09"),
        ("phase: 0.5}", "phase: 2e6}", "links[2].phase", "at most 1e+06 in magnitude"),
        (
            "mean: 1.0, amplitude: 0.3, phase: 0.0",
            "mean: 1e101, amplitude: 0.3",
            "links[0].mean",
            "magnitude at most 1e+100",
        ),
        (
            "steps_per_period: 1000,",
            "steps_per_period: 1000000000,",
            "simulation.steps_per_period",
            "from 1 to 100,000,000",
        ),
        ("max_periods: 1000,", "max_periods: 10000000,", "simulation.max_periods", "from 1 to 1,000,000"),
    ],
)
def test_bounds_are_refused_naming_the_key(old, new, keypath, phrase):
    error = refused(EXAMPLE.replace(old, new))
    assert error.keypath == keypath and phrase in error.message


def test_list_bounds_are_checked_before_the_items():
    coefficients = ", ".join(["0"] * 1001)
    error = refused(
        EXAMPLE.replace(
            "{kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.0}",
            f"{{kind: fourier, mean: 1.0, cos: [{coefficients}]}}",
        )
    )
    assert error.keypath == "links[0].cos"
    assert "expected at most 1,000 entries" in error.message and "got 1,001" in error.message


@pytest.mark.parametrize(
    "text, phrase",
    [
        ("a: " + "[" * 40 + "]" * 40, "nesting deeper than 32 levels"),
        ("a: &a [*a]", "recursive alias *a"),
        (
            "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
            + "".join(f"{x}: &{x} [" + ", ".join([f"*{p}"] * 10) + "]\n" for p, x in zip("abcdef", "bcdefg")),
            "more than 2,000,000 values once its aliases are expanded",
        ),
        ("blocks: " + "9" * 4400, "an integer of 4,400 digits; at most 4,300 are read"),
    ],
)
def test_yaml_refused_before_it_is_built(text, phrase):
    error = refused(text)
    assert error.keypath == "" and phrase in error.message


def test_aliases_that_expand_moderately_are_fine():
    """Sharing one signal across links is what anchors are for."""
    text = EXAMPLE.replace(
        "links:\n  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.0}\n"
        "  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.25}\n"
        "  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.5}\n",
        "links: [&w {kind: cosine, mean: 1.0, amplitude: 0.3}, *w, *w]\n",
    )
    text = text.replace("initial: {positions: [0.0, 1.3, 2.3, 3.0]}\n", "")
    gait = parse_gait(text)
    assert gait.links[0] == gait.links[2] == Cosine(mean=1.0, amplitude=0.3)


def test_gait_files_are_read_with_a_size_limit(tmp_path):
    import os

    from crawlsim.gait.yamlsafe import read_limited

    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * 100 + "\n")
    with pytest.raises(GaitError, match="larger than 50 bytes"):
        read_limited(big, limit=50)
    assert read_limited(big, limit=103) == "# " + "x" * 100 + "\n"
    for special, phrase in (("/dev/zero", "is a device"), (str(tmp_path), "is a folder")):
        with pytest.raises(GaitError, match=phrase):
            load_gait(special)
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    with pytest.raises(GaitError, match="the document is empty"):  # no writer: end of file
        load_gait(fifo)
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"blocks: \xff\xfe\n")
    with pytest.raises(GaitError, match="is not UTF-8 text"):
        load_gait(binary)


def test_dotted_paths_are_below_the_document_no_cycle():
    """`crawlsim.gait.docpaths` edits documents only: importing it loads no gait kind, and
    `Gait.replace` validates with the crawler's own schema and builder (no function-level
    import dodging a cycle)."""
    import subprocess
    import sys

    code = "import sys, crawlsim.gait.docpaths; print(sorted(m for m in sys.modules if m.startswith('crawlsim.gait.')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "crawlsim.gait.docpaths" in out
    assert "crawlsim.gait.document" not in out and "crawlsim.gait.crawler_spec" not in out
    gait = load_gait(GAITS / "inching-2.yaml")
    changed = gait.replace("links.0.amplitude", 0.25)
    assert changed.links[0].amplitude == 0.25 and gait.links[0].amplitude == 0.3
    assert changed.source == f"{gait.source} with links.0.amplitude=0.25"


# -- a wave of links: links: {wave: SIGNAL, phase_step: CYCLES} -----------------------------------
WAVE = {
    "blocks": 4,
    "period": 1.0,
    "stiffness": 10.0,
    "links": {"wave": {"kind": "cosine", "mean": 1.0, "amplitude": 0.3}, "phase_step": 0.3333333333333333},
    "friction": {"forward": 1.0, "backward": 2.0},
}


def test_a_wave_is_the_links_it_stands_for():
    """Link i follows the wave with phase i * phase_step modulo 1, in decimal as written: the
    wave of peristalsis-4 gives its three links exactly (2 x 0.3333333333333333 is the double
    0.6666666666666666 as typed); a step of -0.1 gives link 7 the phase 0.3 (7 x -0.1 in binary
    is -0.7000000000000001, whose remainder would be 0.29999999999999993); a constant wave is
    the constant on every link; the wave's own phase shifts them all."""
    from crawlsim.gait.docpaths import wave_links

    assert load_gait(GAITS / "peristalsis-4.yaml").links == gait_from_document(WAVE, "wave").links
    phases = [link["phase"] for link in wave_links({"wave": {"kind": "cosine", "phase": 0.05}, "phase_step": -0.1}, 12)]
    assert phases == [0.05, 0.95, 0.85, 0.75, 0.65, 0.55, 0.45, 0.35, 0.25, 0.15, 0.05, 0.95]
    assert wave_links({"wave": {"kind": "cosine"}, "phase_step": -0.1}, 8)[7]["phase"] == 0.3
    assert wave_links({"wave": 1.5, "phase_step": 0.2}, 3) == [1.5, 1.5, 1.5]
    assert wave_links({"wave": {"kind": "cosine"}}, 2) == [{"kind": "cosine", "phase": 0.0}] * 2


@pytest.mark.parametrize(
    "links, keypath, phrase",
    [
        ({"wave": {"kind": "cosine", "mean": 1.0, "amplitude": "x"}}, "links.wave.amplitude", "expected"),
        ({"wave": {"kind": "cosine", "mean": 1.0}, "phasestep": 0.1}, "links.phasestep", "did you mean 'phase_step'?"),
        ({"phase_step": 0.1}, "links.wave", "required key is missing"),
        ({"wave": 1.0, "phase_step": "x"}, "links.phase_step", "a number of cycles"),
        (5, "links", "or a wave {wave: SIGNAL, phase_step: CYCLES}"),
    ],
)
def test_a_bad_wave_is_refused_naming_its_key(links, keypath, phrase):
    with pytest.raises(GaitError) as error:
        gait_from_document({**WAVE, "links": links}, "g.yaml")
    assert error.value.keypath == keypath and phrase in error.value.message, str(error.value)


def test_paths_into_a_wave_and_into_the_links_it_generates():
    """links.wave.NUMBER and links.phase_step are the wave's own numbers: every link moves, the
    file stays a wave. links.I.NUMBER and links.*.NUMBER name the generated links: the links are
    written out and that number alone moves. Both at once, in either order: the wave's first,
    then the link's (crawlsim.gait.docpaths)."""
    gait = gait_from_document(WAVE, "wave")
    wider = gait.replace("links.wave.amplitude", 0.2)
    assert wider.document["links"]["wave"]["amplitude"] == 0.2 and {s.amplitude for s in wider.links} == {0.2}
    lag = gait.replace("links.phase_step", 0.25)
    assert [s.phase for s in lag.links] == [0.0, 0.25, 0.5]
    one = gait.replace("links.1.phase", 0.5)
    assert isinstance(one.document["links"], list) and [s.phase for s in one.links] == [0.0, 0.5, 0.6666666666666666]
    every = gait.replace("links.*.amplitude", 0.1)
    assert every.links == gait.replace("links.wave.amplitude", 0.1).links
    for pairs in (
        ("links.2.amplitude", 0.1, "links.wave.amplitude", 0.2),
        ("links.wave.amplitude", 0.2, "links.2.amplitude", 0.1),
    ):
        assert [s.amplitude for s in gait.replace(*pairs).links] == [0.2, 0.2, 0.1]
    with pytest.raises(GaitError, match="out of range"):
        gait.replace("links.3.phase", 0.5)
