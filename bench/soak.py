#!/usr/bin/env python3
"""Soak test (`make soak`, not in CI): 10 million records of the fleet workload (1,000 robots
interleaved, speeds every round, a 360-beam scan every 10th round; bench/gen_workloads.py --stream)
through the release binary with `--instance-by robot`, the child's RSS (/proc/PID/status VmRSS)
sampled every second. Memory must stay flat after warm-up.

Verdict: after warm-up (the first 20% of the samples), the peak RSS may exceed the peak RSS of the
warm-up by at most 5%: memory that returns to the allocator and is taken again (RSS going up and
down between levels the warm-up already reached) is not growth; a leak climbs past them. The RSS
at the end of warm-up and the least-squares slope over the rest are printed too.
Writes target/soak/rss.csv (seconds, RSS KiB) and target/soak/summary.md; exit 1 when not flat.

Usage: python3 bench/soak.py [--records N] [--robots R] [--scan-every K] [--bin PATH]
"""
import argparse
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def rss_kib(pid):
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def hwm_kib(pid):
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def slope(xs, ys):
    if len(xs) < 2:
        return 0.0
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    den = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / den if den else 0.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--records", type=int, default=10_000_000)
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--scan-every", type=int, default=10)
    ap.add_argument("--bin", default=str(ROOT / "target/release/tessla-telegraf"))
    ap.add_argument("--out", default=str(ROOT / "target/soak"))
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    gen = subprocess.Popen([sys.executable, str(ROOT / "bench/gen_workloads.py"), "--stream", "--robots",
                            str(a.robots), "--records", str(a.records), "--scan-every", str(a.scan_every)],
                           stdout=subprocess.PIPE)
    child = subprocess.Popen([a.bin, "run", "--instance-by", "robot"], stdin=gen.stdout,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    gen.stdout.close()
    counted = {"bytes": 0, "lines": 0}

    def drain():
        while chunk := child.stdout.read(1 << 20):
            counted["bytes"] += len(chunk)
            counted["lines"] += chunk.count(b"\n")

    stderr = []
    t_out = threading.Thread(target=drain)
    t_err = threading.Thread(target=lambda: stderr.append(child.stderr.read()))
    t_out.start()
    t_err.start()
    t0 = time.monotonic()
    samples = []
    hwm = None
    while child.poll() is None:
        r = rss_kib(child.pid)
        h = hwm_kib(child.pid)
        if r is not None:
            samples.append((time.monotonic() - t0, r))
            hwm = h or hwm
            if len(samples) % 30 == 0:
                print(f"  {samples[-1][0]:6.0f} s  RSS {r / 1024:6.1f} MB  output lines {counted['lines']:,}",
                      file=sys.stderr, flush=True)
        time.sleep(1.0)
    t_out.join()
    t_err.join()
    gen.wait()
    elapsed = time.monotonic() - t0
    err = b"".join(stderr).decode(errors="replace").strip().splitlines()
    summary_line = next((l for l in reversed(err) if "summary:" in l), "(no summary line)")
    with open(out / "rss.csv", "w") as f:
        f.write("seconds,rss_kib\n")
        for t, r in samples:
            f.write(f"{t:.1f},{r}\n")
    if len(samples) < 5:
        print("too few samples for a verdict", file=sys.stderr)
        sys.exit(1)
    warm = max(1, len(samples) // 5)
    base = max(r for _, r in samples[:warm])
    at_end_of_warm_up = samples[warm - 1][1]
    rest = samples[warm:]
    peak_after = max(r for _, r in rest)
    growth = (peak_after - base) / base
    sl = slope([t for t, _ in rest], [r for _, r in rest]) * 60 / 1024  # MB per minute
    flat = growth <= 0.05
    deciles = [samples[min(len(samples) - 1, i * len(samples) // 10)] for i in range(10)] + [samples[-1]]
    text = [
        f"Soak: {a.records:,} records, {a.robots:,} robots interleaved, a 360-beam scan every {a.scan_every}th "
        f"round, `tessla-telegraf run --instance-by robot` (pass-through on), exit code {child.returncode}.",
        f"Run time {elapsed:.0f} s ({a.records / elapsed:,.0f} records/s wall, generator included); "
        f"{len(samples)} RSS samples, one per second.",
        f"Child's summary: `{summary_line.strip()}`; output lines read: {counted['lines']:,}.",
        "",
        "| time s | RSS MB |", "|---|---|",
        *[f"| {t:.0f} | {r / 1024:.1f} |" for t, r in deciles],
        "",
        f"Warm-up: first {warm} samples (20%). Peak RSS in warm-up {base / 1024:.1f} MB (at its end "
        f"{at_end_of_warm_up / 1024:.1f} MB); peak after warm-up {peak_after / 1024:.1f} MB ({growth * 100:+.1f}% "
        f"over the warm-up's peak); slope after warm-up {sl:+.3f} MB/min; "
        f"VmHWM {((hwm or 0) / 1024):.1f} MB.",
        f"Verdict: {'FLAT' if flat else 'NOT FLAT'} (limit: +5% over the warm-up's peak).",
    ]
    (out / "summary.md").write_text("\n".join(text) + "\n")
    print("\n".join(text))
    sys.exit(0 if flat and child.returncode == 0 else 1)


if __name__ == "__main__":
    main()
