#!/usr/bin/env python3
"""The fleet checkpoint across NATS partitions at 1k, 10k and 100k robots (docs/fleet.md, "The
fleet checkpoint"; the Benchmarks chapter, "Fleet level"). Run by `make bench-fleet` after
bench/fleet.py.

For each N: a nats-server with JetStream on a free loopback port; one partition's process of the
release binary (`run --state nats://...?lease=p0` with the fleet example, specs/fleet/) fed N
robots' records (every robot at one timestamp per round, 5 Hz, 3 rounds), stdin kept open; its
checkpoint lines (`--log-level debug`: `fleet: checkpoint at stream sequence S: J bytes of JSON,
B bytes stored in P parts (held the step loop H ms, encoded in E ms, compressed in C ms, put in T ms)`) are read until two in a row give
the same JSON size within 1% (every record taken in). Then a second process (partition p1, same
bucket) starts and logs how long reading it took (`starting from the fleet checkpoint ... B bytes
in P parts, read in R ms`). Printed per N: JSON and stored bytes (and per robot), parts, the
deflate ratio, the time taking it held the step loop, encode (off the step loop)/compress/put/read times, and the first process's resident memory then (VmRSS);
memory per robot is the slope between the smallest and the largest N.

Usage: python3 bench/fleet_checkpoint.py [--bin target/release/tessla-telegraf] [--baseline OTHER_BINARY]
       [--sizes 1000,10000,100000]
"""
import argparse, os, re, shutil, statistics, subprocess, tempfile, threading, time

import servers

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Since the checkpoint left the step loop: "held the step loop H ms, encoded in E ms"; before
# (a baseline binary, --baseline): "taken and encoded in E ms", all of it on the step loop.
CP = re.compile(r"fleet: checkpoint at stream sequence (\d+): (\d+) bytes of JSON, (\d+) bytes stored in (\d+) parts "
                r"\((?:held the step loop (\d+) ms, encoded in (\d+) ms|taken and encoded in (\d+) ms), "
                r"compressed in (\d+) ms, put in (\d+) ms\)")
START = re.compile(r"starting from the fleet checkpoint at stream sequence (\d+) .*?(\d+) bytes in (\d+) parts, read in (\d+) ms")


def records(n, rounds):
    t0 = time.time_ns()
    out = []
    for k in range(rounds):
        ts = t0 + k * 200_000_000
        for r in range(n):
            x = (r * 7919 % 1000) / 10.0 + 0.01 * k
            y = (r * 104729 % 1000) / 10.0
            act = 0.05 if (r + k) % 17 == 0 else 0.1
            out.append(f"mqtt_consumer,topic=tessla/r{r} expectedSpeed=0.1,actualSpeed={act},x={x:.3f},y={y:.3f} {ts}\n")
    return "".join(out).encode()


class Proc:
    """A run of the binary whose stderr lines are collected by a thread."""

    def __init__(self, args):
        self.p = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        self.lines = []
        self.lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for raw in self.p.stderr:
            line = raw.decode(errors="replace")
            if "fleet: entry " in line:  # the per-entry debug lines: not kept
                continue
            with self.lock:
                self.lines.append(line)

    def matches(self, rx):
        with self.lock:
            return [m for m in (rx.search(l) for l in self.lines) if m]

    def wait(self, rx, what, timeout, pred=lambda ms: bool(ms)):
        end = time.time() + timeout
        while time.time() < end:
            ms = self.matches(rx)
            if pred(ms):
                return ms
            if self.p.poll() is not None:
                break
            time.sleep(0.2)
        with self.lock:
            tail = "".join(self.lines[-20:])
        raise SystemExit(f"no {what} within {timeout} s:\n{tail}")

    def rss_kib(self):
        with open(f"/proc/{self.p.pid}/status") as f:
            for l in f:
                if l.startswith("VmRSS:"):
                    return int(l.split()[1])
        return 0

    def stop(self):
        try:
            self.p.stdin.close()
        except OSError:
            pass
        try:
            self.p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()


def stable(ms):
    if len(ms) < 2:
        return False
    a, b = int(ms[-2].group(2)), int(ms[-1].group(2))
    return abs(a - b) <= 0.01 * max(a, b)


