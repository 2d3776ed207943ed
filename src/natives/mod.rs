//! The application's natives: Rust functions the robot and fleet specs reach through
//! `extern("name")`, added to the engine's builtins for every spec this program compiles.
//!
//! Owns: [`natives`], the one registry (name, TeSSLa signature, function) handed to the engine
//! in its load options (`cli::spec_options::load_options`, which every command that compiles a
//! spec goes through: `run`, `check`, `trace`, `simulate`, `spec`, reloads and the spec
//! channel's check); the lidar scan functions (`lidar`, declared in `specs/lidar.tessla`) and
//! the fleet's closest pair (`fleet`, declared in `specs/lib/fleet.tessla`). The engine crate
//! holds no robot or fleet code. A declaration with another type than the registered signature
//! is a type error when the spec is checked.

pub mod fleet;
pub mod lidar;

use tessla_engine::builtins::{Natives, RegisterError};

/// Every native of this program, registered.
pub fn natives() -> Result<Natives, RegisterError> {
    let mut n = Natives::new();
    n.register(
        "lidar_dropouts",
        "(List[Float], Float, Float) => Int",
        lidar::dropouts,
    )?
    .register(
        "lidar_spikes",
        "(List[Float], Float, Float, Float) => Int",
        lidar::spikes,
    )?
    .register(
        "lidar_sector_min",
        "(List[Float], Float, Float, Float, Float, Float) => Float",
        lidar::sector_min,
    )?
    .register(
        "lidar_sector_valid_fraction",
        "(List[Float], Float, Float, Float, Float, Float) => Float",
        lidar::sector_valid_fraction,
    )?
    .register(
        "fleet_closest_pair",
        "(Map[String, (Float, Float)]) => Option[(String, String, Float)]",
        fleet::closest_pair,
    )?;
    Ok(n)
}

/// The engine's default load options with this program's natives (for tests and benches that
/// compile the robot or fleet specs without the command line).
pub fn load_options() -> Result<tessla_engine::LoadOptions, RegisterError> {
    Ok(tessla_engine::LoadOptions {
        natives: natives()?,
        ..tessla_engine::LoadOptions::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessla_syntax::include::MemResolver;

    /// Why `spec` (with the bundled files beside it) does not load, or `None` when it does.
    fn load_errors(spec: &str) -> Option<String> {
        let mut files: std::collections::HashMap<String, String> = crate::bundled::FILES
            .iter()
            .map(|(n, t)| (n.to_string(), t.to_string()))
            .collect();
        files.insert("main.tessla".into(), spec.into());
        let options = match load_options() {
            Ok(o) => o,
            Err(e) => return Some(e.to_string()),
        };
        tessla_engine::load_with("main.tessla", &MemResolver { files }, &options)
            .err()
            .map(|e| e.render())
    }

    /// Every native is registered, and the robot specs, the bundled default and the fleet
    /// library declare each with its registered signature (else they would not load).
    #[test]
    fn the_specs_declare_every_native_with_its_registered_signature() {
        let names: Vec<&str> = natives().map_or(Vec::new(), |n| n.iter().map(|n| n.name).collect());
        assert_eq!(
            names,
            [
                "lidar_dropouts",
                "lidar_spikes",
                "lidar_sector_min",
                "lidar_sector_valid_fraction",
                "fleet_closest_pair"
            ]
        );
        let robot = load_options().map(|o| crate::bundled::load(&o).map(|_| ()));
        assert!(matches!(robot, Ok(Ok(()))), "the bundled robot spec");
        let fleet = format!(
            "{}\nin m: Events[Map[String, (Float, Float)]]\ndef d = fleetClosestDistance(m)\nout d\n",
            crate::fleet::LIBRARY
        );
        if let Some(e) = load_errors(&fleet) {
            panic!("{e}");
        }
    }

    /// A spec declaring a lidar native with another type is refused when checked, not run
    /// with values the native cannot read.
    #[test]
    fn a_lidar_native_declared_with_another_type_is_refused() {
        let spec = "def drops(scan: List[Float], rmin: Float): Int = extern(\"lidar_dropouts\")\n\
                    in s: Events[List[Float]]\n\
                    def d = slift(s, (l: List[Float]) => drops(l, 0.1))\n\
                    out d\n";
        let err = load_errors(spec).unwrap_or_default();
        assert!(
            err.contains("`drops` is declared with another type than the native `lidar_dropouts`")
                && err.contains("(List[Float], Float, Float) => Int"),
            "{err}"
        );
    }
}
