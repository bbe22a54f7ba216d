"""The uniqueness condition decided exactly at any N (crawlsim.gait.uniqueness, docs/model.md §3).

g_J(t) = sum_{j in J} mu_j^+(t) - sum_{j not in J} mu_j^-(t) must not vanish on an interval for
any subset J of blocks (J = all and J = none included). The tests use friction values that are
exact in binary (small integers, or multiples of 2^-20), so that g_J is computed without
roundoff and "vanishes" means exactly zero: every J reported is checked in exact rational
arithmetic, and every "no violation" is proved by a residue argument.
"""

import itertools
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from crawlsim.errors import GaitError
from crawlsim.gait.document import gait_from_document
from crawlsim.gait.signals import Constant, Cosine
from crawlsim.gait.uniqueness import UniquenessUndecidable, find_violation


def wave(n, forward=1.0, backward=2.0, **simulation):
    """An n-block peristaltic wave with uniform friction."""
    doc = {
        "blocks": n,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.2, "phase": i / n} for i in range(n - 1)],
        "friction": {"forward": forward, "backward": backward},
    }
    if simulation:
        doc["simulation"] = simulation
    return doc


def exact_g(forward, backward, subset):
    """g_J in exact rational arithmetic (the floats' own values)."""
    return sum(Fraction(float(f)) for f, s in zip(forward, subset) if s) - sum(
        Fraction(float(b)) for b, s in zip(backward, subset) if not s
    )


def blocks(indices):
    return "{" + ", ".join(str(i) for i in indices) + "}"


@pytest.mark.parametrize("n", [21, 30, 60, 120])
def test_waves_with_forward_1_backward_2_are_refused_naming_the_subset(n):
    """|J| mu^+ - (N - |J|) mu^- = |J| - 2 (N - |J|) = 0 exactly when |J| = 2N/3, an integer for
    N divisible by 3: the first 2N/3 blocks forward and the rest backward is such a J."""
    with pytest.raises(GaitError) as info:
        gait_from_document(wave(n), "wave.yaml")
    k = 2 * n // 3
    assert info.value.keypath == "friction"
    assert (
        f"for J = {blocks(range(1, k + 1))} (forward) and the rest {blocks(range(k + 1, n + 1))} (backward)"
    ) in info.value.message
    assert "for t in [0, 1] (a whole interval)" in info.value.message


@pytest.mark.parametrize("n", [20, 22, 100, 1000])
def test_waves_without_an_integer_solution_pass(n):
    """3|J| = 2N has no integer solution |J| when 3 does not divide N."""
    if n % 3 == 0:
        pytest.skip("3 divides N")
    assert find_violation([Constant(1.0)] * n, [Constant(2.0)] * n) is None


def test_subset_all_and_subset_none_are_checked():
    """J = all blocks: g = sum mu^+ > 0, but 1e-308 next to mu^- = 1 is zero to roundoff, and the
    run could not tell it from zero either; symmetrically for J = none."""
    with pytest.raises(GaitError) as info:
        gait_from_document(wave(4, forward=1e-308), "g.yaml")
    assert "for J = {1, 2, 3, 4} (forward) and the rest {} (backward)" in info.value.message
    with pytest.raises(GaitError) as info:
        gait_from_document(wave(4, backward=1e-300), "g.yaml")
    assert "for J = {} (forward) and the rest {1, 2, 3, 4} (backward)" in info.value.message


def dyadic(rng, n):
    """Friction values in [0.5, 2], multiples of 2^-20: their sums are exact in binary."""
    return rng.integers(2**19, 2**21, size=n) / 2.0**20


