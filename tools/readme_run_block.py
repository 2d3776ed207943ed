#!/usr/bin/env python3
"""Rewrite the README's `make run` block (after `<!-- make run output -->`) with what `make run`
prints now (make readme-run). tests/first_hour.rs fails while the two differ."""
import pathlib
import sys

output = pathlib.Path(sys.argv[1]).read_text()
readme = pathlib.Path("README.md")
text = readme.read_text()
marker = "<!-- make run output -->\n```\n"
start = text.index(marker) + len(marker)
end = text.index("```", start)
readme.write_text(text[:start] + output + text[end:])
print(f"README.md: make run block rewritten ({len(output.splitlines())} lines)")
