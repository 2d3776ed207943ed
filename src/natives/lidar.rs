//! Lidar scan functions for the robot monitors (P1 and P3), declared in `specs/lidar.tessla`.
//!
//! Owns: beam classification over one scan (`List[Float]`, beam i at angle i·360°/N
//! counter-clockwise from straight ahead, N = the list's length): a beam is *valid* when it is a
//! number within [range_min, range_max]; anything else (0.0 no-return, NaN/missing, out of range)
//! is a *dropout*. A valid beam is a *spike* when both cyclic neighbours are valid and it differs
//! from each by more than gamma in the same direction. Sector functions use valid, non-spike beams.

use std::ops::Range;
use tessla_engine::{RuntimeError, Value};

/// One scan and its parameters, the beams borrowed from the list value: four natives read every
/// scan (P1's two sector functions, P3's spikes and dropouts), so each reads only the beams it
/// needs, once, instead of copying the scan into a vector of its own.
struct Scan<'a> {
    beams: &'a [Value],
    rmin: f64,
    rmax: f64,
    gamma: f64,
}

fn scan(args: &[Value], with_gamma: bool) -> Option<Scan<'_>> {
    let Value::List(l) = args.first()? else {
        return None;
    };
    let num = |i: usize| match args.get(i) {
        Some(Value::Float(f)) => Some(*f),
        _ => None,
    };
    Some(Scan {
        beams: l.as_slice(),
        rmin: num(1)?,
        rmax: num(2)?,
        gamma: if with_gamma { num(3)? } else { 0.0 },
    })
}

/// Beams per block of [`Scan::walk`]: a block's cleaned ranges and its two neighbours live in a
/// stack buffer, so the spike test runs over plain floats.
const BLOCK: usize = 32;

impl Scan<'_> {
    fn len(&self) -> usize {
        self.beams.len()
    }

    /// Bounds `lo`, `hi` with `lo <= r && r <= hi` exactly when `r` is a valid reading (finite
    /// and within [rmin, rmax]): finite bounds leave no room for the infinities, and a NaN bound
    /// admits nothing. Two comparisons per beam instead of three.
    fn bounds(&self) -> (f64, f64) {
        if self.rmin.is_nan() || self.rmax.is_nan() {
            (f64::INFINITY, f64::NEG_INFINITY)
        } else {
            (self.rmin.max(-f64::MAX), self.rmax.min(f64::MAX))
        }
    }

    /// `f(ranges)` for consecutive blocks of `beams`, ascending: `ranges` holds the block's
    /// beams with one cyclic neighbour each side, each its range when it is valid and NaN when it
    /// is not (neighbours NaN in a scan of fewer than 3 beams, which has no spikes). Each beam is
    /// read once into the buffer; [`steep`] on its windows tells the spikes.
    #[inline(always)]
    fn blocks(&self, beams: Range<usize>, mut f: impl FnMut(&[f64])) {
        let n = self.len();
        let (lo, hi) = self.bounds();
        let Some(all) = self.beams.get(beams.clone()) else {
            return;
        };
        let at = |i: usize| match self.beams.get(i) {
            Some(v) if n >= 3 => clean(beam(v), lo, hi),
            _ => f64::NAN,
        };
        let mut buf = [0.0f64; BLOCK + 2];
        let mut prev = at(if beams.start == 0 {
            n.wrapping_sub(1)
        } else {
            beams.start - 1
        });
        let mut next = beams.start;
        for block in all.chunks(BLOCK) {
            next += block.len();
            let k = block.len();
            buf[0] = prev;
            gather(block, &mut buf[1..=k]);
            for r in &mut buf[1..=k] {
                *r = clean(*r, lo, hi);
            }
            buf[k + 1] = at(if next == n { 0 } else { next });
            f(&buf[..k + 2]);
            prev = buf[k];
        }
    }

    /// `f(range, spike)` for each beam of `beams`, ascending, `range` as in [`Scan::blocks`].
    #[inline(always)]
    fn walk(&self, beams: Range<usize>, mut f: impl FnMut(f64, bool)) {
        let g = self.gamma;
        self.blocks(beams, |w| {
            for ((a, r), b) in w.iter().zip(&w[1..]).zip(&w[2..]) {
                f(*r, steep(g, *a, *r, *b));
            }
        });
    }

    /// Beam indices whose angle `i·360/N` lies in the sector `from..to` degrees
    /// (counter-clockwise, wrapping), ascending, as at most two ranges. The angle grows with `i`
    /// (exact products, one rounded division), so each bound cuts `0..N` once: found by bisection
    /// on the same angle expression, the ranges hold exactly the beams a test of every beam finds.
    fn sector(&self, from: f64, to: f64) -> [Range<usize>; 2] {
        let n = self.len();
        let from = from.rem_euclid(360.0);
        let to = to.rem_euclid(360.0);
        let angle = |i: usize| i as f64 * 360.0 / n as f64;
        // The first beam at or past `from` and the first past `to` (none for a NaN bound).
        let lo = first(n, |i| angle(i) >= from);
        let hi = first(n, |i| to.is_nan() || angle(i) > to);
        if from <= to {
            [lo..hi.max(lo), 0..0]
        } else {
            // No beam is both past `from` and up to `to` here, so hi <= lo.
            [0..hi.min(lo), lo..n]
        }
    }
}

