//! The fleet level (`run --fleet-spec FILE`, docs/fleet.md): a plain TeSSLa spec over the whole
//! fleet, whose inputs are robot-spec outputs seen as maps from robot key to latest value.
//!
//! Owns: loading and checking the fleet spec against the robot spec (each input names a robot
//! output and has type `Events[Map[String, T]]` for that output's `T`; a fleet spec that does
//! not check is refused with the usual diagnostics), the fleet's maps, its event-time rule
//! (the watermark over live robots, robots silent past `--fleet-silence` or evicted leaving the
//! maps, late changes stepped 1 ns after the fleet's last step: [`level`]), writing its outputs as
//! line protocol by the Telegraf annotations (default measurement `tessla_fleet`) and its
//! coordinated actions, one `action` metric per addressed robot ([`actions`]). The robot side
//! of it is `crate::processor::fleet_tap`; the step loop drains every processor's tap into the
//! level after each read ([`Feed`]: the level in this process, or, with NATS partitions, the
//! partition's messages to the fleet level and the fleet level run on them: [`nats`], with its
//! rules in [`watermark`] and its checkpoint's store in [`checkpoint`]). In one process the
//! level is also saved in and restored from `--state FILE` ([`Feed::saved`],
//! [`Feed::restore_saved`]: JSON the state file holds as it is).

pub mod actions;
pub mod checkpoint;
pub mod level;
pub mod nats;
pub mod watermark;

pub use level::Level;

use crate::processor::fleet_tap::Drained;
use crate::spec_feed::bundle::Bundle;
use crate::state::lease::Lease;

/// The fleet level as `--state FILE` holds it: the fleet inputs it was saved for (the robot
/// outputs the maps hold, in order) and its state.
#[derive(serde::Serialize, serde::Deserialize)]
struct Saved {
    inputs: Vec<String>,
    level: level::LevelState,
}

/// Where the step loop sends what the robots' instances give the fleet.
pub enum Feed {
    /// One process: the level here.
    Local(Box<Level>),
    /// A partition of a NATS fleet: sent to the fleet level, which every process follows and
    /// the holder of the `fleet` lease writes.
    Nats(Box<nats::FleetNats>),
}

impl Feed {
    /// After a read or a wall-clock advance: `drained` from every processor; `partition`: the
    /// partition lease, if any (only its holder sends); `end`: the input ended.
    pub fn pump(
        &mut self,
        drained: Vec<Drained>,
        end: bool,
        partition: Option<&Lease>,
        out: &mut Vec<u8>,
    ) {
        match self {
            Feed::Local(level) => level.pump(drained, end, out),
            Feed::Nats(n) => n.pump(drained, end, partition.and_then(Lease::generation), out),
        }
    }

    /// A committed fleet rollout (the spec channel's, [`crate::spec_feed::Updates::take_fleet`]):
    /// one process's level switches at its first step at or after max(its start, its next
    /// step); across partitions the fleet lease's holder puts the switch in the fleet's stream,
    /// and every process applies it there (the same step everywhere).
    pub fn switch(&mut self, c: crate::spec_feed::FleetCommit) {
        match self {
            Feed::Local(level) => level.switch_to(&c),
            Feed::Nats(n) => n.committed(c),
        }
    }

    /// A committed robot rollout ([`crate::spec_feed::Updates::take_robot_commits`]): for each
    /// fleet input the running fleet spec reads whose robot output its version lacks, a `W!`
    /// and one `tessla_fleet_status` line, `event="input_unfed"` (written where the fleet's
    /// lines are: here, or by the holder of the `fleet` lease).
    pub fn robot_rollout(&mut self, c: &crate::spec_feed::RobotCommit, out: &mut Vec<u8>) {
        let (level, write) = match self {
            Feed::Local(level) => (&**level, true),
            Feed::Nats(n) => n.level_and_holding(),
        };
        for input in level.unfed(c) {
            log_warn!(
                "fleet: robot spec rollout {} (version {}) has no output `{input}`: the robots it picks ({}) no longer feed the fleet input `{input}`, whose map keeps their last values until they leave",
                c.revision,
                c.id,
                if c.select.is_empty() {
                    "every robot"
                } else {
                    c.select.as_str()
                }
            );
            if write {
                let now = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
                level.unfed_line(c, &input, now, out);
            }
        }
    }

    /// At the end, before the last write.
    pub fn finish(&mut self, out: &mut Vec<u8>) {
        if let Feed::Nats(n) = self {
            n.finish(out);
        }
    }

