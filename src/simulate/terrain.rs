//! The ground along the robot's straight path: height profile and rolling resistance.
//!
//! Owns: [`Terrain`] (a piecewise-linear height profile with a rolling-resistance coefficient
//! per point), the terrain file format ([`Terrain::parse`]), the bundled yoga-mat profile
//! ([`Terrain::yoga_mat`]) and random mats of the same kind ([`Terrain::random`]).
//!
//! File format (documented in docs/book/src/simulation.md): one point per line, `x height [rolling]`
//! (metres, metres, coefficient; separated by spaces, tabs or commas); `#` starts a comment;
//! `x` strictly increasing. Height and rolling coefficient are linear between points; before
//! the first and after the last point the ground is flat with the nearest point's coefficient.

use super::InputError;
use super::robot::{Ground, source};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[derive(Debug, Clone, PartialEq)]
pub struct Terrain {
    /// (x m, height m, rolling coefficient), x strictly increasing, at least one point.
    points: Vec<(f64, f64, f64)>,
}

/// A hill made by an object under the mat: a raised cosine of `height` and half-width
/// `half_width` centred at `centre` (all m).
#[derive(Debug, Clone, Copy)]
struct Bump {
    centre: f64,
    height: f64,
    half_width: f64,
}

/// Length of a mat track (m): longer than the bundled program can drive (0.1 m/s · 400 s).
const TRACK: f64 = 45.0;
/// Spacing of the sampled profile (m).
const SAMPLE: f64 = 0.02;
/// How far the mat drapes on each side of an object under it (m): assumption, see the docs.
const HALF_WIDTH: f64 = 0.4;

impl Terrain {
    /// Build from points; `Err` names the first problem.
    pub fn from_points(points: Vec<(f64, f64, f64)>) -> Result<Terrain, InputError> {
        if points.is_empty() {
            return Err(InputError::NoPoints);
        }
        for (i, p) in points.iter().enumerate() {
            if !(p.0.is_finite() && p.1.is_finite() && p.2.is_finite()) {
                return Err(InputError::NotFinite(i + 1));
            }
            if p.2 < 0.0 {
                return Err(InputError::NegativeRolling(i + 1, p.2));
            }
            if i > 0 && points.get(i - 1).is_some_and(|q| q.0 >= p.0) {
                return Err(InputError::NotAfter(i + 1, p.0));
            }
        }
        Ok(Terrain { points })
    }

    /// Read the file format described at the top of this module. Errors carry the line number.
    pub fn parse(text: &str) -> Result<Terrain, InputError> {
        let mut points = Vec::new();
        for (n, cols) in super::data_rows(text) {
            if !(2..=3).contains(&cols.len()) {
                return Err(InputError::Columns {
                    line: n,
                    expected: "x height [rolling]",
                    found: cols.len(),
                });
            }
            let mut nums = [0.0, 0.0, source::MAT_ROLLING];
            for (slot, col) in nums.iter_mut().zip(&cols) {
                *slot = col
                    .parse::<f64>()
                    .map_err(|_| InputError::NotANumber(n, col.to_string()))?;
            }
            points.push((nums[0], nums[1], nums[2]));
        }
        Terrain::from_points(points).map_err(|e| InputError::TerrainFile(Box::new(e)))
    }

    /// Write in the file format (the inverse of [`Terrain::parse`]).
    pub fn to_text(&self) -> String {
        let mut s = String::from("# x_m height_m rolling\n");
        for (x, h, c) in &self.points {
            s.push_str(&format!("{x} {h} {c}\n"));
        }
        s
    }

    /// The bundled yoga mat, modelled on the paper's description: a mat with objects under it;
    /// a first small hill reached about 100 s into the bundled program, two more later, and
    /// low ripples from thin objects that slow but do not stop the robot.
    pub fn yoga_mat() -> Terrain {
        let hills = [(5.5, 0.006), (11.0, 0.008), (16.5, 0.007)];
        let ripples = [2.0, 3.5, 8.0, 13.5, 19.0, 22.0, 25.0];
        let mut bumps: Vec<Bump> = hills
            .iter()
            .map(|&(centre, height)| Bump {
                centre,
                height,
                half_width: HALF_WIDTH,
            })
            .collect();
        bumps.extend(ripples.iter().map(|&centre| Bump {
            centre,
            height: 0.002,
            half_width: HALF_WIDTH,
        }));
        Terrain::from_bumps(&bumps)
    }

    /// A random mat of the same kind for `seed`: 10 objects at uniform positions along the
    /// first 25 m, heights uniform in 2..9 mm (thin cables to a marker pen).
    pub fn random(seed: u64) -> Terrain {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let bumps: Vec<Bump> = (0..10)
            .map(|_| Bump {
                centre: rng.random_range(1.0..25.0),
                height: rng.random_range(0.002..0.009),
                half_width: HALF_WIDTH,
            })
            .collect();
        Terrain::from_bumps(&bumps)
    }

