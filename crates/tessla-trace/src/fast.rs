//! The fast path of the text trace reader: an event line `TS: name = value` whose value is a
//! plain literal of the input's declared type, read from the line's bytes straight into an
//! [`Event`]: no copy of the line, no pass for UTF-8 over it, no expression parser, no value
//! built only to be checked against the type, and the input found by its name's first eight
//! bytes taken as one word, instead of comparing the name with every input's name.
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

/// The inputs of a program by name: an open-addressing table keyed by a name's first eight
/// bytes (as one word) and its length, so that a name of up to eight bytes is found and
/// checked by comparing two words, without hashing it byte by byte or calling `memcmp`.
pub(crate) struct Inputs<'p> {
    program: &'p Program,
    /// A power of two long.
    slots: Vec<Slot>,
    /// 64 - log2(slots.len()): the top bits of the mixed key pick the slot.
    shift: u32,
}

#[derive(Clone, Copy, Default)]
struct Slot {
    /// The name's first eight bytes, little-endian, zero-padded.
    key: u64,
    len: usize,
    /// Input index + 1; 0 for an empty slot.
    id: usize,
}

/// The bytes of a plain name (`[A-Za-z0-9_]`), by table.
static NAME_BYTE: [bool; 256] = {
    let mut t = [false; 256];
    let mut c = 0;
    while c < 256 {
        let b = c as u8;
        t[c] = b.is_ascii_alphanumeric() || b == b'_';
        c += 1;
    }
    t
};

/// The first eight bytes of `name`, little-endian, zero-padded.
#[inline(always)]
fn key_of(name: &[u8]) -> u64 {
    name.iter()
        .take(8)
        .enumerate()
        .fold(0, |k, (i, &b)| k | u64::from(b) << (8 * i))
}

impl<'p> Inputs<'p> {
    pub(crate) fn new(program: &'p Program) -> Inputs<'p> {
        let n = program.inputs.len();
        let len = (2 * n).next_power_of_two().max(8);
        let mut table = Inputs {
            program,
            slots: vec![Slot::default(); len],
            shift: 64 - len.trailing_zeros(),
        };
        for (k, input) in program.inputs.iter().enumerate() {
            let name = input.name.as_bytes();
            // The first of two inputs of one name wins, as `Program::input_index`.
            if table.find(name, key_of(name)).is_some() {
                continue;
            }
            let mut at = table.home(key_of(name), name.len());
            while let Some(s) = table.slots.get_mut(at) {
                if s.id == 0 {
                    *s = Slot {
                        key: key_of(name),
                        len: name.len(),
                        id: k + 1,
                    };
                    break;
                }
                at = (at + 1) & (len - 1);
            }
        }
        table
    }

    /// The first slot to look in for a name.
    #[inline(always)]
    fn home(&self, key: u64, len: usize) -> usize {
        ((key ^ len as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> self.shift) as usize
    }

    /// The index of the input named `name`, whose first eight bytes are `key`.
    #[inline]
    fn find(&self, name: &[u8], key: u64) -> Option<usize> {
        let mask = self.slots.len() - 1;
        let mut at = self.home(key, name.len());
        loop {
            let s = *self.slots.get(at)?;
            if s.id == 0 {
                return None;
            }
            if s.key == key && s.len == name.len() {
                let input = s.id - 1;
                // Longer names: the rest compared too.
                if name.len() <= 8
                    || self.program.inputs.get(input)?.name.as_bytes().get(8..) == name.get(8..)
                {
                    return Some(input);
                }
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
        // The name: a plain identifier.
        let name_at = p.i;
        while raw.get(p.i).is_some_and(|&c| NAME_BYTE[usize::from(c)]) {
            p.i += 1;
        }
        let n = p.i - name_at;
        if n == 0 {
            return None;
        }
        let key = match raw.get(name_at..name_at + 8) {
            // One load: the bytes after the name masked off.
            Some(&[a, b, c, d, e, f, g, h]) => {
                let word = u64::from_le_bytes([a, b, c, d, e, f, g, h]);
                if n >= 8 {
                    word
                } else {
                    word & ((1u64 << (8 * n)) - 1)
                }
            }
            _ => key_of(raw.get(name_at..p.i)?),
        };
        let input = self.find(raw.get(name_at..p.i)?, key)?;
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
        // Names of eight bytes and more, alike in their first eight, and at the line's end.
        let p = program(
            "in temperat: Events[Unit]\nin temperature_1: Events[Int]\n\
             in temperature_2: Events[Int]\nin t: Events[Unit]\n\
             out temperat\nout temperature_1\nout temperature_2\nout t",
        );
        let inputs = Inputs::new(&p);
        for (l, want) in [
            ("1: temperat", Some(0)),
            ("1: temperat = ()", Some(0)),
            ("1: temperature_1 = 5", Some(1)),
            ("1: temperature_2 = 5", Some(2)),
            ("1: t", Some(3)),
            ("1:t", Some(3)),
            ("1: temperature_3 = 5", None),
            ("1: temperature_ = 5", None),
            ("1: temperatu = 5", None),
            ("1: tempera", None),
            ("1: te", None),
        ] {
            assert_eq!(inputs.event(l.as_bytes(), 1).map(|e| e.input), want, "{l}");
        }
    }
}
