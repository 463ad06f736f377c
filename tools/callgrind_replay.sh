#!/usr/bin/env bash
# Instructions per frame of `fdd replay` on a 1 kHz throttle log, counted with callgrind (exact
# and repeatable, unlike wall time on a shared machine). One frame is one 1 ms time stamp with 4
# messages (/throttle/motor_voltage, /throttle/tps, /throttle/wattmeter, /truth/throttle).
#
# Method: replay the 120 s fixture (fixtures/data/throttle_nominal.mcap) and a 20 s nominal log
# made with `fdd simulate` from a copy of fixtures/scenarios/throttle_nominal.toml, both under
# `valgrind --tool=callgrind`, and divide the difference of the instruction counts (Ir) by the
# difference of the frame counts: start-up, configuration, the summary and every other fixed
# cost cancel out. The same difference per component (inclusive Ir of its function, from
# callgrind_annotate) gives the breakdown.
#
#   tools/callgrind_replay.sh                        # builds target/release/fdd first
#   FDD_BIN=/path/to/fdd tools/callgrind_replay.sh   # measures that binary (no build)
#   CALLGRIND_DIR=/tmp/cg tools/callgrind_replay.sh  # keeps the logs and profiles there
#
# Needs valgrind (callgrind_annotate comes with it). About a minute on one core.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [ -n "${FDD_BIN:-}" ]; then
    bin=$FDD_BIN
else
    cargo build --release --quiet --bin fdd
    bin=target/release/fdd
fi
work=${CALLGRIND_DIR:-$(mktemp -d)}
mkdir -p "$work"

long=fixtures/data/throttle_nominal.mcap
# A scenario's name must equal its file stem and start with its monitor's name.
name=throttle_callgrind_20s
scenario="$work/$name.toml"
short="$work/$name.mcap"
sed -e "s/^name = .*/name = \"$name\"/" \
    -e "s/^duration_s = .*/duration_s = 20/" \
    fixtures/scenarios/throttle_nominal.toml >"$scenario"
"$bin" simulate "$scenario" -o "$short" >/dev/null

# Components: label and the function whose inclusive cost is the component's.
components=(
    "MCAP reading|fdd_monitor::log::reader::LogReader::next_message"
    "JSON field parsing (signals)|fdd_monitor::log::reader::LogMessage::field_f64"
    "truth parsing|fdd::replay::truth::parse_truth"
    "throttle monitor|<fdd_monitor::throttle::ThrottleMonitor as fdd_monitor::monitor::Monitor>::step"
    "staleness monitor|<fdd_monitor::staleness::StalenessMonitor as fdd_monitor::monitor::Monitor>::step"
)
# Parts of the throttle monitor: label and the callee whose calls from its step are counted.
throttle_parts=(
    "UKF predict (2 filters)|fdd_estimators::ukf::Ukf<T,O,_,_,_,_>::predict"
    "UKF update (2 filters)|fdd_estimators::ukf::Ukf<T,O,_,_,_,_>::update_subset"
    "event reporting|fdd_monitor::monitor_events::MonitorEvents::report_one"
    "outputs to the sinks|fdd_monitor::scheduler::Scheduler::run_until::{{closure}}"
)

profile() { # tag log
    valgrind --tool=callgrind --callgrind-out-file="$work/$1.callgrind" \
        "$bin" replay "$2" --no-progress >"$work/$1.summary" 2>"$work/$1.valgrind" || {
        cat "$work/$1.summary" "$work/$1.valgrind" >&2
        exit 1
    }
    callgrind_annotate --inclusive=yes --threshold=100 "$work/$1.callgrind" \
        >"$work/$1.annotate" 2>/dev/null
    callgrind_annotate --inclusive=yes --threshold=100 --tree=calling "$work/$1.callgrind" \
        >"$work/$1.tree" 2>/dev/null
}

