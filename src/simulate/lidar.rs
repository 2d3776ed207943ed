//! The simulated LDS-01 lidar over a 2-D map of walls and boxes.
//!
//! Owns: [`Map`] (axis-aligned rectangles: the corridor's walls and boxes standing along it),
//! ray casting from the robot's position, and the sensor's faults ([`LidarParams`]): Gaussian
//! range noise, dust spikes (a beam reads a short range, as from a particle in front of the
//! sensor) and dropouts (no return), each at a given rate per beam. Conventions follow the
//! LDS-01 driver (ROBOTIS-GIT/hls_lfcd_lds_driver, `src/hlds_laser_publisher.cpp`): beam i at
//! i·360°/N counter-clockwise from straight ahead, ranges in whole millimetres, valid
//! 0.12..3.5 m, no return reported as `0.0`.

use rand::Rng;
use rand_distr::{Distribution, Normal};

/// An axis-aligned rectangle (m): x from `x0` to `x1`, y from `y0` to `y1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub x0: f64,
    pub x1: f64,
    pub y0: f64,
    pub y1: f64,
}

/// The world around the path (the robot drives along y = 0 towards +x).
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    pub obstacles: Vec<Rect>,
}

/// The sensor's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarParams {
    pub beams: usize,
    /// m: shortest valid range (LDS-01 `range_min`).
    pub range_min: f64,
    /// m: longest valid range (LDS-01 `range_max`); beyond it: no return (`0.0`).
    pub range_max: f64,
    /// m: standard deviation of the range noise (Gazebo's Burger model: 0.01).
    pub noise: f64,
    /// Probability per beam and scan of a dust spike.
    pub spike_rate: f64,
    /// Probability per beam and scan of a dropout (`0.0`).
    pub dropout_rate: f64,
}

impl Default for LidarParams {
    fn default() -> Self {
        LidarParams {
            beams: 360,
            range_min: 0.12,
            range_max: 3.5,
            noise: 0.01,
            spike_rate: 0.001,
            dropout_rate: 0.01,
        }
    }
}

/// Half the corridor's width (m).
const HALF_WIDTH: f64 = 0.6;
/// Wall thickness (m).
const WALL: f64 = 0.05;

impl Map {
    /// A corridor 1.2 m wide from x = -1 m to `length` + 1 m, closed at both ends, with boxes
    /// (0.3 m cubes) standing against the walls at the given x positions (alternating sides).
    pub fn corridor(length: f64, boxes: &[f64]) -> Map {
        let (x0, x1) = (-1.0, length + 1.0);
        let mut obstacles = vec![
            Rect {
                x0,
                x1,
                y0: HALF_WIDTH,
                y1: HALF_WIDTH + WALL,
            },
            Rect {
                x0,
                x1,
                y0: -HALF_WIDTH - WALL,
                y1: -HALF_WIDTH,
            },
            Rect {
                x0: x0 - WALL,
                x1: x0,
                y0: -HALF_WIDTH,
                y1: HALF_WIDTH,
            },
            Rect {
                x0: x1,
                x1: x1 + WALL,
                y0: -HALF_WIDTH,
                y1: HALF_WIDTH,
            },
        ];
        for (i, &bx) in boxes.iter().enumerate() {
            let (y0, y1) = if i % 2 == 0 {
                (HALF_WIDTH - 0.3, HALF_WIDTH)
            } else {
                (-HALF_WIDTH, -HALF_WIDTH + 0.3)
            };
            obstacles.push(Rect {
                x0: bx,
                x1: bx + 0.3,
                y0,
                y1,
            });
        }
        Map { obstacles }
    }

    /// Distance from (x, y) along direction `angle` (rad, 0 = +x, counter-clockwise) to the
    /// nearest obstacle, or `None` when the ray hits nothing.
    pub fn cast(&self, x: f64, y: f64, angle: f64) -> Option<f64> {
        let (dx, dy) = (angle.cos(), angle.sin());
        self.obstacles
            .iter()
            .filter_map(|r| slab(x, y, dx, dy, r))
            .min_by(f64::total_cmp)
    }

