//! The end-of-run summary: a table on stdout (or JSON with `--json`) comparing the default
//! robot (monitor off) with the augmented one (monitor on).

use super::closed_loop::Outcome;
use serde::Serialize;

/// What the summary describes.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub terrain: String,
    pub program: String,
    pub seed: u64,
    pub period_s: f64,
    pub delay_s: f64,
    /// Monitor off: the robot's own command.
    pub default: Option<Outcome>,
    /// Monitor on: the twin's actions executed.
    pub augmented: Option<Outcome>,
}

impl Summary {
    /// (augmented − default) / default, when both ran.
    pub fn relative_change(&self) -> Option<f64> {
        match (&self.default, &self.augmented) {
            (Some(d), Some(a)) if d.mse > 0.0 => Some((a.mse - d.mse) / d.mse),
            _ => None,
        }
    }

    pub fn to_json(&self) -> String {
        let mut v = serde_json::to_value(self).unwrap_or_default();
        if let Some(obj) = v.as_object_mut() {
            obj.insert(
                "relative_change".into(),
                self.relative_change()
                    .and_then(serde_json::Number::from_f64)
                    .map_or(serde_json::Value::Null, serde_json::Value::Number),
            );
        }
        v.to_string()
    }

    pub fn to_table(&self) -> String {
        let mut s = format!(
            "simulate: terrain {}, program {}, seed {}, a message every {} s, twin delay {} s\n",
            self.terrain, self.program, self.seed, self.period_s, self.delay_s
        );
        s.push_str(&format!(
            "{:<24} {:>10} {:>12} {:>14} {:>10} {:>10}\n",
            "mode", "MSE", "spec MSE", "interventions", "stuck s", "distance m"
        ));
        let row = |name: &str, o: &Outcome| {
            format!(
                "{:<24} {:>10.6} {:>12} {:>14} {:>10.1} {:>10.2}\n",
                name,
                o.mse,
                o.spec_mse.map_or("-".to_string(), |m| format!("{m:.6}")),
                o.interventions,
                o.stuck_seconds,
                o.distance
            )
        };
        if let Some(d) = &self.default {
            s.push_str(&row("default (monitor off)", d));
        }
        if let Some(a) = &self.augmented {
            s.push_str(&row("augmented (monitor on)", a));
        }
        if let Some(r) = self.relative_change() {
            s.push_str(&format!(
                "relative change of the MSE: {:+.1}% (paper: 0.0017 -> 0.0010, -41%)\n",
                r * 100.0
            ));
        }
        s.push_str("interventions: actions that changed the robot's command (proposed only, with the monitor off)\n");
        if let Some(a) = &self.augmented {
            s.push_str(&format!(
                "actions the robot refused: {} stale (past valid_until), {} repeated (seq); monitor restarts seen: {}\n",
                a.refused_stale, a.refused_repeated, a.monitor_restarts
            ));
            if a.messages_held > 0 {
                s.push_str(&format!(
                    "link drops: {} messages held and sent late; the oldest data behind an applied action: {:.0} ms\n",
                    a.messages_held, a.oldest_applied_ms
                ));
            }
        }
        s
    }
}
