//! The closed loop: robot → message → twin (the monitors) → action → robot.
//!
//! Owns: the simulation clock and its order of events per control period (measure, emit the
//! robot message, hand it to the [`Twin`], queue the returned action until the twin's round-trip
//! delay has passed, integrate the physics to the next period), the robot's speed estimate
//! (as hector SLAM: pose differences over one period, each pose with Gaussian noise), the
//! message as Telegraf's JSON parser delivers it, fields in Go map order
//! ([`Message::to_line`]), and the run's measures ([`Outcome`]). Which speed the robot
//! executes: with the monitor on, the latest action that has arrived, as long as the program's
//! own speed has not changed since the action's message was sent; otherwise (and always with the
//! monitor off) the program's speed.

// The action type lives with the gate that judges it; here too, where it always was.
pub use super::gate::Action;
use super::gate::Gate;
use super::lidar::{LidarParams, Map};
use super::program::Program;
use super::robot::{Params, Robot};
use super::terrain::Terrain;
use lineproto::{FieldValue, LineWriter};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::collections::VecDeque;
use std::io::Write;

/// Everything that defines a run, apart from the twin.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub terrain: Terrain,
    pub program: Program,
    pub map: Map,
    pub robot: Params,
    pub lidar: LidarParams,
    /// s between robot messages (the paper's actuation period: 0.5 s).
    pub period: f64,
    /// s from a message to its action taking effect on the robot.
    pub delay: f64,
    /// m: standard deviation of the SLAM pose estimate.
    pub slam_noise: f64,
    /// rad/s: standard deviation of the reported angular speed (the robot drives straight).
    pub angular_noise: f64,
    pub seed: u64,
    /// `host` tag of the robot messages.
    pub host: String,
    /// ns: timestamp of the first message.
    pub start_ns: i64,
    /// s: physics integration step.
    pub dt: f64,
    /// s: length of the run (at most the program's duration).
    pub duration: f64,
    /// (start s, length s): while the robot's link is down its client holds its messages, and
    /// sends them, in order and with their own times, when it returns (a QoS 1 client that
    /// queues while reconnecting).
    pub link_drops: Vec<(f64, f64)>,
}

/// 2023-11-14T22:13:20Z: a fixed start, so a run's output depends on the seed only.
pub const START_NS: i64 = 1_700_000_000_000_000_000;

/// One robot message.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub time_ns: i64,
    pub expected_speed: f64,
    pub actual_speed: f64,
    pub expected_angular: f64,
    pub actual_angular: f64,
    pub lidar: Vec<f64>,
}

impl Message {
    /// `actualSpeed` as the robot sends it: a string with a number (rounded to 0.1 mm/s).
    pub fn actual_speed_text(&self) -> String {
        format!("{}", (self.actual_speed * 1e4).round() / 1e4)
    }

    /// The line Telegraf's `mqtt_consumer` JSON parser makes of this message: numbers as
    /// floats, `actualSpeed` kept as a string, tags sorted, and the fields in Go map order, a
    /// different order for every message (a shuffle seeded by the message's time, so runs repeat).
    pub fn to_line(&self, host: &str) -> String {
        let mut fields = vec![
            (
                "actualAngular".to_string(),
                FieldValue::Float((self.actual_angular * 1e4).round() / 1e4),
            ),
            (
                "actualSpeed".to_string(),
                FieldValue::Str(self.actual_speed_text()),
            ),
            (
                "expectedAngular".to_string(),
                FieldValue::Float(self.expected_angular),
            ),
            (
                "expectedSpeed".to_string(),
                FieldValue::Float(self.expected_speed),
            ),
        ];
        for (i, r) in self.lidar.iter().enumerate() {
            fields.push((format!("lidar_{i}"), FieldValue::Float(*r)));
        }
        fields.shuffle(&mut ChaCha8Rng::seed_from_u64(self.time_ns as u64));
        let mut w = LineWriter::new("mqtt_consumer");
        w.tag("host", host).tag("topic", "tessla");
        for (k, v) in &fields {
            w.field(k, v);
        }
        w.finish(Some(self.time_ns)).0.unwrap_or_default()
    }
}

