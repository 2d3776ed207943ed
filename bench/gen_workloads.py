#!/usr/bin/env python3
"""Benchmark workloads for `make bench` and `make soak`: robot messages as Telegraf's
mqtt_consumer JSON parser makes them (README "The robot message"), fixed seed, standard library only.

Field order: Telegraf builds a metric's fields from a Go map, whose iteration order is randomised
on every message, so its line protocol carries the fields in a different order each time. The
default (`--order telegraf`) writes each record's fields in a fresh random order (seeded); the
`sorted` variant (fields by key, beams by index) is also written, to measure both paths. Tags are
sorted in both (Telegraf keeps a metric's tags sorted).

Workloads (files under --out, default target/bench-data/, each named by its size and the seed and
regenerated only when missing, so a second `make bench` reuses them):
  p2      N records with expectedSpeed and actualSpeed only (actualSpeed a string, as the paper's
          robot sends it), 100 Hz; also the same events as CSV for rtlola-cli (p2_*.csv).
  lidar   N full robot messages: both speeds, both angular speeds and a 360-beam scan (LDS-01
          dropouts as 0.0, dust spikes, an obstacle ahead), 5 Hz.
  fleet   R robots interleaved round by round (tag robot=tb3-NNNNN), K rounds; every robot sends
          speeds and angular speeds each round and a 360-beam scan every 5th round.
  stream  (`--stream`) the fleet shape written to stdout without end or for --records records,
          a scan every --scan-every rounds, for the soak test (nothing is stored).

Usage:
  python3 bench/gen_workloads.py [--out DIR] [--seed S] [--p2 N] [--lidar N]
                                 [--fleet-robots R] [--fleet-rounds K] [--order telegraf|sorted|both]
      # prints the file paths: p2 .lp, p2 .csv, lidar, fleet for each order (telegraf first)
  python3 bench/gen_workloads.py --stream --robots 1000 --records 10000000 [--seed S] [--order ...]
"""
import argparse
import math
import os
import random
import sys
from pathlib import Path

SEED = 20261123
T0 = 1_700_000_000_000_000_000
BEAMS = 360
SCAN_POOL = 64          # distinct scans; records pick from them (generation stays fast)
HEAD = "mqtt_consumer,host=turtlebot3,topic=tessla "


def fmt(x):
    """Telegraf's float form: shortest round trip, no exponent, no trailing .0."""
    s = repr(float(x))
    if "e" in s or "E" in s:
        s = f"{x:.17f}".rstrip("0").rstrip(".")
    if s.endswith(".0"):
        s = s[:-2]
    return s


