"""Uniqueness errors that fix themselves in one round (crawlsim.gait.uniqueness_advice): the
refusal lists every violating subset J with its intervals and the smallest change of one
coefficient that restores the condition; applying it, from the message alone, makes the gait
valid. Subsets are checked against a brute force over all 2^N subsets in exact decimal
arithmetic (`fractions.Fraction` of the numbers as written)."""

import re
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.errors import GaitError
from crawlsim.gait.docpaths import edited
from crawlsim.gait.document import gait_from_document
from crawlsim.gait.signals import Constant
from crawlsim.gait.uniqueness import alike_subsets, analyse

SIX = {
    "blocks": 6,
    "period": 2.0,
    "stiffness": 10.0,
    "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.2, "phase": i / 6} for i in range(5)],
    "friction": [
        {"forward": f, "backward": b}
        for f, b in [(1.0, 2.0), (1.0, 2.0), (1.0, 3.0), (2.0, 1.0), (2.0, 1.0), (3.0, 2.0)]
    ],
}
"""Six blocks of anisotropic friction in round numbers, with a_j = mu_j^+ + mu_j^- =
(3, 3, 4, 3, 3, 5) and sum mu^- = 11: g_J = 0 exactly for the six J of a-sum 11, which fall in
three kinds: {1, 2, 6}, {4, 5, 6} and the four {i, k, 6} with i in {1, 2}, k in {4, 5}."""


def brute_force(forward, backward):
    """Every J (a frozenset of 1-based blocks) with sum_J mu+ = sum_rest mu-, exactly."""
    f = [Fraction(repr(float(x))) for x in forward]
    b = [Fraction(repr(float(x))) for x in backward]
    n = len(f)
    return {
        frozenset(j + 1 for j in range(n) if mask >> j & 1)
        for mask in range(1 << n)
        if sum(f[j] for j in range(n) if mask >> j & 1) == sum(b[j] for j in range(n) if not mask >> j & 1)
    }


def thresholds(doc):
    return ([e["forward"] for e in doc["friction"]], [e["backward"] for e in doc["friction"]])


def refusal(doc) -> str:
    with pytest.raises(GaitError) as info:
        gait_from_document(doc, "six.yaml")
    assert info.value.keypath == "friction"
    return info.value.message


CHANGE = re.compile(r"change (\S+) from (\S+) to ([0-9.e+-]+)(?: \(path (\S+)\))?: the smallest")


def apply(doc, change, source):
    """The document with the message's change applied (its dotted path, or its key path)."""
    return edited(doc, [(change[4] or change[1], float(change[3]))], source)


def test_three_violating_subsets_are_all_listed_and_fixed_in_one_round():
    expected = brute_force(*thresholds(SIX))
    assert len(expected) == 6
    message = refusal(SIX)
    assert "anisotropic" not in message
    assert message.startswith(
        "uniqueness condition violated: for J = {1, 2, 6} (forward) and "
        "the rest {3, 4, 5} (backward), sum mu+ over J - sum mu- over the "
        "rest = 0 for t in [0, 2] (a whole interval); and for 2 more "
        "subsets: J = {4, 5, 6} (forward) and the rest {1, 2, 3} (backward) "
        "for t in [0, 2]; J = {1, 4, 6} (forward) and the rest {2, 3, 5} "
        "(backward) (and 3 more subsets that exchange blocks of J for "
        "blocks of the same friction) for t in [0, 2]"
    )
    # the fix, from the message alone: apply it, validate again, and it passes
    change = CHANGE.search(message)
    assert change is not None
    fixed = apply(SIX, change, "six.yaml")
    assert gait_from_document(fixed, "six-fixed.yaml").blocks == 6
    assert brute_force(*thresholds(fixed)) == set()
    changed = [
        (j, d) for j in range(6) for d in ("forward", "backward") if fixed["friction"][j][d] != SIX["friction"][j][d]
    ]
    assert len(changed) == 1  # one coefficient
    j, d = changed[0]
    assert change[1] == f"friction[{j}].{d}" and float(change[2]) == SIX["friction"][j][d]


def test_the_fix_is_the_smallest_on_its_grid():
    """Every change of one coefficient by a smaller step of the 1-2-5 grid (from 1 % of that
    coefficient) leaves some g_J = 0 or a friction <= 0: none restores uniqueness."""
    change = CHANGE.search(refusal(SIX))
    assert change is not None
    step = abs(Decimal(change[3]) - Decimal(change[2]))
    forward, backward = thresholds(SIX)
    smaller = [Decimal(m) * Decimal(10) ** e for e in (-3, -2, -1, 0) for m in (1, 2, 5)]
    tried = 0
    for values in (forward, backward):
        for j in range(6):
            for s in smaller:
                if not (Decimal("0.01") * Decimal(repr(values[j])) <= s < step):
                    continue
                for sign in (1, -1):
                    trial = list(values)
                    trial[j] = float(Decimal(repr(values[j])) + sign * s)
                    f, b = (trial, backward) if values is forward else (forward, trial)
                    assert trial[j] <= 0 or brute_force(f, b), (j, s, sign)
                    tried += 1
    assert tried > 0


