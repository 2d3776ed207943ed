//! Building a [`Scenario`] from names: the bundled yoga mat or a random mat for the seed, the
//! bundled program, and the corridor with boxes the lidar sees.

use super::closed_loop::{START_NS, Scenario};
use super::lidar::{LidarParams, Map};
use super::program::Program;
use super::robot::Params;
use super::terrain::Terrain;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Which ground to drive on.
#[derive(Debug, Clone, PartialEq)]
pub enum TerrainChoice {
    /// The bundled profile ([`Terrain::yoga_mat`]).
    YogaMat,
    /// A random mat of the same kind for the seed ([`Terrain::random`]).
    Random,
    /// A terrain file's contents.
    Custom(Terrain),
}

/// Length of the corridor (m), as long as the bundled mats.
const CORRIDOR: f64 = 45.0;

/// Boxes along the bundled corridor (x of their near edge, m; alternating left and right).
const BOXES: [f64; 10] = [1.5, 4.0, 7.0, 9.5, 12.0, 15.0, 18.5, 21.0, 24.0, 28.0];

/// A scenario with the documented default parameters; the caller adjusts fields afterwards.
pub fn build(terrain: TerrainChoice, program: Program, seed: u64) -> Scenario {
    let (terrain, map) = match terrain {
        TerrainChoice::YogaMat => (Terrain::yoga_mat(), Map::corridor(CORRIDOR, &BOXES)),
        TerrainChoice::Random => {
            // Stream 4 of the seed: independent of the noise streams of the closed loop.
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(4);
            let mut boxes: Vec<f64> = (0..10).map(|_| rng.random_range(1.0..30.0)).collect();
            boxes.sort_by(f64::total_cmp);
            (Terrain::random(seed), Map::corridor(CORRIDOR, &boxes))
        }
        TerrainChoice::Custom(t) => (t, Map::corridor(CORRIDOR, &BOXES)),
    };
    let duration = program.duration();
    Scenario {
        terrain,
        program,
        map,
        robot: Params::default(),
        lidar: LidarParams::default(),
        period: 0.5,
        delay: 0.2,
        slam_noise: 0.002,
        angular_noise: 0.005,
        seed,
        host: "sim".into(),
        start_ns: START_NS,
        dt: 0.005,
        duration,
        link_drops: Vec::new(),
    }
}
