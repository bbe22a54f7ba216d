#!/usr/bin/env bash
# Render one of each crawlsim figure from the example gaits into docs/figures/ (small PNGs that
# the README shows; see docs/figures.md). Run from anywhere: scripts/make-figures.sh
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
crawlsim plot "$work/triangle.h5" -o "$out" --only convergence
crawlsim plot "$work/smooth-friction-3.h5" -o "$out" --only shape-space

# The sweep figure: v0 of peristalsis-4 over the backward friction and the stiffness. Equal
# friction both ways (backward 1.0) on four blocks breaks the uniqueness condition, so those
# points fail and are crossed out.
python - "$root/gaits/peristalsis-4.yaml" "$out/peristalsis-4-sweep.png" <<'PY'
import copy
import sys

import numpy as np

from crawlsim import api
from crawlsim.errors import CrawlsimError
from crawlsim.gait import gait_from_document, load_gait, with_simulation
from crawlsim.plotting import sweep_figure

base = load_gait(sys.argv[1])
backward = np.linspace(1.0, 3.0, 9)
stiffness = np.array([5.0, 7.5, 10.0, 15.0, 20.0, 30.0])
v0 = np.full((backward.size, stiffness.size), np.nan)
failed = np.zeros(v0.shape, dtype=bool)
for i, mu in enumerate(backward):
    for j, k in enumerate(stiffness):
        doc = copy.deepcopy(base.document)
        doc["friction"]["backward"] = float(mu)
        doc["stiffness"] = float(k)
        doc["simulation"]["steps_per_period"] = 400
        try:
            v0[i, j] = api.run(gait_from_document(doc, "sweep")).v0
        except CrawlsimError:
            failed[i, j] = True
fig = sweep_figure({"friction.backward": backward, "stiffness": stiffness}, v0, failed,
                   f"{base.name}: average velocity over a sweep")
fig.savefig(sys.argv[2], dpi=150, bbox_inches="tight", metadata={"Software": "crawlsim"})
print(sys.argv[2])
PY
ls -l "$out"