frames() { # summary file
    sed -n 's/.* messages *[0-9]* in \([0-9]*\) frames.*/\1/p' "$1" | head -n1
}

total_ir() { # annotate file
    awk '/PROGRAM TOTALS/ {gsub(",", "", $1); print $1; exit}' "$1"
}

# Inclusive Ir of a function: callgrind_annotate lists a function once per source file its
# code comes from (inlined code counts under its own file too); the whole function is the
# largest of those entries.
fn_ir() { # annotate file, function name
    awk -v fn="$2" '
        { line = $0; sub(/ \[[^]]*\]$/, "", line) }
        substr(line, length(line) - length(fn)) == ":" fn {
            v = $1; gsub(",", "", v); if (v + 0 > max) max = v + 0
        }
        END { printf "%d\n", max }' "$1"
}

# Ir of the calls to `callee` from `caller` (from its every entry, inlined parts included).
callee_ir() { # tree file, caller, callee
    awk -v caller="$2" -v callee="$3" '
        function name(line) {
            sub(/^ *[0-9,]+ +\([^)]*\) +[*>] +/, "", line)
            sub(/ \[[^]]*\]$/, "", line)
            sub(/ \([0-9,]+x\)$/, "", line)
            sub(/^[^:]*:/, "", line)
            return line
        }
        /^ *[0-9,]+ .*  \*  / { in_caller = (name($0) == caller); next }
        /^$/ { in_caller = 0 }
        in_caller && /^ *[0-9,]+ .*  >  / && name($0) == callee {
            v = $1; gsub(",", "", v); sum += v
        }
        END { printf "%d\n", sum }' "$1"
}

echo "==> callgrind: $bin replay $long"
profile long "$long"
echo "==> callgrind: $bin replay $short"
profile short "$short"

f_long=$(frames "$work/long.summary")
f_short=$(frames "$work/short.summary")
ir_long=$(total_ir "$work/long.annotate")
ir_short=$(total_ir "$work/short.annotate")
df=$((f_long - f_short))

echo
printf '%-32s %15s %15s\n' "" "120 s log" "20 s log"
printf '%-32s %15s %15s\n' "frames" "$f_long" "$f_short"
printf '%-32s %15s %15s\n' "instructions (Ir)" "$ir_long" "$ir_short"
echo
per_frame=$(awk -v a="$ir_long" -v b="$ir_short" -v f="$df" 'BEGIN {printf "%.0f", (a - b) / f}')
echo "instructions per frame: $per_frame   ((Ir(120 s) - Ir(20 s)) / $df frames)"
echo
printf '%-32s %10s %7s\n' "component (inclusive)" "Ir/frame" "share"
row() { # label, Ir difference
    awk -v l="$1" -v d="$2" -v f="$df" -v t="$per_frame" \
        'BEGIN {printf "%-32s %10.0f %6.1f%%\n", l, d / f, 100 * d / f / t}'
}
counted=0
throttle=${components[3]#*|}
for c in "${components[@]}"; do
    fn=${c#*|}
    d=$(($(fn_ir "$work/long.annotate" "$fn") - $(fn_ir "$work/short.annotate" "$fn")))
    counted=$((counted + d))
    row "${c%%|*}" "$d"
    if [ "$fn" = "$throttle" ]; then
        for p in "${throttle_parts[@]}"; do
            callee=${p#*|}
            d=$(($(callee_ir "$work/long.tree" "$fn" "$callee") - $(callee_ir "$work/short.tree" "$fn" "$callee")))
            row "  ${p%%|*}" "$d"
        done
    fi
done
awk -v d="$((ir_long - ir_short - counted))" -v f="$df" -v t="$per_frame" \
    'BEGIN {printf "%-32s %10.0f %6.1f%%\n", "the rest", d / f, 100 * d / f / t}'
echo
echo "(profiles in $work: *.callgrind, *.annotate; callgrind_annotate --tree=calling for callees)"
