#!/usr/bin/env python3
"""Rewrite the shown outputs of the README and of the book's pages (docs/book/src/*.md) from the
release binary (make readme-run):
- the `make run` block (after `<!-- make run output -->`, in the book's getting-started.md) with
  the file given (make run's output);
- each block after `<!-- output of the command above -->` with what the last command of the `sh`
  block before it prints (the block's other commands run first), run from the repository with target/release first on PATH.
tests/cli/first_hour.rs and tests/cli/readme_commands.rs fail while the README and the binary differ."""
import os
import pathlib
import subprocess
import sys

env = dict(os.environ, PATH=f"{pathlib.Path('target/release').resolve()}:{os.environ['PATH']}")
make_run = pathlib.Path(sys.argv[1]).read_text()
marker = "<!-- make run output -->\n```\n"


def rewrite(page):
    text = page.read_text()
    if marker in text:
        start = text.index(marker) + len(marker)
        end = text.index("```", start)
        text = text[:start] + make_run + text[end:]
    text, rewritten = rewrite_outputs(text)
    page.write_text(text)
    return rewritten


def rewrite_outputs(text):
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
    return "\n".join(out), rewritten


pages = [pathlib.Path("README.md")] + sorted(pathlib.Path("docs/book/src").glob("*.md"))
total = sum(rewrite(page) for page in pages)
print(f"make run block and {total} command outputs rewritten in the README and the book")
