#!/usr/bin/env bash
# Replays every fixture log with two fdd binaries and checks that the outputs are identical,
# byte for byte: the `--events` file, the `--out` MCAP, and the printed summary (except its
# wall-time line) and the warnings (without their time stamps). For checking that a change meant to be invisible (an optimization) is.
#
#   tools/compare_replays.sh BEFORE_BIN AFTER_BIN [LOG...]   # default: fixtures/data/*.mcap
#   COMPARE="events summary.cmp stderr" tools/compare_replays.sh ...  # leave out the --out MCAP
#
# (A change in floating-point evaluation order, e.g. a closed form that replaces an equivalent
# sum, changes the estimates in the --out MCAP in their last bits but, as a rule, no event and
# no printed figure: compare without the MCAP then.)
#
# Exits 1 at the first difference, after showing it.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [ $# -lt 2 ]; then
    echo "usage: $0 BEFORE_BIN AFTER_BIN [LOG...]" >&2
    exit 2
fi
a=$1
b=$2
shift 2
logs=("$@")
if [ ${#logs[@]} -eq 0 ]; then
    logs=(fixtures/data/*.mcap)
fi
for bin in "$a" "$b"; do
    if [ ! -x "$bin" ]; then
        echo "not an executable: $bin" >&2
        exit 2
    fi
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

run() { # bin tag log (the same output paths for both binaries: the summary names them)
    "$1" replay "$3" --no-progress --events "$work/out.events" --out "$work/out.mcap" \
        >"$work/$2.summary" 2>"$work/$2.log" || true
    # (A replay that fails before writing leaves no file: compared as empty.)
    for f in events mcap; do
        if [ -e "$work/out.$f" ]; then mv "$work/out.$f" "$work/$2.$f"; else : >"$work/$2.$f"; fi
    done
    grep -v 'wall time' "$work/$2.summary" >"$work/$2.summary.cmp" || true
    # Warnings on stderr, without their time stamps.
    sed -E 's/^[0-9]{4}-[0-9T:.-]+Z +//' "$work/$2.log" >"$work/$2.stderr"
}

for log in "${logs[@]}"; do
    run "$a" a "$log"
    run "$b" b "$log"
    for f in ${COMPARE:-events mcap summary.cmp stderr}; do
        if ! cmp -s "$work/a.$f" "$work/b.$f"; then
            echo "DIFFERENT: $log ($f)"
            diff <(od -c "$work/a.$f" | head -50) <(od -c "$work/b.$f" | head -50) | head -20 || true
            exit 1
        fi
    done
    printf 'identical: %-45s events %6d B, out %9d B\n' "$log" \
        "$(stat -c %s "$work/a.events")" "$(stat -c %s "$work/a.mcap")"
done
echo "all ${#logs[@]} logs: identical outputs"
