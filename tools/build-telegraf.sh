#!/usr/bin/env bash
# Builds Telegraf from its Go module (github.com/influxdata/telegraf) with only the plugins the
# shipped confs and the tests use (Telegraf's docs/CUSTOMIZATION.md: `go build -tags custom,...`),
# at the versions the tests run under: the floor the README names and the newest release.
#
#   bash tools/build-telegraf.sh            # both pinned versions
#   bash tools/build-telegraf.sh v1.39.3    # one version
#
# Each build lands in $TELEGRAF_CACHE/<version>/telegraf (default ~/.cache/tessla-telegraf/telegraf)
# beside a stamp naming the version and the plugin tags; a second run with the same tags does
# nothing. Tests find the binaries there (or through TELEGRAF_BIN_<version> / TELEGRAF_DIR).
# Needs Go (>= the version Telegraf's go.mod names: 1.26 for v1.39.3) and the Go module proxy.
set -euo pipefail

VERSIONS_DEFAULT="v1.33.2 v1.33.3 v1.39.3"
# Every plugin a shipped conf or a test names, plus the parsers and serializers their
# data_format options select.
TAGS="custom"
for p in inputs.mqtt_consumer inputs.nats_consumer inputs.socket_listener inputs.file inputs.internal \
    processors.execd processors.regex processors.clone processors.starlark \
    outputs.mqtt outputs.influxdb outputs.file outputs.socket_writer outputs.nats outputs.discard \
    parsers.json parsers.influx serializers.json serializers.influx; do
    TAGS="$TAGS,$p"
done

cache=${TELEGRAF_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/tessla-telegraf/telegraf}
versions=${*:-$VERSIONS_DEFAULT}

if ! command -v go >/dev/null 2>&1; then
    for d in /usr/local/go/bin /usr/lib/go/bin; do [ -x "$d/go" ] && PATH="$d:$PATH"; done
fi
if ! command -v go >/dev/null 2>&1; then
    echo "build-telegraf: no Go toolchain on PATH (Telegraf is built from its Go module; install Go 1.26+)" >&2
    exit 1
fi

for v in $versions; do
    out="$cache/$v"
    stamp="$out/stamp"
    want="telegraf $v tags=$TAGS go=$(go env GOVERSION)"
    if [ -x "$out/telegraf" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
        echo "build-telegraf: $v cached at $out/telegraf" >&2
        continue
    fi
    echo "build-telegraf: building Telegraf $v ($TAGS)" >&2
    mkdir -p "$out"
    # The module's source comes read-only from the module cache; build a private copy so go can
    # write go.sum updates (none are expected) without touching the cache.
    dir=$(GOFLAGS=-mod=mod go mod download -json "github.com/influxdata/telegraf@$v" |
        sed -n 's/^[[:space:]]*"Dir": "\(.*\)",$/\1/p')
    if [ -z "$dir" ] || [ ! -d "$dir" ]; then
        echo "build-telegraf: the Go module proxy did not give github.com/influxdata/telegraf@$v" >&2
        exit 1
    fi
    src="$out/src"
    rm -rf "$src"
    cp -r "$dir" "$src"
    chmod -R u+w "$src"
    (cd "$src" && GOFLAGS=-buildvcs=false go build -trimpath -tags "$TAGS" \
        -ldflags "-s -w -X github.com/influxdata/telegraf/internal.Version=${v#v}" \
        -o "$out/telegraf.new" ./cmd/telegraf)
    mv "$out/telegraf.new" "$out/telegraf"
    rm -rf "$src"
    echo "$want" > "$stamp"
    "$out/telegraf" --version >&2
done
