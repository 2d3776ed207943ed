#!/usr/bin/env bash
# The book's pictures (make book-pictures): `report`'s page and its speed plot, for the bundled
# robot monitors over the recorded-run fixture, as headless Chromium draws them, written as PNGs
# under docs/book/src/images/ (the "Report with the paper's plots" step of the full pipeline).
# Usage: tools/book_pictures.sh BINARY
set -euo pipefail
cd "$(dirname "$0")/.."
bin=$(realpath "$1")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin" run --log-level warn < tests/fixtures/robot/recorded_run.lp > "$work/run.lp"
# From the run's folder, so the page names the file as `run.lp`, not a temporary path.
(cd "$work" && "$bin" report run.lp -o report > /dev/null 2>&1)
shot() { # FILE OUT.png WIDTH HEIGHT
  chromium --headless --no-sandbox --disable-gpu --hide-scrollbars \
    --user-data-dir="$work/profile" --window-size="$3,$4" \
    --screenshot="$2" "file://$1" > /dev/null 2>&1
  test -s "$2"
}
mkdir -p docs/book/src/images
shot "$work/report/index.html" docs/book/src/images/report-page.png 1100 1400
shot "$work/report/speeds.svg" docs/book/src/images/report-plot.png 1000 420
echo "docs/book/src/images/report-page.png, report-plot.png"
