//! The fast path of the text trace reader: an event line `TS: name = value` whose value is a
//! plain literal of the input's declared type, read from the line's bytes straight into an
//! [`Event`]: no copy of the line, no pass for UTF-8 over it, no expression parser, no value
//! built only to be checked against the type, and the input found through a hash of its name
//! instead of comparing it with every input's name.
//!
//! Owns: which lines take this path and the table of input names. It takes only lines that
//! [`reader::parse_line_any`](crate::reader::parse_line_any) reads to the same event (a test
//! holds both to that); for anything else (blank and comment lines, other forms of values,
//! values of another type, names it does not know, unusual spacing) it answers `None` and the
//! caller hands the line to the general reader, which also writes every message.
//!
//! Hand-written, not a parsing crate: the general reader (`tessla_syntax`'s lexer and parser)
//! took about a quarter of `trace`'s time on VAMOS primes, and this path reads a line with a
//! few instructions per byte (BENCHMARKS.md, "Speed, third round: trace on primes").

use crate::reader::{Event, Lit};
use tessla_engine::{Program, Type};

/// The inputs of a program by name: an open-addressing table of FNV-1a hashes of the names.
pub(crate) struct Inputs<'p> {
    program: &'p Program,
    /// Input index + 1 per slot, 0 for an empty slot; a power of two long.
    slots: Vec<u32>,
}

