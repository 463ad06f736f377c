#!/usr/bin/env bash
# Instruction counts (valgrind callgrind) of the host loop through the C ABI against the Rust
# API with the same event queue: benches/runtime.rs's `ffi_*` and `queue_*` benchmarks, counted
# inside `run_ffi` / `run_queue` only (two samples of 10 s of a fixture each). Stable where
# the wall-clock figures of `cargo bench --bench runtime` are noisy.
#
#   tools/ffi_cost.sh
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=$(cargo bench --bench runtime --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for l in sys.stdin:
    m = json.loads(l)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "runtime" and m.get("executable"):
        print(m["executable"])')
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
declare -A ir
for t in queue_throttle ffi_throttle queue_intake ffi_intake; do
    f=run_queue
    case $t in ffi_*) f=run_ffi ;; esac
    valgrind --tool=callgrind --callgrind-out-file="$out/$t.out" "--toggle-collect=*$f*" \
        "$bin" --bench "$t" --sample-count 2 > /dev/null 2> "$out/$t.err"
    ir[$t]=$(grep -o 'Collected : [0-9]*' "$out/$t.err" | grep -o '[0-9]*$')
done
for m in throttle intake; do
    q=${ir[queue_$m]} f=${ir[ffi_$m]}
    python3 -c "q, f = $q, $f; print(f'$m: Rust API {q:,} instructions, C ABI {f:,}: {100 * (f - q) / q:+.2f} %')"
done
