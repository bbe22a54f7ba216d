#!/usr/bin/env bash
# The orbit figures of the paper's Figures 2 and 3 (Section 5), drawn by crawlsim's shape-space
# figure from the example files: docs/figures/paper-acute-angle.png (the acute angle sliding
# vertically, the orbit creeping towards (gamma, 0)) and docs/figures/paper-triangle.png (the
# triangle swept edge to edge, the orbit converging to its one periodic solution).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/docs/figures"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# Starts far from the limit, as in the paper's figures: the angle from (0.1, 0) with alpha = 1
# (gamma = 0.5), the triangle from (0.1, 0.05). 60 steps a period (both processes are exact on
# any grid holding their breakpoints): the grid then holds the sixths and tenths of the period,
# so the acute angle is drawn at tenths (t and T - t give the same set, so six distinct sets)
# and the triangle at sixths.
for name in acute-angle triangle; do
  crawlsim run "$root/gaits/paper/$name.yaml" -o "$work/$name.h5" --steps-per-period 60 >/dev/null
  crawlsim plot "$work/$name.h5" -o "$work" --only shape-space
  mv "$work/$name-shape-space.png" "$out/paper-$name.png"
done
ls -l "$out"/paper-*.png
