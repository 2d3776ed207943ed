#!/usr/bin/env bash
# Stage what the Debian package installs besides the binary (make deb): the man page and shell
# completions made by the binary from its command line, telegraf.tessla, the sample confs,
# dashboards, examples and docs, and any Telegraf systemd drop-in under telegraf/systemd/.
# Usage: tools/deb-assets.sh BINARY OUTDIR. cargo-deb's assets (Cargo.toml) take OUTDIR/usr/**.
set -euo pipefail
bin=$1
out=$2
rm -rf "$out"
share=$out/usr/share
doc=$share/doc/tessla-telegraf
mkdir -p "$share/man/man1" "$share/bash-completion/completions" "$share/zsh/vendor-completions" \
  "$share/fish/vendor_completions.d" "$share/tessla-telegraf" "$doc/examples" "$doc/telegraf"
"$bin" manpage | gzip -9n > "$share/man/man1/tessla-telegraf.1.gz"
"$bin" completions bash > "$share/bash-completion/completions/tessla-telegraf"
"$bin" completions zsh > "$share/zsh/vendor-completions/_tessla-telegraf"
"$bin" completions fish > "$share/fish/vendor_completions.d/tessla-telegraf.fish"
cp specs/telegraf.tessla "$share/tessla-telegraf/"
# The first spec's specs where its telegraf.conf names them (README, "Your first spec").
mkdir -p "$share/tessla-telegraf/first-spec"
cp examples/first-spec/*.tessla "$share/tessla-telegraf/first-spec/"
cp README.md "$doc/"
cp docs/*.md "$doc/"
# The book's Markdown (docs/book/src: chapters, pictures).
cp -r docs/book/src "$doc/book"
cp -rL examples/. "$doc/examples/"
cp telegraf/*.conf "$doc/telegraf/"
cp -r telegraf/dashboards "$doc/telegraf/"
for d in fleet-nats mosquitto; do
  if [ -d "telegraf/$d" ]; then cp -r "telegraf/$d" "$doc/telegraf/"; fi
done
# A Telegraf systemd drop-in (telegraf/systemd/*): files straight in the folder are drop-ins for
# telegraf.service; sub-folders keep their layout under /usr/lib/systemd/system.
if [ -d telegraf/systemd ]; then
  sys=$out/usr/lib/systemd/system
  mkdir -p "$sys/telegraf.service.d" "$doc/telegraf/systemd"
  cp -r telegraf/systemd/. "$doc/telegraf/systemd/"
  for f in telegraf/systemd/*; do
    if [ -d "$f" ]; then cp -r "$f" "$sys/"; else cp "$f" "$sys/telegraf.service.d/"; fi
  done
fi
echo "staged $(find "$out" -type f | wc -l) files in $out"
