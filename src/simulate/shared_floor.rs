//! Robots sharing one floor, for the fleet example (`simulate --shared-floor N`, docs/fleet.md):
//! the records of N robots, each on its own topic `tessla/tb3-<i>`, as Telegraf's
//! `mqtt_consumer` makes them (fields `expectedSpeed`, `actualSpeed`, `x`, `y`; 5 Hz).
//!
//! Owns: the robots' paths and their speed reports. Robot i drives back and forth along the
//! floor's x axis on its own lane, y = 0.25 + 0.4·i m, x(t) = 1 + 3·sin(2πt/60 + 0.3·i) m, so
//! every 30 s the first robots cross zone A (x 0..2, y 0..1 in specs/fleet/fleet.tessla) close
//! behind each other: two robots in zone A at once, lanes 0.4 m apart (closer than the 0.5 m a
//! fleet operator watches). `expectedSpeed` is the path's speed, `actualSpeed` that with
//! Gaussian noise (sd 2 mm/s, seeded); the last robot stalls (actual 0) from 10 s to 12 s, so
//! the fleet's P2 count moves. No monitors run here: the records go to `run --fleet-spec`.

use lineproto::{FieldValue, LineWriter};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// s between a robot's messages (5 Hz, as the fleet fixture).
pub const PERIOD: f64 = 0.2;
/// m between neighbouring lanes.
pub const LANE: f64 = 0.4;
/// s: the period of a robot's back-and-forth.
const LAP: f64 = 60.0;
/// m: half the length of a robot's stretch of floor.
const REACH: f64 = 3.0;
/// rad: phase between neighbouring robots.
const PHASE: f64 = 0.3;

/// The position (m) of robot `i` at `t` s.
pub fn position(i: usize, t: f64) -> (f64, f64) {
    let w = std::f64::consts::TAU / LAP;
    let x = 1.0 + REACH * (w * t + PHASE * i as f64).sin();
    (x, 0.25 + LANE * i as f64)
}

/// The speed (m/s) of robot `i` at `t` s along its lane.
fn speed(i: usize, t: f64) -> f64 {
    let w = std::f64::consts::TAU / LAP;
    (REACH * w * (w * t + PHASE * i as f64).cos()).abs()
}

/// The line protocol of `robots` robots over `seconds` s from `start_ns`, in time order (robot
/// i's message of a period `i` ns after the period's start, as several clients publishing at
/// once), tagged `host`.
pub fn records(robots: usize, seconds: f64, start_ns: i64, seed: u64, host: &str) -> String {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.002).ok();
    let steps = (seconds / PERIOD).floor().max(0.0) as usize;
    let mut out = String::new();
    for k in 0..steps {
        let t = k as f64 * PERIOD;
        for i in 0..robots {
            let expected = (speed(i, t) * 1e4).round() / 1e4;
            let stalled = i + 1 == robots && (10.0..12.0).contains(&t);
            let actual = if stalled {
                0.0
            } else {
                let n = noise.map_or(0.0, |n| n.sample(&mut rng));
                ((expected + n) * 1e4).round() / 1e4
            };
            let (x, y) = position(i, t);
            let mut w = LineWriter::new("mqtt_consumer");
            w.tag("host", host)
                .tag("topic", &format!("tessla/tb3-{}", i + 1));
            w.field("expectedSpeed", &FieldValue::Float(expected));
            w.field("actualSpeed", &FieldValue::Float(actual));
            w.field("x", &FieldValue::Float((x * 1e3).round() / 1e3));
            w.field("y", &FieldValue::Float((y * 1e3).round() / 1e3));
            let ns = start_ns + (t * 1e9).round() as i64 + i as i64;
            // The writer ends the line with its newline.
            if let Some(line) = w.finish(Some(ns)).0 {
                out.push_str(&line);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_two_robots_share_zone_a_closer_than_half_a_metre() {
        let in_zone = |(x, y): (f64, f64)| (0.0..=2.0).contains(&x) && (0.0..=1.0).contains(&y);
        let both = (0..300)
            .map(|k| k as f64 * PERIOD)
            .filter(|&t| in_zone(position(0, t)) && in_zone(position(1, t)))
            .count();
        assert!(both > 10, "{both} periods with two robots in zone A");
        let closest = (0..300)
            .map(|k| {
                let t = k as f64 * PERIOD;
                let (a, b) = (position(0, t), position(1, t));
                (a.0 - b.0).hypot(a.1 - b.1)
            })
            .fold(f64::INFINITY, f64::min);
        assert!(closest < 0.5, "closest {closest}");
        let text = records(3, 2.0, 0, 1, "sim");
        assert_eq!(text.lines().count(), 30);
        assert!(text.contains("topic=tessla/tb3-3 "));
    }
}
