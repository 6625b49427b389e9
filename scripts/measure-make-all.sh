#!/usr/bin/env bash
# Cold and warm `make all` on a fresh clone, back to back: the numbers the README quotes.
#
#   scripts/measure-make-all.sh [REV [REPO]]     (REV: default HEAD; REPO: default this checkout)
#
# Clones REPO at REV into a new temporary folder, then runs `make all` there twice: cold (its
# own .venv, installing from the installer's cache, an empty kernel cache) and warm (everything
# current). Prints the machine's load before each run and both wall times; each run's output
# is kept beside the clone (cold.log, warm.log). MEASURE_TTY=1 runs the cold `make all` on a
# pseudo-terminal (script(1)), so its log shows the progress bars a user sees.
set -uo pipefail
rev=${1:-HEAD}
repo=${2:-$(git -C "$(dirname "$0")/.." rev-parse --show-toplevel)}
work=$(mktemp -d "${TMPDIR:-/tmp}/breve-measure.XXXXXX")
git clone -q "$repo" "$work/clone" && git -C "$work/clone" checkout -q "$rev" || exit 2
# Nothing cached but the installers' (uv's wheels, and uv itself under ~/.cache/breve-pipeline
# once per machine; see scripts/setup-venv.sh): no kernel cache from the environment.
unset NUMBA_CACHE_DIR BREVE_CACHE_DIR
cd "$work/clone" || exit 2
echo "measure: $(git rev-parse --short HEAD) in $work/clone, $(nproc) cores"

one_run() {  # label, [tty]
    local label=$1 tty=${2:-} t0 t1 rc
    echo "measure: $label make all; load: $(uptime | sed 's/.*load average: //')"
    t0=$(date +%s.%N)
    if [ -n "$tty" ] && command -v script >/dev/null; then
        script -qefc "make all" "$work/$label.log" >/dev/null; rc=$?
    else
        make all >"$work/$label.log" 2>&1; rc=$?
    fi
    t1=$(date +%s.%N)
    printf 'measure: %s make all: %.1f s (exit %d; log %s)\n' "$label" \
        "$(echo "$t1 - $t0" | bc)" "$rc" "$work/$label.log"
}

one_run cold "${MEASURE_TTY:-}"
one_run warm
echo "measure: load after: $(uptime | sed 's/.*load average: //')"