@pytest.mark.parametrize("n, seed", [(5, 0), (12, 1), (21, 2), (30, 3), (40, 4)])
def test_planted_violation_is_found_and_is_exact(n, seed):
    """Plant J: set one backward coefficient outside J so that g_J = 0 exactly. Whatever subset
    the search reports must have g_J = 0 in exact arithmetic (the values are dyadic, so a sum
    within the roundoff band of zero is zero)."""
    rng = np.random.default_rng(seed)
    forward, backward = dyadic(rng, n), dyadic(rng, n)
    planted = np.zeros(n, dtype=bool)
    planted[rng.permutation(n)[: (2 * n) // 3]] = True
    k = np.flatnonzero(~planted)[0]
    backward[k] = 0.0
    backward[k] = forward[planted].sum() - backward[~planted].sum()
    assert backward[k] > 0 and exact_g(forward, backward, planted) == 0
    found = find_violation([Constant(f) for f in forward], [Constant(b) for b in backward])
    assert found is not None
    assert exact_g(forward, backward, found.subset) == 0
    assert found.intervals == ((0.0, 1.0),)


def with_residue(forward, backward):
    """Make block 1 contribute 2^-21 (in J) or -2^-22 (not in J) modulo 2^-20 to every g_J.

    All other values are multiples of 2^-20, so every g_J is then nonzero modulo 2^-20:
    no subset can vanish, which the search must find out over all 2^N subsets."""
    forward[0] += 2.0**-21
    backward[0] += 2.0**-22


@pytest.mark.parametrize("n, seed", [(8, 5), (21, 6), (33, 7), (40, 8)])
def test_no_violation_when_every_sum_misses_zero_by_a_residue(n, seed):
    rng = np.random.default_rng(seed)
    forward, backward = dyadic(rng, n), dyadic(rng, n)
    with_residue(forward, backward)
    assert find_violation([Constant(f) for f in forward], [Constant(b) for b in backward]) is None


@given(st.lists(st.tuples(st.integers(1, 4), st.integers(1, 4)), min_size=2, max_size=11))
@example([(1, 1), (1, 1)])
@example([(1, 2), (2, 1), (3, 3)])
def test_small_integer_friction_agrees_with_enumerating_every_subset(pairs):
    """With integer friction, g_J is an exact integer: enumerate all 2^N subsets."""
    forward = [float(f) for f, _ in pairs]
    backward = [float(b) for _, b in pairs]
    expected = any(
        exact_g(forward, backward, subset) == 0 for subset in itertools.product([False, True], repeat=len(pairs))
    )
    found = find_violation([Constant(f) for f in forward], [Constant(b) for b in backward])
    assert (found is not None) == expected
    if found is not None:
        assert exact_g(forward, backward, found.subset) == 0


def test_many_blocks_with_commensurate_friction_are_checked_exactly():
    """300 blocks with integer forward friction 1..5 and backward 7: sum_J (8 + j mod 5) = 2100
    has solutions (60 blocks of each kind reach 3000), and every reported J is exact. With
    block 1 at forward 1.5 and backward 7.25, its contribution to g_J is 1/2 or -1/4 modulo 1,
    so nothing vanishes. The partial sums collapse to a few thousand integers, so 2^300 subsets
    are decided in a few merges of short lists."""
    n = 300
    forward = [float(1 + j % 5) for j in range(n)]
    backward = [7.0] * n
    found = find_violation([Constant(f) for f in forward], [Constant(b) for b in backward])
    assert found is not None and exact_g(forward, backward, found.subset) == 0
    forward[0], backward[0] = 1.5, 7.25
    assert find_violation([Constant(f) for f in forward], [Constant(b) for b in backward]) is None


def test_time_varying_friction_vanishing_on_part_of_the_period():
    """24 identical blocks, mu^+ = 1 on [0, 1/2) and 3 on [1/2, 1), mu^- = 2. On the first half
    a_j = 3 and R = 48: |J| = 16 solves 3|J| = 48; on the second half a_j = 5, and 5|J| = 48
    has no integer solution. So g_J vanishes on [0, T/2] only (T = 4 here)."""
    doc = wave(24, forward={"kind": "steps", "times": [0, 0.5], "values": [1.0, 3.0]})
    doc["period"] = 4.0
    with pytest.raises(GaitError) as info:
        gait_from_document(doc, "steps.yaml")
    assert f"for J = {blocks(range(1, 17))} (forward)" in info.value.message
    assert "for t in [0, 2] (a whole interval)" in info.value.message


def test_cosine_friction_shared_by_two_directions_vanishes_everywhere():
    """mu_1^+ = mu_2^- = 1 + 0.5 cos(2 pi u): J = {1} gives g = mu_1^+ - mu_2^- = 0 for all t,
    even though each coefficient varies."""
    varying = Cosine(mean=1.0, amplitude=0.5, phase=0.1)
    found = find_violation([varying, Constant(3.0)], [Constant(2.0), varying])
    assert found is not None and found.subset.tolist() == [True, False]
    assert found.intervals == ((0.0, 1.0),)


def test_cosine_friction_crossing_zero_at_isolated_times_passes():
    """g_J = 1 + 0.5 cos(2 pi u) - 1.25 (J = {1}) vanishes only where cos = 1/2: two instants,
    not an interval; no other J vanishes (g_J > 0 for J = {1, 2}, < 0 for J = {}, and
    J = {2}: 3 - 2 = 1)."""
    found = find_violation([Cosine(mean=1.0, amplitude=0.5), Constant(3.0)], [Constant(2.0), Constant(1.25)])
    assert found is None


def test_forty_distinct_cosine_blocks_are_within_the_bounds():
    """Per-block cosine friction with 40 distinct phases: 2^20 sums of 4 samples per half, the
    largest search the bounds allow, with no two blocks alike. With no breakpoints g_J is a
    trigonometric polynomial of degree 1 on the whole cycle, so vanishing on an interval means
    vanishing identically, mean included; the means carry the residue of `with_residue`, so no
    J can vanish, and the search must complete and say so."""
    rng = np.random.default_rng(9)
    n = 40
    means, backward = dyadic(rng, n), dyadic(rng, n)
    with_residue(means, backward)
    forward = [Cosine(mean=m + 0.5, amplitude=0.25, phase=p) for m, p in zip(means, rng.random(n))]
    assert find_violation(forward, [Constant(b) for b in backward]) is None


def test_beyond_the_bounds_refused_unless_the_file_opts_in():
    """50 blocks of distinct, incommensurate friction: 2^25 sums per half exceed the bound, so
    the file is refused with the reason, unless it sets unchecked_uniqueness."""
    rng = np.random.default_rng(11)
    n = 50
    doc = wave(n)
    doc["friction"] = [
        {"forward": float(f), "backward": float(b)} for f, b in zip(rng.uniform(1, 2, n), rng.uniform(2, 3, n))
    ]
    with pytest.raises(GaitError) as info:
        gait_from_document(doc, "wide.yaml")
    assert info.value.keypath == "friction"
    assert "beyond an exact check" in info.value.message
    assert "unchecked_uniqueness: true" in info.value.message
    with pytest.raises(UniquenessUndecidable):
        find_violation(
            [Constant(f["forward"]) for f in doc["friction"]], [Constant(f["backward"]) for f in doc["friction"]]
        )
    doc["simulation"] = {"unchecked_uniqueness": True}
    gait = gait_from_document(doc, "wide.yaml")
    assert gait.uniqueness_unchecked and gait.simulation.unchecked_uniqueness


def test_opt_in_does_not_skip_a_decidable_violation():
    """unchecked_uniqueness only admits what cannot be checked: a wave that can be checked and
    fails is still refused."""
    with pytest.raises(GaitError) as info:
        gait_from_document(wave(21, unchecked_uniqueness=True), "wave.yaml")
    assert "uniqueness condition violated" in info.value.message
    gait = gait_from_document(wave(22, unchecked_uniqueness=True), "wave.yaml")
    assert not gait.uniqueness_unchecked


def test_thousand_identical_blocks_are_n_plus_one_candidates():
    """All blocks alike: only |J| matters. mu^+ = 1, mu^- = 1.5: |J| = 1.5 (1000 - |J|) / 1 has
    the solution |J| = 600."""
    found = find_violation([Constant(1.0)] * 1000, [Constant(1.5)] * 1000)
    assert found is not None and found.subset.sum() == 600 and found.subset[:600].all()


@given(
    st.lists(st.lists(st.sampled_from([0.0, -0.0, 1.0, 2.5, -1.0]), min_size=3, max_size=3), min_size=1, max_size=25)
)
@example([[0.0, 1.0, 2.5], [-0.0, 1.0, 2.5], [0.0, 1.0, -1.0]])
def test_unique_rows_is_numpys_unique_along_an_axis(rows):
    """`_unique_rows` (the search's grouping of equal samples and equal friction pairs) gives
    np.unique's rows, lexicographic order and inverse, -0.0 and 0.0 one value."""
    from crawlsim.gait.uniqueness import _unique_rows

    x = np.array(rows)
    values, inverse = _unique_rows(x)
    want, want_inverse = np.unique(x, axis=0, return_inverse=True)
    assert np.array_equal(values, want)
    assert np.array_equal(inverse, np.ravel(want_inverse))
    assert np.array_equal(values[inverse], x)


def test_key_weights_are_a_fixed_sequence():
    """The search's hash multipliers are odd and below 2^63, its key weights in [1, 2), and both
    the same in every process (SplitMix64 from a fixed seed: its first word from seed 0 is
    0xE220A8397B1DCDAF, the published reference value)."""
    from crawlsim.gait import uniqueness

    words = uniqueness._hash_words()
    assert words.dtype == np.uint64 and len(np.unique(words)) == 64
    assert np.all(words & np.uint64(1)) and np.all(words < np.uint64(1 << 63))
    seed = uniqueness._KEY_WEIGHTS_SEED
    try:
        uniqueness._KEY_WEIGHTS_SEED = 0
        assert int(uniqueness._splitmix64(1)[0]) == 0xE220A8397B1DCDAF
    finally:
        uniqueness._KEY_WEIGHTS_SEED = seed


def test_a_tie_within_roundoff_is_reported_as_what_it_is():
    """0.1 + 0.2 - 0.3 is 5.6e-17 in double precision, not 0: J = {1, 2} with the rest {3} is a
    tie of the file's decimals, which the refusal reports as within roundoff of one (it said
    "= 0"), 3.7e-17 of the friction's sum 1.5; an exact tie in binary still says "= 0"."""
    doc = wave(3)
    doc["friction"] = [
        {"forward": 0.1, "backward": 0.2},
        {"forward": 0.2, "backward": 0.4},
        {"forward": 0.3, "backward": 0.3},
    ]
    with pytest.raises(GaitError) as info:
        gait_from_document(doc, "near.yaml")
    message = info.value.message
    assert "J = {1, 2} (forward) and the rest {3} (backward)" in message
    assert "sum mu- over the rest is within 1e-16 of a tie (3.7e-17 of the sum of the friction" in message
    with pytest.raises(GaitError, match=r"over the rest = 0 for t in \[0, 1\]"):
        gait_from_document(wave(2, forward=2.0, backward=2.0), "tie.yaml")


def step_switched_parity(n: int) -> dict:
    """n blocks of friction switched by steps, written with three decimals, each block's own:
    every mu^+ + mu^- an even number of thousandths and sum mu^- an odd one on every piece
    (block 1 carries an odd thousandth both ways), so no g_J vanishes, by parity."""

    def steps(start, first, step, j):
        odd = 0.001 if j == 0 else 0.0
        values = [round(first + step * j + odd, 3), round(first + 0.1 + step * j + odd, 3)]
        return {"kind": "steps", "times": [0.0, round(start + 0.01 * (j % 37), 3)], "values": values}

    doc = wave(n)
    doc["friction"] = [{"forward": steps(0.3, 0.4, 0.002, j), "backward": steps(0.31, 0.6, 0.004, j)} for j in range(n)]
    return doc


def test_step_switched_decimals_are_decided_on_whole_numbers(monkeypatch):
    """39 blocks of distinct three-decimal friction switched by steps (about 70 pieces of time):
    each piece is decided on whole numbers of thousandths, so the search over subsets (2^19
    sums a half, a third of a second a piece) never runs, and the gait is valid. A file's
    friction was checked piece by piece that way for 42 s."""
    import crawlsim.gait.uniqueness as uniqueness

    searched = []
    search = uniqueness._search_piece
    monkeypatch.setattr(uniqueness, "_search_piece", lambda *args: searched.append(1) or search(*args))
    gait = gait_from_document(step_switched_parity(39), "steps.yaml")
    assert gait.blocks == 39 and searched == []
    assert find_violation(gait.forward, gait.backward) is None and searched == []


@given(st.lists(st.tuples(st.integers(1, 999), st.integers(1, 999)), min_size=2, max_size=9))
@example([(100, 200), (200, 400), (300, 300)])
def test_three_decimal_friction_agrees_with_enumerating_every_subset(pairs):
    """Friction of three decimals (thousandths from the integers drawn): violated exactly when
    some subset's g_J is 0 in thousandths (enumerated in integers), whatever its roundoff."""
    forward = [Constant(f / 1000) for f, _ in pairs]
    backward = [Constant(b / 1000) for _, b in pairs]
    tie = any(
        sum(f for (f, _), s in zip(pairs, subset) if s) == sum(b for (_, b), s in zip(pairs, subset) if not s)
        for subset in itertools.product([False, True], repeat=len(pairs))
    )
    assert (find_violation(forward, backward) is not None) == tie


@given(
    st.lists(st.tuples(st.floats(0.5, 1e4), st.integers(1, 3)), min_size=1, max_size=8),
    st.floats(0.0, 1e5),
)
def test_nearest_subset_sum_is_the_nearest_to_half_a_unit(items, target):
    """`nearest_subset_sum`: within 1/2 (the unit of its values) of the nearest sum of counts
    0 <= c_g <= n_g, enumerated."""
    from crawlsim.gait.uniqueness import nearest_subset_sum

    values, sizes = np.array([v for v, _ in items]), np.array([n for _, n in items])
    nearest = min(
        abs(sum(c * v for c, v in zip(counts, values)) - target)
        for counts in itertools.product(*[range(n + 1) for n in sizes])
    )
    assert abs(nearest_subset_sum(values, sizes, target) - nearest) <= 0.5
