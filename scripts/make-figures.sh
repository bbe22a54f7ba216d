#!/usr/bin/env bash
# Render one of each crawlsim figure from the example gaits into docs/figures/ (small PNGs that
# the README and docs/figures.md show). Run from anywhere: scripts/make-figures.sh
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/docs/figures"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# Figures of single runs, through the command line exactly as a user would draw them.
crawlsim run "$root/gaits/peristalsis-4.yaml" -o "$work/peristalsis-4.h5" >/dev/null
crawlsim run "$root/gaits/smooth-friction-3.yaml" -o "$work/smooth-friction-3.h5" >/dev/null
crawlsim run "$root/gaits/paper/triangle.yaml" -o "$work/triangle.h5" >/dev/null
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only motion
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only gait-diagram
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only convergence
crawlsim plot "$work/triangle.h5" -o "$out" --only convergence
crawlsim plot "$work/smooth-friction-3.h5" -o "$out" --only shape-space

# A 1-D sweep through the command line: v0 of the three-block wave against the phase of its
# second link, written as a sweep file and drawn by `crawlsim plot`.
crawlsim velocity "$root/gaits/peristalsis-3.yaml" --sweep links.1.phase=0:1:21 \
    --steps-per-period 400 -o "$work/peristalsis-3-phase.h5" 2>/dev/null
crawlsim plot "$work/peristalsis-3-phase.h5" -o "$out"

# A 2-D sweep: v0 of peristalsis-4 over the backward friction and a log-spaced stiffness.
# Equal friction both ways (backward 1.0) on four blocks breaks the uniqueness condition, so
# those gaits are refused (status invalid) and their cells are hatched and marked.
python - "$root/gaits/peristalsis-4.yaml" "$out/peristalsis-4-sweep.png" <<'PY'
import copy
import sys

import numpy as np

from crawlsim import api
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.gait import gait_from_document, load_gait
from crawlsim.plotting import save_figure, sweep_data_figure

base = load_gait(sys.argv[1])
backward = np.linspace(1.0, 3.0, 9)
stiffness = np.geomspace(5.0, 40.0, 7)
v0, displacement, status = [], [], []
for mu in backward:
    for k in stiffness:
        doc = copy.deepcopy(base.document)
        doc["friction"]["backward"] = float(mu)
        doc["stiffness"] = float(k)
        doc["simulation"]["steps_per_period"] = 400
        doc.pop("initial", None)
        try:
            result = api.run(gait_from_document(doc, "sweep"))
        except InputError:
            v0.append(np.nan), displacement.append(np.nan), status.append("invalid")
            continue
        except CrawlsimError:
            v0.append(np.nan), displacement.append(np.nan), status.append("failed")
            continue
        v0.append(result.v0)
        displacement.append(result.displacement_per_period)
        status.append("ok" if result.converged else "not-converged")
data = {"paths": ["friction.backward", "stiffness"], "axes": [backward, stiffness],
        "points": np.arange(len(v0)),
        "columns": {"v0": np.array(v0), "displacement_per_period": np.array(displacement),
                    "status": np.array(status, dtype=object)},
        "gait_yaml": base.source_text,
        "source": sys.argv[1]}
fig = sweep_data_figure(data, f"{base.name}: average velocity over a sweep")
save_figure(fig, sys.argv[2])
print(sys.argv[2])
PY
ls -l "$out"
