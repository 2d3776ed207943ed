//! Fleet functions that TeSSLa cannot express at an acceptable cost: the closest pair of
//! robot positions (`fleet_closest_pair`). In TeSSLa itself it is a fold over every pair,
//! O(n²) per step (1k robots: half a million distances per fleet step); here it is the grid
//! method, O(n) expected (`make bench-fleet` measures both at 1k, 10k and 100k robots).

use std::collections::HashMap;
use std::sync::Arc;
use tessla_engine::{RuntimeError, Value};

fn bad(name: &str) -> Value {
    Value::Error(RuntimeError::Other(
        format!("{name}: expected a Map[String, (Float, Float)]").into(),
    ))
}

/// `fleet_closest_pair(positions: Map[String, (Float, Float)]): Option[(String, String, Float)]`:
/// the two robots closest to each other (their keys in order) and their distance; `None` with
/// fewer than two robots with finite positions.
///
/// The grid method (Rabin; Khuller and Matias): the first pair's distance is a first bound δ;
/// points are put in cells of side δ, and each point is compared only with the points of its
/// own and the 8 neighbouring cells; when a closer pair is found, the grid is rebuilt with the
/// smaller δ. With the points taken in a pseudo-random order (by a hash of their keys, so the
/// result does not depend on the map's order), the expected number of rebuilds' work is O(n).
pub fn closest_pair(a: &[Value]) -> Value {
    let [Value::Map(m)] = a else {
        return bad("fleet_closest_pair");
    };
    let mut pts: Vec<(u64, &str, f64, f64)> = Vec::with_capacity(m.len());
    for (k, v) in m.iter() {
        let (Value::Str(k), Value::Tuple(t)) = (k, v) else {
            return bad("fleet_closest_pair");
        };
        let (Some(Value::Float(x)), Some(Value::Float(y))) = (t.first(), t.get(1)) else {
            return bad("fleet_closest_pair");
        };
        if x.is_finite() && y.is_finite() {
            pts.push((mix(k), k, *x, *y));
        }
    }
    match closest(&mut pts) {
        Some((i, j, d)) => {
            let (a, b) = if pts[i].1 <= pts[j].1 {
                (pts[i].1, pts[j].1)
            } else {
                (pts[j].1, pts[i].1)
            };
            Value::Some(Arc::new(Value::Tuple(Arc::from(vec![
                Value::Str(Arc::from(a)),
                Value::Str(Arc::from(b)),
                Value::Float(d),
            ]))))
        }
        None => Value::None,
    }
}

/// A hash of a key (FNV-1a, then a final mix): the order points are taken in.
fn mix(k: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in k.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^ (h >> 33)
}

/// The closest pair of `pts` (indices after sorting them by hash, then key) and its distance.
pub fn closest(pts: &mut [(u64, &str, f64, f64)]) -> Option<(usize, usize, f64)> {
    if pts.len() < 2 {
        return None;
    }
    pts.sort_unstable_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
    let dist =
        |i: usize, j: usize| ((pts[i].2 - pts[j].2).powi(2) + (pts[i].3 - pts[j].3).powi(2)).sqrt();
    let mut best = (0, 1, dist(0, 1));
    if best.2 == 0.0 {
        return Some(best);
    }
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::with_capacity(pts.len());
    let cell = |d: f64, x: f64, y: f64| ((x / d).floor() as i64, (y / d).floor() as i64);
    let build = |grid: &mut HashMap<(i64, i64), Vec<usize>>, d: f64, upto: usize| {
        grid.clear();
        for (i, p) in pts.iter().enumerate().take(upto) {
            grid.entry(cell(d, p.2, p.3)).or_default().push(i);
        }
    };
    build(&mut grid, best.2, 2);
    for (i, p) in pts.iter().enumerate().skip(2) {
        let (cx, cy) = cell(best.2, p.2, p.3);
        let mut found: Option<(usize, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(v) = grid.get(&(cx + dx, cy + dy)) {
                    for &j in v {
                        let d = dist(i, j);
                        if d < found.map_or(best.2, |f| f.1) {
                            found = Some((j, d));
                        }
                    }
                }
            }
        }
        match found {
            Some((j, d)) => {
                best = (j, i, d);
                if d == 0.0 {
                    return Some(best);
                }
                build(&mut grid, d, i + 1);
            }
            None => grid.entry((cx, cy)).or_default().push(i),
        }
    }
    Some(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(pts: &[(u64, &str, f64, f64)]) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..pts.len() {
            for j in i + 1..pts.len() {
                let d = ((pts[i].2 - pts[j].2).powi(2) + (pts[i].3 - pts[j].3).powi(2)).sqrt();
                best = best.min(d);
            }
        }
        best
    }

    /// The grid gives the brute force's distance on random point sets of many sizes.
    #[test]
    fn grid_matches_brute_force() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % 10_000) as f64 / 100.0
        };
        let names: Vec<String> = (0..300).map(|i| format!("r{i}")).collect();
        for n in [2, 3, 10, 50, 300] {
            for _ in 0..20 {
                let mut pts: Vec<(u64, &str, f64, f64)> = names
                    .iter()
                    .take(n)
                    .map(|k| (mix(k), k.as_str(), rnd(), rnd()))
                    .collect();
                let want = brute(&pts);
                let (_, _, got) = closest(&mut pts).unwrap_or((0, 0, f64::NAN));
                assert!((got - want).abs() < 1e-12, "{n} points: {got} != {want}");
            }
        }
    }

    #[test]
    fn fewer_than_two_is_none() {
        let m = tessla_engine::collections::map_of(vec![(
            Value::Str(Arc::from("a")),
            Value::Tuple(Arc::from(vec![Value::Float(1.0), Value::Float(2.0)])),
        )]);
        assert_eq!(closest_pair(&[m]), Value::None);
    }
}