/// `r` when `lo <= r <= hi`, else NaN: the exponent and quiet bits or-ed in by mask, no select.
#[inline(always)]
fn clean(r: f64, lo: f64, hi: f64) -> f64 {
    let bad = u64::from(!((r >= lo) & (r <= hi)));
    f64::from_bits(r.to_bits() | bad.wrapping_neg() & f64::NAN.to_bits())
}

/// Whether `r` differs from both neighbours `a` and `b` by more than `g` in the same direction:
/// a spike when all three are valid ranges, and never when one is NaN (an invalid beam), as a NaN
/// fails every comparison. `a - r` is exactly `-(r - a)`, so two differences suffice.
#[inline(always)]
fn steep(g: f64, a: f64, r: f64, b: f64) -> bool {
    let (d1, d2) = (r - a, r - b);
    ((d1 > g) & (d2 > g)) | ((d1 < -g) & (d2 < -g))
}

/// Each beam's range into `out` (NaN for an element that is not a float), four at a time: the
/// element's tag decides a branch per beam, so the unrolled loop saves the loop's own count.
#[inline(always)]
fn gather(beams: &[Value], out: &mut [f64]) {
    let mut o4 = out.chunks_exact_mut(4);
    let mut b4 = beams.chunks_exact(4);
    for (o, b) in (&mut o4).zip(&mut b4) {
        if let ([o0, o1, o2, o3], [b0, b1, b2, b3]) = (o, b) {
            (*o0, *o1, *o2, *o3) = (beam(b0), beam(b1), beam(b2), beam(b3));
        }
    }
    for (o, b) in o4.into_remainder().iter_mut().zip(b4.remainder()) {
        *o = beam(b);
    }
}

/// A beam's range: NaN for an element that is not a float.
#[inline]
fn beam(v: &Value) -> f64 {
    match v {
        Value::Float(f) => *f,
        _ => f64::NAN,
    }
}

/// The first `i` in `0..n` where `holds` (n when none), for a `holds` false up to some point and
/// true from there on.
fn first(n: usize, holds: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if holds(mid) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo
}

fn bad(name: &str) -> Value {
    Value::Error(RuntimeError::Other(
        format!("{name}: expected (List[Float], Float, ...)").into(),
    ))
}

/// `lidar_dropouts(scan, range_min, range_max): Int`.
pub fn dropouts(a: &[Value]) -> Value {
    match scan(a, false) {
        Some(s) => {
            // Gathered a block at a time, then counted over plain floats (vectorised).
            let (lo, hi) = s.bounds();
            let mut buf = [0.0f64; BLOCK];
            let mut bad = 0usize;
            for block in s.beams.chunks(BLOCK) {
                let rs = &mut buf[..block.len()];
                gather(block, rs);
                bad += rs
                    .iter()
                    .map(|r| usize::from(!((*r >= lo) & (*r <= hi))))
                    .sum::<usize>();
            }
            Value::Int(bad as i64)
        }
        None => bad("lidar_dropouts"),
    }
}