def measure(binary, n, rounds):
    tmp = tempfile.mkdtemp()
    server, port = servers.start_nats(tmp)
    try:
        state = f"nats://127.0.0.1:{port}/fleet_cp"
        base = [binary, "run", "--spec", os.path.join(ROOT, "specs/fleet/robot.tessla"), "--instance-by", "topic",
                "--fleet-spec", os.path.join(ROOT, "specs/fleet/fleet.tessla"), "--max-ahead", "off",
                "--allowed-lateness", "off", "--no-passthrough", "--log-level", "debug"]
        a = Proc(base + ["--state", f"{state}?lease=p0"])
        a.wait(re.compile(r"lease\.vfleet taken by|partition fleet: held by this process"), "fleet lease", 60)
        a.p.stdin.write(records(n, rounds))
        a.p.stdin.flush()
        cp = a.wait(CP, "stable checkpoint", 600, stable)[-1]
        rss = a.rss_kib()
        b = Proc(base + ["--state", f"{state}?lease=p1"])
        st = b.wait(START, "start from the checkpoint", 300)[-1]
        b.stop()
        a.stop()
        if cp.group(7) is not None:  # an earlier binary: taken and encoded on the step loop
            held = encode = int(cp.group(7))
        else:
            held, encode = int(cp.group(5)), int(cp.group(6))
        return {
            "json": int(cp.group(2)), "stored": int(cp.group(3)), "parts": int(cp.group(4)),
            "held_ms": held, "encode_ms": encode, "compress_ms": int(cp.group(8)), "put_ms": int(cp.group(9)),
            "read_ms": int(st.group(4)), "read_bytes": int(st.group(2)), "rss_kib": rss,
        }
    finally:
        servers.stop(server)
        shutil.rmtree(tmp, ignore_errors=True)


def line(n, r):
    return (f"{r['json']:.0f} B JSON ({r['json'] / n:.0f} B/robot), {r['stored']:.0f} B stored in {r['parts']:.0f} parts "
            f"({r['stored'] / n:.0f} B/robot, deflate {r['json'] / max(r['stored'], 1):.1f}x); "
            f"held the step loop {r['held_ms']:.0f} ms, encode {r['encode_ms']:.0f} ms, compress {r['compress_ms']:.0f} ms, "
            f"put {r['put_ms']:.0f} ms, read {r['read_ms']:.0f} ms; VmRSS {r['rss_kib']:.0f} KiB")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/tessla-telegraf"))
    ap.add_argument("--baseline", help="a second binary (an earlier build) measured in the same run, its runs "
                    "interleaved with --bin's; the step-loop hold is compared")
    ap.add_argument("--sizes", default="1000,10000,100000")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=3, help="runs per size; every figure is their median")
    a = ap.parse_args()
    sizes = [int(s) for s in a.sizes.split(",")]
    print(f"3. fleet checkpoint on NATS (the fleet example, {a.rounds} rounds at 5 Hz, one partition, nats-server max_payload 1 MiB; medians of {a.reps} runs)")
    got = {}
    for n in sizes:
        runs, base = [], []
        for _ in range(max(a.reps, 1)):
            runs.append(measure(a.bin, n, a.rounds))
            if a.baseline:
                base.append(measure(a.baseline, n, a.rounds))
        r = {k: statistics.median(run[k] for run in runs) for k in runs[0]}
        got[n] = r
        print(f"  {n} robots: {line(n, r)}")
        if base:
            b = {k: statistics.median(run[k] for run in base) for k in base[0]}
            print(f"  {n} robots, baseline: {line(n, b)}")
            print(f"  {n} robots: the step loop held {r['held_ms']:.0f} ms against the baseline's {b['held_ms']:.0f} ms")
    if len(sizes) >= 2:
        lo, hi = min(sizes), max(sizes)
        per = (got[hi]["rss_kib"] - got[lo]["rss_kib"]) * 1024 / (hi - lo)
        print(f"  memory per robot (VmRSS slope {lo}..{hi}, robot monitors and the fleet level): {per:.0f} B")


if __name__ == "__main__":
    main()
