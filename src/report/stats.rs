//! The report's numbers: the MSE between expected and actual speed (the paper's Table I) and
//! the count of violations per property.

use super::data::Run;
use super::series::Picked;

/// Everything the report's table shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Records of the run, and records that were not line protocol.
    pub records: usize,
    pub skipped: usize,
    /// Duration from the first to the last record, in seconds.
    pub duration_s: f64,
    /// Mean squared error between expected and actual speed over the records that carry both,
    /// computed here from the pass-through telemetry.
    pub mse: Option<f64>,
    /// Number of (expected, actual) pairs in `mse`.
    pub mse_pairs: usize,
    /// The spec's own running MSE (`speed_mse`) at the end of the run.
    pub spec_mse: Option<f64>,
    /// P2: steps with `p2_violated` true, and steps it was reported.
    pub p2_violations: usize,
    pub p2_steps: usize,
    /// Actions that differ from the robot's own command.
    pub augmented_actions: usize,
    pub actions: usize,
    /// Augmented actions per `reason` (`p1`, `p2`, `p1,p2`), in that order, then any other.
    pub reasons: Vec<(String, usize)>,
    /// Augmented actions P1 lowered while its status was `unknown`: the `unknown_speed_cap`.
    pub capped_actions: usize,
    /// P1: steps per status.
    pub p1_violated: usize,
    pub p1_unknown: usize,
    pub p1_ok: usize,
    /// P3: scans with at least one spike, total spikes, total dropouts, scans reported.
    pub p3_scans_with_spikes: usize,
    pub p3_spikes: f64,
    pub p3_dropouts: f64,
    pub p3_scans: usize,
    /// The spec's other verdicts (any spec's): steps per value, most frequent first.
    pub verdicts: Vec<(String, Vec<(String, usize)>)>,
    /// The robot's silent periods, when the run has `robot_silent`.
    pub silence: Option<super::series::Silence>,
    /// The robot spec's outputs this report looks for that the run does not have (empty when
    /// the run has none of the robot spec's own outputs: then it is another spec's run).
    pub missing_robot: Vec<&'static str>,
    /// Whether the run has any of the robot spec's own outputs (`p1_status`, `p2_violated`,
    /// `p3_spikes`, `speed_mse`): only then the robot's sections are shown.
    pub robot: bool,
    /// The steps of the run: each instance's (its most frequent output's events), totalled.
    pub steps: usize,
    /// A fleet's splits (tags whose value differs between instances): steps per value.
    pub splits: Vec<(String, Vec<(String, usize)>)>,
    /// Status lines (`tessla_spec`) and records refused as ahead of the clock, left out.
    pub status_lines: usize,
    pub ahead: usize,
}

/// Verdicts the robot's lines of the summary already show.
const ROBOT_VERDICTS: [&str; 7] = [
    "p1_status",
    "p2_violated",
    "p3_ok",
    "p2_augmented",
    "augmented",
    "reason",
    "robot_silent",
];

