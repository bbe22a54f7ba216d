#!/usr/bin/env bash
# Render one of each crawlsim figure from the example gaits into docs/figures/ (small PNGs that
# docs/figures.md shows; the README shows peristalsis-4-motion.png). Run from anywhere: scripts/make-figures.sh
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/docs/figures"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# Figures of single runs, through the command line exactly as a user would draw them.
crawlsim run "$root/gaits/peristalsis-4.yaml" -o "$work/peristalsis-4.h5" --rigid >/dev/null
crawlsim run "$root/gaits/smooth-friction-3.yaml" -o "$work/smooth-friction-3.h5" >/dev/null
crawlsim run "$root/gaits/paper/triangle.yaml" -o "$work/triangle.h5" >/dev/null
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only motion
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only gait-diagram
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only kymograph
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only convergence
crawlsim plot "$work/peristalsis-4.h5" -o "$out" --only rigid
crawlsim plot "$work/triangle.h5" -o "$out" --only convergence
crawlsim plot "$work/smooth-friction-3.h5" -o "$out" --only shape-space

# A large crawler: the kymograph of earthworm-100 and its motion, following the crawler over its
# last three periods (the default beyond 32 blocks).
crawlsim run "$root/gaits/earthworm-100.yaml" -o "$work/earthworm-100.h5" >/dev/null
crawlsim plot "$work/earthworm-100.h5" -o "$out" --only kymograph
crawlsim plot "$work/earthworm-100.h5" -o "$out" --only motion

# The crawler in motion over its limit period (a GIF for docs/figures.md, kept small).
crawlsim animate "$work/peristalsis-4.h5" -o "$out/peristalsis-4-crawl.gif" --frames-per-period 30 \
    --dpi 64 --fps 15 --force

# A 1-D sweep through the command line: v0 of the three-block wave against the phase of its
# second link, written as a sweep file and drawn by `crawlsim plot`.
crawlsim velocity "$root/gaits/peristalsis-3.yaml" --sweep links.1.phase=0:1:21 \
    --steps-per-period 400 --quiet -o "$work/peristalsis-3-phase.h5"
crawlsim plot "$work/peristalsis-3-phase.h5" -o "$out"

# A 2-D sweep: v0 of peristalsis-4 over the backward friction and a log-spaced stiffness.
# Equal friction both ways (backward 1.0) on four blocks breaks the uniqueness condition, so
# those points are recorded as invalid (status column) and their cells hatched and marked.
mkdir -p "$work/sweep"
crawlsim velocity "$root/gaits/peristalsis-4.yaml" --steps-per-period 400 --quiet \
    --sweep friction.backward=1:3:9 --sweep stiffness=log:5:40:7 \
    -o "$work/sweep/peristalsis-4.h5"
crawlsim plot "$work/sweep/peristalsis-4.h5" -o "$out"
ls -l "$out"
