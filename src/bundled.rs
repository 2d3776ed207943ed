//! The robot monitors compiled into the binary: `specs/*.tessla`, the default spec of `run`.
//!
//! Owns: the table of bundled spec files (embedded with `include_str!`, so the binary works out
//! of the box and needs no files next to it) and loading `robot.tessla` from it.

use tessla_engine::{LoadError, LoadOptions, Loaded};
use tessla_syntax::include::MemResolver;

/// Every bundled spec file, by the name `include` uses.
pub const FILES: &[(&str, &str)] = &[
    ("telegraf.tessla", include_str!("../specs/telegraf.tessla")),
    ("lidar.tessla", include_str!("../specs/lidar.tessla")),
    (
        "p1_braking.tessla",
        include_str!("../specs/p1_braking.tessla"),
    ),
    (
        "p2_tolerance.tessla",
        include_str!("../specs/p2_tolerance.tessla"),
    ),
    ("p3_lidar.tessla", include_str!("../specs/p3_lidar.tessla")),
    (
        "lib/p1_braking.tessla",
        include_str!("../specs/lib/p1_braking.tessla"),
    ),
    (
        "lib/p2_tolerance.tessla",
        include_str!("../specs/lib/p2_tolerance.tessla"),
    ),
    (
        "lib/p3_lidar.tessla",
        include_str!("../specs/lib/p3_lidar.tessla"),
    ),
    ("lib/link.tessla", include_str!("../specs/lib/link.tessla")),
    ("robot.tessla", include_str!("../specs/robot.tessla")),
];

/// The name of the default spec.
pub const DEFAULT: &str = "robot.tessla";

/// Load the bundled robot monitors.
pub fn load(options: &LoadOptions) -> Result<Loaded, LoadError> {
    let resolver = MemResolver {
        files: FILES
            .iter()
            .map(|(n, t)| (n.to_string(), t.to_string()))
            .collect(),
    };
    tessla_engine::load_with(DEFAULT, &resolver, options)
}
