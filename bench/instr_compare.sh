#!/usr/bin/env bash
# Instructions (valgrind --tool=cachegrind, no cache simulation) of two tessla-telegraf binaries
# on the engine's workloads, one run each, as a Markdown table: P2 (20,000 records, bench spec),
# P2 with its action (specs/p2_tolerance.tessla), lidar (2,000 records), the fleet (1,000 robots x 5,
# one thread), the robot monitors on the recorded fixture, parse-only (the P2 yardstick: the
# parse_only example beside each binary, when both were built), VAMOS primes (its 80k trace, `trace`) and
# Auction (the first CRV trace, `trace`) when ../shared/corpora is there. Counts of one binary move
# by at most about 0.1M between runs (hash seeds).
#
# Usage: bench/instr_compare.sh BASE_BINARY NEW_BINARY [WORKDIR]
set -euo pipefail
base=$(realpath "$1")
new=$(realpath "$2")
work=${3:-$(mktemp -d)}
root=$(cd "$(dirname "$0")/.." && pwd)
corpora=$root/../shared/corpora
primes=$corpora/tessla-wild2/vamos-shamon/930b14d/experiments/tessla_compare
auction=$corpora/perf-anchors/PRECISE-SMEDL/b0096d1/tests/monitors/auction/auction_trace_invalid1
mkdir -p "$work"
mapfile -t w < <(python3 "$root/bench/gen_workloads.py" --out "$work" --p2 20000 --lidar 2000 \
    --fleet-robots 1000 --fleet-rounds 5 --order telegraf)
p2=${w[0]} lidar=${w[2]} fleet=${w[3]}

# Instructions of one command (stdin from $1), in millions.
count() {
    local input=$1
    shift
    valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null "$@" <"$input" 2>&1 >/dev/null |
        awk '/I *refs:/ { gsub(",", "", $NF); printf "%.2f", $NF / 1e6 }'
}

row() {
    local name=$1 input=$2
    shift 2
    local b n
    b=$(count "$input" "$base" "$@")
    n=$(count "$input" "$new" "$@")
    echo "| $name | ${b}M | ${n}M | $(awk -v b="$b" -v n="$n" 'BEGIN { printf "%.3f", n / b }') |"
}

echo "| workload | base | new | new / base |"
echo "|---|---|---|---|"
row "P2, 20,000 records (run --max-ahead off --spec bench/p2.tessla)" "$p2" run --max-ahead off --spec "$root/bench/p2.tessla"
row "P2 with its action (--spec specs/p2_tolerance.tessla)" "$p2" run --max-ahead off --spec "$root/specs/p2_tolerance.tessla"
row "lidar, 2,000 records (run --max-ahead off)" "$lidar" run --max-ahead off
row "fleet, 1,000 robots x 5 (--instance-by robot --threads 1)" "$fleet" run --max-ahead off --instance-by robot --threads 1
row "robot monitors, recorded fixture (run --max-ahead off)" "$root/tests/fixtures/robot/recorded_run.lp" run --max-ahead off
# The P2 yardstick: the parse-only example beside each binary (built by `cargo build --release
# --example parse_only` in each tree), when both are there.
base_po=$(dirname "$base")/examples/parse_only
new_po=$(dirname "$new")/examples/parse_only
if [ -x "$base_po" ] && [ -x "$new_po" ]; then
    (
        base=$base_po new=$new_po
        row "parse-only (lineproto example), the same 20,000 P2 records" "$p2"
    )
fi
if [ -f "$primes/primes.tessla" ]; then
    row "VAMOS primes, its 80k trace (trace)" "$primes/gen_tessla_input/primes.in" trace "$primes/primes.tessla"
fi
if [ -f "$auction" ]; then
    python3 "$root/bench/auction_trace.py" "$auction" "$work/auction1.input" "$work/auction1.csv"
    row "Auction, auction_trace_invalid1 (trace bench/auction.tessla)" "$work/auction1.input" trace "$root/bench/auction.tessla"
fi