impl Summary {
    pub fn compute(run: &Run, picked: &Picked) -> Summary {
        let (mse, mse_pairs) = mse_of_records(run);
        let first = run.records.first().map_or(0.0, |r| r.t);
        let last = run.records.iter().map(|r| r.t).fold(first, f64::max);
        let status_count = |s: &str| {
            picked
                .p1_status
                .points
                .iter()
                .filter(|(_, v)| v == s)
                .count()
        };
        let outputs = super::outputs::Outputs::from_run(run);
        let verdicts = outputs
            .verdict_counts()
            .into_iter()
            .filter(|(name, _)| {
                let base = name.split('[').next().unwrap_or(name);
                !ROBOT_VERDICTS.contains(&base)
            })
            .collect();
        let robot = !(picked.p1_status.is_empty()
            && picked.p2_violated.is_empty()
            && picked.p3_spikes.is_empty()
            && picked.speed_mse.is_empty());
        let missing_robot = [
            ("p1_status", picked.p1_status.is_empty()),
            ("p2_violated", picked.p2_violated.is_empty()),
            ("p3_spikes", picked.p3_spikes.is_empty()),
            ("action.augmented", picked.augmented.is_empty()),
            ("speed_mse", picked.speed_mse.is_empty()),
        ]
        .into_iter()
        .filter(|(_, absent)| robot && *absent)
        .map(|(name, _)| name)
        .collect();
        Summary {
            robot,
            steps: outputs.steps(),
            splits: outputs.splits(),
            status_lines: run.status_lines,
            ahead: run.ahead,
            verdicts,
            silence: super::series::Silence::from_run(run),
            missing_robot,
            records: run.records.len(),
            skipped: run.skipped,
            duration_s: last - first,
            mse,
            mse_pairs,
            spec_mse: picked.speed_mse.points.last().map(|(_, v)| *v),
            p2_violations: picked.p2_violated.points.iter().filter(|(_, v)| *v).count(),
            p2_steps: picked.p2_violated.points.len(),
            augmented_actions: picked.augmented.points.iter().filter(|(_, v)| *v).count(),
            actions: picked.augmented.points.len(),
            reasons: reasons(picked),
            capped_actions: capped(picked),
            p1_violated: status_count("violated"),
            p1_unknown: status_count("unknown"),
            p1_ok: status_count("ok"),
            p3_scans_with_spikes: picked
                .p3_spikes
                .points
                .iter()
                .filter(|(_, v)| *v > 0.0)
                .count(),
            p3_spikes: picked.p3_spikes.points.iter().map(|(_, v)| v).sum(),
            p3_dropouts: picked.p3_dropouts.points.iter().map(|(_, v)| v).sum(),
            p3_scans: picked
                .p3_spikes
                .points
                .len()
                .max(picked.p3_dropouts.points.len()),
        }
    }
}

/// Augmented actions per reason, `p1`, `p2`, `p1,p2` first (also when 0), then others.
fn reasons(picked: &Picked) -> Vec<(String, usize)> {
    let mut out: Vec<(String, usize)> = ["p1", "p2", "p1,p2"]
        .iter()
        .map(|r| (r.to_string(), 0))
        .collect();
    for (_, r) in &picked.reason.points {
        match out.iter_mut().find(|(k, _)| k == r) {
            Some((_, n)) => *n += 1,
            None => out.push((r.clone(), 1)),
        }
    }
    out
}

/// Actions whose reason names P1 while the action's `p1_status` is `unknown` (same time).
fn capped(picked: &Picked) -> usize {
    let unknown: std::collections::HashSet<u64> = picked
        .action_p1_status
        .points
        .iter()
        .filter(|(_, s)| s == "unknown")
        .map(|(t, _)| t.to_bits())
        .collect();
    picked
        .reason
        .points
        .iter()
        .filter(|(t, r)| r.split(',').any(|p| p == "p1") && unknown.contains(&t.to_bits()))
        .count()
}

