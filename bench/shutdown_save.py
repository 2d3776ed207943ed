#!/usr/bin/env python3
"""Shutdown time with `--state` (`make shutdown-save`): how long the release binary takes from the
moment its stdin closes (how Telegraf stops an execd child) to its exit, with N robot instances
to save. Telegraf's budget for that (internal/process/process_posix.go, process_windows.go):
SIGTERM 5 s after stdin closed, SIGKILL 5 s later; on Windows a kill after 5 s.

Each repetition: a fresh `tessla-telegraf run --no-passthrough --instance-by topic
--max-instances N --state FILE` is fed the first two records of the recorded run for each of N
`topic` values (the fleet input of docs/book/src/state-and-reload.md), then one record of a sentinel
robot; once the sentinel's output arrives (so every record before it was stepped), stdin is
closed and the time to exit is measured. The `I! state: saved ... in T ms` line gives the save
alone. Prints each repetition and the medians; the machine's load average is printed too
(timings on a shared machine are upper bounds).

Usage: python3 bench/shutdown_save.py [--instances N ...] [--reps R] [--bin PATH]
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "tests/fixtures/robot/recorded_run.lp"


def templates():
    lines = FIXTURE.read_text().splitlines()[:3]
    out = []
    for line in lines:
        series, rest = line.split(" ", 1)
        assert "topic=tessla" in series, series
        out.append((series.replace("topic=tessla", "topic={}"), rest))
    return out


def feed(stdin, n, tpl):
    """Two records per robot, robots interleaved, then the sentinel's record."""
    for k in range(2):
        series, rest = tpl[k]
        chunk = []
        for r in range(n):
            chunk.append(f"{series.format(f'robot{r}')} {rest}\n")
            if len(chunk) == 2000:
                stdin.write("".join(chunk).encode())
                chunk.clear()
        stdin.write("".join(chunk).encode())
    series, rest = tpl[2]
    stdin.write(f"{series.format('sentinel')} {rest}\n".encode())
    stdin.flush()


def one_run(binary, n, state):
    proc = subprocess.Popen(
        [binary, "run", "--no-passthrough", "--instance-by", "topic",
         "--max-instances", str(n + 1), "--state", state, "--log-level", "info"] +
        (["--threads", "1"] if state.startswith("nats://") else []),
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = threading.Event()

    def read_out():
        for line in proc.stdout:
            if b"topic=sentinel" in line:
                seen.set()
        seen.set()

    err_lines = []

    def read_err():
        for line in proc.stderr:
            err_lines.append(line.decode(errors="replace").rstrip())

    threads = [threading.Thread(target=read_out), threading.Thread(target=read_err)]
    for t in threads:
        t.start()
    feed(proc.stdin, n, templates())
    if not seen.wait(600):
        proc.kill()
        sys.exit("no output for the sentinel record within 600 s")
    start = time.monotonic()
    proc.stdin.close()
    rc = proc.wait()
    took = time.monotonic() - start
    for t in threads:
        t.join()
    if rc != 0:
        sys.exit(f"exit code {rc}: " + "\n".join(err_lines[-5:]))
    saved = None
    for line in err_lines:
        m = re.search(r"state: saved (\d+) monitor instances to .* in (\d+) ms", line)
        if m:
            saved = (int(m.group(1)), int(m.group(2)))
    if saved is None or saved[0] != n + 1:
        sys.exit(f"no save of {n + 1} instances logged: " + "\n".join(err_lines[-5:]))
    return took, saved[1] / 1000.0, (0 if state.startswith("nats://") else os.path.getsize(state))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--instances", type=int, nargs="+", default=[10_000, 25_000, 50_000])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--nats", default=None, metavar="HOST:PORT[,HOST:PORT...]",
                    help="save to a JetStream bucket on these nats-servers instead of a file")
    ap.add_argument("--nats-options", default="", metavar="QUERY",
                    help="the bucket URL's options, e.g. replicas=3")
    ap.add_argument("--dir", default=None, help="folder for the state files (default: the system temp folder)")
    ap.add_argument("--bin", default=str(ROOT / "target/release/tessla-telegraf"))
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    for n in args.instances:
        exits, saves, size = [], [], 0
        with tempfile.TemporaryDirectory(dir=args.dir) as d:
            for rep in range(args.reps):
                if args.nats:
                    state = f"nats://{args.nats}/save{n}x{rep}"
                    if args.nats_options:
                        state += "?" + args.nats_options
                else:
                    state = os.path.join(d, f"state-{rep}.json")
                took, save, size = one_run(args.bin, n, state)
                if not args.nats:
                    os.remove(state)
                exits.append(took)
                saves.append(save)
                print(f"  {n} instances, run {rep + 1}: stdin closed -> exit {took:.2f} s "
                      f"(save {save:.2f} s), file {size / 1e6:.1f} MB", flush=True)
        print(f"{n} instances: median stdin closed -> exit {statistics.median(exits):.2f} s "
              f"(max {max(exits):.2f} s), median save {statistics.median(saves):.2f} s, "
              f"file {size / 1e6:.1f} MB; load average now {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
