#!/usr/bin/env bash
# A fleet on one machine (README, "A fleet on one machine"), started by one command:
#
#   bash examples/fleet-one-machine/start.sh            # the bundled robot monitors
#   bash examples/fleet-one-machine/start.sh --fleet    # the fleet example (docs/fleet.md)
#
# One nats-server (nats.conf: the state bucket, the spec channel and the robots' MQTT gateway,
# no TLS, no logins, replicas=1) and two partitions with a standby each: telegraf-p0.conf and
# telegraf-p1.conf, each run as member a (the primary: started first, it takes the partition's
# lease) and member b (the standby), four Telegrafs in all. It makes the spec channel's bucket
# and the operator's signing key (first run only), prints how to feed it and what to look at,
# and stops everything, each Telegraf as systemd would (SIGTERM: the monitors save their state),
# at Ctrl-C or SIGTERM.
#
# --fleet: the fleet example of docs/fleet.md ("Walkthrough: the example on two partitions
# through Telegraf") instead of the bundled monitors: each Telegraf runs the example's robot
# spec with its fleet spec (`--spec specs/fleet/robot.tessla --fleet-spec specs/fleet/fleet.tessla
# --max-ahead off --allowed-lateness off`, for recordings replayed with their own timestamps), so
# all four processes take part in one fleet level over both partitions; the holder of the fleet
# lease writes the `tessla_fleet` and `tessla_fleet_status` lines (each Telegraf to its own
# $FLEET_DIR/fleet-p<N>-<member>.lp) and the `action,source=fleet` slow-downs (to the robots'
# MQTT topics, as robot actions). The confs it runs are written to $FLEET_DIR/telegraf-p<N>.conf
# from the shipped ones.
#
# Environment (defaults in brackets): FLEET_DIR, where the logs, JetStream's files and the
# signing key go [${XDG_STATE_HOME:-~/.local/state}/tessla-fleet-one-machine]; FLEET_NATS_PORT
# [4222]; FLEET_MQTT_PORT [1883]; TELEGRAF [telegraf]; NATS_SERVER [nats-server];
# TESSLA_TELEGRAF [tessla-telegraf on PATH, else /usr/bin/tessla-telegraf]; FLEET_SPECS, the
# folder of the fleet example's robot.tessla and fleet.tessla [specs/fleet beside examples/]. Needs Telegraf
# >= 1.33.3 and nats-server >= 2.9.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
fleet=no
case "${1:-}" in
  "") ;;
  --fleet) fleet=yes ;;
  *) echo "start.sh: unknown argument $1 (the only one is --fleet)" >&2; exit 2 ;;
esac
export FLEET_DIR=${FLEET_DIR:-${XDG_STATE_HOME:-$HOME/.local/state}/tessla-fleet-one-machine}
export FLEET_NATS_PORT=${FLEET_NATS_PORT:-4222}
export FLEET_MQTT_PORT=${FLEET_MQTT_PORT:-1883}
export FLEET_JETSTREAM=$FLEET_DIR/jetstream
TELEGRAF=${TELEGRAF:-telegraf}
NATS_SERVER=${NATS_SERVER:-nats-server}
if [ -z "${TESSLA_TELEGRAF:-}" ]; then
  TESSLA_TELEGRAF=$(command -v tessla-telegraf || echo /usr/bin/tessla-telegraf)
fi
export TESSLA_TELEGRAF
for tool in "$TELEGRAF" "$NATS_SERVER" "$TESSLA_TELEGRAF"; do
  command -v "$tool" >/dev/null || { echo "start.sh: $tool not found (see the header for the variables that name it)" >&2; exit 1; }
done
mkdir -p "$FLEET_JETSTREAM"

# The confs the Telegrafs run: the shipped ones, or with --fleet the same with the fleet example.
conf=$here
if [ "$fleet" = yes ]; then
  specs=${FLEET_SPECS:-$here/../../specs/fleet}
  specs=$(cd "$specs" 2>/dev/null && pwd) || { echo "start.sh: no folder ${FLEET_SPECS:-$here/../../specs/fleet} (FLEET_SPECS)" >&2; exit 1; }
  for f in robot.tessla fleet.tessla; do
    [ -f "$specs/$f" ] || { echo "start.sh: no $specs/$f (FLEET_SPECS)" >&2; exit 1; }
  done
  conf=$FLEET_DIR
  for p in 0 1; do
    sed -e "s|\"run\", \"--instance-by\", \"robot\",|\"run\", \"--instance-by\", \"robot\", \"--spec\", \"$specs/robot.tessla\", \"--fleet-spec\", \"$specs/fleet.tessla\", \"--max-ahead\", \"off\", \"--allowed-lateness\", \"off\",|" \
      "$here/telegraf-p$p.conf" >"$conf/telegraf-p$p.conf"
    grep -q -- "--fleet-spec" "$conf/telegraf-p$p.conf" || { echo "start.sh: could not add the fleet spec to telegraf-p$p.conf" >&2; exit 1; }
    cat >>"$conf/telegraf-p$p.conf" <<'EOC'