/// `lidar_spikes(scan, range_min, range_max, gamma): Int`.
pub fn spikes(a: &[Value]) -> Value {
    match scan(a, true) {
        Some(s) => {
            let mut count = 0usize;
            s.walk(0..s.len(), |_, spike| count += usize::from(spike));
            Value::Int(count as i64)
        }
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
    let (g, mut m) = (s.gamma, f64::INFINITY);
    let mut keep = [0.0f64; BLOCK];
    for beams in s.sector(*from, *to) {
        s.blocks(beams, |w| {
            // The block's ranges with spikes made NaN (a pass over plain floats), then their
            // minimum in beam order: a NaN (an invalid beam or a spike) leaves `m` as it is.
            let keep = &mut keep[..w.len() - 2];
            for (k, ((a, r), b)) in keep.iter_mut().zip(w.iter().zip(&w[1..]).zip(&w[2..])) {
                let spike = u64::from(steep(g, *a, *r, *b));
                *k = f64::from_bits(r.to_bits() | spike.wrapping_neg() & f64::NAN.to_bits());
            }
            m = keep.iter().fold(m, |m, r| first_min(m, *r));
        });
    }
    Value::Float(if m.is_finite() { m } else { s.rmax })
}

/// The smaller of `m` and `r`, `m` when they are equal or `r` is NaN: a minimum taken in beam
/// order is then the first of equal beams, whatever the build (`f64::min` may return either of
/// 0.0 and -0.0, and which one changes with vectorisation).
#[inline(always)]
fn first_min(m: f64, r: f64) -> f64 {
    if r < m { r } else { m }
}

/// `lidar_sector_valid_fraction(scan, range_min, range_max, gamma, from_deg, to_deg): Float`:
/// the share of the sector's beams that are valid and not spikes (0.0 for an empty sector).
pub fn sector_valid_fraction(a: &[Value]) -> Value {
    let (Some(s), Some(Value::Float(from)), Some(Value::Float(to))) =
        (scan(a, true), a.get(4), a.get(5))
    else {
        return bad("lidar_sector_valid_fraction");
    };
    let sector = s.sector(*from, *to);
    let all: usize = sector.iter().map(ExactSizeIterator::len).sum();
    if all == 0 {
        return Value::Float(0.0);
    }
    let mut ok = 0usize;
    for beams in sector {
        s.walk(beams, |r, spike| ok += usize::from(!r.is_nan() & !spike));
    }
    Value::Float(ok as f64 / all as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn list(v: &[f64]) -> Value {
        Value::List(Arc::new(v.iter().map(|x| Value::Float(*x)).collect()))
    }

    /// The definitions above written the plain way (every beam tested, a neighbour found by
    /// `%`, the sector by the angle of each beam): the natives must give exactly these values.
    mod reference {
        pub struct Scan {
            pub beams: Vec<f64>,
            pub rmin: f64,
            pub rmax: f64,
            pub gamma: f64,
        }

        impl Scan {
            pub fn valid(&self, i: usize) -> bool {
                let r = self.beams[i];
                r.is_finite() && r >= self.rmin && r <= self.rmax
            }

            pub fn spike(&self, i: usize) -> bool {
                let n = self.beams.len();
                if n < 3 || !self.valid(i) {
                    return false;
                }
                let (p, q) = ((i + n - 1) % n, (i + 1) % n);
                if !self.valid(p) || !self.valid(q) {
                    return false;
                }
                let (r, a, b) = (self.beams[i], self.beams[p], self.beams[q]);
                let g = self.gamma;
                (r - a > g && r - b > g) || (a - r > g && b - r > g)
            }

            pub fn sector(&self, from: f64, to: f64) -> Vec<usize> {
                let n = self.beams.len();
                let from = from.rem_euclid(360.0);
                let to = to.rem_euclid(360.0);
                (0..n)
                    .filter(|i| {
                        let a = *i as f64 * 360.0 / n as f64;
                        if from <= to {
                            a >= from && a <= to
                        } else {
                            a >= from || a <= to
                        }
                    })
                    .collect()
            }

            pub fn sector_min(&self, from: f64, to: f64) -> f64 {
                let m = self
                    .sector(from, to)
                    .into_iter()
                    .filter(|i| self.valid(*i) && !self.spike(*i))
                    .map(|i| self.beams[i])
                    .fold(f64::INFINITY, |m, r| if r < m { r } else { m });
                if m.is_finite() { m } else { self.rmax }
            }

            pub fn sector_valid_fraction(&self, from: f64, to: f64) -> f64 {
                let all = self.sector(from, to);
                if all.is_empty() {
                    return 0.0;
                }
                let ok = all
                    .iter()
                    .filter(|i| self.valid(**i) && !self.spike(**i))
                    .count();
                ok as f64 / all.len() as f64
            }
        }
    }

    #[test]
    fn the_natives_equal_the_plain_definitions() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        let bounds = [
            0.0,
            1.0,
            29.5,
            30.0,
            45.0,
            90.0,
            179.0,
            180.0,
            300.0,
            330.0,
            359.0,
            359.9,
            360.0,
            -30.0,
            390.0,
            720.5,
            -0.0,
            f64::NAN,
            f64::INFINITY,
        ];
        for round in 0..6000 {
            let n = match round % 8 {
                0 => (next() % 5) as usize,
                1 => 360,
                2 => 7,
                _ => (next() % 50) as usize,
            };
            let beams: Vec<f64> = (0..n)
                .map(|_| match next() % 18 {
                    0 => 0.0,
                    1 => f64::NAN,
                    2 => 5.0,
                    3 => 0.05,
                    4 => 3.5,
                    5 => 0.12,
                    6 => f64::INFINITY,
                    7 => f64::NEG_INFINITY,
                    8 => -0.0,
                    9 => -((next() % 3400) as f64) / 1000.0,
                    10 => f64::MAX,
                    _ => (next() % 3400) as f64 / 1000.0 + 0.1,
                })
                .collect();
            // Mostly the robots' bounds; also bounds admitting zeros, negatives, everything
            // finite, or nothing (NaN), and gammas that are negative, infinite or NaN.
            let (rmin, rmax) = match (round / 3) % 9 {
                0 => (0.0, 3.5),
                1 => (-0.0, 0.0),
                2 => (f64::NEG_INFINITY, f64::INFINITY),
                3 => (-1.0, f64::MAX),
                4 => (f64::NAN, 3.5),
                5 => (0.12, f64::NAN),
                6 => (3.5, 0.12),
                _ => (0.12, 3.5),
            };
            let r = reference::Scan {
                beams: beams.clone(),
                rmin,
                rmax,
                gamma: [
                    0.3,
                    0.0,
                    1.0,
                    0.3,
                    -0.5,
                    f64::NAN,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                ][(round / 7) % 8],
            };
            let mut l = list(&beams);
            if round % 5 == 0 && n > 0 {
                // An element that is not a float reads as NaN.
                let Value::List(items) = &mut l else {
                    unreachable!()
                };
                let i = (next() % n as u64) as usize;
                Arc::make_mut(items)[i] = if next() % 2 == 0 {
                    Value::Int(1)
                } else {
                    Value::Bool(true)
                };
                let mut b = beams.clone();
                b[i] = f64::NAN;
                check_against(&l, &reference::Scan { beams: b, ..r }, &bounds, &mut next);
            } else {
                check_against(&l, &r, &bounds, &mut next);
            }
        }
    }

    fn check_against(
        l: &Value,
        r: &reference::Scan,
        bounds: &[f64],
        next: &mut impl FnMut() -> u64,
    ) {
        let (rmin, rmax, g) = (
            Value::Float(r.rmin),
            Value::Float(r.rmax),
            Value::Float(r.gamma),
        );
        let n = r.beams.len();
        let want_drop = (0..n).filter(|i| !r.valid(*i)).count() as i64;
        assert_eq!(
            dropouts(&[l.clone(), rmin.clone(), rmax.clone()]),
            Value::Int(want_drop)
        );
        let want_spikes = (0..n).filter(|i| r.spike(*i)).count() as i64;
        let base = [l.clone(), rmin, rmax, g];
        assert_eq!(spikes(&base), Value::Int(want_spikes), "{:?}", r.beams);
        for _ in 0..6 {
            let from = bounds[(next() % bounds.len() as u64) as usize];
            let to = bounds[(next() % bounds.len() as u64) as usize];
            let mut a = base.to_vec();
            a.extend([Value::Float(from), Value::Float(to)]);
            let (Value::Float(m), Value::Float(f)) = (sector_min(&a), sector_valid_fraction(&a))
            else {
                panic!("not floats")
            };
            assert_eq!(
                m.to_bits(),
                r.sector_min(from, to).to_bits(),
                "{from}..{to} {:?}",
                r.beams
            );
            assert_eq!(
                f.to_bits(),
                r.sector_valid_fraction(from, to).to_bits(),
                "{from}..{to} {:?}",
                r.beams
            );
        }
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
