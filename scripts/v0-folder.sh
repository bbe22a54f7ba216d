#!/usr/bin/env bash
# v0 of every gait file in a folder, into one CSV: gait,v0,status.
#
#   scripts/v0-folder.sh FOLDER [OUT.csv] [crawlsim velocity options...]
#   scripts/v0-folder.sh gaits v0.csv --steps-per-period 400
#
# status is ok, not-converged (exit code 3: v0 of the last period is still given), skipped (a
# sweeping process, kind: sweeping-process, which has no velocity; run it with crawlsim run) or
# failed (exit code 1 or 2; the error message goes to stderr). The CSV is written atomically.
set -euo pipefail
folder=${1:?usage: v0-folder.sh FOLDER [OUT.csv] [crawlsim velocity options...]}
out=${2:-/dev/stdout}
shift $(( $# >= 2 ? 2 : 1 ))
shopt -s nullglob
files=("$folder"/*.yaml "$folder"/*.yml)
if [ ${#files[@]} -eq 0 ]; then
    echo "v0-folder.sh: no .yaml gait files in $folder" >&2
    exit 2
fi
tmp=$(mktemp)
err=$(mktemp)
trap 'rm -f "$tmp" "$err"' EXIT
echo "gait,v0,status" > "$tmp"
for gait in "${files[@]}"; do
    set +e
    v0=$(crawlsim velocity "$gait" "$@" 2>"$err")
    code=$?
    set -e
    case $code in
        0) status=ok ;;
        3) status=not-converged ;;
        *) status=failed; v0= ;;
    esac
    # crawlsim velocity refuses a sweeping process (exit code 2) in these words
    if [ "$code" -eq 2 ] && grep -q "a sweeping process has no velocity v0" "$err"; then
        status=skipped
        echo "v0-folder.sh: skipped $gait: a sweeping process has no velocity (crawlsim run runs it)" >&2
    else
        cat "$err" >&2
    fi
    echo "$(basename "$gait" | sed 's/\.ya\?ml$//'),$v0,$status" >> "$tmp"
done
if [ "$out" = /dev/stdout ]; then cat "$tmp"; else mv "$tmp" "$out"; fi