def test_a_shared_friction_is_changed_once_for_all_blocks():
    """Six blocks of one friction (forward 1, backward 2): |J| = 2 (6 - |J|) at |J| = 4, the
    C(6, 4) = 15 subsets alike; the fix changes friction.forward or friction.backward."""
    doc = dict(SIX, friction={"forward": 1.0, "backward": 2.0})
    message = refusal(doc)
    assert (
        "for J = {1, 2, 3, 4} (forward) and the rest {5, 6} (backward) (and 14 more subsets "
        "that exchange blocks of J for blocks of the same friction)"
    ) in message
    change = CHANGE.search(message)
    assert change is not None and change[1] in ("friction.forward", "friction.backward")
    fixed = apply(doc, change, "shared.yaml")
    assert gait_from_document(fixed, "fixed.yaml").blocks == 6
    f, b = fixed["friction"]["forward"], fixed["friction"]["backward"]
    assert brute_force([f] * 6, [b] * 6) == set()


def test_steps_friction_names_the_value_and_the_interval():
    """Friction that switches halfway: mu_2^- = 1 on [0, T/2] makes g_{1} = mu_1^+ - mu_2^-
    vanish there only, and the fix is a value of the steps signal or a coefficient of g_{1}."""
    doc = {
        "blocks": 2,
        "period": 4.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3}],
        "friction": [
            {"forward": 1.0, "backward": 2.0},
            {"forward": 1.5, "backward": {"kind": "steps", "times": [0.0, 0.5], "values": [1.0, 3.0]}},
        ],
    }
    message = refusal(doc)
    assert (
        "for J = {1} (forward) and the rest {2} (backward), sum mu+ over J - sum mu- over "
        "the rest = 0 for t in [0, 2] (a whole interval):"
    ) in message
    change = CHANGE.search(message)
    assert change is not None
    assert change[4] in ("friction.0.forward", "friction.1.backward.values.0")
    fixed = apply(doc, change, "steps.yaml")
    assert gait_from_document(fixed, "fixed.yaml").blocks == 2


def test_validate_explain_prints_the_whole_analysis(tmp_path):
    bad = tmp_path / "six.yaml"
    bad.write_text(yaml.safe_dump(SIX))
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(edited(SIX, [("friction.2.backward", 3.5)], "good.yaml")))
    broken = tmp_path / "broken.yaml"
    broken.write_text(yaml.safe_dump(dict(SIX, stiffness=-1.0)))
    result = CliRunner().invoke(main, ["validate", "--explain", str(bad), str(good), str(broken)])
    assert result.exit_code == 2
    listed = {
        frozenset(int(x) for x in m.split(", "))
        for m in re.findall(
            rf"{re.escape(str(bad))}:     J = \{{([0-9, ]+)\}}: g_J = 0 "
            r"for t in \[0, 2\]",
            result.output,
        )
    }
    assert listed == brute_force(*thresholds(SIX))
    assert f"{bad}:   violated by 6 subsets:" in result.output
    assert f"{bad}:   To restore it, change friction[" in result.output
    assert f"{good}: valid" in result.output
    assert f"{good}:   holds: no g_J vanishes on an interval (decided exactly)" in result.output
    assert f"{broken}: stiffness: " in result.output
    assert (
        f"{broken}: uniqueness condition (docs/model.md §3): not analysed until the errors above are fixed"
    ) in result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize("seed", range(40))
def test_analyse_lists_exactly_the_subsets_of_a_brute_force(seed):
    """Random friction of small integers on 2 to 8 blocks: the subsets `analyse` lists, with
    those alike written out (`alike_subsets`), are exactly the J with g_J = 0."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 9))
    forward = [float(v) for v in rng.integers(1, 4, n)]
    backward = [float(v) for v in rng.integers(1, 4, n)]
    expected = brute_force(forward, backward)
    f, b = [Constant(v) for v in forward], [Constant(v) for v in backward]
    analysis = analyse(f, b)
    if not expected:
        assert analysis is None
        return
    assert analysis is not None and analysis.complete
    listed = [
        frozenset(int(j) + 1 for j in np.flatnonzero(s))
        for v in analysis.violations
        for s in alike_subsets(v, f, b, limit=1 << 10)
    ]
    assert len(listed) == len(set(listed)) == sum(v.alike for v in analysis.violations)
    assert set(listed) == expected
    assert all(v.intervals == ((0.0, 1.0),) for v in analysis.violations)


def test_blocks_of_equal_friction_written_one_by_one_cannot_be_fixed_by_one_coefficient():
    """Six blocks each written (forward 1, backward 2): the 15 subsets of four blocks violate,
    and every coefficient misses some of them (mu_j^+ enters g_J only for j in J, mu_j^- only for
    j outside), so the refusal says no single change can work, and a brute force agrees."""
    doc = dict(SIX, friction=[{"forward": 1.0, "backward": 2.0} for _ in range(6)])
    message = refusal(doc)
    assert "(and 14 more subsets that exchange blocks of J" in message
    assert "No single friction coefficient of the file enters the g_J of every subset" in message
    forward, backward = thresholds(doc)
    for j in range(6):
        for values in (forward, backward):
            trial = list(values)
            trial[j] += 0.05
            f, b = (trial, backward) if values is forward else (forward, trial)
            assert brute_force(f, b)
