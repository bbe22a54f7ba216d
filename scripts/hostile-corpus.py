#!/usr/bin/env python
"""The hostile-input corpus (tests/test_hostile.py) through `crawlsim run`, one file per line:
exit code, wall time and peak resident memory of the child, under RLIMIT_AS = 1 GiB, next to
the time of `crawlsim run` on a valid two-block gait (the ratio says how much of each refusal
is interpreter start-up).

Usage: python scripts/hostile-corpus.py [--repeats 3]
"""

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.test_hostile import corpus, run_hostile, run_limited

VALID = """\
blocks: 2
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}]
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 100, max_periods: 20}
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / "valid.yaml").write_text(VALID)
        base = statistics.median(
            run_limited(["run", str(folder / "valid.yaml"), "-o", "v.h5"], folder)["seconds"]
            for _ in range(args.repeats)
        )
        print(f"{'file':30s} {'exit':>4s} {'time (s)':>9s} {'/valid':>7s} {'peak RSS (MB)':>14s}")
        print(f"{'valid two-block run':30s} {0:4d} {base:9.2f} {1.0:7.2f}")
        made = folder / "made"
        made.mkdir()
        for name, path in corpus(made):
            results = []
            for _ in range(args.repeats):
                results.append(run_hostile(name, path, folder))
            seconds = statistics.median(r["seconds"] for r in results)
            peak = statistics.median(r["peak"] for r in results) / 1e6
            codes = sorted({r["code"] for r in results})
            print(f"{name:30s} {','.join(map(str, codes)):>4s} {seconds:9.2f} {seconds / base:7.2f} {peak:14.0f}")


if __name__ == "__main__":
    main()
