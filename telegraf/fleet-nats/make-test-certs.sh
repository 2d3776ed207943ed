#!/usr/bin/env bash
# TEST-ONLY certificates for the fleet (never for production: the CA key sits next to them and
# nothing protects it). Usage: make-test-certs.sh DIR [NAME...]
# Writes into DIR (created if missing):
#   ca.pem, ca-key.pem            a CA (10 days)
#   server.pem, server-key.pem    the servers' certificate (NATS clients, routes, MQTT; Mosquitto),
#                                 for the names nats-1, nats-2, nats-3, localhost and 127.0.0.1
#                                 plus every NAME given; usable as a route's client certificate
#   client.pem, client-key.pem    a client certificate (CN tessla-telegraf) for mutual TLS
#   other-ca.pem                  a second, unrelated CA (to test that a wrong CA is refused)
# Needs the openssl command line (tools/setup.sh installs it).
set -euo pipefail
dir=${1:?usage: make-test-certs.sh DIR [NAME...]}
shift
mkdir -p "$dir"
cd "$dir"
san="DNS:nats-1,DNS:nats-2,DNS:nats-3,DNS:localhost,IP:127.0.0.1"
for name in "$@"; do san="$san,DNS:$name"; done

key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

key ca-key.pem
openssl req -x509 -new -key ca-key.pem -sha256 -days 10 -subj "/CN=tessla-fleet test CA" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out ca.pem 2>/dev/null

sign() { # name cn extensions
    key "$1-key.pem"
    openssl req -new -key "$1-key.pem" -subj "/CN=$2" -out "$1.csr" 2>/dev/null
    printf '%s\n' "$3" > "$1.ext"
    openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca-key.pem -CAcreateserial -days 10 \
        -sha256 -extfile "$1.ext" -out "$1.pem" 2>/dev/null
    rm -f "$1.csr" "$1.ext"
}
sign server "tessla-fleet server" "subjectAltName=$san
extendedKeyUsage=serverAuth,clientAuth
basicConstraints=CA:FALSE"
sign client "tessla-telegraf" "extendedKeyUsage=clientAuth
basicConstraints=CA:FALSE"

key other-ca-key.pem
openssl req -x509 -new -key other-ca-key.pem -sha256 -days 10 -subj "/CN=unrelated test CA" \
    -addext "basicConstraints=critical,CA:TRUE" -out other-ca.pem 2>/dev/null
rm -f other-ca-key.pem ca.srl
chmod 600 ./*-key.pem
echo "make-test-certs: TEST-ONLY certificates in $dir" >&2
