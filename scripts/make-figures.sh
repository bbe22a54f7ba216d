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

# The sweep figure: v0 of peristalsis-4 over the backward friction and the stiffness, through
# the command line. Backward friction 1.0 (equal to the forward one) or 3.0 breaks the uniqueness
# condition on four blocks: those points are recorded as invalid and crossed out.
mkdir -p "$work/sweep"
crawlsim velocity "$root/gaits/peristalsis-4.yaml" --steps-per-period 400 --quiet \
    --sweep friction.backward=1:3:9 --sweep 'stiffness=[5,7.5,10,15,20,30]' \
    -o "$work/sweep/peristalsis-4.h5"
crawlsim plot "$work/sweep/peristalsis-4.h5" -o "$out"
ls -l "$out"