#[derive(Debug, Default)]
pub struct Reply {
    /// Line protocol to record: the message as the pipeline saw it, then the monitors' outputs.
    pub lines: Vec<u8>,
    pub action: Option<Action>,
    /// ns: the robot's clock when the action arrived, when the twin measured it (an MQTT twin
    /// whose actions carry Telegraf's wall-clock time); otherwise the message's time plus the
    /// scenario's delay.
    pub received_ns: Option<i64>,
}

/// Why the monitors gave no answer: the broker behind them failed (in-process monitors always
/// answer).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TwinError {
    /// Publishing the robot's message failed.
    #[error(transparent)]
    Mqtt(#[from] crate::replay::mqtt::MqttError),
    /// The subscriber's client failed (the broker as shown, the client's text).
    #[error("MQTT broker {broker}: {error}")]
    Subscriber { broker: String, error: String },
    /// The broker did not confirm the subscription in time.
    #[error("MQTT broker {broker}: no subscription acknowledgement within {seconds} s")]
    NoSubAck { broker: String, seconds: f64 },
    /// A message after [`crate::simulate::mqtt_twin::MqttTwin::finish`].
    #[error("MQTT publisher already closed")]
    Closed,
}

/// Why a closed-loop run stopped.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A period that is not a positive number of seconds.
    #[error("period {0} s: must be positive")]
    Period(f64),
    /// A delay that is negative or not a number.
    #[error("delay {0} s: must be zero or positive")]
    Delay(f64),
    /// A noise level the normal distribution refuses.
    #[error("{0}")]
    Noise(rand_distr::NormalError),
    /// The output could not be written.
    #[error("cannot write the output: {0}")]
    Output(std::io::Error),
    /// The monitors gave no answer.
    #[error(transparent)]
    Twin(#[from] TwinError),
}

/// The monitors, in-process or behind a broker.
pub trait Twin {
    /// Hand over one message (`line` is its line-protocol form) and return the answer.
    /// `arrival_ns`: the robot's clock when the message reaches the twin (its own time, or later
    /// when a link drop held it back).
    fn exchange(
        &mut self,
        line: &str,
        message: &Message,
        arrival_ns: i64,
    ) -> Result<Reply, TwinError>;
}

/// A run's measures.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Outcome {
    /// Robot messages sent.
    pub messages: usize,
    /// Mean squared error between expected and reported actual speed over all messages.
    pub mse: f64,
    /// s the robot stood still while its command asked it to move.
    pub stuck_seconds: f64,
    /// Actions that changed the robot's command (executed with the monitor on; only proposed
    /// with it off).
    pub interventions: usize,
    /// Messages answered with an action.
    pub actions: usize,
    /// The spec's own `speed_mse` in the last action.
    pub spec_mse: Option<f64>,
    /// m driven.
    pub distance: f64,
    /// Actions refused because the robot's clock had passed their `valid_until`.
    pub refused_stale: usize,
    /// Actions refused as repeated: `seq` not above the last accepted one and not newer.
    pub refused_repeated: usize,
    /// Actions accepted from a restarted monitor: a lower `seq` with a newer timestamp.
    pub monitor_restarts: usize,
    /// Messages a link drop held back and sent late.
    pub messages_held: usize,
    /// ms: the age of the oldest data behind an action the robot accepted (its arrival on the
    /// robot's clock minus its message's time): what the robot acted on, judged by the robot's
    /// own record of what it sent, not by the action's `valid_until`.
    pub oldest_applied_ms: f64,
}