impl Summary {
    /// A few lines for a person (`report --summary`, `make run`), none wider than 80
    /// characters: steps, violations per property, augmented actions and why, the final MSE
    /// (the robot's lines only for the robot outputs the run has), the silent periods, and any
    /// other verdicts of the spec with their steps per value.
    pub fn text(&self, source: &str) -> String {
        use super::text::{short, wrap};
        let mut out = format!(
            "summary of {source}: {} steps over {} s\n",
            self.steps,
            short(self.duration_s)
        );
        // A line of the summary; one starting with two spaces goes under the previous line.
        let mut line = |text: String| {
            let head = if text.starts_with("  ") { "    " } else { "  " };
            out.push_str(&wrap(head, &text, 80, 2));
        };
        let left_out: Vec<String> = [
            (self.status_lines, "status lines (tessla_spec)"),
            (self.ahead, "records stamped ahead of the clock"),
        ]
        .iter()
        .filter(|(n, _)| *n > 0)
        .map(|(n, what)| format!("{n} {what}"))
        .collect();
        if !left_out.is_empty() {
            line(format!("left out of the clock: {}", left_out.join(", ")));
        }
        for (key, values) in &self.splits {
            let values: Vec<String> = values.iter().map(|(v, n)| format!("{v} {n}")).collect();
            line(format!("steps per {key}: {}", values.join(", ")));
        }
        let p1_steps = self.p1_violated + self.p1_unknown + self.p1_ok;
        if p1_steps > 0 {
            line(format!(
                "P1 braking distance: {} violated, {} unknown (blinded), {} ok, of {p1_steps}",
                self.p1_violated, self.p1_unknown, self.p1_ok
            ));
        }
        if self.p2_steps > 0 {
            line(format!(
                "P2 speed tolerance: {} violated of {}",
                self.p2_violations, self.p2_steps
            ));
        }
        if self.p3_scans > 0 {
            line(format!(
                "P3 lidar: {} spikes in {} of {} scans, {} dropouts",
                short(self.p3_spikes),
                self.p3_scans_with_spikes,
                self.p3_scans,
                short(self.p3_dropouts)
            ));
        }
        if self.actions > 0 {
            let reasons: Vec<String> = self
                .reasons
                .iter()
                .map(|(r, n)| format!("{r} {n}"))
                .collect();
            line(format!(
                "actions: {} of {} augmented; why: {}",
                self.augmented_actions,
                self.actions,
                reasons.join(", "),
            ));
            line(format!(
                "  capped at unknown_speed_cap while P1 was unknown: {}",
                self.capped_actions,
            ));
        }
        match &self.silence {
            Some(s) if s.periods.is_empty() => {
                line("robot silent: never (robot_silent false throughout)".to_string());
            }
            Some(s) => {
                let open = if s.open_at_end {
                    " (the last still silent at the end)"
                } else {
                    ""
                };
                line(format!(
                    "robot silent: {} periods, {} s in all, longest {} s{open}",
                    s.periods.len(),
                    short(s.total()),
                    short(s.longest())
                ));
            }
            None => {}
        }
        for (name, counts) in &self.verdicts {
            let counts: Vec<String> = counts.iter().map(|(v, n)| format!("{v} {n}")).collect();
            line(format!("{name}: {} (steps per value)", counts.join(", ")));
        }
        let mse = match (self.mse, self.spec_mse) {
            (Some(m), _) => Some(format!("{m:.6e} (from the telemetry)")),
            (None, Some(m)) => Some(format!("{m:.6e} (the spec's speed_mse at the end)")),
            (None, None) => None,
        };
        if let Some(mse) = mse {
            line(format!("final MSE expected/actual speed: {mse}"));
        }
        out
    }
}

/// MSE over the records that carry both `expectedSpeed` and `actualSpeed` (a string
/// `actualSpeed` counts when it holds a number).
pub fn mse_of_records(run: &Run) -> (Option<f64>, usize) {
    let mut sum = 0.0;
    let mut n = 0usize;
    for r in &run.records {
        let expected = r.field("expectedSpeed").and_then(|v| v.as_f64());
        let actual = r.field("actualSpeed").and_then(|v| v.as_f64());
        if let (Some(e), Some(a)) = (expected, actual) {
            sum += (e - a) * (e - a);
            n += 1;
        }
    }
    ((n > 0).then(|| sum / n as f64), n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::series::running_mse;

    #[test]
    fn mse_and_counts() {
        let run = Run::parse(
            "mqtt_consumer expectedSpeed=0.1,actualSpeed=\"0.05\" 0\n\
             mqtt_consumer expectedSpeed=0.1 1\n\
             mqtt_consumer expectedSpeed=0.2,actualSpeed=0.1 2\n\
             action p1_status=\"violated\",p2_violated=true,augmented=true,p3_spikes=2,p3_dropouts=1,speed_mse=0.00625 2\n\
             action p1_status=\"unknown\",p2_violated=false,augmented=false,p3_spikes=0,p3_dropouts=4 3\n",
        );
        let s = Summary::compute(&run, &Picked::from_run(&run));
        assert_eq!(s.mse_pairs, 2);
        let expected = (0.05f64.powi(2) + 0.1f64.powi(2)) / 2.0;
        assert!((s.mse.unwrap() - expected).abs() < 1e-15);
        assert_eq!(s.spec_mse, Some(0.00625));
        assert_eq!((s.p2_violations, s.p2_steps), (1, 2));
        assert_eq!((s.augmented_actions, s.actions), (1, 2));
        assert_eq!((s.p1_violated, s.p1_unknown, s.p1_ok), (1, 1, 0));
        assert_eq!(
            (s.p3_scans_with_spikes, s.p3_spikes, s.p3_dropouts),
            (1, 2.0, 5.0)
        );
        assert_eq!(running_mse(&run).len(), 2);
    }
}
