//! Any spec's outputs, as the report shows them without knowing the spec: its numeric outputs
//! over time, its verdicts (Bool fields and text fields such as a status) with the times each
//! changed, the augmented actions in runs, and the robot's silent periods (`robot_silent`, found by
//! [`super::series::Silence`]).
//!
//! Telemetry passed through is left out: the measurement `mqtt_consumer` (Telegraf's MQTT
//! input, what every shipped conf feeds the monitor), or those `report --telemetry` names.
//! Every other measurement is the spec's.
//! An output is named by its field, or by its measurement when the field is `value` (the
//! connector's `@TelegrafOut` form); `action` fields that repeat another measurement's field are
//! shown once, from the other measurement (the robot's action copies its verdicts).
//! A fleet's outputs are per instance (tag set): the run's steps are each instance's, totalled,
//! and [`Outputs::splits`] counts them per value of each tag that differs (`robot`,
//! `spec_version`).

use super::data::{Run, Value};
use super::series::Picked;
// The text helpers, still reachable here (`report::outputs::short`, as the CLI uses them).
pub use super::text::{short, wrap};

/// One output of the spec over time.
#[derive(Debug, Clone, PartialEq)]
pub struct Output<T> {
    /// The output's name (its field, or its measurement for a `value` field), with the
    /// instance's tags in brackets when the run has more than one tag set.
    pub name: String,
    /// The name without the instance's tags.
    pub base: String,
    /// The instance's tags, `k=v,...` (empty when the run has one tag set).
    pub instance: String,
    pub points: Vec<(f64, T)>,
    /// Every value was a line-protocol integer (a count, a TeSSLa `Int`).
    pub ints: bool,
}

/// The spec's outputs found in a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outputs {
    pub numeric: Vec<Output<f64>>,
    /// Bool outputs as `true`/`false`, text outputs as they are.
    pub verdicts: Vec<Output<String>>,
}

fn label(measurement: &str, field: &str) -> String {
    if field == "value" {
        measurement.to_string()
    } else {
        field.to_string()
    }
}

impl Outputs {
    pub fn from_run(run: &Run) -> Outputs {
        let ours = |m: &str| !run.telemetry.iter().any(|t| t == m);
        let mut tag_sets: Vec<&[(String, String)]> = Vec::new();
        for r in run.records.iter().filter(|r| ours(&r.measurement)) {
            if !tag_sets.contains(&r.tags.as_slice()) {
                tag_sets.push(&r.tags);
            }
        }
        let show_tags = tag_sets.len() > 1;
        // Names that a measurement other than `action` carries: `action`'s copy is left out.
        let mut elsewhere: Vec<String> = Vec::new();
        for r in run
            .records
            .iter()
            .filter(|r| ours(&r.measurement) && r.measurement != "action")
        {
            for (f, _) in &r.fields {
                let name = label(&r.measurement, f);
                if !elsewhere.contains(&name) {
                    elsewhere.push(name);
                }
            }
        }
        let mut out = Outputs::default();
        for r in run.records.iter().filter(|r| ours(&r.measurement)) {
            for (f, v) in &r.fields {
                let base = label(&r.measurement, f);
                if r.measurement == "action" && elsewhere.contains(&base) {
                    continue;
                }
                let instance = if show_tags {
                    let tags: Vec<String> =
                        r.tags.iter().map(|(k, v)| format!("{k}={v}")).collect();
                    tags.join(",")
                } else {
                    String::new()
                };
                let key = Key {
                    base: &base,
                    instance: &instance,
                    int: matches!(v, Value::Int(_)),
                };
                match v {
                    Value::Float(_) | Value::Int(_) => {
                        if let Some(x) = v.as_f64() {
                            push(&mut out.numeric, key, (r.t, x));
                        }
                    }
                    Value::Bool(b) => push(&mut out.verdicts, key, (r.t, b.to_string())),
                    Value::Str(s) => match v.as_f64() {
                        Some(x) => push(&mut out.numeric, key, (r.t, x)),
                        None => push(&mut out.verdicts, key, (r.t, s.clone())),
                    },
                }
            }
        }
        out
    }

