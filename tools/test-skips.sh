#!/usr/bin/env bash
# After `cargo test` (make test): say loudly which suites skipped and why. A test that skips
# writes a note into the folder given here (target/tmp/skipped-suites: see
# crates/test-support/src/paths.rs); no note, no skip.
set -u
dir=${1:-target/tmp/skipped-suites}
shopt -s nullglob
notes=("$dir"/*)
if [ ${#notes[@]} -eq 0 ]; then
  echo "make test: no suite was skipped"
  exit 0
fi
bar='!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!'
echo "$bar"
echo "SKIPPED, NOT PASSED: ${#notes[@]} suite(s) did not run (their tests count as passed above):"
for note in "${notes[@]}"; do
  echo "  - $(basename "$note"): $(head -n 1 "$note")"
done
if ls "$dir" | grep -qv '^needs-'; then
cat <<'TXT'
Suites named after a test need TeSSLa's conformance cases (the TeSSLa project's back-end test
suite, one folder per topic with a <case>.json descriptor per case: see the book, "TeSSLa reference",
"Tests and TeSSLa's suite"). Put the folder at ../shared/tessla-suite beside this repository, or point
TESSLA_SUITE at it:
  TESSLA_SUITE=/path/to/tessla-suite make test
REQUIRE_TESSLA_SUITE=1 (as CI sets) turns a missing suite into a failure.
TXT
fi
if ls "$dir" | grep -q '^needs-'; then
cat <<'TXT'
Suites named needs-<program> need that server or tool: `bash tools/setup.sh` installs them
(Debian packages; needs-telegraf-<version>: Telegraf built from its Go module by
tools/build-telegraf.sh, which needs Go 1.26 and the Go module proxy). REQUIRE_SERVERS=1 (as CI
sets) turns a missing one into a failure.
TXT
fi
echo "$bar"
