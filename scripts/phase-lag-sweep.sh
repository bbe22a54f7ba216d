#!/usr/bin/env bash
# Phase-lag sweep of the three-block peristaltic wave: v0 against the lag of link 2 behind
# link 1 (links.1.phase, in periods), written to a CSV and drawn as a plot.
#
#   scripts/phase-lag-sweep.sh [OUTDIR] [POINTS] [crawlsim velocity options...]
#   scripts/phase-lag-sweep.sh lag 101 --steps-per-period 400 --jobs 2
#
# Writes OUTDIR/phase-lag.csv and OUTDIR/phase-lag-sweep.png. Rerunning after an interruption
# resumes the sweep (finished points are kept in OUTDIR/phase-lag.csv.journal).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
outdir=${1:-phase-lag}
points=${2:-101}
shift $(( $# >= 2 ? 2 : $# ))
gait=${GAIT:-$here/../gaits/peristalsis-3.yaml}
mkdir -p "$outdir"
crawlsim velocity "$gait" --sweep "links.1.phase=0:1:$points" \
    -o "$outdir/phase-lag.csv" --plot "$@" >/dev/null
echo "wrote $outdir/phase-lag.csv and $outdir/phase-lag-sweep.png"
