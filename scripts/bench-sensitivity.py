#!/usr/bin/env python
"""Benchmark: the cost of ``crawlsim velocity GAIT --sensitivity ...`` against ``crawlsim velocity
GAIT`` alone, for p = 1, 2, 5 and 10 parameters, measured in one run (issue 22's bar: a ratio of
at most 1 + 0.2 p).

``velocity`` alone is ``crawlsim.api.run(gait, history=False)``; with ``--sensitivity`` the
command runs the same and then ``crawlsim.analysis.sensitivity.sensitivity(gait, paths, run=result.settled)``,
which walks the run's own limit period once with p + n tangent columns and solves (I - dP/dw)
for the p right-hand sides together: the limit is not searched again, and no parameter costs a
run. The two are interleaved, repeat by repeat, so that a change of load on the machine hits
both alike; the ratio printed is the median of the repeats' ratios (each repeat's pair run
back to back), beside the median times.

Two more columns, measured in the same repeats: ``sens`` is the sensitivity call alone (what
``--sensitivity`` adds to a run), and ``stepping`` the periods that run stepped, stepped again
on a fresh stepper of its compiled process (the integrator's own cost, without compiling the
gait, the run's analysis or its bookkeeping); ``sens/step`` is the median of their ratios.

``ratio`` calls `sensitivity` on a gait it has seen before (what a call derives from the gait
alone is kept on the `Gait` object: a notebook or a script that asks again). ``first`` is the
ratio of a run and its first `sensitivity` call on a new `Gait` object (nothing cached) to the
run alone: what one ``crawlsim velocity --sensitivity`` process, or one point of a sweep, pays.
The bar is read on ``first``.

``command`` is the literal measure: ``crawlsim velocity GAIT --sensitivity PATH ...`` against
``crawlsim velocity GAIT``, each run in this process through click's test runner (the gait file
read, validated and run, the report formatted; the interpreter's start-up, the same for both,
left out), interleaved like the others.

    python scripts/bench-sensitivity.py              # a minute or two
    python scripts/bench-sensitivity.py --repeats 21 --clock cpu
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import copy
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import crawlsim
from crawlsim import api
from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.stepping import make_stepper

ROOT = Path(__file__).resolve().parents[1]


def wave(blocks: int) -> crawlsim.Gait:
    """A cosine wave of blocks - 1 links, a lag of 1/(blocks - 1) period each."""
    links = [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / (blocks - 1)} for i in range(blocks - 1)]
    doc = {
        "name": f"wave-{blocks}",
        "blocks": blocks,
        "period": 1.0,
        "stiffness": 10.0,
        "links": links,
        "friction": {"forward": 1.0, "backward": 2.0},
        "simulation": {"steps_per_period": 1000, "max_periods": 1000, "tolerance": 1e-12},
    }
    gait = gait_from_document(doc, f"wave-{blocks}")
    assert isinstance(gait, crawlsim.Gait)
    return gait


def command_ratio(gait: crawlsim.Gait, paths: list[str], folder: Path, repeats: int, clock) -> float:
    """The median ratio of ``crawlsim velocity GAIT --sensitivity PATH...`` to ``crawlsim
    velocity GAIT`` (the gait written to a file), in this process, interleaved."""
    import yaml
    from click.testing import CliRunner

    from crawlsim.cli import main

    gait_file = folder / f"{gait.name}-{gait.simulation.integrator}.yaml"
    gait_file.write_text(yaml.safe_dump(gait.document, sort_keys=False))
    alone = ["velocity", str(gait_file)]
    both = alone + [x for path in paths for x in ("--sensitivity", path)]
    runner = CliRunner()
    for args in (alone, both):  # warm
        result = runner.invoke(main, args)
        assert result.exit_code == 0, result.output
    ratios = []
    for _ in range(repeats):
        began = clock()
        runner.invoke(main, alone)
        middle = clock()
        runner.invoke(main, both)
        ratios.append((clock() - middle) / (middle - began))
    return statistics.median(ratios)


def cases() -> list[tuple[crawlsim.Gait, dict[int, list[str]]]]:
    """(gait, {p: paths naming p numbers}) for p = 1, 2, 5, 10."""
    peristalsis = crawlsim.load_gait(ROOT / "gaits" / "peristalsis-4.yaml")
    assert isinstance(peristalsis, crawlsim.Gait)
    catch_up = peristalsis.replace("simulation.integrator", "catch-up")
    four = {
        1: ["links.1.phase"],
        2: ["links.1.phase", "links.2.phase"],
        5: ["links.*.phase", "links.0.amplitude", "links.1.amplitude"],
        10: ["links.*.phase", "links.*.amplitude", "links.*.mean", "stiffness"],
    }
    eleven = {
        1: ["links.1.phase"],
        2: ["links.1.phase", "links.2.phase"],
        5: [f"links.{i}.phase" for i in range(5)],
        10: ["links.*.phase"],
    }
    return [(peristalsis, four), (wave(11), eleven), (catch_up, four)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="wall time (perf_counter) or this process's CPU time "
        "(process_time: less sensitive to other load on the machine)",
    )
    args = parser.parse_args()
    clock = time.perf_counter if args.clock == "wall" else time.process_time
    print(
        f"{'gait':16s} {'integrator':10s} {'p':>3s} {'velocity':>10s} {'--sensitivity':>14s} "
        f"{'ratio':>7s} {'first':>7s} {'command':>7s} {'bar':>5s} {'sens':>9s} "
        f"{'stepping':>9s} {'sens/step':>9s}"
    )
    folder = Path(tempfile.mkdtemp(prefix="bench-sensitivity-"))
    for gait, path_sets in cases():
        for p, paths in path_sets.items():
            result = api.run(gait, history=False)  # warm (and the count of parameters)
            got = len(sensitivity(gait, paths, run=result.settled).parameters)
            assert got == p, (gait.name, paths, got)
            process = result.settled.process
            periods = result.periods + result.solver.periods
            alone, both, sens, stepping, first = [], [], [], [], []
            for _ in range(args.repeats):  # interleaved
                began = clock()
                api.run(gait, history=False)
                alone.append(clock() - began)
                began = clock()
                result = api.run(gait, history=False)
                middle = clock()
                sensitivity(gait, paths, run=result.settled)
                ended = clock()
                both.append(ended - began)
                sens.append(ended - middle)
                # the first call on a gait (a new Gait object: nothing of it is cached), as in
                # one `crawlsim velocity --sensitivity` process or one point of a sweep
                fresh = copy.copy(gait)
                began = clock()
                result = api.run(fresh, history=False)
                sensitivity(fresh, paths, run=result.settled)
                first.append(clock() - began)
                began = clock()
                stepper = make_stepper(process, gait.simulation.integrator)
                for _ in range(periods):
                    stepper.step_period()
                stepping.append(clock() - began)
            a, b = statistics.median(alone), statistics.median(both)
            ratio = statistics.median(y / x for x, y in zip(alone, both))
            first_ratio = statistics.median(y / x for x, y in zip(alone, first))
            fixed = statistics.median(x / y for x, y in zip(sens, stepping))
            command = command_ratio(gait, paths, folder, args.repeats, clock)
            print(
                f"{gait.name:16s} {gait.simulation.integrator:10s} {p:3d} {a:9.4f}s "
                f"{b:13.4f}s {ratio:7.2f} {first_ratio:7.2f} {command:7.2f} {1 + 0.2 * p:5.1f} "
                f"{statistics.median(sens) * 1e3:7.3f}ms "
                f"{statistics.median(stepping) * 1e3:7.3f}ms {fixed:9.2f}"
            )
    shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
