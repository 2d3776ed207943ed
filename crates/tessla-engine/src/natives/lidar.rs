//! Lidar scan functions for the robot monitors (P1 and P3), declared in `specs/lidar.tessla`.
//!
//! Owns: beam classification over one scan (`List[Float]`, beam i at angle i·360°/N
//! counter-clockwise from straight ahead, N = the list's length): a beam is *valid* when it is a
//! number within [range_min, range_max]; anything else (0.0 no-return, NaN/missing, out of range)
//! is a *dropout*. A valid beam is a *spike* when both cyclic neighbours are valid and it differs
//! from each by more than gamma in the same direction. Sector functions use valid, non-spike beams.

use crate::value::{RuntimeError, Value};

struct Scan<'a> {
    beams: Vec<f64>,
    rmin: f64,
    rmax: f64,
    gamma: f64,
    _p: std::marker::PhantomData<&'a ()>,
}

fn scan(args: &[Value], with_gamma: bool) -> Option<Scan<'static>> {
    let Value::List(l) = args.first()? else {
        return None;
    };
    let num = |i: usize| match args.get(i) {
        Some(Value::Float(f)) => Some(*f),
        _ => None,
    };
    let beams = l
        .iter()
        .map(|v| match v {
            Value::Float(f) => *f,
            _ => f64::NAN,
        })
        .collect();
    Some(Scan {
        beams,
        rmin: num(1)?,
        rmax: num(2)?,
        gamma: if with_gamma { num(3)? } else { 0.0 },
        _p: std::marker::PhantomData,
    })
}

impl Scan<'_> {
    fn valid(&self, i: usize) -> bool {
        let r = self.beams[i];
        r.is_finite() && r >= self.rmin && r <= self.rmax
    }

    fn spike(&self, i: usize) -> bool {
        let n = self.beams.len();
        if n < 3 || !self.valid(i) {
            return false;
        }
        let (p, q) = ((i + n - 1) % n, (i + 1) % n);
        if !self.valid(p) || !self.valid(q) {
            return false;
        }
        let (r, a, b) = (self.beams[i], self.beams[p], self.beams[q]);
        (r - a > self.gamma && r - b > self.gamma) || (a - r > self.gamma && b - r > self.gamma)
    }

    /// Beam indices whose angle lies in the sector `from..to` degrees (counter-clockwise, wrapping).
    fn sector(&self, from: f64, to: f64) -> impl Iterator<Item = usize> + '_ {
        let n = self.beams.len();
        let from = from.rem_euclid(360.0);
        let to = to.rem_euclid(360.0);
        (0..n).filter(move |i| {
            let a = *i as f64 * 360.0 / n as f64;
            if from <= to {
                a >= from && a <= to
            } else {
                a >= from || a <= to
            }
        })
    }
}

fn bad(name: &str) -> Value {
    Value::Error(RuntimeError::Other(
        format!("{name}: expected (List[Float], Float, ...)").into(),
    ))
}

/// `lidar_dropouts(scan, range_min, range_max): Int`.
pub fn dropouts(a: &[Value]) -> Value {
    match scan(a, false) {
        Some(s) => Value::Int((0..s.beams.len()).filter(|i| !s.valid(*i)).count() as i64),
        None => bad("lidar_dropouts"),
    }
}

/// `lidar_spikes(scan, range_min, range_max, gamma): Int`.
pub fn spikes(a: &[Value]) -> Value {
    match scan(a, true) {
        Some(s) => Value::Int((0..s.beams.len()).filter(|i| s.spike(*i)).count() as i64),
        None => bad("lidar_spikes"),
    }
}

/// `lidar_sector_min(scan, range_min, range_max, gamma, from_deg, to_deg): Float`: the minimum
/// over valid, non-spike beams in the sector; `range_max` when there is none.
pub fn sector_min(a: &[Value]) -> Value {
    let (Some(s), Some(Value::Float(from)), Some(Value::Float(to))) =
        (scan(a, true), a.get(4), a.get(5))
    else {
        return bad("lidar_sector_min");
    };
    let m = s
        .sector(*from, *to)
        .filter(|i| s.valid(*i) && !s.spike(*i))
        .map(|i| s.beams[i])
        .fold(f64::INFINITY, f64::min);
    Value::Float(if m.is_finite() { m } else { s.rmax })
}

/// `lidar_sector_valid_fraction(scan, range_min, range_max, gamma, from_deg, to_deg): Float`:
/// the share of the sector's beams that are valid and not spikes (0.0 for an empty sector).
pub fn sector_valid_fraction(a: &[Value]) -> Value {
    let (Some(s), Some(Value::Float(from)), Some(Value::Float(to))) =
        (scan(a, true), a.get(4), a.get(5))
    else {
        return bad("lidar_sector_valid_fraction");
    };
    let all: Vec<usize> = s.sector(*from, *to).collect();
    if all.is_empty() {
        return Value::Float(0.0);
    }
    let ok = all.iter().filter(|i| s.valid(**i) && !s.spike(**i)).count();
    Value::Float(ok as f64 / all.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn list(v: &[f64]) -> Value {
        Value::List(Arc::new(v.iter().map(|x| Value::Float(*x)).collect()))
    }

    #[test]
    fn dropouts_count_zero_nan_and_out_of_range() {
        let s = list(&[1.0, 0.0, f64::NAN, 5.0, 0.1, 2.0]);
        assert_eq!(
            dropouts(&[s, Value::Float(0.12), Value::Float(3.5)]),
            Value::Int(4)
        );
    }

    #[test]
    fn spikes_need_two_valid_neighbours_same_direction() {
        // Beam 2 spikes up, beam 5 spikes down, beam 7 next to a dropout is not a spike.
        let s = list(&[1.0, 1.0, 2.0, 1.0, 1.0, 0.3, 1.0, 2.5, 0.0, 1.0]);
        let args = [s, Value::Float(0.12), Value::Float(3.5), Value::Float(0.3)];
        assert_eq!(spikes(&args), Value::Int(2));
    }

    #[test]
    fn sector_min_wraps_and_skips_spikes_for_any_beam_count() {
        // 8 beams: 0°, 45°, ..., 315°. Sector 330..30 holds only beam 0 (0°); 300..60 holds 7, 0, 1.
        let s = list(&[2.0, 1.9, 3.0, 3.0, 3.0, 3.0, 2.0, 1.8]);
        let base = [s, Value::Float(0.12), Value::Float(3.5), Value::Float(0.3)];
        let mut a = base.to_vec();
        a.extend([Value::Float(330.0), Value::Float(30.0)]);
        assert_eq!(sector_min(&a), Value::Float(2.0));
        let mut b = base.to_vec();
        b.extend([Value::Float(300.0), Value::Float(60.0)]);
        assert_eq!(sector_min(&b), Value::Float(1.8));
        assert_eq!(sector_valid_fraction(&b), Value::Float(1.0));
    }

    #[test]
    fn a_blinded_sector_has_no_valid_beams() {
        let s = list(&[0.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0]);
        let a = [
            s,
            Value::Float(0.12),
            Value::Float(3.5),
            Value::Float(0.3),
            Value::Float(300.0),
            Value::Float(60.0),
        ];
        assert_eq!(sector_valid_fraction(&a), Value::Float(1.0 / 3.0));
        assert_eq!(sector_min(&a), Value::Float(1.0));
    }
}
