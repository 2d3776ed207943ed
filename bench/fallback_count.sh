#!/usr/bin/env bash
# How many nodes fall back to the general step (no form in the flat plan), over every spec in
# specs/, bench/ and TeSSLa's conformance suite that `check --ir` accepts: the last line of
# `check --ir` names them. Prints one line per spec that falls back, then the totals.
#
# Usage: bench/fallback_count.sh BINARY [SUITE]
set -uo pipefail
bin=$(realpath "$1")
root=$(cd "$(dirname "$0")/.." && pwd)
suite=${2:-${TESSLA_SUITE:-$root/../shared/tessla-suite}}
specs=0 planned=0 slow_specs=0 slow_nodes=0 nodes=0
while IFS= read -r spec; do
    last=$(cd "$(dirname "$spec")" && "$bin" check --ir "$spec" 2>/dev/null | tail -n 1)
    case $last in
    "-- step: the flat plan"*)
        specs=$((specs + 1)) planned=$((planned + 1)) ;;
    "-- step: the general step"*)
        specs=$((specs + 1)) slow_specs=$((slow_specs + 1))
        all=$(sed -E 's/.*for all ([0-9]+) nodes.*/\1/' <<<"$last")
        named=$(sed -E 's/.*: //' <<<"$last" | tr ',' '\n' | grep -c 'n[0-9]')
        nodes=$((nodes + all)) slow_nodes=$((slow_nodes + named))
        echo "${spec#"$root"/}: $named of $all nodes: ${last##*: }" ;;
    esac
done < <({ find "$root/specs" "$root/bench" -maxdepth 1 -name '*.tessla'; [ -d "$suite" ] && find "$(realpath "$suite")" -name '*.tessla'; } | sort)
echo "specs checked: $specs; on the flat plan: $planned; on the general step: $slow_specs" \
    "($slow_nodes nodes named as without a form, of the $nodes nodes those specs have)"
