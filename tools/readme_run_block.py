#!/usr/bin/env python3
"""Rewrite the README's shown outputs from the release binary (make readme-run):
- the `make run` block (after `<!-- make run output -->`) with the file given (make run's output);
- each block after `<!-- output of the command above -->` with what the last command of the `sh`
  block before it prints (the block's other commands run first), run from the repository with target/release first on PATH.
tests/cli/first_hour.rs and tests/cli/readme_commands.rs fail while the README and the binary differ."""
import os
import pathlib
import subprocess
import sys

readme = pathlib.Path("README.md")
text = readme.read_text()
marker = "<!-- make run output -->\n```\n"
start = text.index(marker) + len(marker)
end = text.index("```", start)
text = text[:start] + pathlib.Path(sys.argv[1]).read_text() + text[end:]

env = dict(os.environ, PATH=f"{pathlib.Path('target/release').resolve()}:{os.environ['PATH']}")
lines = text.split("\n")
out, cmds, in_sh, i, rewritten = [], [], False, 0, 0
while i < len(lines):
    line = lines[i]
    out.append(line)
    if line.strip() == "```sh":
        in_sh, cmds = True, []
    elif in_sh and line.strip().startswith("```"):
        in_sh = False
    elif in_sh and line.strip() and not line.strip().startswith("#"):
        cmds.append(line.strip())
    elif line.strip() == "<!-- output of the command above -->" and cmds:
        # The block that follows: its opening fence, the old body, its closing fence.
        out.append(lines[i + 1])
        j = i + 2
        while not lines[j].startswith("```"):
            j += 1
        # The block's earlier commands first (they may write what the last one reads).
        for cmd in cmds[:-1]:
            subprocess.run(["bash", "-c", f"set -eo pipefail; {cmd}"], env=env,
                           capture_output=True, check=True)
        got = subprocess.run(["bash", "-c", f"set -eo pipefail; {cmds[-1]}"], env=env,
                             capture_output=True, text=True, check=True).stdout
        out.extend(got.rstrip("\n").split("\n"))
        out.append(lines[j])
        rewritten += 1
        i = j
    i += 1
readme.write_text("\n".join(out))
print(f"README.md: make run block and {rewritten} command outputs rewritten")
