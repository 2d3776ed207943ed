#!/usr/bin/env python3
"""Whole-process benchmarks of tessla-telegraf against its baselines, side by side in one run
(`make bench` calls this after the criterion benches; figures go to BENCHMARKS.md).

For each workload of bench/gen_workloads.py (fixed seed; fields in Telegraf's random order, and
tessla-telegraf also on the same records with sorted fields), every command reads the workload from a
pipe (`cat FILE | CMD > /dev/null`, as Telegraf's execd feeds its child) and is timed by GNU time
(`/usr/bin/time -f '%e %U %S %M'`: wall, user, system seconds, peak RSS in KiB), REPS times; the
tables show medians. Rows:
  cat            the pipe floor (`cat` copying the same bytes)
  parse-only     crates/lineproto splitting + parsing, nothing evaluated or written (bench/parse_only.rs)
  tessla-telegraf  `tessla-telegraf run` (pass-through on), stdin to stdout; the fleet with
                   `--threads 1`, `--threads 2` and the default (the machine's cores)
  python P2      bench/p2_processor.py (the paper's DT language, standard library only), P2 only
  rtlola-cli     `rtlola-cli monitor` on bench/p2.lola over the same events as CSV, P2 only
Two `trace` yardsticks from public data in ../shared/corpora (skipped with a note without it):
  primes         VAMOS primes.tessla over its 80k-event trace x10 (timestamps shifted), against
                 the monitor TeSSLa 1.2.3's Rust back end compiled from the same spec (built
                 apart, see BENCHMARKS.md; its path in $TESSLA_PRIMES_MONITOR, else left out)
  auction        bench/auction.tessla (CRV 2016 Auction, one Map) over the three 84,780-event
                 traces, and on the first --auction-prefix events of the first trace beside
                 rtlola-cli on bench/auction.lola (far slower, so a prefix)
Also: spec load (start-up of `run` on empty input), answer latency at 1k and 10k lines/s
(bench/latency.rs) beside its floor (the same tool's `--echo` child, which only echoes each line), and a check that the Python baseline writes exactly what tessla-telegraf writes.

With --base BINARY (another tessla-telegraf, e.g. main's built in the same session into its own
target dir), the primes and Auction sections run it beside this tree's binary, and every command of
those sections is measured alternately (paired runs: one run of each in turn, REPS rounds), so a
ratio is not skewed by load that changes between the commands. The binary is
$CARGO_TARGET_DIR/release/tessla-telegraf (target/ without it).

Usage: python3 bench/run.py [--reps N] [--no-build] [--no-rtlola] [--latency-reps N] [--latency-only]
                           [--only p2,lidar,fleet,startup,latency,primes,auction]
                           [--auction-prefix N] [--base BINARY] [--out target/bench-results.md]
"""
import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET = Path(os.environ.get("CARGO_TARGET_DIR") or ROOT / "target")
BIN = TARGET / "release/tessla-telegraf"
EXAMPLES = TARGET / "release/examples"
P2_SPEC = ROOT / "bench/p2.tessla"
P2_LOLA = ROOT / "bench/p2.lola"
AUCTION_SPEC = ROOT / "bench/auction.tessla"
AUCTION_LOLA = ROOT / "bench/auction.lola"
CORPORA = ROOT.parent / "shared/corpora"
PRIMES_DIR = CORPORA / "tessla-wild2/vamos-shamon/930b14d/experiments/tessla_compare"
AUCTION_DIR = CORPORA / "perf-anchors/PRECISE-SMEDL/b0096d1/tests/monitors/auction"
SECTIONS = ["p2", "lidar", "fleet", "startup", "latency", "primes", "auction"]
TIME = "/usr/bin/time"


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def build():
    log("== building the release binary and bench tools")
    subprocess.run(["cargo", "build", "--release", "--bin", "tessla-telegraf", "--example", "parse_only",
                    "--example", "latency"], cwd=ROOT, check=True)


def find_rtlola(install):
    """rtlola-cli on PATH or in ~/.cargo/bin; installed with `cargo install rtlola-cli` when missing."""
    cands = [shutil.which("rtlola-cli"), str(Path.home() / ".cargo/bin/rtlola-cli")]
    for c in cands:
        if c and Path(c).exists():
            return c
    if not install:
        return None
    log("== rtlola-cli missing: cargo install rtlola-cli --version 0.1.2 (a baseline only, never a dependency)")
    r = subprocess.run(["cargo", "install", "rtlola-cli", "--version", "0.1.2"], cwd=tempfile.gettempdir())
    if r.returncode != 0:
        log("rtlola-cli could not be installed; its rows are left out")
        return None
    return find_rtlola(False)


