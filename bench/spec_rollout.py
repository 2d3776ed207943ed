#!/usr/bin/env python3
"""Publish to every process of a two-partition fleet: how long from `spec publish` until both
processes run the new version, and whether any record is lost or judged by a mix of versions.

Starts a nats-server (JetStream, a free loopback port), makes an operator key, and runs two
`tessla-telegraf run` processes as the two partitions of a fleet (`--state nats://...?lease=p0`
and `lease=p1`, `--spec-channel`, `--version-tag spec_version`), each fed records of its own
robots at about 200 per second with the current time. Then it publishes `--reps` versions in
turn (two specs alternating, each from the time of its publish) and times, for each, the
moment the command starts until both processes have written their `tessla_spec ...
outcome=committed` status line (the proposal, both processes' votes, the decision, and both
acting on it). At the end it checks every record got exactly one output line,
and that each robot's version tags change only at publishes (never back and forth).

Usage: python3 bench/spec_rollout.py [--bin target/release/tessla-telegraf] [--reps 10]
"""
import argparse, os, shutil, statistics, subprocess, sys, tempfile, threading, time

import servers

SPEC_A = "in x: Events[Int]\ndef c = count(x)\ndef y = x + 1\nout c\nout y\n"
SPEC_B = "in x: Events[Int]\ndef c = count(x)\ndef y = x * 10\nout c\nout y\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/tessla-telegraf")
    ap.add_argument("--reps", type=int, default=10)
    a = ap.parse_args()
    binary = os.path.abspath(a.bin)
    tmp = tempfile.mkdtemp()
    nats, port = servers.start_nats(tmp + "/js")
    url = f"nats://127.0.0.1:{port}"
    procs = []
    try:
        seed = tmp + "/operator.seed"
        out = subprocess.run([binary, "spec", "keygen", "--seed-file", seed], capture_output=True, text=True, check=True)
        public = next(l.split(": ", 1)[1] for l in out.stdout.splitlines() if l.startswith("public key: "))
        specs = []
        for name, text in (("a.tessla", SPEC_A), ("b.tessla", SPEC_B)):
            with open(f"{tmp}/{name}", "w") as f:
                f.write(text)
            specs.append(f"{tmp}/{name}")

        def publish(spec, label):
            subprocess.run([binary, "spec", "publish", spec, "--label", label, "--channel", url,
                            "--sign-key-file", seed], capture_output=True, text=True, check=True)

        # The bucket exists before the processes start (the first publish makes it).
        publish(specs[0], "start")
        lines = [[], []]
        fed = [0, 0]
        stop = threading.Event()
        for p in range(2):
            cmd = [binary, "run", "--spec", specs[0], "--no-passthrough", "--instance-by", "robot",
                   "--version-tag", "spec_version", "--spec-channel", url, "--spec-trust", public,
                   "--state", f"{url}/tessla_state?lease=p{p}"]
            proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL, text=True, bufsize=1)
            procs.append(proc)

            def read(proc=proc, p=p):
                for line in proc.stdout:
                    lines[p].append((time.monotonic(), line.rstrip("\n")))
            threading.Thread(target=read, daemon=True).start()

            def feed(proc=proc, p=p):
                k = 0
                while not stop.is_set():
                    robot = f"p{p}r{k % 10}"
                    proc.stdin.write(f"m,robot={robot} x={k}i {time.time_ns()}\n")
                    proc.stdin.flush()
                    fed[p] += 1
                    k += 1
                    time.sleep(0.005)
            threading.Thread(target=feed, daemon=True).start()
        time.sleep(2)
        waits, after_cmd = [], []
        for i in range(1, a.reps + 1):
            revision = i + 1
            seen = [len(lines[0]), len(lines[1])]
            t0 = time.monotonic()
            publish(specs[i % 2], f"rep {i}")
            t1 = time.monotonic()
            done = [None, None]
            while None in done:
                for p in range(2):
                    for t, l in lines[p][seen[p]:]:
                        if l.startswith("tessla_spec,") and "outcome=committed" in l and f"revision={revision}i" in l:
                            done[p] = t
                if time.monotonic() - t0 > 30:
                    sys.exit(f"rollout {revision} not committed in both within 30 s")
                time.sleep(0.002)
            waits.append(max(done) - t0)
            after_cmd.append(max(done) - t1)
            time.sleep(0.5)
        stop.set()
        time.sleep(0.2)
        for proc in procs:
            proc.stdin.close()
        for proc in procs:
            proc.wait(timeout=30)
        time.sleep(0.2)
        lost = 0
        flips = 0
        for p in range(2):
            outs = [l for _, l in lines[p] if l.startswith("tessla,")]
            lost += fed[p] - len(outs)
            last = {}
            changes = {}
            for l in outs:
                tags = dict(t.split("=", 1) for t in l.split(" ", 1)[0].split(",")[1:])
                r, v = tags["robot"], tags["spec_version"]
                if last.get(r) != v:
                    changes[r] = changes.get(r, 0) + 1
                last[r] = v
            # Each robot changes version at most once per publish.
            flips += sum(max(0, n - 1 - a.reps) for n in changes.values())
        med = statistics.median(waits)
        print(f"publish -> both partitions running it: median {med*1000:.0f} ms, max {max(waits)*1000:.0f} ms "
              f"({a.reps} publishes; from the command's end: median {statistics.median(after_cmd)*1000:.0f} ms, "
              f"max {max(after_cmd)*1000:.0f} ms)")
        print(f"records fed {sum(fed)}, output lines missing {lost}, version changes beyond one per publish {flips}")
        if lost or flips:
            sys.exit(1)
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
        servers.stop(nats)
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