    /// One scan from the robot at (x, 0) heading +x.
    pub fn scan<R: Rng>(&self, x: f64, p: &LidarParams, rng: &mut R) -> Vec<f64> {
        let noise = Normal::new(0.0, p.noise.max(0.0)).ok();
        (0..p.beams)
            .map(|i| {
                let angle = i as f64 * std::f64::consts::TAU / p.beams as f64;
                let truth = self.cast(x, 0.0, angle);
                // Draw every random number for every beam, so the stream stays aligned between
                // runs whose robots are at different places.
                let n = noise.as_ref().map_or(0.0, |d| d.sample(rng));
                let spike = rng.random::<f64>() < p.spike_rate;
                let spike_frac = rng.random_range(0.2..0.6);
                let dropout = rng.random::<f64>() < p.dropout_rate;
                let Some(truth) = truth else { return 0.0 };
                let mut r = truth + n;
                if spike {
                    r = truth * spike_frac;
                }
                if dropout || r > p.range_max {
                    return 0.0;
                }
                (r.max(0.0) * 1000.0).round() / 1000.0
            })
            .collect()
    }
}

/// Ray-rectangle intersection (slab method): the entry distance, if the ray hits `r` ahead.
fn slab(x: f64, y: f64, dx: f64, dy: f64, r: &Rect) -> Option<f64> {
    let axis = |o: f64, d: f64, lo: f64, hi: f64| -> Option<(f64, f64)> {
        if d.abs() < 1e-12 {
            (lo..=hi)
                .contains(&o)
                .then_some((f64::NEG_INFINITY, f64::INFINITY))
        } else {
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            Some((a.min(b), a.max(b)))
        }
    };
    let (tx0, tx1) = axis(x, dx, r.x0, r.x1)?;
    let (ty0, ty1) = axis(y, dy, r.y0, r.y1)?;
    let (enter, exit) = (tx0.max(ty0), tx1.min(ty1));
    (enter <= exit && exit >= 0.0).then_some(enter.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn rays_hit_walls_and_boxes() {
        let map = Map::corridor(10.0, &[3.0]);
        // Straight left: the wall at 0.6 m.
        let left = map.cast(0.0, 0.0, std::f64::consts::FRAC_PI_2).unwrap();
        assert!((left - 0.6).abs() < 1e-9);
        // Straight ahead: the end wall at 11 m.
        assert!((map.cast(0.0, 0.0, 0.0).unwrap() - 11.0).abs() < 1e-9);
        // Left from beside the box: the box face at 0.3 m.
        let at_box = map.cast(3.1, 0.0, std::f64::consts::FRAC_PI_2).unwrap();
        assert!((at_box - 0.3).abs() < 1e-9);
    }

    #[test]
    fn scan_marks_no_return_and_applies_faults_at_their_rates() {
        let map = Map::corridor(10.0, &[]);
        let clean = LidarParams {
            noise: 0.0,
            spike_rate: 0.0,
            dropout_rate: 0.0,
            ..LidarParams::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let s = map.scan(0.0, &clean, &mut rng);
        assert_eq!(s.len(), 360);
        assert_eq!(s[0], 0.0, "ahead: 11 m, beyond range_max");
        assert_eq!(s[90], 0.6);
        assert!((s[30] - 1.2).abs() < 1e-3, "{}", s[30]);

        let faulty = LidarParams {
            noise: 0.0,
            spike_rate: 0.05,
            dropout_rate: 0.1,
            ..LidarParams::default()
        };
        let (mut spikes, mut drops, mut total) = (0, 0, 0);
        for _ in 0..100 {
            let f = map.scan(0.0, &faulty, &mut rng);
            for (a, b) in s.iter().zip(&f) {
                if *a > 0.0 {
                    total += 1;
                    if *b == 0.0 {
                        drops += 1;
                    } else if *b < a - 0.05 {
                        spikes += 1;
                    }
                }
            }
        }
        let (d, sp) = (drops as f64 / total as f64, spikes as f64 / total as f64);
        assert!((0.08..0.12).contains(&d), "dropout rate {d}");
        assert!((0.035..0.055).contains(&sp), "spike rate {sp}");
    }
}
