#!/usr/bin/env python3
"""Generate the recorded-run fixture: a TurtleBot3 "yoga mat" run as in the paper, in the line protocol
Telegraf's processors.execd writes for what its mqtt_consumer JSON parser makes of the robot's messages
(tags sorted; every number a float in Telegraf's form; actualSpeed a string; the fields in Go map order,
that is a different order on every record: a seeded shuffle here), plus an independent ground truth of
the verdicts.

Fixed seed, standard library only. Writes tests/fixtures/robot/recorded_run.lp and
tests/fixtures/robot/recorded_run.truth.json. The ground truth is computed here from the
property definitions (docs in README), never by tessla-telegraf.

Run: python3 tools/gen_robot_run.py
"""
import json
import math
import random
from pathlib import Path

SEED = 20261122
N_RECORDS = 300          # 60 s at 5 Hz
PERIOD_NS = 200_000_000  # 5 Hz scans
T0 = 1_700_000_000_000_000_000
BEAMS = 360
# Parameters as in the bundled specs.
DELTA, GAIN, MAX_SPEED = 0.02, 0.5, 0.22
GAMMA, RMIN, RMAX = 0.3, 0.12, 3.5
T_REACT, DECEL, MARGIN, HALF_TRACK, MIN_VALID = 0.5, 0.5, 0.09, 0.08, 0.5

STUCK = [(60, 90), (180, 210)]      # record ranges where the robot is stuck on a hill
BLINDED = range(250, 256)           # forward sector covered (all 0.0)
SPIKES = {r: 90 + (r % 7) * 20 for r in range(10, N_RECORDS, 25)}  # record -> beam with dust spike


def fmt(x):
    """Telegraf's float form: shortest round trip, no exponent, no trailing .0."""
    s = repr(float(x))
    if "e" in s or "E" in s:
        s = f"{x:.17f}".rstrip("0").rstrip(".")
    if s.endswith(".0"):
        s = s[:-2]
    return s


def expected_speed(i):
    steps = [0.015, 0.03, 0.05, 0.07, 0.1]
    return steps[min(i // 60, len(steps) - 1)]


def main():
    rnd = random.Random(SEED)
    # Go map order of the fields: its own generator, so the values do not depend on it.
    order = random.Random(SEED + 1)
    root = Path(__file__).resolve().parent.parent / "tests" / "fixtures" / "robot"
    root.mkdir(parents=True, exist_ok=True)
    lines, truth = [], []
    for i in range(N_RECORDS):
        ts = T0 + i * PERIOD_NS
        t = i * PERIOD_NS / 1e9
        exp = expected_speed(i)
        stuck = any(a <= i < b for a, b in STUCK)
        act = round(exp * 0.2 + rnd.uniform(-0.002, 0.002), 4) if stuck else round(exp + rnd.uniform(-0.004, 0.004), 4)
        exp_ang = 0.0
        act_ang = round(rnd.uniform(-0.02, 0.02), 4)
        # Lidar: walls 2.5 m around, an obstacle ahead approaching to 0.13 m at the end.
        ahead = max(0.13, 2.0 - 0.035 * t)
        scan = []
        for b in range(BEAMS):
            ang = b  # degrees
            base = ahead if (ang >= 340 or ang <= 20) else 2.5 + 0.3 * math.sin(math.radians(ang * 3))
            scan.append(round(base + rnd.uniform(-0.01, 0.01), 3))
        missing = set()
        # LDS-01 no-returns (0.0) at a few side beams, never next to an injected spike.
        for _ in range(4):
            b = rnd.randrange(45, 315)
            if i in SPIKES and abs(b - SPIKES[i]) <= 1:
                continue
            scan[b] = 0.0
        # A missing beam now and then: the robot sends `null`, which Telegraf's JSON parser skips (the
        # other beams keep their indices). A NaN or Infinity instead would make the whole message
        # invalid JSON, and Telegraf would drop the message, not the field.
        if i % 40 == 5:
            b = 200 + i % 30
            if not (i in SPIKES and abs(b - SPIKES[i]) <= 1):
                missing.add(b)
        if i in BLINDED:
            for b in list(range(330, 360)) + list(range(0, 31)):
                scan[b] = 0.0
        if i in SPIKES:
            b = SPIKES[i]
            scan[b] = round(scan[b] + 0.6, 3)  # stays below range_max
        fields = [f"actualAngular={fmt(act_ang)}", f'actualSpeed="{act}"', f"expectedAngular={fmt(exp_ang)}",
                  f"expectedSpeed={fmt(exp)}"]
        fields += [f"lidar_{b}={fmt(v)}" for b, v in enumerate(scan) if b not in missing]
        order.shuffle(fields)
        lines.append(f"mqtt_consumer,host=turtlebot3,topic=tessla {','.join(fields)} {ts}\n")

        # ---- ground truth, from the property definitions ----
        beams = [float("nan") if b in missing else v for b, v in enumerate(scan)]
        valid = [RMIN <= v <= RMAX for v in beams]  # NaN compares False
        spikes = []
        for b in range(BEAMS):
            p, q = (b - 1) % BEAMS, (b + 1) % BEAMS
            if valid[b] and valid[p] and valid[q]:
                r, a, c = beams[b], beams[p], beams[q]
                if (r - a > GAMMA and r - c > GAMMA) or (a - r > GAMMA and c - r > GAMMA):
                    spikes.append(b)
        dropouts = sum(1 for v in valid if not v)
        sector = [b for b in range(BEAMS) if b * 360 / BEAMS >= 330 or b * 360 / BEAMS <= 30]
        good = [b for b in sector if valid[b] and b not in spikes]
        ldist = min((beams[b] for b in good), default=RMAX)
        v = abs(act) + abs(act_ang) * HALF_TRACK
        bdist = v * T_REACT + v * v / (2 * DECEL) + MARGIN
        frac = len(good) / len(sector)
        status = "unknown" if frac < MIN_VALID else ("violated" if bdist > ldist else "ok")
        diff = exp - act
        truth.append({"ts": ts, "p2_violated": abs(diff) > DELTA, "p3_spikes": spikes, "p3_dropouts": dropouts,
                      "p1_status": status, "p1_margin": ldist - bdist, "stuck": stuck})
    (root / "recorded_run.lp").write_text("".join(lines))
    (root / "recorded_run.truth.json").write_text(json.dumps(
        {"seed": SEED, "stuck": STUCK, "blinded": [BLINDED.start, BLINDED.stop], "spikes": SPIKES,
         "records": truth}, indent=0))


if __name__ == "__main__":
    main()
