//! Picking the report's quantities out of a run, wherever the output binding put them.
//!
//! A quantity `q` (e.g. `p1_margin`) is taken from measurement `q` (field `value`, or its only
//! field) when the run has it (the connector style `q value=… ts`); otherwise from field `q` of
//! whichever measurement carries it most often (the `action` metric's fields, the pass-through
//! `mqtt_consumer` telemetry). So one quantity is never counted twice.
//!
//! Also owns the two quantities derived while picking: the robot's silent periods ([`Silence`],
//! from its `robot_silent` verdict) and the running MSE between expected and actual speed
//! ([`running_mse`]).

use super::data::{Record, Run, Value};

/// Where a quantity was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Source {
    pub measurement: String,
    pub field: String,
}

/// The values of one quantity over time.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series<T> {
    pub source: Option<Source>,
    pub points: Vec<(f64, T)>,
}

impl<T> Series<T> {
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// Every quantity the report shows.
#[derive(Debug, Clone, Default)]
pub struct Picked {
    pub expected_speed: Series<f64>,
    pub actual_speed: Series<f64>,
    /// The speed sent to the robot: `action.speed`, else `p2_action`.
    pub action_speed: Series<f64>,
    /// Whether that action was augmented: `action.augmented`, else `p2_augmented`.
    pub augmented: Series<bool>,
    /// Why an action was augmented (`action.reason`: `p1`, `p2`, `p1,p2`).
    pub reason: Series<String>,
    /// P1's status as the action carried it (tells the cap, `unknown`, from a violation).
    pub action_p1_status: Series<String>,
    pub p2_violated: Series<bool>,
    pub speed_mse: Series<f64>,
    /// The running MSE computed by the report from the pass-through telemetry.
    pub running_mse: Series<f64>,
    pub p1_status: Series<String>,
    pub p1_margin: Series<f64>,
    pub p3_spikes: Series<f64>,
    pub p3_dropouts: Series<f64>,
    pub p3_ok: Series<bool>,
    /// The robot's silent periods (`robot_silent`), when the run has them.
    pub silence: Option<Silence>,
    /// The time of the run's last record.
    pub end_t: Option<f64>,
}

impl Picked {
    pub fn from_run(run: &Run) -> Picked {
        Picked {
            expected_speed: pick(run, "expectedSpeed", Value::as_f64),
            actual_speed: pick(run, "actualSpeed", Value::as_f64),
            action_speed: first_non_empty(pick_in(run, "action", "speed", Value::as_f64), || {
                pick(run, "p2_action", Value::as_f64)
            }),
            augmented: first_non_empty(pick_in(run, "action", "augmented", Value::as_bool), || {
                pick(run, "p2_augmented", Value::as_bool)
            }),
            reason: pick_in(run, "action", "reason", |v| Some(v.as_text())),
            action_p1_status: pick_in(run, "action", "p1_status", |v| Some(v.as_text())),
            p2_violated: pick(run, "p2_violated", Value::as_bool),
            speed_mse: pick(run, "speed_mse", Value::as_f64),
            running_mse: Series {
                source: None,
                points: running_mse(run),
            },
            p1_status: pick(run, "p1_status", |v| Some(v.as_text())),
            p1_margin: pick(run, "p1_margin", Value::as_f64),
            p3_spikes: pick(run, "p3_spikes", Value::as_f64),
            p3_dropouts: pick(run, "p3_dropouts", Value::as_f64),
            p3_ok: pick(run, "p3_ok", Value::as_bool),
            silence: Silence::from_run(run),
            end_t: run.records.iter().map(|r| r.t).reduce(f64::max),
        }
    }
}

fn first_non_empty<T>(first: Series<T>, second: impl FnOnce() -> Series<T>) -> Series<T> {
    if first.is_empty() { second() } else { first }
}

/// The field of record `r` that holds quantity `name` when `r` is measurement `name`.
fn own_field<'a>(r: &'a Record, name: &str) -> Option<&'a Value> {
    if r.measurement != name {
        return None;
    }
    r.field("value").or(match r.fields.as_slice() {
        [(_, only)] => Some(only),
        _ => None,
    })
}

/// Quantity `name`: its own measurement first, else the measurement carrying field `name` most.
pub fn pick<T>(run: &Run, name: &str, convert: impl Fn(&Value) -> Option<T>) -> Series<T> {
    let own: Vec<(f64, T)> = run
        .records
        .iter()
        .filter_map(|r| own_field(r, name).and_then(&convert).map(|v| (r.t, v)))
        .collect();
    if !own.is_empty() {
        let field = run
            .records
            .iter()
            .find(|r| r.measurement == name)
            .and_then(|r| match r.field("value") {
                Some(_) => Some("value".to_string()),
                None => r.fields.first().map(|(f, _)| f.clone()),
            })
            .unwrap_or_else(|| "value".to_string());
        return Series {
            source: Some(Source {
                measurement: name.to_string(),
                field,
            }),
            points: own,
        };
    }
    // Count which measurement carries the field most often.
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for r in run.records.iter().filter(|r| r.field(name).is_some()) {
        match counts.iter_mut().find(|(m, _)| *m == r.measurement) {
            Some((_, n)) => *n += 1,
            None => counts.push((&r.measurement, 1)),
        }
    }
    let best = counts
        .iter()
        .max_by_key(|(_, n)| *n)
        .map(|(m, _)| m.to_string());
    match best {
        Some(measurement) => pick_in(run, &measurement, name, convert),
        None => Series::default_empty(),
    }
}

