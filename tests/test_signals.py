import numpy as np
import pytest

from crawlsim.errors import GaitError
from crawlsim.gait.signals import (
    Constant,
    Cosine,
    Fourier,
    PiecewiseLinear,
    Steps,
    evaluate_many,
    parse_signal,
    union_breakpoints,
)


def parse(value):
    return parse_signal(value, "links[0]", "g.yaml")


def test_constant_is_a_plain_number():
    s = parse(2.5)
    assert s == Constant(2.5)
    np.testing.assert_array_equal(s(np.array([0.0, 0.3, 7.2])), [2.5, 2.5, 2.5])
    np.testing.assert_array_equal(s.rate(np.array([0.1])), [0.0])
    assert s.is_smooth and s.harmonics == 0 and s.breakpoints().size == 0
    assert s.to_dict() == 2.5


def test_cosine_values_and_rate():
    s = parse({"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 0.25})
    u = np.array([0.0, 0.25, 0.5, 1.25, -0.75])
    np.testing.assert_allclose(s(u), [1.0, 1.3, 1.0, 1.3, 1.3], atol=1e-15)
    np.testing.assert_allclose(s.rate(np.array([0.0, 0.5])), [2 * np.pi * 0.3, -2 * np.pi * 0.3], atol=1e-14)
    assert s.is_smooth and s.harmonics == 1
    assert s.minimum() == pytest.approx((0.7, 0.75))


def test_fourier_against_closed_form():
    s = parse({"kind": "fourier", "mean": 1.0, "cos": [0.5], "sin": [0.0, 0.3], "phase": 0.1})
    u = np.linspace(-1.0, 2.0, 31)
    v = u - 0.1
    expected = 1.0 + 0.5 * np.cos(2 * np.pi * v) + 0.3 * np.sin(4 * np.pi * v)
    expected_rate = -np.pi * np.sin(2 * np.pi * v) + 1.2 * np.pi * np.cos(4 * np.pi * v)
    np.testing.assert_allclose(s(u), expected, atol=1e-14)
    np.testing.assert_allclose(s.rate(u), expected_rate, atol=1e-13)
    assert s.harmonics == 2
    grid = np.linspace(0, 1, 200001)
    assert s.minimum()[0] == pytest.approx(np.min(s(grid)), abs=1e-9)


def test_fourier_without_coefficients_is_constant():
    s = parse({"kind": "fourier", "mean": 3.0})
    np.testing.assert_array_equal(s(np.array([0.0, 0.4])), [3.0, 3.0])
    assert s.harmonics == 0


def test_piecewise_linear_interpolates_periodically():
    s = parse({"kind": "piecewise-linear", "times": [0.0, 0.25, 1.0], "values": [1.0, 2.0, 1.0]})
    u = np.array([0.0, 0.125, 0.25, 0.625, 1.125, -0.875, 3.25])
    np.testing.assert_allclose(s(u), [1.0, 1.5, 2.0, 1.5, 1.5, 1.5, 2.0])
    np.testing.assert_allclose(s.rate(np.array([0.1, 0.25, 0.5, 1.0])), [4.0, -4 / 3, -4 / 3, 4.0])
    np.testing.assert_allclose(s.breakpoints(), [0.0, 0.25])
    assert not s.is_smooth and s.harmonics == 0


def test_piecewise_linear_breakpoints_follow_phase_and_skip_collinear_knots():
    s = PiecewiseLinear(times=(0.0, 0.25, 0.5, 1.0), values=(0.0, 1.0, 2.0, 0.0), phase=0.7)
    np.testing.assert_allclose(s.breakpoints(), [0.2, 0.7])
    assert s(np.array([1.2]))[0] == pytest.approx(2.0)


def test_steps_are_right_continuous():
    s = parse({"kind": "steps", "times": [0.0, 0.5], "values": [1.0, 3.0]})
    np.testing.assert_array_equal(s(np.array([0.0, 0.49, 0.5, 0.99, 1.0, 1.5])), [1, 1, 3, 3, 1, 3])
    np.testing.assert_array_equal(s.rate(np.array([0.2, 0.5])), [0.0, 0.0])
    np.testing.assert_allclose(s.breakpoints(), [0.0, 0.5])


def test_steps_jump_landing_on_a_third_after_phase_roundoff():
    phase = 1.0 / 3.0 - 0.05
    assert 1.0 / 3.0 - phase < 0.05
    s = Steps(times=(0.0, 0.05), values=(5.0, 7.0), phase=phase)
    assert s(np.array([1.0 / 3.0]))[0] == 7.0
    assert s(np.array([1.0 / 3.0 - 1e-13]))[0] == 7.0
    assert s(np.array([1.0 / 3.0 - 1e-9]))[0] == 5.0
    assert s(np.array([phase - 1e-13]))[0] == 5.0
    np.testing.assert_allclose(s.breakpoints(), [phase, 1.0 / 3.0])


def test_steps_breakpoints_after_phase_wrap():
    s = Steps(times=(0.0, 0.5), values=(1.0, 2.0), phase=0.75)
    np.testing.assert_allclose(s.breakpoints(), [0.25, 0.75])
    assert s(np.array([0.25]))[0] == 2.0
    assert Steps(times=(0.0,), values=(4.0,)).breakpoints().size == 0


@pytest.mark.parametrize(
    "signal",
    [
        Constant(1.5),
        Cosine(mean=1.0, amplitude=-0.2, phase=0.3),
        Fourier(mean=2.0, cos=(0.1, 0.2), sin=(0.3,), phase=0.05),
        PiecewiseLinear(times=(0.0, 0.4, 1.0), values=(1.0, 0.5, 1.0), phase=0.2),
        Steps(times=(0.0, 0.6), values=(1.0, 2.0), phase=0.5),
    ],
)
def test_to_dict_round_trips(signal):
    assert parse(signal.to_dict()) == signal


def test_evaluate_many_shape():
    u = np.array([0.0, 0.25, 0.5])
    out = evaluate_many([Constant(1.0), Cosine(mean=0.0, amplitude=1.0)], u)
    assert out.shape == (3, 2)
    np.testing.assert_allclose(out[:, 1], [1.0, 0.0, -1.0], atol=1e-15)


def test_union_breakpoints_merges_and_wraps():
    merged = union_breakpoints([np.array([0.5, 1.0 - 1e-14]), np.array([0.5 + 1e-14, 0.25])])
    np.testing.assert_allclose(merged, [0.0, 0.25, 0.5])


@pytest.mark.parametrize(
    "value, keypath, phrase",
    [
        (True, "links[0]", "expected a number or a signal mapping with 'kind', got a boolean (true)"),
        ({"kind": "cosin", "mean": 1}, "links[0].kind", "did you mean 'cosine'?"),
        ({"kind": "cosine", "mean": 1, "amplitud": 1}, "links[0].amplitud", "did you mean 'amplitude'?"),
        ({"kind": "cosine", "mean": 1}, "links[0].amplitude", "required key is missing"),
        ({"kind": "cosine", "mean": "1", "amplitude": 1}, "links[0].mean", "expected a number"),
        ({"kind": "fourier", "mean": 1, "cos": [1, False]}, "links[0].cos[1]", "got a boolean"),
        ({"kind": "piecewise-linear", "times": [0, 1], "values": [1, 2]}, "links[0].values", "must be periodic"),
        ({"kind": "piecewise-linear", "times": [0, 0.5], "values": [1, 1]}, "links[0].times[1]", "expected 1"),
        ({"kind": "piecewise-linear", "times": [0.1, 1], "values": [1, 1]}, "links[0].times[0]", "expected 0"),
        (
            {"kind": "piecewise-linear", "times": [0, 0.5, 0.5, 1], "values": [1, 2, 3, 1]},
            "links[0].times[2]",
            "strictly increasing",
        ),
        (
            {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": [1, 1]},
            "links[0].values",
            "as many values as times (3)",
        ),
        ({"kind": "steps", "times": [0, 1.0], "values": [1, 2]}, "links[0].times[1]", "expected a time < 1"),
        ({"kind": "steps", "times": [0.2], "values": [1]}, "links[0].times[0]", "expected 0"),
        (float("inf"), "links[0]", "finite"),
    ],
)
def test_invalid_signals(value, keypath, phrase):
    with pytest.raises(GaitError) as info:
        parse(value)
    assert info.value.source == "g.yaml"
    assert info.value.keypath == keypath
    assert phrase in info.value.message


def test_phase_is_reduced_exactly_to_one_cycle():
    """Whole cycles change nothing, and fmod is exact: phase 1000.25 is the signal of phase
    0.25, evaluated without the low bits that u - 1000.25 would lose."""
    far = parse({"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 1000.25})
    near = parse({"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": 0.25})
    assert far == near and far.phase == 0.25
    steps = parse({"kind": "steps", "times": [0, 0.5], "values": [1, 2], "phase": -3.75})
    assert steps.phase == -0.75
    np.testing.assert_allclose(steps.breakpoints(), [0.25, 0.75])


def test_fourier_evaluated_in_chunks_agrees_with_one_pass():
    """Many harmonics times many times are evaluated in bounded chunks: same values."""
    rng = np.random.default_rng(0)
    s = Fourier(mean=0.5, cos=tuple(rng.normal(size=300)), sin=tuple(rng.normal(size=200)), phase=0.1)
    u = np.linspace(0.0, 1.0, 5001)
    v = (u - 0.1)[:, None] * np.arange(1, 301)
    a = np.asarray(s.cos)
    b = np.concatenate([s.sin, np.zeros(100)])
    expected = 0.5 + np.cos(2 * np.pi * v) @ a + np.sin(2 * np.pi * v) @ b
    np.testing.assert_allclose(s(u), expected, atol=1e-10)
    np.testing.assert_allclose(
        s(u[:5000].reshape(50, 100)), expected[:5000].reshape(50, 100), atol=1e-10
    )  # shapes are kept


@pytest.mark.parametrize(
    "value, phrase",
    [
        (1e101, "magnitude at most 1e+100"),
        ({"kind": "cosine", "mean": 1.0, "amplitude": -2e100}, "magnitude at most 1e+100"),
        ({"kind": "cosine", "mean": 1.0, "amplitude": 1.0, "phase": 1e7}, "at most 1e+06 in magnitude"),
        (
            {"kind": "steps", "times": list(np.linspace(0, 0.99, 10001)), "values": [1.0] * 10001},
            "expected at most 10,000 entries",
        ),
    ],
)
def test_signal_bounds(value, phrase):
    with pytest.raises(GaitError) as info:
        parse(value)
    assert phrase in info.value.message