/// FNV-1a, one byte.
#[inline(always)]
fn fnv(h: u64, b: u8) -> u64 {
    (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
}

const FNV_START: u64 = 0xcbf2_9ce4_8422_2325;

impl<'p> Inputs<'p> {
    pub(crate) fn new(program: &'p Program) -> Inputs<'p> {
        let n = program.inputs.len();
        let len = (2 * n).next_power_of_two().max(8);
        let mut slots = vec![0u32; len];
        for (k, input) in program.inputs.iter().enumerate() {
            let Ok(id) = u32::try_from(k + 1) else {
                break;
            };
            let h = input.name.bytes().fold(FNV_START, fnv);
            let mut at = h as usize & (len - 1);
            loop {
                match slots.get(at).copied() {
                    // The first of two inputs of one name wins, as `Program::input_index`.
                    Some(s) if s != 0 && program_name(program, s) == Some(input.name.as_str()) => {
                        break;
                    }
                    Some(0) => {
                        if let Some(slot) = slots.get_mut(at) {
                            *slot = id;
                        }
                        break;
                    }
                    Some(_) => at = (at + 1) & (len - 1),
                    None => break,
                }
            }
        }
        Inputs { program, slots }
    }

    /// The index of the input named `name`, whose FNV-1a hash is `h`.
    #[inline]
    fn find(&self, name: &[u8], h: u64) -> Option<usize> {
        let mask = self.slots.len() - 1;
        let mut at = h as usize & mask;
        loop {
            let s = *self.slots.get(at)?;
            if s == 0 {
                return None;
            }
            if program_name(self.program, s).is_some_and(|n| n.as_bytes() == name) {
                return Some(s as usize - 1);
            }
            at = (at + 1) & mask;
        }
    }

    /// The event of one line (without its line ending), if the line is a plain event line on a
    /// declared input whose value is a plain literal of the input's type; `None` for every other
    /// line, which the general reader then reads.
    #[inline]
    pub(crate) fn event(&self, raw: &[u8], line: usize) -> Option<Event> {
        let mut p = Lit { b: raw, i: 0 };
        // `TS:`, spaces around TS.
        p.spaces();
        let digits_at = p.i;
        let mut ts: i64 = 0;
        while let Some(&c) = raw.get(p.i)
            && c.is_ascii_digit()
        {
            ts = ts.wrapping_mul(10).wrapping_add(i64::from(c - b'0'));
            p.i += 1;
        }
        // At most 18 digits: no overflow (longer ones are left to the general reader).
        if !(1..=18).contains(&(p.i - digits_at)) {
            return None;
        }
        p.spaces();
        (*raw.get(p.i)? == b':').then_some(())?;
        p.i += 1;
        p.spaces();
        // The name: a plain identifier, hashed as it is read.
        let name_at = p.i;
        let mut h = FNV_START;
        while let Some(&c) = raw.get(p.i)
            && (c.is_ascii_alphanumeric() || c == b'_')
        {
            h = fnv(h, c);
            p.i += 1;
        }
        let name = raw.get(name_at..p.i)?;
        if name.is_empty() {
            return None;
        }
        let input = self.find(name, h)?;
        let ty = &self.program.inputs.get(input)?.ty;
        p.spaces();
        let value = match raw.get(p.i) {
            // `TS: name`: a unit event.
            None if *ty == Type::Unit => tessla_engine::Value::Unit,
            Some(b'=') => {
                p.i += 1;
                let v = p.typed(ty, 0)?;
                p.spaces();
                v
            }
            _ => return None,
        };
        (p.i == raw.len()).then_some(Event {
            line,
            ts,
            input,
            value,
        })
    }
}

/// The name of input `id - 1`.
#[inline]
fn program_name(program: &Program, id: u32) -> Option<&str> {
    program
        .inputs
        .get((id as usize).checked_sub(1)?)
        .map(|i| i.name.as_str())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reader::{Read, parse_line_any};
    use crate::tests::program;

    /// Every line the fast path takes is read by the general reader to the same event.
    #[test]
    fn the_fast_path_reads_what_the_general_reader_reads() {
        let p = program(
            "in a: Events[Int]\nin b: Events[(Int, Int)]\nin c: Events[Float]\n\
             in d: Events[String]\nin e: Events[Bool]\nin u: Events[Unit]\n\
             in t: Events[(Int, (String, Bool), Float)]\nin a_2: Events[Int]\n\
             in f: Events[(Int, Int, Int, Int)]\nin o: Events[Option[Int]]\n\
             out a\nout b\nout c\nout d\nout e\nout u\nout t\nout a_2\nout f\nout o",
        );
        let inputs = Inputs::new(&p);
        let fast = [
            "1: a = 5",
            "  12 :a=  -7  ",
            "\t3:\ta\t=\t0\t",
            "000000000000000012: a = 123456789012345678",
            "4: b = (1, 2)",
            "4: b = ( -1 ,2 )",
            "5: c = 1.5",
            "5: c = -0.0",
            "5: c = 1e-3",
            "6: d = \"x y -- # z\"",
            "6: d = \"\"",
            "6: d = \"µ\"",
            "7: e = true",
            "7: e = false",
            "8: u",
            "8: u = ()",
            "8: u = ( )",
            "9: t = (1, (\"s\", true), 2.5)",
            "10: a_2 = 3",
            "11: f = (1, 2, 3, 4)",
        ];
        for l in fast {
            let got = inputs.event(l.as_bytes(), 7);
            assert!(got.is_some(), "{l} should take the fast path");
            let want = match parse_line_any(l, 7, &p) {
                Some(Ok(Read::Event(e))) => e,
                other => panic!("{l}: {other:?}"),
            };
            assert_eq!(got, Some(want), "{l}");
        }
        let general = [
            "",
            "# 1: a = 5",
            "-- 1: a = 5",
            "1: a = 5 # comment",
            "1: a = 5 -- comment",
            "1: a = 5 x",
            "1: a = 5\r",
            "1: a",
            "1: a =",
            "1 a = 5",
            ": a = 5",
            "-1: a = 5",
            "+1: a = 5",
            "1234567890123456789: a = 5",
            "1: zz = 5",
            "1: A = 5",
            "1: `a` = 5",
            "1: a = 1.5",
            "1: a = 007",
            "1: a = 0x1f",
            "1: a = 1 + 2",
            "1: a = 1234567890123456789",
            "1: a = \"5\"",
            "1: a = true",
            "1: c = 1",
            "1: d = 1",
            "1: d = \"a\\nb\"",
            "1: d = \"${1}\"",
            "1: d = \"50%\"",
            "1: e = 1",
            "1: e = trueish",
            "1: b = (1, 2, 3)",
            "1: b = (1)",
            "1: b = (1, 2",
            "1: b = {_1 = 1, _2 = 2}",
            "1: b = (1, 2.5)",
            "1: u = 5",
            "1: o = Some(1)",
            "1: o = None",
            "1: a = 5 = 6",
            "1: a == 5",
            "1 : a 5",
        ];
        for l in general {
            assert_eq!(inputs.event(l.as_bytes(), 1), None, "{l}");
        }
    }

    #[test]
    fn names_are_found_among_many_inputs() {
        let mut spec = String::new();
        for k in 0..40 {
            spec.push_str(&format!("in s{k}: Events[Int]\nout s{k}\n"));
        }
        let p = program(&spec);
        let inputs = Inputs::new(&p);
        for k in 0..40 {
            let l = format!("{k}: s{k} = {k}");
            let e = inputs.event(l.as_bytes(), 1);
            assert_eq!(e.map(|e| e.input), p.input_index(&format!("s{k}")), "{l}");
        }
        assert_eq!(inputs.event(b"1: s40 = 1", 1), None);
    }
}
