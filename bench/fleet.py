#!/usr/bin/env python3
"""The fleet level's cost (docs/fleet.md, "Cost"; BENCHMARKS.md, "Fleet level").

1. Cost per record: N robots (1k, 10k) each sending R records at 5 Hz, time-ordered, through
   `run --threads 1 --instance-by topic` with the example robot spec, without and with a fleet
   spec; the difference over the records is the fleet level's cost per record. Two fleet specs:
   `size` (one map input, `Map.size`: the level's own machinery, maps and watermark, O(log n) per
   change) and the example (specs/fleet/fleet.tessla: folds over every robot, O(n) per fleet
   step). Peak memory (max RSS) with and without, over N: memory per robot.
2. The closest pair at 1k, 10k, 100k robots: every robot reports at one timestamp per round
   (one fleet step per round holding n positions); the native grid (`fleetClosestDistance`)
   against `Map.size` over the same maps; the difference per round is one closest-pair query.
   At 1k also the pure-TeSSLa O(n^2) fold (`fleetClosestDistanceSlow`).

Medians of --reps runs. Usage: python3 bench/fleet.py [--reps 3] [--bin target/release/tessla-telegraf]
"""
import argparse, os, statistics, subprocess, tempfile, time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def gen_stream(n, rounds, same_time):
    lines = []
    t0 = 1_700_000_000_000_000_000
    for k in range(rounds):
        for r in range(n):
            ts = t0 + k * 200_000_000 + (0 if same_time else r)
            x = (r * 7919 % 1000) / 10.0 + 0.01 * k
            y = (r * 104729 % 1000) / 10.0
            act = 0.05 if (r + k) % 17 == 0 else 0.1
            lines.append(
                f"mqtt_consumer,topic=tessla/r{r} expectedSpeed=0.1,actualSpeed={act},x={x:.3f},y={y:.3f} {ts}\n"
            )
    return "".join(lines).encode()


def run(binary, data, fleet):
    args = [
        "/usr/bin/time", "-f", "%M", binary, "run",
        "--spec", os.path.join(ROOT, "specs/fleet/robot.tessla"),
        "--instance-by", "topic", "--threads", "1", "--no-passthrough",
        "--max-ahead", "off", "--allowed-lateness", "off",
    ]
    if fleet:
        args += ["--fleet-spec", fleet]
    start = time.perf_counter()
    p = subprocess.run(args, input=data, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    took = time.perf_counter() - start
    if p.returncode != 0:
        raise SystemExit(p.stderr.decode())
    rss_kib = int(p.stderr.decode().strip().splitlines()[-1])
    return took, rss_kib


def median_run(binary, data, fleet, reps):
    runs = [run(binary, data, fleet) for _ in range(reps)]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/tessla-telegraf"))
    a = ap.parse_args()
    tmp = tempfile.mkdtemp()
    lib = os.path.join(ROOT, "specs/lib/fleet.tessla")

    def spec(name, body):
        p = os.path.join(tmp, name)
        with open(p, "w") as f:
            f.write(f'include "{lib}"\n' + body)
        return p

    size = spec("size.tessla", "in p2_violated: Events[Map[String, Bool]]\nout Map.size(p2_violated) as robots\n")
    example = os.path.join(ROOT, "specs/fleet/fleet.tessla")
    pos_size = spec("pos_size.tessla", "in position: Events[Map[String, (Float, Float)]]\nout Map.size(position) as robots\n")
    grid = spec("grid.tessla", "in position: Events[Map[String, (Float, Float)]]\nout Map.size(position) as robots\nout fleetClosestDistance(position) as d\n")
    slow = spec("slow.tessla", "in position: Events[Map[String, (Float, Float)]]\nout Map.size(position) as robots\nout fleetClosestDistanceSlow(position) as d\n")

    print("1. fleet level, cost per record (--threads 1, medians of %d)" % a.reps)
    for n, rounds in [(1000, 20), (10000, 4)]:
        data = gen_stream(n, rounds, False)
        recs = n * rounds
        base, base_rss = median_run(a.bin, data, None, a.reps)
        print(f"  {n} robots, {recs} records: without fleet {base / recs * 1e9:.0f} ns/record, max RSS {base_rss} KiB")
        for name, f in [("size", size)]:
            t, rss = median_run(a.bin, data, f, a.reps)
            extra = (t - base) / recs * 1e9
            per_robot = (rss - base_rss) * 1024 / n
            print(f"    fleet spec {name}: {t / recs * 1e9:.0f} ns/record, fleet level +{extra:.0f} ns/record ({t / base:.2f}x); "
                  f"max RSS {rss} KiB, +{per_robot:.0f} B per robot")
    # The example's folds cost O(n) per fleet step: 1k robots, 3 rounds.
    data = gen_stream(1000, 3, False)
    base, base_rss = median_run(a.bin, data, None, a.reps)
    t, rss = median_run(a.bin, data, example, a.reps)
    print(f"  1000 robots, 3000 records, fleet spec example: fleet level +{(t - base) / 3000 * 1e6:.0f} us/record "
          f"({t / base:.1f}x); +{(rss - base_rss) * 1024 / 1000:.0f} B per robot")
    print("2. closest pair, one fleet step per round of n positions (medians of %d)" % a.reps)
    # About 200k records per size, so that the difference is well above the runs' noise.
    for n, rounds in [(1000, 200), (10000, 20), (100000, 2)]:
        data = gen_stream(n, rounds, True)
        base, _ = median_run(a.bin, data, pos_size, a.reps)
        t, _ = median_run(a.bin, data, grid, a.reps)
        per = (t - base) / rounds * 1e3
        print(f"  {n} robots: grid {per:.3f} ms per query ({per / n * 1e6:.0f} ns per robot)")
        if n == 1000:
            few = gen_stream(n, 5, True)
            fbase, _ = median_run(a.bin, few, pos_size, a.reps)
            ts, _ = median_run(a.bin, few, slow, a.reps)
            per_s = (ts - fbase) / 5 * 1e3
            print(f"  {n} robots: TeSSLa fold over pairs {per_s:.1f} ms per query ({per_s / max(per, 1e-9):.0f}x the grid)")


if __name__ == "__main__":
    main()