def rtlola_cmd(exe, verbosity):
    """rtlola-cli 0.1.x: offline monitoring of the CSV trace on stdin (column `time`, seconds
    relative to the start: rtlola-cli's `--offline relative`). `outputs` writes every output's new
    value (the work comparable to our verdict lines); `silent` only evaluates."""
    return [exe, "monitor", "--offline", "relative", "--stdin", "--verbosity", verbosity, str(P2_LOLA)]


def timed(cmd, input_path):
    """One run of `cat input | cmd > /dev/null`: (wall s, user s, sys s, peak RSS KiB)."""
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
        cat = subprocess.Popen(["cat", str(input_path)], stdout=subprocess.PIPE)
        t0 = time.perf_counter()
        p = subprocess.run([TIME, "-f", "%e %U %S %M", "-o", tf.name, *cmd], stdin=cat.stdout,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        wall = time.perf_counter() - t0
        cat.stdout.close()
        cat.wait()
        if p.returncode != 0:
            raise RuntimeError(f"{cmd} exited {p.returncode}: {p.stderr.decode()[-500:]}")
        fields = tf.read().split()[-4:]
        _, user, sys_, rss = (float(x) for x in fields)
        return wall, user, sys_, rss


def measure(name, cmd, input_path, records, reps):
    runs = [timed(cmd, input_path) for _ in range(reps)]
    med = [statistics.median(x) for x in zip(*runs)]
    wall, user, sys_, rss = med
    cpu = user + sys_
    row = {"name": name, "wall": wall, "cpu": cpu, "rss_mb": rss / 1024, "records": records,
           "rate": records / wall if wall > 0 else float("inf"),
           "cpu_rate": records / cpu if cpu > 0 else float("inf"), "walls": [r[0] for r in runs]}
    log(f"   {name:<34} wall {wall:7.3f} s  cpu {cpu:7.3f} s  {row['rate']:>12,.0f}/s  "
        f"{row['cpu_rate']:>12,.0f}/cpu-s  rss {row['rss_mb']:6.1f} MB")
    return row


def measure_paired(cmds, input_path, records, reps):
    """Rows of several commands run alternately: round k runs each command once, in turn."""
    runs = {name: [] for name, _ in cmds}
    for _ in range(reps):
        for name, cmd in cmds:
            runs[name].append(timed(cmd, input_path))
    rows = []
    for name, _ in cmds:
        med = [statistics.median(x) for x in zip(*runs[name])]
        wall, user, sys_, rss = med
        cpu = user + sys_
        rows.append({"name": name, "wall": wall, "cpu": cpu, "rss_mb": rss / 1024, "records": records,
                     "rate": records / wall if wall > 0 else float("inf"),
                     "cpu_rate": records / cpu if cpu > 0 else float("inf"),
                     "walls": [r[0] for r in runs[name]]})
        log(f"   {name:<34} wall {wall:7.3f} s  cpu {cpu:7.3f} s  {rows[-1]['rate']:>12,.0f}/s  "
            f"{rows[-1]['cpu_rate']:>12,.0f}/cpu-s  rss {rows[-1]['rss_mb']:6.1f} MB (paired)")
    return rows


def count_lines(path):
    n = 0
    with open(path, "rb") as f:
        while chunk := f.read(1 << 24):
            n += chunk.count(b"\n")
    return n


def fmt_rate(x):
    if x == float("inf"):
        return "-"
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.0f} k"