/// Field `field` of measurement `measurement`.
pub fn pick_in<T>(
    run: &Run,
    measurement: &str,
    field: &str,
    convert: impl Fn(&Value) -> Option<T>,
) -> Series<T> {
    let points: Vec<(f64, T)> = run
        .records
        .iter()
        .filter(|r| r.measurement == measurement)
        .filter_map(|r| r.field(field).and_then(&convert).map(|v| (r.t, v)))
        .collect();
    Series {
        source: (!points.is_empty()).then(|| Source {
            measurement: measurement.to_string(),
            field: field.to_string(),
        }),
        points,
    }
}

impl<T> Series<T> {
    fn default_empty() -> Self {
        Series {
            source: None,
            points: Vec::new(),
        }
    }
}

/// The running MSE after each pair, for the plot when the spec's `speed_mse` is absent.
pub fn running_mse(run: &Run) -> Vec<(f64, f64)> {
    let mut sum = 0.0;
    let mut n = 0.0;
    let mut out = Vec::new();
    for r in &run.records {
        let expected = r.field("expectedSpeed").and_then(|v| v.as_f64());
        let actual = r.field("actualSpeed").and_then(|v| v.as_f64());
        if let (Some(e), Some(a)) = (expected, actual) {
            sum += (e - a) * (e - a);
            n += 1.0;
            out.push((r.t, sum / n));
        }
    }
    out
}

/// The robot's silent periods from its `robot_silent` verdict: `true` when its messages
/// stopped for longer than `max_silence`, `false` when they resumed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Silence {
    /// `(from, to)` in seconds since the run's start; `to` is the run's end for a period that
    /// had not ended.
    pub periods: Vec<(f64, f64)>,
    /// Whether the last period was still open at the end of the run.
    pub open_at_end: bool,
}

impl Silence {
    /// `None` when the run has no `robot_silent` field.
    pub fn from_run(run: &Run) -> Option<Silence> {
        let series = pick(run, "robot_silent", Value::as_bool);
        if series.is_empty() {
            return None;
        }
        let end = run.records.iter().map(|r| r.t).fold(0.0, f64::max);
        let mut s = Silence::default();
        let mut since: Option<f64> = None;
        for (t, silent) in &series.points {
            match (since, silent) {
                (None, true) => since = Some(*t),
                (Some(from), false) => {
                    s.periods.push((from, *t));
                    since = None;
                }
                _ => {}
            }
        }
        if let Some(from) = since {
            s.periods.push((from, end.max(from)));
            s.open_at_end = true;
        }
        Some(s)
    }

    pub fn total(&self) -> f64 {
        self.periods.iter().map(|(a, b)| b - a).sum()
    }

    pub fn longest(&self) -> f64 {
        self.periods.iter().map(|(a, b)| b - a).fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_measurement_wins_over_action_field() {
        let run = Run::parse(
            "p1_margin value=0.5 0\n\
             action p1_margin=9.0,speed=0.1,augmented=false 0\n\
             p1_margin value=0.25 1000000000\n",
        );
        let picked = Picked::from_run(&run);
        assert_eq!(picked.p1_margin.points, vec![(0.0, 0.5), (1.0, 0.25)]);
        assert_eq!(
            picked.p1_margin.source.as_ref().unwrap().measurement,
            "p1_margin"
        );
        assert_eq!(picked.action_speed.points, vec![(0.0, 0.1)]);
        assert_eq!(picked.augmented.points, vec![(0.0, false)]);
    }

    #[test]
    fn falls_back_to_the_measurement_that_carries_the_field() {
        let run = Run::parse(
            "mqtt_consumer expectedSpeed=0.1,actualSpeed=\"0.07\" 0\n\
             action p1_status=\"violated\" 0\n\
             p2_action value=0.115 0\n\
             p2_augmented value=true 0\n",
        );
        let picked = Picked::from_run(&run);
        assert_eq!(picked.actual_speed.points, vec![(0.0, 0.07)]);
        assert_eq!(picked.p1_status.points, vec![(0.0, "violated".to_string())]);
        assert_eq!(picked.action_speed.points, vec![(0.0, 0.115)]);
        assert_eq!(picked.augmented.points, vec![(0.0, true)]);
        assert!(picked.p3_spikes.is_empty());
    }
}
