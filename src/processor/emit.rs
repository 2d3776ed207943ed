//! Writing a step's outputs: the events an instance's monitor produced in one step, collected
//! and encoded as metrics, one group per timestamp, with the instance's tags, by the encodings
//! of the version that computed them (each version's prepared once, in its `Version`); with
//! `--fleet-spec`, the events the fleet level reads are kept in the fleet tap as well.

use super::Counters;
use super::fleet_tap::Tap;
use crate::log;
use crate::telegraf::encode::{self, Prepared, StepEvent};
use std::sync::Arc;
use tessla_engine::{OutputEvent, Program, Value};

/// One output event of a step, as the monitor produced it: its TeSSLa time, the output's index
/// and its value (kept in [`Emitter::events`] until the step is written).
pub(super) struct Fired {
    pub(super) ts: i64,
    pub(super) output: usize,
    pub(super) value: Value,
}

impl Fired {
    /// The monitor's event, its value copied out of the monitor.
    #[inline]
    pub(super) fn of(e: OutputEvent<'_>) -> Fired {
        Fired {
            ts: e.ts,
            output: e.output,
            value: e.value.clone(),
        }
    }
}

impl StepEvent for Fired {
    #[inline]
    fn output(&self) -> usize {
        self.output
    }
    #[inline]
    fn value(&self) -> &Value {
        &self.value
    }
}

/// What writing a step's outputs needs, apart from the instance.
pub(super) struct Emitter {
    pub(super) events: Vec<Fired>,
    /// Scratch: the encoder's buffers (the same whatever version writes).
    pub(super) encode: encode::Scratch,
    /// With `--fleet-spec`: what the fleet level takes from this processor.
    pub(super) tap: Option<Tap>,
}

impl Emitter {
    /// Write the collected events as metrics, one group per timestamp, by `encodings` (those
    /// of the version whose monitor produced the events) after the instance's tags escaped
    /// once (`escaped_tags`: [`encode::escape_tags`]); `from`: the instance's fleet key and
    /// the program that produced them, for the fleet tap.
    pub(super) fn emit(
        &mut self,
        encodings: &Prepared,
        escaped_tags: &str,
        from: (&Arc<str>, &Arc<Program>),
        counters: &mut Counters,
        out: &mut Vec<u8>,
    ) {
        if self.events.is_empty() {
            return;
        }
        if let Some(t) = &mut self.tap {
            let events = self.events.iter().map(|e| (e.ts, e.output, &e.value));
            t.take(events, from.0, from.1);
        }
        let mut rest = &self.events[..];
        while let Some(&Fired { ts, .. }) = rest.first() {
            // One timestamp's events, encoded in place.
            let n = rest.iter().take_while(|e| e.ts == ts).count();
            let (step, tail) = rest.split_at(n);
            rest = tail;
            counters.outputs += step.len() as u64;
            let dropped = encode::encode_prepared_escaped(
                &mut self.encode,
                encodings,
                ts,
                step,
                escaped_tags,
                out,
            );
            for d in dropped {
                counters.dropped_values += 1;
                log::warn_limited("output value", || {
                    format!("output `{}` at {ts}: {}; field dropped", d.output, d.reason)
                });
            }
        }
        // Keep the buffer's capacity for the next step.
        self.events.clear();
    }
}