/// Run `scenario` against `twin`; `monitor_on` decides whether actions are executed. Every
/// line the twin returns is written to `out`.
pub fn run(
    scenario: &Scenario,
    monitor_on: bool,
    twin: &mut dyn Twin,
    out: &mut dyn Write,
) -> Result<Outcome, RunError> {
    let s = scenario;
    if !(s.period.is_finite() && s.period > 0.0) {
        return Err(RunError::Period(s.period));
    }
    if !(s.delay.is_finite() && s.delay >= 0.0) {
        return Err(RunError::Delay(s.delay));
    }
    let substeps = (s.period / s.dt.max(1e-6)).ceil().max(1.0) as usize;
    let dt = s.period / substeps as f64;
    let periods = (s.duration.min(s.program.duration()).max(0.0) / s.period).floor() as usize;

    // Independent streams: the robots of two runs with the same seed see the same noise.
    let stream = |n: u64| {
        let mut r = ChaCha8Rng::seed_from_u64(s.seed);
        r.set_stream(n);
        r
    };
    let (mut slam_rng, mut lidar_rng, mut angular_rng) = (stream(1), stream(2), stream(3));
    let slam = Normal::new(0.0, s.slam_noise.max(0.0)).map_err(RunError::Noise)?;
    let angular = Normal::new(0.0, s.angular_noise.max(0.0)).map_err(RunError::Noise)?;

    let mut robot = Robot::new(s.robot.clone());
    let mut pose_prev = robot.x + slam.sample(&mut slam_rng);
    // (arrival s, the program's speed when the message was sent, action speed)
    let mut pending: VecDeque<(f64, f64, f64)> = VecDeque::new();
    let mut executing: Option<(f64, f64)> = None;
    let mut outcome = Outcome {
        messages: 0,
        mse: 0.0,
        stuck_seconds: 0.0,
        interventions: 0,
        actions: 0,
        spec_mse: None,
        distance: 0.0,
        refused_stale: 0,
        refused_repeated: 0,
        monitor_restarts: 0,
        messages_held: 0,
        oldest_applied_ms: 0.0,
    };
    // (message, the program's speed when it was sent, s: when the link returns) held by a drop.
    let mut held: Vec<(Message, f64, f64)> = Vec::new();
    let mut gate = Gate::default();
    let delay_ns = (s.delay * 1e9).round() as i64;
    let mut sum_sq = 0.0;
    for k in 0..=periods {
        let t = k as f64 * s.period;
        let pose = robot.x + slam.sample(&mut slam_rng);
        let actual = if k == 0 {
            0.0
        } else {
            (pose - pose_prev) / s.period
        };
        pose_prev = pose;
        let expected = s.program.speed_at(t);
        let message = Message {
            time_ns: s.start_ns.saturating_add((t * 1e9).round() as i64),
            expected_speed: expected,
            actual_speed: actual,
            expected_angular: 0.0,
            actual_angular: angular.sample(&mut angular_rng),
            lidar: s.map.scan(robot.x, &s.lidar, &mut lidar_rng),
        };
        // The error as the monitor sees it: the reported (rounded) speed.
        let reported: f64 = message.actual_speed_text().parse().unwrap_or(actual);
        sum_sq += (expected - reported).powi(2);
        outcome.messages += 1;
        if let Some(&(a, l)) = s.link_drops.iter().find(|&&(a, l)| t >= a && t < a + l) {
            outcome.messages_held += 1;
            held.push((message, expected, a + l));
        } else {
            // The link is up: what it held went when it came back, then this message.
            for (message, expected, arrival) in held
                .drain(..)
                .chain(std::iter::once((message, expected, t)))
            {
                let arrival_ns = s.start_ns.saturating_add((arrival * 1e9).round() as i64);
                let reply = twin.exchange(&message.to_line(&s.host), &message, arrival_ns)?;
                out.write_all(&reply.lines).map_err(RunError::Output)?;
                let Some(a) = reply.action else {
                    continue;
                };
                outcome.actions += 1;
                if a.augmented {
                    outcome.interventions += 1;
                }
                if a.speed_mse.is_some() {
                    outcome.spec_mse = a.speed_mse;
                }
                // The robot judges the action when it arrives (the book, "What a robot must do
                // with an action"); with the monitor off it would not execute it anyway.
                let clock = reply
                    .received_ns
                    .unwrap_or_else(|| arrival_ns.saturating_add(delay_ns));
                let accepted = gate.judge(&a, clock).accepted();
                if accepted {
                    let age = clock.saturating_sub(message.time_ns) as f64 / 1e6;
                    outcome.oldest_applied_ms = outcome.oldest_applied_ms.max(age);
                }
                if monitor_on && accepted && a.speed.is_finite() {
                    pending.push_back((arrival + s.delay, expected, a.speed));
                }
            }
        }
        if k == periods {
            break;
        }
        for j in 0..substeps {
            let now = t + j as f64 * dt;
            while let Some(&(arrival, setpoint, speed)) = pending.front() {
                if arrival > now + dt / 2.0 {
                    break;
                }
                executing = Some((setpoint, speed));
                pending.pop_front();
            }
            let own = s.program.speed_at(now);
            let command = match executing {
                Some((setpoint, speed)) if setpoint == own => speed,
                _ => own,
            };
            robot.step(command, s.terrain.ground(robot.x), dt);
            if robot.at_rest() && command.abs() > 0.0 {
                outcome.stuck_seconds += dt;
            }
        }
    }
    outcome.mse = sum_sq / outcome.messages.max(1) as f64;
    // Summed in 5 ms steps: keep the millisecond, drop the rounding noise.
    outcome.stuck_seconds = (outcome.stuck_seconds * 1000.0).round() / 1000.0;
    outcome.distance = robot.x;
    outcome.refused_stale = gate.refused_stale;
    outcome.refused_repeated = gate.refused_repeated;
    outcome.monitor_restarts = gate.monitor_restarts;
    Ok(outcome)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::scenario::{self, TerrainChoice};

    /// A twin that answers every message with the same speed and counts what it saw.
    struct Fixed {
        speed: f64,
        seen: Vec<f64>,
    }

    impl Twin for Fixed {
        fn exchange(&mut self, line: &str, message: &Message, _: i64) -> Result<Reply, TwinError> {
            assert!(line.starts_with("mqtt_consumer,host=sim,topic=tessla "));
            self.seen.push(message.expected_speed);
            Ok(Reply {
                lines: line.as_bytes().to_vec(),
                action: Some(Action {
                    speed: self.speed,
                    augmented: self.speed != message.expected_speed,
                    speed_mse: None,
                    seq: None,
                    valid_until: None,
                    time_ns: None,
                }),
                received_ns: None,
            })
        }
    }

    fn flat(delay: f64) -> Scenario {
        let terrain = Terrain::parse("0 0\n100 0\n").unwrap();
        let program = Program::parse("10 0.1\n").unwrap();
        let mut s = scenario::build(TerrainChoice::Custom(terrain), program, 1);
        s.delay = delay;
        s
    }

    fn drive(s: &Scenario, on: bool, speed: f64) -> (Outcome, Vec<u8>) {
        let mut twin = Fixed {
            speed,
            seen: Vec::new(),
        };
        let mut out = Vec::new();
        let o = run(s, on, &mut twin, &mut out).unwrap();
        assert_eq!(twin.seen.len(), o.messages);
        (o, out)
    }

    #[test]
    fn the_robot_executes_actions_only_with_the_monitor_on_and_after_the_delay() {
        let s = flat(0.2);
        // A twin that always says "stop".
        let (off, out) = drive(&s, false, 0.0);
        assert_eq!(off.messages, 21);
        // 10 s at 0.1 m/s, less what the controller's lag (tau = 0.5 s) and the integral's
        // build-up against rolling resistance cost at the start.
        assert!(
            off.distance > 0.85 && off.distance < 1.0,
            "{}",
            off.distance
        );
        assert_eq!(off.interventions, 21, "proposed, not executed");
        assert_eq!(
            out.iter().filter(|b| **b == b'\n').count(),
            21,
            "every line the twin returned is written"
        );
        let (on, _) = drive(&s, true, 0.0);
        // It moves only during the first 0.2 s, until the first "stop" arrives.
        assert!(on.distance < 0.02, "{}", on.distance);
        assert_eq!(
            on.stuck_seconds, 0.0,
            "standing still on command is not being stuck"
        );
        // A delay longer than the run: no action ever takes effect.
        let (late, _) = drive(&flat(20.0), true, 0.0);
        assert_eq!(late.distance, off.distance);
        assert_eq!(late.mse, off.mse);
    }

    #[test]
    fn the_mse_is_over_the_reported_speed() {
        let (o, _) = drive(&flat(0.2), false, 0.1);
        // The first message reports 0 against 0.1 and the next ones the start-up lag; then the
        // robot tracks the command within the estimate's noise.
        assert!(o.mse > 0.01 / 21.0 && o.mse < 0.002, "{}", o.mse);
        assert_eq!(o.stuck_seconds, 0.0);
    }
}