    /// The fleet level of this process as JSON, for `--state FILE` (one process; a fleet of
    /// NATS partitions keeps its level in its stream and checkpoint): `None` when there is
    /// none to save, or it cannot be saved now (a fleet rollout switched it, a function value:
    /// a `W!`; a restart then rebuilds the maps from the robots' next events).
    pub fn saved(&self) -> Option<Vec<u8>> {
        let Feed::Local(level) = self else {
            return None;
        };
        let Some(state) = level.state() else {
            crate::log::warn_limited("fleet state", || {
                "state: the fleet level cannot be saved (a fleet rollout switched it, or it holds a function value); a restart rebuilds its maps from the robots' next events".into()
            });
            return None;
        };
        let saved = Saved {
            inputs: level.names().to_vec(),
            level: state,
        };
        serde_json::to_vec(&saved).ok()
    }

    /// Go on from the fleet level `json` held by `--state FILE` ([`Feed::saved`]), read before
    /// the first record. A level saved for other fleet inputs, or JSON that is not one, is not
    /// used (a `W!`): the maps are rebuilt from the robots' next events.
    pub fn restore_saved(&mut self, json: &str, place: &str) {
        let Feed::Local(level) = self else {
            return;
        };
        match serde_json::from_str::<Saved>(json) {
            Ok(saved) if saved.inputs == level.names() => {
                let robots = saved.level.robots();
                level.restore(saved.level);
                log_info!("state: restored the fleet level ({robots} robots) from {place}");
            }
            Ok(saved) => log_warn!(
                "state: the fleet level in {place} was saved for the fleet inputs {:?}, not {:?}; not used, its maps are rebuilt from the robots' next events",
                saved.inputs,
                level.names()
            ),
            Err(e) => log_warn!(
                "state: the fleet level in {place} is not one ({e}); not used, its maps are rebuilt from the robots' next events"
            ),
        }
    }

    /// At the end, after the last write.
    pub fn release(&mut self) {
        if let Feed::Nats(n) = self {
            n.release();
        }
    }
}

use std::path::Path;
use tessla_engine::{LoadOptions, Program};
use tessla_syntax::ast::{Statement, Type as SynType};
use tessla_syntax::diag::{Category, Diagnostic};
use tessla_syntax::source::SourceMap;

/// The measurement of fleet outputs without a Telegraf annotation.
pub const MEASUREMENT: &str = "tessla_fleet";

/// `--fleet-silence`: a robot whose clock stays this far (event time) behind the newest robot's
/// no longer holds the fleet back, and leaves the fleet's maps this long after its last step.
/// Two seconds are ten periods of the robots' 5 Hz messages: a Wi-Fi retry or a broker hiccup
/// passes in far less, a robot switched off or out of range does not.
pub const DEFAULT_SILENCE: std::time::Duration = std::time::Duration::from_secs(2);

/// The bundled library a fleet spec may include (`include "fleet.tessla"`).
pub const LIBRARY: &str = include_str!("../../specs/lib/fleet.tessla");

/// How the fleet spec is loaded: the robot spec's base time and `--set`s, and the bundled
/// `fleet.tessla` and `Telegraf.tessla` for includes that are not beside it.
pub fn load_options(robot: &LoadOptions) -> LoadOptions {
    let mut o = robot.clone();
    o.bundled_includes = vec![
        ("fleet.tessla".into(), LIBRARY.into()),
        (
            "Telegraf.tessla".into(),
            include_str!("../../specs/telegraf.tessla").into(),
        ),
    ];
    o.on_bundled_include = None;
    o
}

/// The tags of the fleet's lines: the static `--tag`s and, with `--version-tag TAG`, TAG set
/// to the fleet spec's version `id` (as each robot line carries its own spec's), sorted.
pub fn version_tags(
    tags: &[(String, String)],
    version_tag: Option<&str>,
    id: &str,
) -> Vec<(String, String)> {
    let mut tags = tags.to_vec();
    if let Some(t) = version_tag {
        tags.retain(|(k, _)| k != t);
        tags.push((t.to_string(), id.to_string()));
        tags.sort();
    }
    tags
}

/// A checked fleet spec: the program, per fleet input (in the program's order) the robot output
/// it reads, and the bundle it was read as (its [`Bundle::id`] is the fleet spec's version, as
/// a robot spec's is).
pub struct Checked {
    pub loaded: tessla_engine::Loaded,
    pub names: Vec<String>,
    pub bundle: Bundle,
}

/// Why [`check`] or [`check_bundle`] refused a fleet spec.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The spec does not compile, or its inputs do not match the robot spec's outputs
    /// (diagnostics with file, line, column).
    #[error("{0}")]
    Diagnostics(#[from] tessla_engine::LoadError),
    /// A bundle without a file.
    #[error("the fleet spec is empty")]
    Empty,
    /// A fleet spec version (a rollout) reads a robot output the running fleet level does not
    /// collect.
    #[error(
        "fleet spec input `{input}` reads a robot output the running fleet level does not collect (it collects {collects}: the inputs of the fleet spec it started with); restart with a --fleet-spec that reads it"
    )]
    NotCollected { input: String, collects: String },
}

