#!/usr/bin/env python3
"""P2 (speed tolerance) as a Telegraf processors.execd child in Python, standard library only: the
benchmark baseline for the way the paper's digital twin ran its monitors (the DT called a Python
function `optimizeActualSpeed` per robot message; paper §"Experiment setup").

Reads line protocol on stdin, writes every record back unchanged (pass-through) followed by
`tessla p2_diff=..,p2_violated=..,p2_action=..,p2_augmented=..,speed_mse=.. <ts>` for each record
with both speeds, the same metric bench/p2.tessla makes tessla-telegraf write (make bench checks
that both outputs are byte-identical on the P2 workload's first records). Like tessla-telegraf it
answers each read of stdin at once: whatever complete lines one read brings are processed, written
and flushed together.

Line-protocol parsing covers what Telegraf's JSON parser writes for the robot (escaped names,
quoted string fields with commas, spaces and escaped quotes); a record it cannot read is passed
through and reported on stderr.
"""
import os
import sys

DELTA = 0.02      # m/s, tolerated |expected - actual|
GAIN = 0.5        # proportional gain of the correction
MAX_SPEED = 0.22  # m/s, TurtleBot3 Burger


def fmt(x):
    """Shortest round-trip float without exponent (Rust's Display, as tessla-telegraf writes)."""
    s = repr(x)
    if "e" not in s:
        return s[:-2] if s.endswith(".0") else s
    mant, _, exp = s.partition("e")
    sign = "-" if mant.startswith("-") else ""
    whole, _, frac = mant.lstrip("-").partition(".")
    digits = (whole + frac).rstrip("0") or "0"
    point = len(whole) + int(exp)
    if point <= 0:
        s = "0." + "0" * (-point) + digits
    elif point >= len(digits):
        s = digits + "0" * (point - len(digits))
    else:
        s = digits[:point] + "." + digits[point:]
    return sign + s


def optimize_actual_speed(expected, actual):
    """The paper's tolerance monitor: (action, augmented) for one message."""
    diff = expected - actual
    violated = diff > DELTA or diff < -DELTA
    if not violated:
        action = expected
    else:
        action = expected + GAIN * diff
        if action > MAX_SPEED:
            action = MAX_SPEED
        elif action < -MAX_SPEED:
            action = -MAX_SPEED
    return diff, violated, action, action != expected


def split_unquoted(s, sep):
    """Split at `sep` outside double quotes, honouring backslash escapes."""
    parts, start, quoted, i, n = [], 0, False, 0, len(s)
    while i < n:
        c = s[i]
        if c == "\\":
            i += 2
            continue
        if c == '"':
            quoted = not quoted
        elif c == sep and not quoted:
            parts.append(s[start:i])
            start = i + 1
        i += 1
    parts.append(s[start:])
    return parts


def parse(line):
    """(fields dict of raw value text, timestamp text) of one record, or None."""
    if '"' in line or "\\" in line:
        # the general case: quoted strings may hold spaces and commas
        sections = [p for p in split_unquoted(line, " ") if p]
        if len(sections) < 2:
            return None
        pairs = split_unquoted(sections[1], ",")
    else:
        sections = line.split()
        if len(sections) < 2:
            return None
        pairs = sections[1].split(",")
    fields = {}
    for p in pairs:
        k, eq, v = p.partition("=")
        if not eq:
            return None
        fields[k] = v
    return fields, sections[2] if len(sections) > 2 else None


def number(v):
    if v.startswith('"'):
        v = v[1:-1]
    elif v.endswith(("i", "u")):
        v = v[:-1]
    return float(v)


class P2:
    def __init__(self):
        self.sum_sq = 0.0
        self.n = 0

    def record(self, line, out):
        out.append(line)
        text = line.rstrip("\r\n")
        if not text or text.lstrip().startswith("#"):
            return
        parsed = parse(text)
        if parsed is None:
            sys.stderr.write(f"W! cannot parse: {text[:60]}\n")
            return
        fields, ts = parsed
        if "expectedSpeed" not in fields or "actualSpeed" not in fields:
            return
        try:
            e, a = number(fields["expectedSpeed"]), number(fields["actualSpeed"])
        except ValueError:
            sys.stderr.write(f"W! not a number: {text[:60]}\n")
            return
        diff, violated, action, augmented = optimize_actual_speed(e, a)
        self.sum_sq += diff * diff
        self.n += 1
        mse = self.sum_sq / self.n
        tail = f" {ts}\n" if ts else "\n"
        out.append(
            f"tessla p2_diff={fmt(diff)},p2_violated={'true' if violated else 'false'},"
            f"p2_action={fmt(action)},p2_augmented={'true' if augmented else 'false'},"
            f"speed_mse={fmt(mse)}{tail}"
        )


def main():
    p2 = P2()
    rest = b""
    stdout = sys.stdout.buffer
    while True:
        chunk = os.read(0, 65536)
        if not chunk:
            break
        data = rest + chunk
        cut = data.rfind(b"\n") + 1
        rest = data[cut:]
        out = []
        for line in data[:cut].decode("utf-8", "replace").splitlines(keepends=True):
            p2.record(line, out)
        if out:
            stdout.write("".join(out).encode())
            stdout.flush()
    if rest:
        out = []
        p2.record(rest.decode("utf-8", "replace") + "\n", out)
        stdout.write("".join(out).encode())
        stdout.flush()


if __name__ == "__main__":
    try:
        main()
    except (BrokenPipeError, KeyboardInterrupt):
        pass