# start.sh --fleet: the fleet level's lines, written by whichever process holds the fleet lease
# (the fleet's slow-downs are `action` metrics tagged with their robot: outputs.mqtt above).
[[outputs.file]]
  files = ["${FLEET_DIR}/fleet-p${FLEET_PARTITION}-${TESSLA_MEMBER}.lp"]
  namepass = ["tessla_fleet", "tessla_fleet_status"]
  data_format = "influx"
EOC
  done
fi

pids=()
stop() {
  trap - INT TERM EXIT
  echo "stopping the fleet"
  # The Telegrafs first (newest first: the standbys), then the server they save their state to.
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
    kill -TERM "${pids[$i]}" 2>/dev/null || true
    wait "${pids[$i]}" 2>/dev/null || true
  done
  exit "$1"
}
trap 'stop 0' INT TERM
trap 'stop $?' EXIT

# Wait until `$2` appears in file `$1`, at most `$3` seconds.
wait_for() {
  local n=0
  until grep -q "$2" "$1" 2>/dev/null; do
    n=$((n + 1))
    if [ "$n" -gt $(($3 * 10)) ]; then
      echo "start.sh: no \"$2\" in $1 within $3 s; its last lines:" >&2
      tail -20 "$1" >&2 || true
      exit 1
    fi
    sleep 0.1
  done
}

"$NATS_SERVER" -c "$here/nats.conf" >"$FLEET_DIR/nats.log" 2>&1 &
pids+=($!)
wait_for "$FLEET_DIR/nats.log" "Server is ready" 30

channel="nats://127.0.0.1:$FLEET_NATS_PORT/tessla_specs?replicas=1"
if [ ! -s "$FLEET_DIR/spec-trust.pub" ]; then
  "$TESSLA_TELEGRAF" spec keygen --seed-file "$FLEET_DIR/spec-sign.seed" \
    | sed -n 's/^public key: //p' >"$FLEET_DIR/spec-trust.pub"
fi
"$TESSLA_TELEGRAF" spec init --channel "$channel"

# The primaries, each once it holds its partition's lease, then the standbys.
for member in a b; do
  for p in 0 1; do
    log=$FLEET_DIR/telegraf-p$p-$member.log
    : >"$log"
    TESSLA_MEMBER=$member FLEET_PARTITION=$p "$TELEGRAF" --config "$conf/telegraf-p$p.conf" >"$log" 2>&1 &
    pids+=($!)
    if [ "$member" = a ]; then wait_for "$log" "holding partition p$p" 60; fi
  done
done
for p in 0 1; do wait_for "$FLEET_DIR/telegraf-p$p-b.log" "Started the NATS consumer service" 60; done

if [ "$fleet" = yes ]; then
  cat <<EOT
fleet ready (the fleet example): nats-server on 127.0.0.1:$FLEET_NATS_PORT (MQTT $FLEET_MQTT_PORT), partitions p0 and p1, members a (primary) and b (standby)
  four robots:   $TESSLA_TELEGRAF simulate --shared-floor 4 --output floor.lp
                 for r in 1 2 3 4; do grep "topic=tessla/tb3-\$r " floor.lp > tb3-\$r.lp
                   $TESSLA_TELEGRAF replay tb3-\$r.lp --broker mqtt://127.0.0.1:$FLEET_MQTT_PORT --topic robots/tb3-\$r/telemetry --time-key time --speed 1 & done
  the fleet:     tail -f $FLEET_DIR/fleet-p*.lp    (tessla_fleet, tessla_fleet_status)
  slow-downs:    mosquitto_sub -p $FLEET_MQTT_PORT -t 'robots/+/action' -v
  the holder:    grep -l 'holding the fleet level' $FLEET_DIR/telegraf-p*.log
  logs:          $FLEET_DIR/*.log
Ctrl-C stops the fleet.
EOT
  wait
  exit 0
fi
cat <<EOT
fleet ready: nats-server on 127.0.0.1:$FLEET_NATS_PORT (MQTT $FLEET_MQTT_PORT), partitions p0 and p1, members a (primary) and b (standby)
  a robot:       $TESSLA_TELEGRAF replay tests/fixtures/robot/recorded_run.lp --broker mqtt://127.0.0.1:$FLEET_MQTT_PORT --topic robots/r1/telemetry --time-key time --string-field actualSpeed --speed 1
  its actions:   mosquitto_sub -p $FLEET_MQTT_PORT -t 'robots/+/action' -v
  the processes: $TESSLA_TELEGRAF spec status --channel '$channel'
  a new spec:    $TESSLA_TELEGRAF spec publish SPEC --channel '$channel' --sign-key-file $FLEET_DIR/spec-sign.seed
  logs:          $FLEET_DIR/*.log
Ctrl-C stops the fleet.
EOT
wait