/// Load the fleet spec at `path` and check its inputs against the robot spec's outputs.
pub fn check(path: &Path, robot: &Program, options: &LoadOptions) -> Result<Checked, CheckError> {
    let (bundle, loaded) = Bundle::read(path, &load_options(options))?;
    check_loaded(bundle, loaded, robot)
}

/// Check a fleet spec version as it travels (a published bundle, loaded with this process's
/// options), as [`check`] checks a file.
pub fn check_bundle(
    bundle: Bundle,
    robot: &Program,
    options: &LoadOptions,
) -> Result<Checked, CheckError> {
    let loaded = bundle.load(&load_options(options))?;
    check_loaded(bundle, loaded, robot)
}

fn check_loaded(
    bundle: Bundle,
    loaded: tessla_engine::Loaded,
    robot: &Program,
) -> Result<Checked, CheckError> {
    let (name, text) = match bundle.files.first() {
        Some(f) => (f.name.clone(), f.text.clone()),
        None => return Err(CheckError::Empty),
    };
    let path = Path::new(&name);
    let mut sources = SourceMap::new();
    let file = sources.add(path.display().to_string(), Some(path), text.clone());
    let (ast, _) = tessla_syntax::parser::parse(&text, file);
    let mut diags = Vec::new();
    let mut names = Vec::new();
    for input in &loaded.program.inputs {
        let decl = ast.statements.iter().find_map(|s| match s {
            Statement::In { name, ty, .. } if name.name == input.name => Some((name, ty)),
            _ => None,
        });
        let Some((name, ty)) = decl else {
            diags.push(Diagnostic::error(
                Category::Other,
                None,
                format!(
                    "fleet spec input `{}` is not declared in {} itself (declare the fleet's inputs in the fleet spec, not in an include)",
                    input.name,
                    path.display()
                ),
            ));
            continue;
        };
        let Some(out) = robot.outputs.iter().find(|o| o.name == input.name) else {
            let known: Vec<&str> = robot.outputs.iter().map(|o| o.name.as_str()).collect();
            diags.push(Diagnostic::error(
                Category::Name,
                Some(name.span),
                format!(
                    "fleet spec input `{}` is not an output of the robot spec (its outputs: {})",
                    input.name,
                    known.join(", ")
                ),
            ));
            continue;
        };
        let want = format!("Events[Map[String, {}]]", out.ty);
        let got = show_type(ty);
        if !out.ty.is_known() {
            diags.push(Diagnostic::error(
                Category::Type,
                Some(ty.span()),
                format!(
                    "fleet spec input `{}`: the robot output's type is not one the fleet level can carry (a map, set or function)",
                    input.name
                ),
            ));
        } else if got != want {
            diags.push(Diagnostic::error(
                Category::Type,
                Some(ty.span()),
                format!(
                    "fleet spec input `{}` has type {got}; robot output `{}` is Events[{}], so the fleet reads it as {want}",
                    input.name, out.name, out.ty
                ),
            ));
        }
        names.push(input.name.clone());
    }
    if loaded.program.outputs.is_empty() {
        diags.push(Diagnostic::error(
            Category::Other,
            None,
            format!("{}: the fleet spec has no outputs", path.display()),
        ));
    }
    if !diags.is_empty() {
        return Err(CheckError::Diagnostics(tessla_engine::LoadError {
            sources,
            diagnostics: diags,
        }));
    }
    Ok(Checked {
        loaded,
        names,
        bundle,
    })
}

/// A syntax type in TeSSLa's notation, as the engine prints types (`Map[String, (Float, Float)]`).
fn show_type(t: &SynType) -> String {
    match t {
        SynType::Name(id) => id.name.clone(),
        SynType::App { name, args, .. } => format!(
            "{}[{}]",
            name.name,
            args.iter().map(show_type).collect::<Vec<_>>().join(", ")
        ),
        SynType::Tuple { elems, .. } if elems.is_empty() => "Unit".into(),
        SynType::Tuple { elems, .. } => format!(
            "({})",
            elems.iter().map(show_type).collect::<Vec<_>>().join(", ")
        ),
        SynType::Record { fields, .. } => format!(
            "{{{}}}",
            fields
                .iter()
                .map(|(n, t)| format!("{}: {}", n.name, show_type(t)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        SynType::Function { .. } => "a function".into(),
    }
}
