#!/usr/bin/env python
"""Timings of the exact uniqueness check (crawlsim.gait.uniqueness.find_violation).

Cases: 21, 120 and 1000 identical blocks (forward 1, backward 2: the 21- and 120-block waves
violate the condition, 1000 does not), and 40 blocks of distinct friction, constant and cosine
(the largest searches the bounds allow; built with a residue so that no subset vanishes and the
whole search runs). The comparison in one run: at 20 distinct blocks, the enumeration of all
2^20 subsets that the check replaced, as a ratio.

Usage: python scripts/bench-uniqueness.py [--repeats 5]
"""

import argparse
import statistics
import time

import numpy as np

from crawlsim.gait.signals import Constant, Cosine
from crawlsim.gait.uniqueness import TOLERANCE, find_violation


def distinct(n, cosine=False, seed=0):
    rng = np.random.default_rng(seed)
    forward = rng.integers(2**19, 2**21, size=n) / 2.0**20
    backward = rng.integers(2**19, 2**21, size=n) / 2.0**20
    forward[0] += 2.0**-21  # every g_J is then nonzero modulo 2^-20
    backward[0] += 2.0**-22
    if cosine:
        phases = rng.random(n)
        return (
            [Cosine(mean=f + 0.5, amplitude=0.25, phase=p) for f, p in zip(forward, phases)],
            [Constant(b) for b in backward],
        )
    return [Constant(f) for f in forward], [Constant(b) for b in backward]


def enumerate_all(forward, backward):
    """The former check: every subset as a row of a 0/1 matrix, in chunks."""
    f = np.array([s.value for s in forward])
    b = np.array([s.value for s in backward])
    n = len(f)
    tolerance = TOLERANCE * (f.sum() + b.sum())
    bits = np.arange(n)
    for start in range(0, 2**n, 1 << 16):
        codes = np.arange(start, min(start + (1 << 16), 2**n))
        subsets = ((codes[:, None] >> bits) & 1).astype(float)
        g = subsets @ (f + b) - b.sum()
        if np.any(np.abs(g) <= tolerance):
            return True
    return False


def timed(action, repeats):
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        result = action()
        times.append(time.perf_counter() - began)
    return statistics.median(times), result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cases = [(f"{n} identical blocks", [Constant(1.0)] * n, [Constant(2.0)] * n) for n in (21, 120, 1000)]
    cases += [("40 distinct constant blocks", *distinct(40)), ("40 distinct cosine blocks", *distinct(40, cosine=True))]
    print(f"{'case':32s} {'median (s)':>10s}  result")
    for name, forward, backward in cases:
        seconds, found = timed(lambda f=forward, b=backward: find_violation(f, b), args.repeats)
        verdict = "holds" if found is None else f"violated, |J| = {int(found.subset.sum())}"
        print(f"{name:32s} {seconds:10.4f}  {verdict}")
    forward, backward = distinct(20)
    exact, _ = timed(lambda: find_violation(forward, backward), args.repeats)
    brute, _ = timed(lambda: enumerate_all(forward, backward), max(1, args.repeats // 2))
    print(
        f"20 distinct blocks: exact check {exact:.4f} s, enumeration of 2^20 subsets "
        f"{brute:.4f} s, ratio {brute / exact:.1f}"
    )


if __name__ == "__main__":
    main()