def table(title, unit, rows, ours):
    """Markdown table; ratios are tessla-telegraf's rate over the row's (>1: we are faster)."""
    out = [f"### {title}", "",
           f"| command | wall s (median) | {unit}/s wall | {unit}/s per CPU-second | peak RSS MB | ours vs this (wall) | ours vs this (CPU) |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        rw = ours["rate"] / r["rate"] if r["rate"] else float("nan")
        rc = ours["cpu_rate"] / r["cpu_rate"] if r["cpu_rate"] not in (0, float("inf")) else float("nan")
        out.append(f"| {r['name']} | {r['wall']:.3f} | {fmt_rate(r['rate'])} | {fmt_rate(r['cpu_rate'])} | "
                   f"{r['rss_mb']:.1f} | {rw:.2f}x | {'-' if rc != rc else f'{rc:.2f}x'} |")
    return "\n".join(out) + "\n"


def startup(cmd, reps=21):
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       check=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1000


def same_output(p2_lp, n=20_000):
    """Python baseline and tessla-telegraf give byte-identical output on the first n P2 records."""
    with open(p2_lp, "rb") as f:
        head = b"".join(line for _, line in zip(range(n), f))
    ours = subprocess.run([str(BIN), "run", "--spec", str(P2_SPEC)], input=head, capture_output=True).stdout
    py = subprocess.run([sys.executable, str(ROOT / "bench/p2_processor.py")], input=head,
                        capture_output=True).stdout
    return ours == py and len(ours) > len(head)


def latency_run(rate, secs, prefix, echo=False):
    """One run of bench/latency.rs (P2 spec; with `echo`, its own `--echo` child, the floor): its key=value
    line as a dict."""
    child = ["--bin", str(EXAMPLES / "latency"), "--", "--echo"] if echo else \
        ["--bin", str(BIN), "--", "run", "--spec", str(P2_SPEC)]
    r = subprocess.run([*prefix, str(EXAMPLES / "latency"), "--rate", str(rate), "--seconds", str(secs), *child],
                       capture_output=True, text=True, check=True).stdout.strip()
    log(f"   {' '.join(prefix)} {r}".strip())
    return dict(x.split("=", 1) for x in r.split())


def latency_section(reps):
    """Answer latency, each configuration `reps` times; the table shows the median of each percentile
    over the runs, the range of the runs' p99, and the load average (1 min) before and after."""
    log("== latency (bench/latency.rs, P2 spec, pass-through on)")
    lines = ["### Answer latency: write a record into stdin -> read its verdict line (P2 spec)", "",
             f"Each row: {reps} runs, the median of each percentile over the runs, the runs' p99 range, and "
             "the load average (1 min) before and after the row.", "",
             "| rate | runs x records | p50 µs | p90 µs | p99 µs | p99 range µs | p99.9 µs | max µs | load before/after |",
             "|---|---|---|---|---|---|---|---|---|"]
    # Rows: as Telegraf would run us; at 10k/s; the tool and the child pinned to one core (`taskset`),
    # so that a wake-up never waits for the other virtual CPU to be scheduled by the host; and at
    # real-time priority (`chrt -f 50`, inherited by the child; needs root or CAP_SYS_NICE), so that
    # other processes cannot delay a wake-up. Rows whose tool is missing or refused are left out.
    last_cpu = str((os.cpu_count() or 1) - 1)
    # The floor first: a child that only echoes each line (`latency --echo`), the same pipes and
    # wake-ups without any work; a percentile of ours below the floor's is out of our hands.
    runs = [("floor: an echo child (`latency --echo`), 1,000/s", 1000, 10, [], True),
            ("1,000/s", 1000, 10, [], False), ("10,000/s", 10000, 5, [], False)]
    if shutil.which("taskset") and subprocess.run(["taskset", "-c", last_cpu, "true"],
                                                  capture_output=True).returncode == 0:
        runs.append((f"1,000/s, pinned to CPU {last_cpu} (`taskset -c {last_cpu}`)", 1000, 10,
                     ["taskset", "-c", last_cpu], False))
    if shutil.which("chrt") and subprocess.run(["chrt", "-f", "50", "true"], capture_output=True).returncode == 0:
        runs.append(("1,000/s (`chrt -f 50`)", 1000, 10, ["chrt", "-f", "50"], False))
    for label, rate, secs, prefix, echo in runs:
        before = os.getloadavg()[0]
        kvs = [latency_run(rate, secs, prefix, echo) for _ in range(reps)]
        after = os.getloadavg()[0]

        def med(key):
            return statistics.median(float(kv[key]) for kv in kvs)

        p99s = sorted(float(kv["p99_us"]) for kv in kvs)
        lines.append(f"| {label} | {reps} x {kvs[0]['measured']} | {med('p50_us'):.1f} | {med('p90_us'):.1f} | "
                     f"{med('p99_us'):.1f} | {p99s[0]:.1f} to {p99s[-1]:.1f} | {med('p999_us'):.1f} | "
                     f"{med('max_us'):.1f} | {before:.1f} / {after:.1f} |")
    lines.append("")
    return "\n".join(lines) + "\n"


def primes_section(reps, base=None):
    """VAMOS primes x10 through `trace`, beside TeSSLa's compiled monitor when it is given."""
    spec, src = PRIMES_DIR / "primes.tessla", PRIMES_DIR / "gen_tessla_input/primes.in"
    title = "### Trace: VAMOS primes.tessla, its 80,000-event trace x10 (timestamps shifted)\n"
    if not src.exists():
        log(f"== primes: SKIPPED ({src} not found)")
        return f"{title}\nSkipped: {src} not found (../shared/corpora).\n"
    data = ROOT / "target/bench-data/primes_x10.in"
    if not data.exists():
        data.parent.mkdir(parents=True, exist_ok=True)
        lines = src.read_text().splitlines()
        with open(data, "w") as f:
            for k in range(10):
                for line in lines:
                    ts, rest = line.split(":", 1)
                    f.write(f"{int(ts) + 40000 * k}:{rest}\n")
    n = count_lines(data)
    log(f"== primes: {n:,} events")
    peer = os.environ.get("TESSLA_PRIMES_MONITOR")
    note = ""
    cmds = [("cat (pipe floor)", ["cat"]), ("tessla-telegraf trace primes.tessla (stdin)", [str(BIN), "trace", str(spec)])]
    if base:
        cmds.append((f"base: {base} trace primes.tessla", [str(base), "trace", str(spec)]))
    if peer and Path(peer).exists():
        cmds.append(("TeSSLa 1.2.3 compiled monitor (Rust back end)", [peer]))
    rows = measure_paired(cmds, data, n, reps)
    ours = rows[1]
    if peer and Path(peer).exists():
        mine = subprocess.run([str(BIN), "trace", str(spec), str(data)], capture_output=True).stdout
        with open(data, "rb") as f:
            theirs = subprocess.run([peer], stdin=f, capture_output=True).stdout
        same = "yes" if mine == theirs else "NO"
        note = f"Outputs byte-identical: {same} ({len(mine.splitlines()):,} lines).\n"
    else:
        log("   TeSSLa's compiled monitor: SKIPPED (set TESSLA_PRIMES_MONITOR to its binary)")
        note = ("TeSSLa's compiled monitor left out: set TESSLA_PRIMES_MONITOR to the binary built from "
                "ista-vamos/shamon experiments/tessla_compare/primes_tessla (BENCHMARKS.md).\n")
    return table(title[4:].strip(), "events", rows, ours) + note


def auction_section(reps, rtlola, prefix, base=None):
    """bench/auction.tessla on the CRV traces; rtlola-cli on a prefix, beside ours on it."""
    title = "### Auction (CRV 2016, one Map of item states): bench/auction.tessla, bench/auction.lola\n"
    traces = [AUCTION_DIR / f"auction_trace_invalid{i}" for i in (1, 2, 3)]
    if not traces[0].exists():
        log(f"== auction: SKIPPED ({AUCTION_DIR} not found)")
        return f"{title}\nSkipped: {AUCTION_DIR} not found (../shared/corpora).\n"
    data = ROOT / "target/bench-data"
    data.mkdir(parents=True, exist_ok=True)
    conv = []
    for t in traces:
        tin, tcsv = data / f"{t.name}.input", data / f"{t.name}.csv"
        subprocess.run([sys.executable, str(ROOT / "bench/auction_trace.py"), str(t), str(tin), str(tcsv)],
                       check=True)
        conv.append((t.name, tin, tcsv))
    # The prefix: the first `prefix` events in both formats (the CSV keeps its header).
    name, tin, tcsv = conv[0]
    pin, pcsv = data / f"{name}_{prefix}.input", data / f"{name}_{prefix}.csv"
    with open(tin) as f:
        pin.write_text("".join(line for _, line in zip(range(prefix), f)))
    with open(tcsv) as f:
        pcsv.write_text("".join(line for _, line in zip(range(prefix + 1), f)))
    out = []
    rows = []
    for name, tin, _ in conv:
        n = count_lines(tin)
        log(f"== auction: {name}, {n:,} events")
        cmds = [(f"tessla-telegraf trace auction.tessla, {name}", [str(BIN), "trace", str(AUCTION_SPEC)])]
        if base:
            cmds.append((f"base: {base}, {name}", [str(base), "trace", str(AUCTION_SPEC)]))
        rows.extend(measure_paired(cmds, tin, n, reps))
    out.append(table(title[4:].strip() + ", whole traces", "events", rows, rows[0]))
    log(f"== auction: the first {prefix:,} events of {conv[0][0]}")
    ours = measure(f"tessla-telegraf trace auction.tessla, first {prefix:,}", [str(BIN), "trace", str(AUCTION_SPEC)],
                   pin, prefix, reps)
    rows = [ours]
    if rtlola:
        cmd = [rtlola, "monitor", "--offline", "relative", "--stdin", "--verbosity", "violations", str(AUCTION_LOLA)]
        try:
            rows.append(measure(f"rtlola-cli monitor bench/auction.lola, first {prefix:,}", cmd, pcsv, prefix,
                                max(1, min(reps, 3))))
        except RuntimeError as e:
            log(f"rtlola-cli failed: {e}")
    out.append(table(f"Auction, the first {prefix:,} events of {conv[0][0]} (rtlola-cli on all of it would "
                     f"take minutes)", "events", rows, ours))
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--no-rtlola", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "target/bench-results.md"))
    ap.add_argument("--latency-reps", type=int, default=3, help="runs of each latency row (median shown)")
    ap.add_argument("--latency-only", action="store_true", help="only the latency table (after the build)")
    ap.add_argument("--only", default=",".join(SECTIONS), help="comma-separated sections: " + ",".join(SECTIONS))
    ap.add_argument("--base", default=None,
                    help="another tessla-telegraf binary run beside ours, paired, in the primes and auction sections")
    ap.add_argument("--auction-prefix", type=int, default=10_000,
                    help="events of the first Auction trace that rtlola-cli and ours both run")
    a = ap.parse_args()
    only = set(a.only.split(","))
    if only - set(SECTIONS):
        ap.error(f"unknown sections {sorted(only - set(SECTIONS))}")
    if not a.no_build:
        build()
    if a.latency_only:
        text = latency_section(a.latency_reps)
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(text)
        print(text)
        return
    rtlola = None if a.no_rtlola else find_rtlola(True)
    log("== generating workloads (cached in target/bench-data)")
    paths = subprocess.run([sys.executable, str(ROOT / "bench/gen_workloads.py"), "--out",
                            str(ROOT / "target/bench-data")], check=True, capture_output=True,
                           text=True).stdout.split()
    # Telegraf's field order first, then the same records with sorted fields.
    p2_lp, p2_csv, lidar_lp, fleet_lp, p2_sorted, _, lidar_sorted, fleet_sorted = (Path(p) for p in paths)
    parse_only = [str(EXAMPLES / "parse_only")]
    ours = [str(BIN), "run"]
    report = [f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {platform.node()} "
              f"({os.cpu_count()} CPUs, {platform.machine()}, load average at start "
              f"{os.getloadavg()[0]:.1f}); {a.reps} runs each, medians. Input through a pipe from `cat`, "
              f"output to /dev/null; pass-through on. Fields in Telegraf's random order unless a row says "
              f"sorted.", ""]

    if "p2" in only:
        log(f"== P2: {p2_lp.name}")
        n = count_lines(p2_lp)
        rows = [measure("cat (pipe floor)", ["cat"], p2_lp, n, a.reps),
                measure("parse-only (lineproto)", parse_only, p2_lp, n, a.reps)]
        ours_p2 = measure("tessla-telegraf run --spec bench/p2.tessla", [*ours, "--spec", str(P2_SPEC)], p2_lp, n,
                          a.reps)
        rows.append(ours_p2)
        rows.append(measure("same, fields sorted", [*ours, "--spec", str(P2_SPEC)], p2_sorted, n, a.reps))
        # The shipped P2 monitor: the same verdicts plus the action metric (what rtlola-cli's
        # p2_action stream computes), the row issue 35's "4x rtlola-cli with the action" reads.
        rows.append(measure("tessla-telegraf run --spec specs/p2_tolerance.tessla (with the action)",
                            [*ours, "--spec", str(ROOT / "specs/p2_tolerance.tessla")], p2_lp, n, a.reps))
        rows.append(measure("tessla-telegraf run (robot spec)", ours, p2_lp, n, a.reps))
        rows.append(measure("python3 bench/p2_processor.py", [sys.executable, str(ROOT / "bench/p2_processor.py")],
                            p2_lp, n, a.reps))
        if rtlola:
            for verbosity in ["outputs", "silent"]:
                try:
                    rows.append(measure(f"rtlola-cli monitor bench/p2.lola, CSV, --verbosity {verbosity}",
                                        rtlola_cmd(rtlola, verbosity), p2_csv, n, a.reps))
                except RuntimeError as e:
                    log(f"rtlola-cli failed: {e}")
        report.append(table(f"P2: {n:,} records (expectedSpeed, actualSpeed)", "records", rows, ours_p2))
        report.append(f"Python baseline output byte-identical to tessla-telegraf's on the first 20,000 records: "
                      f"{'yes' if same_output(p2_lp) else 'NO'}\n")

    if "lidar" in only:
        log(f"== lidar: {lidar_lp.name}")
        n = count_lines(lidar_lp)
        rows = [measure("cat (pipe floor)", ["cat"], lidar_lp, n, a.reps),
                measure("parse-only (lineproto)", parse_only, lidar_lp, n, a.reps)]
        ours_l = measure("tessla-telegraf run (robot spec: P1, P2, P3)", ours, lidar_lp, n, a.reps)
        rows.append(ours_l)
        rows.append(measure("same, fields sorted", ours, lidar_sorted, n, a.reps))
        report.append(table(f"Lidar: {n:,} robot messages with 360 beams", "scans", rows, ours_l))

    if "fleet" in only:
        log(f"== fleet: {fleet_lp.name}")
        n = count_lines(fleet_lp)
        rows = [measure("cat (pipe floor)", ["cat"], fleet_lp, n, a.reps),
                measure("parse-only (lineproto)", parse_only, fleet_lp, n, a.reps)]
        one = [*ours, "--instance-by", "robot", "--threads", "1"]
        ours_f = measure("tessla-telegraf run --instance-by robot --threads 1", one, fleet_lp, n, a.reps)
        rows.append(ours_f)
        rows.append(measure("same, fields sorted", one, fleet_sorted, n, a.reps))
        rows.append(measure("same, --threads 2", [*ours, "--instance-by", "robot", "--threads", "2"], fleet_lp, n,
                            a.reps))
        rows.append(measure(f"same, default --threads (the machine's {os.cpu_count()} cores)",
                            [*ours, "--instance-by", "robot"], fleet_lp, n, a.reps))
        report.append(table(f"Fleet: {n:,} records from 10,000 robots interleaved (robot spec)", "records", rows,
                            ours_f))

    if "startup" in only:
        log("== spec load (start-up on empty input)")
        lines = ["### Spec load: start-up of the whole process on empty input (median of 21)", "",
                 "| command | ms |", "|---|---|"]
        for name, cmd in [("tessla-telegraf run --spec bench/p2.tessla", [*ours, "--spec", str(P2_SPEC)]),
                          ("tessla-telegraf run (bundled robot spec)", ours), ("true (process floor)", ["true"])]:
            ms = startup(cmd)
            log(f"   {name:<44} {ms:.2f} ms")
            lines.append(f"| {name} | {ms:.2f} |")
        if rtlola:
            empty = Path(tempfile.gettempdir()) / "p2_empty.csv"
            empty.write_text("time,expectedSpeed,actualSpeed\n")
            cmd = [rtlola, "monitor", "--offline", "relative", "--csv-in", str(empty), "--verbosity", "silent",
                   str(P2_LOLA)]
            try:
                ms = startup(cmd, 5)
                lines.append(f"| rtlola-cli monitor bench/p2.lola | {ms:.2f} |")
            except subprocess.CalledProcessError as e:
                log(f"rtlola start-up failed: {e}")
        report.append("\n".join(lines) + "\n")

    if "primes" in only:
        report.append(primes_section(a.reps, a.base))
    if "auction" in only:
        report.append(auction_section(a.reps, rtlola, a.auction_prefix, a.base))
    if "latency" in only:
        report.append(latency_section(a.latency_reps))

    text = "\n".join(report)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(text)
    print(text)
    log(f"== written to {a.out}")


if __name__ == "__main__":
    main()