    fn from_bumps(bumps: &[Bump]) -> Terrain {
        let n = (TRACK / SAMPLE).round() as usize;
        let points = (0..=n)
            .map(|i| {
                let x = i as f64 * SAMPLE;
                // Overlapping objects: the mat rests on the higher one.
                let h = bumps
                    .iter()
                    .map(|b| {
                        let d = (x - b.centre).abs();
                        if d < b.half_width {
                            b.height / 2.0 * (1.0 + (std::f64::consts::PI * d / b.half_width).cos())
                        } else {
                            0.0
                        }
                    })
                    .fold(0.0, f64::max);
                (x, h, source::MAT_ROLLING)
            })
            .collect();
        Terrain { points }
    }

    /// Grade and rolling resistance at `x`.
    pub fn ground(&self, x: f64) -> Ground {
        let i = self.points.partition_point(|p| p.0 <= x);
        match (
            i.checked_sub(1).and_then(|j| self.points.get(j)),
            self.points.get(i),
        ) {
            (Some(a), Some(b)) => {
                let t = (x - a.0) / (b.0 - a.0);
                Ground {
                    slope: (b.1 - a.1) / (b.0 - a.0),
                    rolling: a.2 + t * (b.2 - a.2),
                }
            }
            (Some(a), None) | (None, Some(a)) => Ground {
                slope: 0.0,
                rolling: a.2,
            },
            (None, None) => Ground {
                slope: 0.0,
                rolling: source::MAT_ROLLING,
            },
        }
    }

    /// Height at `x` (m).
    pub fn height(&self, x: f64) -> f64 {
        let i = self.points.partition_point(|p| p.0 <= x);
        match (
            i.checked_sub(1).and_then(|j| self.points.get(j)),
            self.points.get(i),
        ) {
            (Some(a), Some(b)) => a.1 + (x - a.0) / (b.0 - a.0) * (b.1 - a.1),
            (Some(a), None) | (None, Some(a)) => a.1,
            (None, None) => 0.0,
        }
    }

    /// The steepest uphill slope of the profile.
    pub fn max_slope(&self) -> f64 {
        self.points
            .windows(2)
            .filter_map(|w| match w {
                [a, b] => Some((b.1 - a.1) / (b.0 - a.0)),
                _ => None,
            })
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_reads_points_comments_and_defaults() {
        let t = Terrain::parse("# mat\n0 0\n1.0, 0.01, 0.03 # hill\n\n2\t0\n").unwrap();
        let g = t.ground(0.5);
        assert!((g.slope - 0.01).abs() < 1e-12);
        assert!((g.rolling - (source::MAT_ROLLING + 0.03) / 2.0).abs() < 1e-12);
        assert!((t.height(1.5) - 0.005).abs() < 1e-12);
        assert_eq!(t.ground(5.0).slope, 0.0);
        assert_eq!(t.ground(-1.0).slope, 0.0);
    }

    #[test]
    fn parse_errors_name_the_line() {
        assert!(
            Terrain::parse("0 0\nx 1\n")
                .unwrap_err()
                .to_string()
                .contains("line 2")
        );
        assert!(
            Terrain::parse("0 0\n1 2 3 4\n")
                .unwrap_err()
                .to_string()
                .contains("line 2")
        );
        assert!(
            Terrain::parse("1 0\n0 0\n")
                .unwrap_err()
                .to_string()
                .contains("point 2")
        );
        assert!(
            Terrain::parse("# nothing\n")
                .unwrap_err()
                .to_string()
                .contains("no points")
        );
        assert!(
            Terrain::parse("0 0 -1\n")
                .unwrap_err()
                .to_string()
                .contains("negative")
        );
    }

    #[test]
    fn text_round_trips() {
        let t = Terrain::yoga_mat();
        assert_eq!(Terrain::parse(&t.to_text()).unwrap(), t);
    }

    #[test]
    fn yoga_mat_has_hills_steeper_than_its_ripples() {
        let t = Terrain::yoga_mat();
        // Raised cosine: steepest slope = height · π / (2 · half_width).
        let steepest = 0.008 * std::f64::consts::PI / (2.0 * HALF_WIDTH);
        assert!((t.max_slope() - steepest).abs() < 1e-3, "{}", t.max_slope());
        assert!(t.height(11.0) > 0.0079 && t.height(7.0) == 0.0);
    }

    #[test]
    fn random_mats_depend_on_the_seed_only() {
        assert_eq!(Terrain::random(3), Terrain::random(3));
        assert_ne!(Terrain::random(3), Terrain::random(4));
    }
}
