#!/usr/bin/env bash
# Installs what the tests need on a fresh Debian/Ubuntu machine: the Rust toolchain is assumed
# (rustup), the MQTT broker, InfluxDB 1.x and nats-server (the fleet tests' 3-node cluster) come
# from Debian packages, and the openssl command line (the security tests make their TEST-ONLY
# certificates with telegraf/fleet-nats/make-test-certs.sh), babeltrace2 (the reference CTF reader
# that tests/cli/trace_ctf.rs checks `trace --ctf` against) and chromium (tests/cli/report_chromium.rs
# renders `report`'s page headless and takes screenshots). Then Telegraf itself, built from its Go
# module at the two pinned versions the tests run under (tools/build-telegraf.sh; cached, so a
# second run costs nothing), and Grafana's dashboard schema (@grafana/schema with the TypeScript
# compiler that checks the dashboards against it, pinned in tools/grafana-schema/package-lock.json;
# npm, from the Debian package, installs them there). Idempotent: does nothing when everything
# is present. Needs root (or sudo) only when a Debian package is missing. Without Go, or without the Go module proxy, the
# Telegraf tests skip with the loud banner at the end of `make test`; with REQUIRE_SERVERS=1 (CI)
# a Telegraf that cannot be built fails the set-up. The book's builder, mdBook, comes from
# crates.io at the pinned version (`cargo install --locked`, only the search feature: no server);
# `make test` fails without it (tests/cli/book.rs).
set -euo pipefail
cd "$(dirname "$0")/.."

build_telegraf() {
    if bash tools/build-telegraf.sh; then
        return 0
    fi
    if [ "${REQUIRE_SERVERS:-}" = 1 ]; then
        echo "setup: REQUIRE_SERVERS=1 and Telegraf could not be built (above)" >&2
        exit 1
    fi
    echo "setup: Telegraf not built; the tests under the real Telegraf will skip (make test says so)" >&2
}

# The dashboards' schema check (tests/cli/pipeline_dashboards.rs runs tools/grafana-schema/check.mjs).
install_schema_check() {
    if [ -d tools/grafana-schema/node_modules/@grafana/schema ] \
        && [ -x tools/grafana-schema/node_modules/.bin/tsc ]; then
        return 0
    fi
    if (cd tools/grafana-schema && npm ci --no-audit --no-fund); then
        return 0
    fi
    if [ "${REQUIRE_SERVERS:-}" = 1 ]; then
        echo "setup: REQUIRE_SERVERS=1 and tools/grafana-schema could not be installed (above)" >&2
        exit 1
    fi
    echo "setup: Grafana's schema not installed; the dashboards' schema test will skip" >&2
}

# mdBook, pinned: the book (docs/book) is built by `make book` and by the tests.
MDBOOK_VERSION=0.4.52
install_mdbook() {
    if [ "$(mdbook --version 2>/dev/null)" = "mdbook v$MDBOOK_VERSION" ]; then
        return 0
    fi
    echo "setup: installing mdbook $MDBOOK_VERSION (cargo install)" >&2
    cargo install --locked mdbook --version "$MDBOOK_VERSION" --no-default-features --features search
}

need=()
command -v mosquitto >/dev/null 2>&1 || [ -x /usr/sbin/mosquitto ] || need+=(mosquitto)
command -v influxd >/dev/null 2>&1 || [ -x /usr/bin/influxd ] || need+=(influxdb)
command -v nats-server >/dev/null 2>&1 || [ -x /usr/bin/nats-server ] || need+=(nats-server)
command -v python3 >/dev/null 2>&1 || need+=(python3)
command -v openssl >/dev/null 2>&1 || need+=(openssl)
command -v babeltrace2 >/dev/null 2>&1 || need+=(babeltrace2)
command -v npm >/dev/null 2>&1 || need+=(npm)
command -v chromium >/dev/null 2>&1 || need+=(chromium)

if [ ${#need[@]} -eq 0 ]; then
    install_mdbook
    build_telegraf
    install_schema_check
    exit 0
fi

echo "setup: installing ${need[*]} (Debian packages)" >&2
sudo=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else
        echo "setup: not root and no sudo; install by hand: apt-get install -y ${need[*]}" >&2
        exit 1
    fi
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq "${need[@]}"
# The packages start system services; the tests run their own instances on free ports.
for svc in mosquitto influxdb nats-server; do
    $sudo systemctl stop "$svc" >/dev/null 2>&1 || $sudo service "$svc" stop >/dev/null 2>&1 || true
done
install_mdbook
build_telegraf
install_schema_check
