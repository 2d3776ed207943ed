//! The status metric: one line of line protocol per outcome of a spec version in this process
//! (a reload accepted or refused; a rollout's vote, accepted or refused; then the fleet's
//! decision: committed, unrunnable here, or aborted; and why), which Telegraf carries to
//! InfluxDB beside the verdicts, so the operator sees a rollout on the dashboards.
//!
//! `tessla_spec,host=H,partition=P,version=ID,outcome=accepted|refused|committed|unrunnable|aborted revision=3i,label="…",reason="…",reset_outputs="a,b",from=T i,pid=N i TIME`
//! (`partition` only with a lease; `label`, `reason` and `reset_outputs` only when not empty;
//! `late_instances=Ni` when a rollout arrived after instances it picks had passed its start.)

use super::Outcome;
use lineproto::{
    FieldValue, write_field_key, write_field_value, write_measurement, write_tag_key,
    write_tag_value, write_timestamp,
};

/// The status metric's measurement.
pub const MEASUREMENT: &str = "tessla_spec";

pub fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// An event time for messages (its home is the processor's clock, which names rollouts'
/// starts in its own messages).
pub use crate::processor::clock::show_time;

/// Append the status line of `o` (version in force from `from`) to `out`.
pub fn write_line(out: &mut Vec<u8>, host: &str, partition: &str, o: &Outcome, from: i64) {
    let mut line = String::with_capacity(160);
    write_measurement(&mut line, MEASUREMENT);
    let mut tags = vec![("host", host), ("outcome", o.word())];
    if !partition.is_empty() {
        tags.push(("partition", partition));
    }
    if !o.id.is_empty() {
        tags.push(("version", &o.id));
    }
    tags.sort();
    for (k, v) in tags.iter().filter(|(_, v)| !v.is_empty()) {
        line.push(',');
        write_tag_key(&mut line, k);
        line.push('=');
        write_tag_value(&mut line, v);
    }
    let mut fields = vec![
        (
            "revision",
            FieldValue::Int(i64::try_from(o.revision).unwrap_or(i64::MAX)),
        ),
        ("from", FieldValue::Int(from)),
        ("pid", FieldValue::Int(i64::from(std::process::id()))),
    ];
    if o.late_instances > 0 {
        let n = i64::try_from(o.late_instances).unwrap_or(i64::MAX);
        fields.push(("late_instances", FieldValue::Int(n)));
    }
    for (k, v) in [
        ("label", &o.label),
        ("reason", &o.reason),
        ("reset_outputs", &o.reset_outputs.join(",")),
    ] {
        if !v.is_empty() {
            fields.push((k, FieldValue::Str(v.clone())));
        }
    }
    for (i, (k, v)) in fields.iter().enumerate() {
        line.push(if i == 0 { ' ' } else { ',' });
        write_field_key(&mut line, k);
        line.push('=');
        // Integers and strings only: never a float that cannot be written.
        let _ = write_field_value(&mut line, v);
    }
    line.push(' ');
    write_timestamp(&mut line, now_ns());
    line.push('\n');
    out.extend_from_slice(line.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_is_one_line_of_line_protocol_with_its_reason() {
        let o = Outcome {
            revision: 3,
            id: "0123456789ab".into(),
            label: "tight delta".into(),
            accepted: false,
            reason: "it does not check here: \"x\"".into(),
            ..Outcome::default()
        };
        let mut out = Vec::new();
        write_line(&mut out, "h 1", "p0", &o, 5);
        let text = String::from_utf8(out).unwrap();
        let m = lineproto::parse_record(text.as_bytes()).unwrap().unwrap();
        assert_eq!(m.measurement, MEASUREMENT);
        assert_eq!(m.tag("host"), Some("h 1"));
        assert_eq!(m.tag("outcome"), Some("refused"));
        assert_eq!(m.tag("partition"), Some("p0"));
        assert_eq!(m.tag("version"), Some("0123456789ab"));
        assert_eq!(m.field("revision"), Some(&FieldValue::Int(3)));
        assert_eq!(
            m.field("reason"),
            Some(&FieldValue::Str("it does not check here: \"x\"".into()))
        );
        assert!(m.field("reset_outputs").is_none());
    }
}
