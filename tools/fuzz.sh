#!/usr/bin/env bash
# Runs fdd's fuzz targets (fuzz/, cargo-fuzz + libFuzzer, nightly) and prints each one's final
# libFuzzer status line (execs, cov, corpus). Not part of CI: a campaign takes hours.
#
#   tools/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     (default 600 s, every target)
#   FUZZ_RUNS=10000000 tools/fuzz.sh 3600 mcap_reader  (stop at 10M executions or 1 h)
#
# Built without a sanitizer (-s none): fdd has no unsafe code of its own, and AddressSanitizer's
# quarantine of freed memory would count against the RSS limit. Each target runs with its seeds (fuzz/seeds/<t>) and grows fuzz/corpus/<t>; limits per input:
# 1 s (-timeout) and 256 MB RSS (-rss_limit_mb). A crash lands in fuzz/artifacts/<t>/; once
# fixed, copy it to fuzz/regressions/<t>/<what-it-was>.bin so `cargo test` replays it. Then
# minimize the corpus: `cargo +nightly fuzz cmin -O <t> fuzz/corpus/<t>`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../fuzz"
secs=${1:-600}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(mcap_reader json_field runtime_config throttle_config intake_config scenario replay)
fi
cargo +nightly fuzz build -O -s none
for t in "${targets[@]}"; do
    dict=dicts/toml.dict
    case $t in mcap_reader | replay | json_field) dict=dicts/mcap.dict ;; esac
    mkdir -p "corpus/$t" "logs"
    cargo +nightly fuzz run -O -s none "$t" "corpus/$t" "seeds/$t" -- \
        -dict="$dict" -max_total_time="$secs" -runs="${FUZZ_RUNS:--1}" -timeout=1 -rss_limit_mb=256 \
        -max_len=65536 -print_final_stats=1 > "logs/$t.log" 2>&1 || echo "$t: FAILED, see fuzz/logs/$t.log"
    echo "$t: $(grep -E '^#[0-9]+.*(DONE|pulse|NEW|REDUCE)' "logs/$t.log" | tail -1)"
    grep -E '^stat::number_of_executed_units|^stat::peak_rss_mb' "logs/$t.log" | tr '\n' ' '
    echo
done
