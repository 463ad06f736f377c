#!/usr/bin/env bash
# Benchmark of `fdd replay` end to end with events only: a nominal throttle log of DURATION_S
# seconds at 1 kHz (default 3600 s: 3.6 M frames, 14.4 M messages) is generated with
# `fdd simulate` from a copy of fixtures/scenarios/throttle_nominal.toml, then replayed under
# `/usr/bin/time -v`. Prints the replay's frames/s (from its summary) and the peak RSS.
#
# Targets (issue): >= 500,000 frames/s, peak RSS <= 100 MB whatever the log length.
#
#   tools/bench_replay.sh                 # 1 hour
#   DURATION_S=600 tools/bench_replay.sh  # 10 minutes
#   BENCH_DIR=/tmp/fdd-bench tools/bench_replay.sh   # keep (and reuse) the generated log
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

duration_s=${DURATION_S:-3600}
work=${BENCH_DIR:-$(mktemp -d)}
mkdir -p "$work"
# A scenario's name must equal its file stem and start with its monitor's name.
name="throttle_bench_${duration_s}s"
scenario="$work/$name.toml"
log="$work/$name.mcap"
events="$work/events.jsonl"

sed -e "s/^name = .*/name = \"$name\"/" \
    -e "s/^duration_s = .*/duration_s = $duration_s/" \
    fixtures/scenarios/throttle_nominal.toml >"$scenario"

cargo build --release --quiet --bin fdd

if [ ! -s "$log" ]; then
    echo "==> generating $log ($duration_s s at 1 kHz)"
    target/release/fdd simulate "$scenario" -o "$log"
fi
ls -l "$log"

echo "==> fdd replay $log --events $events"
/usr/bin/time -v target/release/fdd replay "$log" --events "$events" --no-progress \
    >"$work/summary.txt" 2>"$work/time.txt" || {
    cat "$work/summary.txt" "$work/time.txt"
    exit 1
}
sed -n '1,10p' "$work/summary.txt"

frames_per_s=$(grep -o '[0-9]* frames/s' "$work/summary.txt" | head -n1)
rss_kb=$(awk -F': ' '/Maximum resident set size/ {print $2}' "$work/time.txt")
wall=$(awk -F'): ' '/Elapsed \(wall clock\) time/ {print $2}' "$work/time.txt")
echo
echo "replay throughput: $frames_per_s (events only)"
echo "process wall time: $wall"
echo "peak RSS:          $((rss_kb / 1024)) MB ($rss_kb kB)"
echo "(work files in $work)"