def expected_speed(i, period):
    """The paper's speed steps 0.015..0.1 m/s, one step per `period` records."""
    steps = [0.015, 0.03, 0.05, 0.07, 0.1]
    return steps[(i // period) % len(steps)]


def speeds(rnd, i, period):
    """(expected, actual as written, expected angular, actual angular); stuck on a hill 10% of the time."""
    exp = expected_speed(i, period)
    stuck = (i // (period // 2)) % 10 == 3
    act = exp * 0.2 + rnd.uniform(-0.002, 0.002) if stuck else exp + rnd.uniform(-0.015, 0.015)
    return exp, f"{act:.4f}", 0.0, round(rnd.uniform(-0.02, 0.02), 4)


def scan_pool(rnd):
    """SCAN_POOL scans as field lists `lidar_0=..`, .., `lidar_359=..` with dropouts, spikes and an obstacle."""
    pool = []
    for k in range(SCAN_POOL):
        ahead = 0.2 + 1.8 * k / SCAN_POOL
        scan = []
        for b in range(BEAMS):
            base = ahead if (b >= 340 or b <= 20) else 2.5 + 0.3 * math.sin(math.radians(b * 3))
            scan.append(round(base + rnd.uniform(-0.01, 0.01), 3))
        for _ in range(4):
            scan[rnd.randrange(45, 315)] = 0.0  # LDS-01 no-return
        if k % 3 == 0:
            b = rnd.randrange(60, 300)
            scan[b] = round(scan[b] + 0.6, 3)  # a dust spike
        pool.append([f"lidar_{b}={fmt(v)}" for b, v in enumerate(scan)])
    return pool


class Order:
    """A record's fields in Telegraf's order (a fresh random order per record, from its own
    seeded generator so both orders carry the same values) or sorted (keys, then beam index)."""

    def __init__(self, order, seed):
        self.sorted = order == "sorted"
        self.rnd = random.Random(seed + 100)

    def join(self, fields):
        if self.sorted:
            return ",".join(fields)
        fields = list(fields)
        self.rnd.shuffle(fields)
        return ",".join(fields)


def robot_fields(rnd, i, period):
    """The speed fields of one robot message, sorted by key."""
    exp, act, exp_ang, act_ang = speeds(rnd, i, period)
    return [f"actualAngular={fmt(act_ang)}", f'actualSpeed="{act}"', f"expectedAngular={fmt(exp_ang)}",
            f"expectedSpeed={fmt(exp)}"]


def suffix(order):
    """`_telegraf` or `_sorted`: files cached by an older version (sorted, no suffix) are not reused."""
    return f"_{order}"


def write_p2(out, n, seed, order):
    lp, csv = out / f"p2_{n}_s{seed}{suffix(order)}.lp", out / f"p2_{n}_s{seed}{suffix(order)}.csv"
    o = Order(order, seed)
    if lp.exists() and csv.exists():
        return [lp, csv]
    rnd = random.Random(seed)
    tmp_lp, tmp_csv = lp.with_suffix(".lp.tmp"), csv.with_suffix(".csv.tmp")
    with open(tmp_lp, "w") as f, open(tmp_csv, "w") as g:
        g.write("time,expectedSpeed,actualSpeed\n")
        lines, rows = [], []
        for i in range(n):
            exp, act, _, _ = speeds(rnd, i, 500)
            ts = T0 + i * 10_000_000  # 100 Hz
            fields = o.join([f'actualSpeed="{act}"', f"expectedSpeed={fmt(exp)}"])
            lines.append(f"{HEAD}{fields} {ts}\n")
            rows.append(f"{i * 0.01:.2f},{fmt(exp)},{act}\n")
            if len(lines) >= 100_000:
                f.write("".join(lines))
                g.write("".join(rows))
                lines, rows = [], []
        f.write("".join(lines))
        g.write("".join(rows))
    os.replace(tmp_lp, lp)
    os.replace(tmp_csv, csv)
    return [lp, csv]


def write_lidar(out, n, seed, order):
    path = out / f"lidar_{n}_s{seed}{suffix(order)}.lp"
    o = Order(order, seed)
    if path.exists():
        return [path]
    rnd = random.Random(seed + 1)
    pool = scan_pool(rnd)
    tmp = path.with_suffix(".lp.tmp")
    with open(tmp, "w") as f:
        lines = []
        for i in range(n):
            ts = T0 + i * 200_000_000  # 5 Hz
            fields = robot_fields(rnd, i, 60) + pool[rnd.randrange(SCAN_POOL)]
            lines.append(f"{HEAD}{o.join(fields)} {ts}\n")
            if len(lines) >= 10_000:
                f.write("".join(lines))
                lines = []
        f.write("".join(lines))
    os.replace(tmp, path)
    return [path]


def fleet_lines(seed, robots, rounds=None, scan_every=5, order="telegraf"):
    """Fleet records: round by round, every robot once per round (its own clock offset), a
    360-beam scan in every `scan_every`-th round."""
    rnd = random.Random(seed + 2)
    o = Order(order, seed)
    pool = scan_pool(rnd)
    heads = [f"mqtt_consumer,host=dt,robot=tb3-{r:05d},topic=tessla " for r in range(robots)]
    step = max(1, 200_000_000 // robots)
    k = 0
    while rounds is None or k < rounds:
        with_scan = k % scan_every == 0
        for r in range(robots):
            ts = T0 + k * 200_000_000 + r * step
            scan = pool[(r + k) % SCAN_POOL] if with_scan else []
            yield f"{heads[r]}{o.join(robot_fields(rnd, k + r, 60) + scan)} {ts}\n"
        k += 1


def write_fleet(out, robots, rounds, seed, order):
    path = out / f"fleet_{robots}x{rounds}_s{seed}{suffix(order)}.lp"
    if path.exists():
        return [path]
    tmp = path.with_suffix(".lp.tmp")
    with open(tmp, "w") as f:
        lines = []
        for line in fleet_lines(seed, robots, rounds, order=order):
            lines.append(line)
            if len(lines) >= 10_000:
                f.write("".join(lines))
                lines = []
        f.write("".join(lines))
    os.replace(tmp, path)
    return [path]


def stream(robots, records, seed, scan_every, order):
    out = sys.stdout
    buf = []
    n = 0
    try:
        for line in fleet_lines(seed, robots, None, scan_every, order):
            if records is not None and n >= records:
                break
            buf.append(line)
            n += 1
            if len(buf) >= 1000:
                out.write("".join(buf))
                buf = []
        out.write("".join(buf))
        out.flush()
    except BrokenPipeError:
        pass


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="target/bench-data")
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--p2", type=int, default=1_000_000)
    ap.add_argument("--lidar", type=int, default=100_000)
    ap.add_argument("--fleet-robots", type=int, default=10_000)
    ap.add_argument("--fleet-rounds", type=int, default=20)
    ap.add_argument("--order", choices=["telegraf", "sorted", "both"], default="both",
                    help="field order of the files (both: telegraf's, then sorted); --stream: telegraf")
    ap.add_argument("--stream", action="store_true")
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--records", type=int)
    ap.add_argument("--scan-every", type=int, default=5, help="stream: a scan every N-th round")
    a = ap.parse_args()
    if a.stream:
        stream(a.robots, a.records, a.seed, a.scan_every, "sorted" if a.order == "sorted" else "telegraf")
        return
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for order in ["telegraf", "sorted"] if a.order == "both" else [a.order]:
        paths += write_p2(out, a.p2, a.seed, order) + write_lidar(out, a.lidar, a.seed, order) + write_fleet(
            out, a.fleet_robots, a.fleet_rounds, a.seed, order)
    for p in paths:
        print(p)


if __name__ == "__main__":
    main()
