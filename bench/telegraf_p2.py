#!/usr/bin/env python3
"""P2 inside one Telegraf: tessla-telegraf's processors.execd against the same P2 written for
processors.starlark (bench/p2.star), paired, in the same Telegraf (`make bench-telegraf`).

Each run is `telegraf --once` on a conf `inputs.file` (N P2 records of bench/gen_workloads.py) ->
processor -> `outputs.discard`; its CPU (user + system of Telegraf and its child, from the
rusage of the waited-for processes) less the CPU of the same conf without a processor (the
floor, measured in the same round) is the processor's cost; divided by N, per record. The
variants, one round each in turn, `--reps` rounds; medians over the rounds and the ratio to
Starlark's cost in the same round:

  floor            no processor
  starlark         processors.starlark, bench/p2.star
  execd echo       processors.execd, `run --spec specs/p2_tolerance.tessla` (pass-through: the
                   record, the verdicts and the action written back and parsed again by Telegraf)
  execd clone      processors.clone (order 1, tags the copy) -> processors.execd (order 2, takes
                   only the tagged copy, removes the tag) with --no-passthrough: the original
                   goes round the processor; Telegraf parses only the verdicts and the action
  clone+upstream   the same with `influx_parser_type = "upstream"` on processors.execd
  execd alone      processors.execd with --no-passthrough and no clone: the record is not kept
                   (the NATS partition confs, whose only output takes the actions); not the
                   same output as Starlark's, so no ratio
  (and, after the table, our binary alone on the same records, without Telegraf)
  clone+null child the clone wiring with a child that reads and writes nothing (`cat >
                   /dev/null`): what feeding any execd child costs Telegraf, before any output
  starlark 1       bench/p2.star with `one_metric = true`: the verdicts inside the action metric
  clone 1          execd clone running bench/p2_one_metric.tessla: the same one metric

  python3 bench/telegraf_p2.py [--telegraf PATH] [--bin PATH] [--records N] [--reps R]
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
import gen_workloads  # noqa: E402

SPEC = ROOT / "specs/p2_tolerance.tessla"
ONE_METRIC = ROOT / "bench/p2_one_metric.tessla"
STAR = ROOT / "bench/p2.star"


def default_telegraf():
    if os.environ.get("TELEGRAF_BIN"):
        return os.environ["TELEGRAF_BIN"]
    cache = os.environ.get("TELEGRAF_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "tessla-telegraf/telegraf")
    return os.path.join(cache, "v1.39.3", "telegraf")


def toml_list(args):
    return "[" + ", ".join('"' + a.replace("\\", "\\\\").replace('"', '\\"') + '"' for a in args) + "]"


def processors(variant, binary):
    spec = ONE_METRIC if variant.endswith(" 1") else SPEC
    run = [binary, "run", "--spec", str(spec), "--log-level", "warn"]
    if variant == "floor":
        return ""
    if variant.startswith("starlark"):
        one = "true" if variant.endswith(" 1") else "false"
        return (f'[[processors.starlark]]\n  namepass = ["mqtt_consumer"]\n  script = "{STAR}"\n'
                f'  [processors.starlark.constants]\n    one_metric = {one}\n')
    if variant == "clone+null child":
        return processors("execd clone", binary).replace(
            toml_list(run + ["--no-passthrough"]), toml_list(["sh", "-c", "cat > /dev/null"]))
    if variant == "execd alone":
        return (f'[[processors.execd]]\n  namepass = ["mqtt_consumer"]\n'
                f'  command = {toml_list(run + ["--no-passthrough"])}\n')
    if variant == "execd echo":
        return (f'[[processors.execd]]\n  namepass = ["mqtt_consumer"]\n  command = {toml_list(run)}\n')
    upstream = '  influx_parser_type = "upstream"\n' if variant == "clone+upstream" else ""
    return ('[[processors.clone]]\n  order = 1\n  namepass = ["mqtt_consumer"]\n'
            '  [processors.clone.tags]\n    tessla_copy = "1"\n'
            '[[processors.execd]]\n  order = 2\n  namepass = ["mqtt_consumer"]\n'
            f'  command = {toml_list(run + ["--no-passthrough"])}\n{upstream}'
            '  tagexclude = ["tessla_copy"]\n  [processors.execd.tagpass]\n    tessla_copy = ["1"]\n')


def conf(variant, binary, records, n, output):
    return ('[agent]\n  interval = "1h"\n  flush_interval = "1h"\n  omit_hostname = true\n  precision = "1ns"\n'
            f'  metric_batch_size = 10000\n  metric_buffer_limit = {4 * n + 10000}\n'
            '  skip_processors_after_aggregators = true\n'
            f'[[inputs.file]]\n  files = ["{records}"]\n  data_format = "influx"\n'
            f'  name_override = "mqtt_consumer"\n{processors(variant, binary)}{output}')


def cpu_of(telegraf, path):
    """CPU seconds (user + system) of `telegraf --once` and the child it waited for."""
    before = os.times()
    subprocess.run([telegraf, "--config", str(path), "--once"], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = os.times()
    return (after.children_user - before.children_user) + (after.children_system - before.children_system)


VARIANTS = ["floor", "starlark", "execd echo", "execd clone", "clone+upstream", "execd alone", "clone+null child",
            "starlark 1", "clone 1"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--telegraf", default=default_telegraf())
    ap.add_argument("--bin", default=str(ROOT / "target/release/tessla-telegraf"))
    ap.add_argument("--records", type=int, default=200_000)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    a = ap.parse_args()
    variants = a.variants.split(",")
    if variants[0] != "floor":
        variants.insert(0, "floor")
    out_dir = ROOT / "target/bench-data"
    out_dir.mkdir(parents=True, exist_ok=True)
    records = gen_workloads.write_p2(out_dir, a.records, gen_workloads.SEED, "telegraf")[0]
    version = subprocess.run([a.telegraf, "--version"], capture_output=True, text=True).stdout.strip()
    print(f"# P2 inside one {version}: inputs.file ({a.records} records) -> processor -> outputs.discard, "
          f"{a.reps} paired rounds", flush=True)
    cpu = {v: [] for v in variants}
    with tempfile.TemporaryDirectory() as tmp:
        paths = {}
        for v in variants:
            paths[v] = Path(tmp) / (v.replace(" ", "_").replace("+", "_") + ".conf")
            paths[v].write_text(conf(v, a.bin, records, a.records, "[[outputs.discard]]\n"))
        for r in range(a.reps):
            # Each round starts at another variant, so no variant always follows the same one.
            order = variants[r % len(variants):] + variants[:r % len(variants)]
            for v in order:
                cpu[v].append(cpu_of(a.telegraf, paths[v]))
            print(f"round {r + 1}: " + ", ".join(f"{v} {cpu[v][-1]:.2f} s" for v in variants), flush=True)
    per = {v: [(cpu[v][i] - cpu["floor"][i]) / a.records * 1e6 for i in range(a.reps)] for v in variants}
    print(f"\n| variant | CPU s (median) | µs/record above the floor (median) | ratio to Starlark (same output; median of rounds) |")
    print("|---|---|---|---|")
    for v in variants:
        ratio = "-"
        base = "starlark 1" if v.endswith(" 1") else "starlark"
        if v not in ("floor", "execd alone", "clone+null child") and not v.startswith("starlark") and base in per:
            ratio = f"{statistics.median(p / s for p, s in zip(per[v], per[base])):.2f}"
        above = "-" if v == "floor" else f"{statistics.median(per[v]):.2f}"
        print(f"| {v} | {statistics.median(cpu[v]):.2f} | {above} | {ratio} |")
    # Our child's own share: the binary alone on the same records (no Telegraf), CPU per record.
    alone = []
    for _ in range(a.reps):
        with open(records, "rb") as f:
            before = os.times()
            subprocess.run([a.bin, "run", "--spec", str(SPEC), "--no-passthrough", "--log-level", "warn"],
                           stdin=f, stdout=subprocess.DEVNULL, check=True)
            after = os.times()
        alone.append((after.children_user - before.children_user) + (after.children_system - before.children_system))
    print(f"\nour binary alone (no Telegraf), `run --spec specs/p2_tolerance.tessla --no-passthrough` on the "
          f"same records: {statistics.median(alone) / a.records * 1e6:.2f} µs/record (median of {a.reps})")


if __name__ == "__main__":
    main()
