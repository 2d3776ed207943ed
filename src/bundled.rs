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
    (
        "lib/action.tessla",
        include_str!("../specs/lib/action.tessla"),
    ),
    ("robot.tessla", include_str!("../specs/robot.tessla")),
];

/// Library files a user's spec may include without having them: the TeSSLa Telegraf
/// Connector's `Telegraf.tessla` (its annotations, which come with the connector, not with the
/// spec), served by our `telegraf.tessla` when no such file is beside the spec.
pub const LIBRARIES: &[(&str, &str)] =
    &[("Telegraf.tessla", include_str!("../specs/telegraf.tessla"))];

/// The `I!` line saying a bundled library served an include (`name` as written in `from`).
pub fn say_bundled_include(name: &str, from: &str) {
    log_info!(
        "{from}: include \"{name}\": no such file beside the spec, using the bundled \
             Telegraf annotations (@TelegrafIn, @TelegrafOut, @TelegrafField, \
             @TelegrafListLength)"
    );
}

/// The name of the default spec.
pub const DEFAULT: &str = "robot.tessla";

/// The bundled robot monitors' files, by name.
pub fn resolver() -> MemResolver {
    MemResolver {
        files: FILES
            .iter()
            .map(|(n, t)| (n.to_string(), t.to_string()))
            .collect(),
    }
}

/// Load the bundled robot monitors.
pub fn load(options: &LoadOptions) -> Result<Loaded, LoadError> {
    tessla_engine::load_with(DEFAULT, &resolver(), options)
}
