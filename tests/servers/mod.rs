//! Against real servers: Telegraf (the pinned builds of `tools/build-telegraf.sh`), Mosquitto,
//! InfluxDB 1.x and nats-server clusters, each started on free loopback ports in a temporary
//! folder and stopped on drop. A missing server skips its test (and leaves a note for `make
//! test`'s banner, tools/test-skips.sh); `REQUIRE_SERVERS=1` makes it a failure.

mod combinations_nats;
#[cfg(feature = "tools")]
mod dashboards_influx;
mod fleet_checkpoint_nats;
mod fleet_level_nats;
mod fleet_nats;
mod fleet_nats_security;
mod fleet_nats_specs;
mod fleet_nats_state;
#[cfg(feature = "tools")]
mod fleet_one_machine;
mod fleet_spec_rollout;
mod fleet_takeover_nats;
mod pipeline_influx;
#[cfg(feature = "tools")]
mod pipeline_mqtt;
#[cfg(feature = "tools")]
mod pipeline_replay;
#[cfg(feature = "tools")]
mod security_mqtt;
#[cfg(feature = "tools")]
mod simulate_mqtt;
#[cfg(feature = "tools")]
mod telegraf_broker_persistence;
#[cfg(feature = "tools")]
mod telegraf_real;
#[cfg(feature = "tools")]
mod telegraf_real_failures;
#[cfg(feature = "tools")]
mod telegraf_real_nats;
mod telegraf_real_versions;
#[cfg(feature = "tools")]
mod telegraf_wiring;
