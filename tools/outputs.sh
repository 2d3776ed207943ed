#!/usr/bin/env bash
# Writes everything a refactor of the engine must leave byte-identical, one file per case, so
# that two binaries can be compared with `diff -r` (`make outputs-compare BASE=path/to/old-binary`):
#   run/      `run` on the recorded fixture and the bench workloads (p2, lidar, fleet), default
#             options and `--no-passthrough`
#   trace/    `trace` on every case of TeSSLa's conformance suite and of the standard-library and
#             user-spec fixtures (stdout, stderr, exit code)
#   check/    `check` and `check --ir` of every shipped spec, example and broken-spec case
# Every file holds stdout, then stderr, then the exit code, so a changed message or code shows up.
#
# Usage: tools/outputs.sh BINARY OUTDIR [SUITE]
set -uo pipefail
bin=$(realpath "$1")
out=$2
suite=${3:-${TESSLA_SUITE:-../shared/tessla-suite}}
root=$(cd "$(dirname "$0")/.." && pwd)
rm -rf "$out" && mkdir -p "$out/run" "$out/trace" "$out/check"

# One case: stdout, stderr and exit code of the command into one file.
capture() {
    local file=$1
    shift
    local err
    err=$(mktemp)
    "$@" >"$file" 2>"$err"
    local rc=$?
    { echo "--- stderr"; cat "$err"; echo "--- exit $rc"; } >>"$file"
    rm -f "$err"
}

# `run`: the recorded fixture and the bench workloads (small sizes, fixed seed).
data=$root/target/outputs-data
mapfile -t work < <(python3 "$root/bench/gen_workloads.py" --out "$data" --p2 20000 --lidar 2000 \
    --fleet-robots 50 --fleet-rounds 100 --order sorted)
inputs=("$root/tests/fixtures/robot/recorded_run.lp")
for f in "${work[@]}"; do
    case $f in *.lp) inputs+=("$f") ;; esac
done
for f in "${inputs[@]}"; do
    name=$(basename "$f" .lp)
    capture "$out/run/$name.default" "$bin" run --max-ahead off <"$f"
    capture "$out/run/$name.no-passthrough" "$bin" run --max-ahead off --no-passthrough <"$f"
done
capture "$out/run/fleet-by-robot" "$bin" run --max-ahead off --instance-by robot \
    <"$(printf '%s\n' "${inputs[@]}" | grep fleet | head -1)"

# `trace`: conformance suite, standard-library and user-spec fixtures.
trace_case() {
    local spec=$1 input=$2 name=$3
    local dir
    dir=$(dirname "$spec")
    (cd "$dir" && capture "$out/trace/$name" "$bin" trace "$spec" "$input")
}
if [ -d "$suite" ]; then
    while IFS= read -r spec; do
        input=${spec%.tessla}.input
        [ -f "$input" ] || continue
        rel=${spec#"$suite"/}
        trace_case "$spec" "$input" "suite_${rel//\//_}"
    done < <(find "$(realpath "$suite")" -name '*.tessla' | sort)
else
    echo "outputs.sh: no conformance suite at $suite; trace cases of the suite left out" >&2
fi
while IFS= read -r spec; do
    input=${spec%.tessla}.input
    [ -f "$input" ] || continue
    rel=${spec#"$root"/tests/fixtures/}
    trace_case "$spec" "$input" "fixture_${rel//\//_}"
done < <(find "$root/tests/fixtures/stdlib" "$root/tests/fixtures/userspecs" -name '*.tessla' | sort)

# `check` and `check --ir`: shipped specs, examples, broken specs.
while IFS= read -r spec; do
    rel=${spec#"$root"/}
    name=${rel//\//_}
    capture "$out/check/$name" "$bin" check "$spec"
    capture "$out/check/$name.ir" "$bin" check --ir "$spec"
done < <(find "$root/specs" "$root/examples" "$root/tests/fixtures/broken-specs" -name '*.tessla' | sort)

echo "outputs.sh: $(find "$out" -type f | wc -l) cases written to $out"