    /// Steps per value of each verdict, most frequent first: `(name, [(value, steps)])`.
    pub fn verdict_counts(&self) -> Vec<(String, Vec<(String, usize)>)> {
        self.verdicts
            .iter()
            .map(|o| {
                let mut counts: Vec<(String, usize)> = Vec::new();
                for (_, v) in &o.points {
                    match counts.iter_mut().find(|(k, _)| k == v) {
                        Some((_, n)) => *n += 1,
                        None => counts.push((v.clone(), 1)),
                    }
                }
                counts.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
                (o.name.clone(), counts)
            })
            .collect()
    }
}

/// Which output a value belongs to, and whether it was an integer.
struct Key<'a> {
    base: &'a str,
    instance: &'a str,
    int: bool,
}

fn push<T>(list: &mut Vec<Output<T>>, key: Key<'_>, point: (f64, T)) {
    match list
        .iter_mut()
        .find(|o| o.base == key.base && o.instance == key.instance)
    {
        Some(o) => {
            o.points.push(point);
            o.ints &= key.int;
        }
        None => list.push(Output {
            name: if key.instance.is_empty() {
                key.base.to_string()
            } else {
                format!("{}[{}]", key.base, key.instance)
            },
            base: key.base.to_string(),
            instance: key.instance.to_string(),
            points: vec![point],
            ints: key.int,
        }),
    }
}

impl Outputs {
    /// The instances (tag sets, `k=v,...`) with outputs, in order of appearance; one empty
    /// string when the run has one tag set.
    pub fn instances(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        let all = self
            .numeric
            .iter()
            .map(|o| o.instance.as_str())
            .chain(self.verdicts.iter().map(|o| o.instance.as_str()));
        for i in all {
            if !out.contains(&i) {
                out.push(i);
            }
        }
        out
    }

    /// The steps of one instance: the events of its most frequent output.
    pub fn steps_of(&self, instance: &str) -> usize {
        let numeric = self.numeric.iter().filter(|o| o.instance == instance);
        let verdicts = self.verdicts.iter().filter(|o| o.instance == instance);
        numeric
            .map(|o| o.points.len())
            .chain(verdicts.map(|o| o.points.len()))
            .max()
            .unwrap_or(0)
    }

    /// The steps of the run: each instance's, totalled.
    pub fn steps(&self) -> usize {
        self.instances().iter().map(|i| self.steps_of(i)).sum()
    }

    /// A fleet's splits: for each tag whose value differs between instances (`robot`,
    /// `spec_version`, ...), its values with the steps of the instances that carry each, in
    /// order of appearance. Empty for a run of one instance.
    pub fn splits(&self) -> Vec<(String, Vec<(String, usize)>)> {
        let mut keys: Vec<(String, Vec<(String, usize)>)> = Vec::new();
        let instances = self.instances();
        for instance in &instances {
            let steps = self.steps_of(instance);
            for (k, v) in instance.split(',').filter_map(|kv| kv.split_once('=')) {
                let i = match keys.iter().position(|(key, _)| key == k) {
                    Some(i) => i,
                    None => {
                        keys.push((k.to_string(), Vec::new()));
                        keys.len() - 1
                    }
                };
                let values = &mut keys[i].1;
                match values.iter_mut().find(|(value, _)| value == v) {
                    Some((_, n)) => *n += steps,
                    None => values.push((v.to_string(), steps)),
                }
            }
        }
        keys.retain(|(_, values)| values.len() > 1);
        keys
    }
}

