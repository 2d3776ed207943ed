#!/usr/bin/env bash
# How the specs' steps run, over every spec in specs/, bench/ and TeSSLa's conformance suite that
# `check --ir` accepts (its last line says, and names the nodes): on the flat plan; on the general
# step because the plan would call compiled functions (nodes named: the calls); or on the general
# step because some nodes have no form in the plan at all (named). Prints one line per spec not
# on the plan, then the totals.
#
# Usage: bench/fallback_count.sh BINARY [SUITE]
set -uo pipefail
bin=$(realpath "$1")
root=$(cd "$(dirname "$0")/.." && pwd)
suite=${2:-${TESSLA_SUITE:-$root/../shared/tessla-suite}}
specs=0 planned=0 slow_specs=0 slow_nodes=0 nodes=0 call_specs=0 call_nodes=0
while IFS= read -r spec; do
    last=$(cd "$(dirname "$spec")" && "$bin" check --ir "$spec" 2>/dev/null | tail -n 1)
    case $last in
    "-- step: the flat plan"*)
        specs=$((specs + 1)) planned=$((planned + 1)) ;;
    "-- step: the general step"*"would call"*)
        specs=$((specs + 1)) call_specs=$((call_specs + 1))
        all=$(sed -E 's/.*for all ([0-9]+) nodes.*/\1/' <<<"$last")
        named=$(sed -E 's/.*: //' <<<"$last" | tr ',' '\n' | grep -c 'n[0-9]')
        nodes=$((nodes + all)) call_nodes=$((call_nodes + named))
        echo "${spec#"$root"/}: calls $named of $all nodes: ${last##*: }" ;;
    "-- step: the general step"*)
        specs=$((specs + 1)) slow_specs=$((slow_specs + 1))
        all=$(sed -E 's/.*for all ([0-9]+) nodes.*/\1/' <<<"$last")
        named=$(sed -E 's/.*: //' <<<"$last" | tr ',' '\n' | grep -c 'n[0-9]')
        nodes=$((nodes + all)) slow_nodes=$((slow_nodes + named))
        echo "${spec#"$root"/}: no form for $named of $all nodes: ${last##*: }" ;;
    esac
done < <({ find "$root/specs" "$root/bench" -maxdepth 1 -name '*.tessla'; [ -d "$suite" ] && find "$(realpath "$suite")" -name '*.tessla'; } | sort)
echo "specs checked: $specs; on the flat plan: $planned; on the general step for calls:" \
    "$call_specs ($call_nodes call nodes); on the general step for nodes without any form:" \
    "$slow_specs ($slow_nodes such nodes); $nodes nodes in the specs not on the plan"