/// The terminal view (`report --timeline`): when each verdict changed (changes at one time on
/// one line), each run of augmented actions with its reason, and the silent periods, in time
/// order, every line at most `width` characters.
pub fn timeline(picked: &Picked, outputs: &Outputs, width: usize) -> String {
    // (time, order within the time, text)
    let mut events: Vec<(f64, u8, String)> = Vec::new();
    // Verdict changes. `action`'s `reason` is shown with the actions.
    let mut changes: Vec<(f64, String)> = Vec::new();
    for o in &outputs.verdicts {
        // The action's flags are shown with the runs of augmented actions.
        if !picked.augmented.is_empty()
            && ["reason", "augmented", "p2_augmented"].contains(&o.base.as_str())
        {
            continue;
        }
        let mut last: Option<&str> = None;
        for (t, v) in &o.points {
            if last != Some(v.as_str()) {
                changes.push((*t, format!("{} {v}", o.name)));
                last = Some(v.as_str());
            }
        }
    }
    changes.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut i = 0;
    while let Some((t, _)) = changes.get(i) {
        let t = *t;
        let same: Vec<&str> = changes
            .iter()
            .skip(i)
            .take_while(|(u, _)| *u == t)
            .map(|(_, s)| s.as_str())
            .collect();
        i += same.len();
        events.push((t, 0, same.join(", ")));
    }
    // Augmented actions: consecutive augmented actions with one reason form a run.
    let reason_at = |t: f64| {
        picked
            .reason
            .points
            .iter()
            .find(|(u, _)| *u == t)
            .map_or("none given", |(_, r)| r.as_str())
    };
    let value_at =
        |points: &[(f64, f64)], t: f64| points.iter().rev().find(|(u, _)| *u <= t).map(|(_, v)| *v);
    let mut k = 0;
    let acts = &picked.augmented.points;
    while let Some((t0, aug)) = acts.get(k) {
        if !aug {
            k += 1;
            continue;
        }
        let reason = reason_at(*t0);
        let run_len = acts
            .iter()
            .skip(k)
            .take_while(|(t, a)| *a && reason_at(*t) == reason)
            .count();
        let times: Vec<f64> = acts.iter().skip(k).take(run_len).map(|(t, _)| *t).collect();
        let sent: Vec<f64> = times
            .iter()
            .filter_map(|t| value_at(&picked.action_speed.points, *t))
            .collect();
        let asked: Vec<f64> = times
            .iter()
            .filter_map(|t| value_at(&picked.expected_speed.points, *t))
            .collect();
        let last = times.last().copied().unwrap_or(*t0);
        let what = if run_len == 1 {
            "1 action".to_string()
        } else {
            format!("{run_len} actions to {}", secs(last))
        };
        let mut text = format!("augmented, reason {reason}: {what}");
        if !sent.is_empty() {
            text.push_str(&format!(", speed {}", range(&sent)));
            if !asked.is_empty() {
                text.push_str(&format!(" for {}", range(&asked)));
            }
        }
        events.push((*t0, 1, text));
        k += run_len.max(1);
    }
    events.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut out = String::new();
    for (t, _, text) in events {
        let head = format!("{:>7} ", secs(t));
        out.push_str(&wrap(&head, &text, width, 0));
    }
    out
}

/// `12.4 s`.
fn secs(t: f64) -> String {
    format!("{:.1} s", t + 0.0)
}

/// `0.05` or `0.05..0.06`.
fn range(values: &[f64]) -> String {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if (hi - lo).abs() < 1e-12 {
        short(lo)
    } else {
        format!("{}..{}", short(lo), short(hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::series::Silence;

    #[test]
    fn seconds_never_show_minus_zero() {
        assert_eq!(secs(-0.0), "0.0 s");
    }

    #[test]
    fn outputs_verdicts_and_silence() {
        let run = Run::parse(
            "mqtt_consumer actualSpeed=\"0.1\",ok=true 0\n\
             tessla hot=false,level=\"low\",temp=20.5,robot_silent=false 0\n\
             hot value=true 1000000000\n\
             tessla hot=true,level=\"high\",temp=31,robot_silent=true 2000000000\n\
             tessla hot=true,level=\"high\",temp=30,robot_silent=false 5000000000\n\
             tessla robot_silent=true 6000000000\n\
             tessla temp=29 7000000000\n",
        );
        let o = Outputs::from_run(&run);
        let names: Vec<&str> = o.numeric.iter().map(|n| n.name.as_str()).collect();
        assert_eq!(names, ["temp"], "telemetry is left out");
        let verdicts: Vec<&str> = o.verdicts.iter().map(|n| n.name.as_str()).collect();
        assert_eq!(verdicts, ["hot", "level", "robot_silent"]);
        assert_eq!(
            o.verdicts[0].points.len(),
            4,
            "the `hot value=` form joins `hot`"
        );
        let counts = o.verdict_counts();
        assert_eq!(counts[1].1, vec![("high".into(), 2), ("low".into(), 1)]);
        let s = Silence::from_run(&run).unwrap();
        assert_eq!(s.periods, vec![(2.0, 5.0), (6.0, 7.0)]);
        assert!(s.open_at_end);
        assert_eq!(s.total(), 4.0);
        let picked = Picked::from_run(&run);
        let text = timeline(&picked, &o, 80);
        assert!(
            text.contains("0.0 s hot false, level low, robot_silent false"),
            "{text}"
        );
        assert!(
            text.contains("2.0 s level high, robot_silent true"),
            "{text}"
        );
        assert!(!text.contains("temp"), "{text}");
    }
}
