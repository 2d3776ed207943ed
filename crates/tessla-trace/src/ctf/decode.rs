//! The binary side of CTF 1.8: a stream file's packets (packet header, packet context) and its
//! events (event header, stream event context, event context, fields) decoded with the types of
//! [`super::tsdl`]. Integers of 1 to 64 bits at any bit alignment in either byte order, floats,
//! strings, enums, structs, arrays, sequences and tagged variants. Every read is bounds-checked
//! against the packet's content: bad data is an error naming the byte, never a panic.

use super::tsdl::{IntType, Len, Metadata, Order, Stream, StructType, Type};
use std::collections::HashMap;

/// The name of the event a packet starts with when the writer discarded events before it
/// (its `events_discarded` grew), as Trace Compass's reader names it; its fields are
/// `Lost events` (how many) and `duration` (to the packet's end).
pub const LOST_EVENT: &str = "Lost event";

/// A decoded value.
#[derive(Debug, Clone, PartialEq)]
pub enum Field {
    /// An integer of any size and sign the metadata allows.
    Int(i128),
    /// A floating-point number (32 or 64 bits).
    Float(f64),
    /// A null-terminated string.
    Str(String),
    /// The value and its label (none when no label's range holds it).
    Enum(i128, Option<String>),
    /// A struct's members by name, in declaration order.
    Struct(Vec<(String, Field)>),
    /// An array's or sequence's elements.
    Array(Vec<Field>),
    /// The chosen option's name and value.
    Variant(String, Box<Field>),
}

impl Field {
    /// The member at a dotted path of nested structs (variants are passed through, as a tag
    /// or length path may lead through one).
    pub fn get(&self, path: &str) -> Option<&Field> {
        let mut f = self;
        for part in path.split('.') {
            if let Field::Variant(_, inner) = f {
                f = inner;
            }
            let Field::Struct(fs) = f else { return None };
            f = fs.iter().find(|(n, _)| n == part).map(|(_, v)| v)?;
        }
        Some(f)
    }

    fn int(&self) -> Option<i128> {
        match self {
            Field::Int(i) | Field::Enum(i, _) => Some(*i),
            _ => None,
        }
    }
}

/// One decoded event.
#[derive(Debug, Clone, PartialEq)]
pub struct RawEvent {
    /// Index into `Metadata::events`; `None` for a [`LOST_EVENT`].
    pub decl: Option<usize>,
    /// The clock value (cycles), extended over the header's wrapping timestamp field.
    pub ts: u64,
    /// The stream's event header (id and timestamp), if the stream declares one.
    pub header: Option<Field>,
    /// The stream's per-event context, if declared.
    pub stream_context: Option<Field>,
    /// The event's own context, if its declaration has one.
    pub context: Option<Field>,
    /// The event's payload fields, if declared.
    pub fields: Option<Field>,
    /// The context of the packet the event is in.
    pub packet_context: Option<Field>,
}

/// Bits of one packet.
struct Bits<'a> {
    data: &'a [u8],
    /// Position in bits from the start of `data`.
    pos: u64,
    /// The end of the content, in bits.
    end: u64,
    big_endian: bool,
}

/// Why a stream file cannot be decoded further (the packet's offset is added by the caller).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// A value runs past the end of the packet's content.
    #[error("truncated: {bits} bits needed at byte {at}, the content ends at byte {end}")]
    Truncated {
        /// Bits the value needs.
        bits: u64,
        /// Where it starts (byte).
        at: u64,
        /// Where the content ends (byte).
        end: u64,
    },
    /// A packet header whose magic number is not CTF's.
    #[error("bad packet magic number {0:#x} (expected 0xc1fc1fc1)")]
    Magic(i128),
    /// A packet of a stream the metadata does not declare.
    #[error("packet of stream {0}, which the metadata does not declare")]
    UnknownStream(i128),
    /// A packet context whose sizes do not fit the file.
    #[error(
        "packet context: content size {content} bits, packet size {size} bits do not fit the {rest} bits left in the file"
    )]
    PacketSize {
        /// `content_size` (bits).
        content: i128,
        /// `packet_size` (bits).
        size: i128,
        /// Bits left in the file.
        rest: u64,
    },
    /// An event id the stream does not declare (`(none)` when it has none).
    #[error("event id {id} is not declared for stream {stream}")]
    UnknownEvent {
        /// The id read, or `(none)`.
        id: String,
        /// The stream's id.
        stream: u64,
    },
    /// An event that reads no bit.
    #[error("empty event `{0}`")]
    EmptyEvent(String),
    /// A value outside a packet.
    #[error("no packet")]
    NoPacket,
    /// A string without its terminating zero.
    #[error("string at byte {0} has no terminating zero before the end of the packet content")]
    Unterminated(usize),
    /// A sequence whose length field was not read before it.
    #[error("sequence length `{0}` is not an integer field read before")]
    NoLength(String),
    /// An array longer than the packet.
    #[error("array length {n} at byte {at} is more than the {left} bits left in the packet")]
    ArrayLength {
        /// The length read.
        n: i128,
        /// Where the array starts (byte).
        at: u64,
        /// Bits left in the packet.
        left: u64,
    },
    /// A variant whose tag value has no label.
    #[error("variant tag `{tag}` = {value} matches no label of its enum")]
    Unlabelled {
        /// The tag's path.
        tag: String,
        /// Its value.
        value: i128,
    },
    /// A variant whose tag is not an enum read before.
    #[error("variant tag `{0}` is not an enum field read before")]
    NoTag(String),
    /// A variant without the option its tag names.
    #[error("variant has no option `{label}` (tag `{tag}`)")]
    NoOption {
        /// The label the tag gave.
        label: String,
        /// The tag's path.
        tag: String,
    },
}

type R<T> = Result<T, DecodeError>;

impl Bits<'_> {
    fn align(&mut self, a: u32) -> R<()> {
        let a = u64::from(a.max(1));
        let p = self.pos.div_ceil(a).saturating_mul(a);
        if p > self.end {
            return Err(self.truncated(p - self.pos));
        }
        self.pos = p;
        Ok(())
    }

    fn truncated(&self, bits: u64) -> DecodeError {
        DecodeError::Truncated {
            bits,
            at: self.pos / 8,
            end: self.end / 8,
        }
    }

    fn bit(&self, p: u64, big: bool) -> u8 {
        let byte = self.data.get((p / 8) as usize).copied().unwrap_or(0);
        let k = (p % 8) as u8;
        if big {
            (byte >> (7 - k)) & 1
        } else {
            (byte >> k) & 1
        }
    }

    /// `n` bits (1 to 64) as an unsigned number.
    fn uint(&mut self, n: u32, order: Order) -> R<u64> {
        let n64 = u64::from(n);
        if self.pos.saturating_add(n64) > self.end {
            return Err(self.truncated(n64));
        }
        let big = match order {
            Order::Native => self.big_endian,
            Order::Be => true,
            Order::Le => false,
        };
        let mut v: u64 = 0;
        if self.pos.is_multiple_of(8) && n.is_multiple_of(8) {
            let start = (self.pos / 8) as usize;
            let bytes = self
                .data
                .get(start..start + (n / 8) as usize)
                .ok_or_else(|| self.truncated(n64))?;
            for (k, b) in bytes.iter().enumerate() {
                if big {
                    v = (v << 8) | u64::from(*b);
                } else {
                    v |= u64::from(*b) << (8 * k);
                }
            }
        } else if big {
            for i in 0..n64 {
                v = (v << 1) | u64::from(self.bit(self.pos + i, true));
            }
        } else {
            for i in 0..n64 {
                v |= u64::from(self.bit(self.pos + i, false)) << i;
            }
        }
        self.pos += n64;
        Ok(v)
    }

    fn int(&mut self, t: &IntType) -> R<i128> {
        self.align(t.align)?;
        let v = self.uint(t.size, t.order)?;
        Ok(
            if t.signed && t.size < 128 && (v >> (t.size - 1)) & 1 == 1 {
                i128::from(v) - (1i128 << t.size)
            } else {
                i128::from(v)
            },
        )
    }
}

/// Decodes the events of one stream file, packet by packet.
pub struct StreamDecoder<'a> {
    md: &'a Metadata,
    data: &'a [u8],
    /// Start of the current packet in bytes.
    packet_start: usize,
    bits: Option<Bits<'a>>,
    stream: Option<&'a Stream>,
    packet_context: Option<Field>,
    packet_header: Option<Field>,
    last_ts: u64,
    /// Partially decoded structs, innermost last, for sequence lengths and variant tags.
    scopes: Vec<Vec<(String, Field)>>,
    /// Completed scopes of the current event (`stream.event.header`, ...).
    done: Vec<(&'static str, Field)>,
    failed: bool,
    /// The scope being read (`event.fields`, ...).
    current: &'static str,
    /// The events of each stream, by id.
    ids: HashMap<u64, Vec<(u64, usize)>>,
    /// `events_discarded` of the previous packet.
    discarded: i128,
    /// The lost event the current packet starts with: how many, and the duration.
    lost: Option<(i128, u64)>,
}

impl<'a> StreamDecoder<'a> {
    /// A decoder of `data` (one stream file's bytes) by the types of `md`.
    pub fn new(md: &'a Metadata, data: &'a [u8]) -> StreamDecoder<'a> {
        StreamDecoder {
            md,
            data,
            packet_start: 0,
            bits: None,
            stream: None,
            packet_context: None,
            packet_header: None,
            last_ts: 0,
            scopes: Vec::new(),
            done: Vec::new(),
            failed: false,
            current: "",
            ids: md
                .events
                .iter()
                .enumerate()
                .fold(HashMap::new(), |mut m, (i, e)| {
                    m.entry(e.stream_id).or_default().push((e.id, i));
                    m
                }),
            discarded: 0,
            lost: None,
        }
    }

    /// The byte offset where the current packet starts (for messages).
    pub fn packet_offset(&self) -> usize {
        self.packet_start
    }

    /// The next event, `None` at the end of the file; after an error, `None`.
    pub fn next_event(&mut self) -> Option<R<RawEvent>> {
        if self.failed {
            return None;
        }
        let r = self.next_inner();
        if !matches!(r, Some(Ok(_))) {
            self.failed = true;
        }
        r
    }

    fn next_inner(&mut self) -> Option<R<RawEvent>> {
        loop {
            match &self.bits {
                Some(b) if b.pos < b.end => {
                    if let Some((count, duration)) = self.lost.take() {
                        return Some(Ok(self.lost_event(count, duration)));
                    }
                    return Some(self.event());
                }
                Some(_) => {
                    let size = self.packet_size();
                    self.bits = None;
                    self.packet_start = self.packet_start.saturating_add(size);
                }
                None => {
                    if self.packet_start >= self.data.len() {
                        return None;
                    }
                    if let Err(e) = self.open_packet() {
                        return Some(Err(e));
                    }
                }
            }
        }
    }

    /// The packet's size in bytes (`packet_size` of its context; the rest of the file without).
    fn packet_size(&self) -> usize {
        let rest = self.data.len().saturating_sub(self.packet_start);
        match self
            .packet_context
            .as_ref()
            .and_then(|c| c.get("packet_size"))
            .and_then(Field::int)
        {
            Some(bits) => usize::try_from(bits / 8).unwrap_or(rest).max(1),
            None => rest,
        }
    }

    fn open_packet(&mut self) -> R<()> {
        let data = self.data.get(self.packet_start..).unwrap_or_default();
        self.bits = Some(Bits {
            data,
            pos: 0,
            end: (data.len() as u64).saturating_mul(8),
            big_endian: self.md.big_endian,
        });
        self.done.clear();
        self.packet_header = match &self.md.packet_header {
            Some(t) => Some(self.read(t, "trace.packet.header")?),
            None => None,
        };
        if let Some(h) = &self.packet_header {
            if let Some(m) = h.get("magic").and_then(Field::int)
                && m != 0xC1FC_1FC1
            {
                return Err(DecodeError::Magic(m));
            }
            self.done.push(("trace.packet.header", h.clone()));
        }
        let sid = self
            .packet_header
            .as_ref()
            .and_then(|h| h.get("stream_id"))
            .and_then(Field::int)
            .unwrap_or(0);
        let stream = self.md.streams.iter().find(|s| i128::from(s.id) == sid);
        let stream = match stream {
            Some(s) => Some(s),
            None if self.md.streams.is_empty() && sid == 0 => None,
            None => {
                return Err(DecodeError::UnknownStream(sid));
            }
        };
        self.stream = stream;
        self.packet_context = match stream.and_then(|s| s.packet_context.as_ref()) {
            Some(t) => Some(self.read(t, "stream.packet.context")?),
            None => None,
        };
        let rest = (data.len() as u64).saturating_mul(8);
        if let Some(c) = &self.packet_context {
            let int = |k| c.get(k).and_then(Field::int);
            let content = int("content_size").or_else(|| int("packet_size"));
            let size = int("packet_size").or(content);
            if let (Some(content), Some(size)) = (content, size) {
                let pos = self.bits.as_ref().map_or(0, |b| b.pos);
                if content < i128::from(pos)
                    || size < content
                    || size > i128::from(rest)
                    || size % 8 != 0
                {
                    return Err(DecodeError::PacketSize {
                        content,
                        size,
                        rest,
                    });
                }
                if let Some(b) = &mut self.bits {
                    b.end = u64::try_from(content).unwrap_or(0);
                }
            }
            self.last_ts = int("timestamp_begin")
                .and_then(|t| u64::try_from(t).ok())
                .unwrap_or(0);
            if let Some(d) = int("events_discarded") {
                let lost = d - self.discarded;
                self.discarded = d;
                let end = int("timestamp_end").and_then(|t| u64::try_from(t).ok());
                if lost > 0 {
                    let duration = end.map_or(0, |e| e.saturating_sub(self.last_ts));
                    self.lost = Some((lost, duration));
                }
            }
            self.done.push(("stream.packet.context", c.clone()));
        }
        Ok(())
    }

    fn event(&mut self) -> R<RawEvent> {
        let start = self.bits.as_ref().map_or(0, |b| b.pos);
        self.done.truncate(
            usize::from(self.packet_header.is_some()) + usize::from(self.packet_context.is_some()),
        );
        let stream = self.stream;
        let header = match stream.and_then(|s| s.event_header.as_ref()) {
            Some(t) => Some(self.read(t, "stream.event.header")?),
            None => None,
        };
        let (mut id, mut ts) = (None, None);
        if let Some(h) = &header {
            let field = |f: &Field, k: &str| f.get(k).cloned();
            id = field(h, "id").and_then(|f| f.int());
            ts = field(h, "timestamp");
            if let Some(Field::Variant(_, v)) = h.get("v") {
                if let Some(i) = v.get("id").and_then(Field::int) {
                    id = Some(i);
                }
                if let Some(t) = v.get("timestamp") {
                    ts = Some(t.clone());
                }
            }
            self.done.push(("stream.event.header", h.clone()));
        }
        if let Some(Field::Int(t)) = ts {
            let bits = self.timestamp_bits(header.as_ref());
            let t = u64::try_from(t).unwrap_or(0);
            self.last_ts = if bits >= 64 {
                t
            } else {
                let mask = (1u64 << bits) - 1;
                let mut v = (self.last_ts & !mask) | t;
                if v < self.last_ts {
                    v = v.wrapping_add(1u64 << bits);
                }
                v
            };
        }
        let sid = stream.map_or(0, |s| s.id);
        let in_stream = self.ids.get(&sid).map_or(&[][..], Vec::as_slice);
        let decl = match id {
            Some(id) => in_stream
                .iter()
                .find(|(e, _)| i128::from(*e) == id)
                .map(|(_, i)| *i),
            None if in_stream.len() == 1 => in_stream.first().map(|(_, i)| *i),
            None => None,
        };
        let Some((decl, d)) = decl.and_then(|i| Some((i, self.md.events.get(i)?))) else {
            return Err(DecodeError::UnknownEvent {
                id: id.map_or_else(|| "(none)".to_string(), |i| i.to_string()),
                stream: sid,
            });
        };
        let stream_context = match stream.and_then(|s| s.event_context.as_ref()) {
            Some(t) => {
                let f = self.read(t, "stream.event.context")?;
                self.done.push(("stream.event.context", f.clone()));
                Some(f)
            }
            None => None,
        };
        let context = match &d.context {
            Some(t) => {
                let f = self.read(t, "event.context")?;
                self.done.push(("event.context", f.clone()));
                Some(f)
            }
            None => None,
        };
        let fields = match &d.fields {
            Some(t) => Some(self.read(t, "event.fields")?),
            None => None,
        };
        if self.bits.as_ref().map_or(0, |b| b.pos) == start {
            return Err(DecodeError::EmptyEvent(d.name.clone()));
        }
        Ok(RawEvent {
            decl: Some(decl),
            ts: self.last_ts,
            header,
            stream_context,
            context,
            fields,
            packet_context: self.packet_context.clone(),
        })
    }

    fn lost_event(&self, count: i128, duration: u64) -> RawEvent {
        RawEvent {
            decl: None,
            ts: self.last_ts,
            header: None,
            stream_context: None,
            context: None,
            fields: Some(Field::Struct(vec![
                ("Lost events".into(), Field::Int(count)),
                ("duration".into(), Field::Int(i128::from(duration))),
            ])),
            packet_context: self.packet_context.clone(),
        }
    }

    /// The size of the event header's timestamp field (64 when not found).
    fn timestamp_bits(&self, header: Option<&Field>) -> u32 {
        fn find(t: &Type, sel: Option<&Field>) -> Option<u32> {
            match t {
                Type::Struct(s) => s.fields.iter().find_map(|(n, ft)| match (n.as_str(), ft) {
                    ("timestamp", Type::Int(i)) => Some(i.size),
                    ("v", Type::Variant { options, .. }) => {
                        let chosen = match sel.and_then(|h| h.get("v")) {
                            Some(Field::Variant(name, _)) => name.clone(),
                            _ => return None,
                        };
                        options
                            .iter()
                            .find(|(o, _)| *o == chosen)
                            .and_then(|(_, ot)| find(ot, None))
                    }
                    _ => None,
                }),
                _ => None,
            }
        }
        self.stream
            .and_then(|s| s.event_header.as_ref())
            .and_then(|t| find(t, header))
            .unwrap_or(64)
    }

    /// Read a scope's top type.
    /// Read a scope's top type; `scope` is its absolute name (`event.fields`), for length and
    /// tag paths that name it.
    fn read(&mut self, t: &Type, scope: &'static str) -> R<Field> {
        self.scopes.clear();
        self.current = scope;
        self.value(t)
    }

    fn lookup(&self, path: &str) -> Option<i128> {
        let f = self.lookup_field(path)?;
        f.int()
    }

    fn lookup_field(&self, path: &str) -> Option<&Field> {
        if let Some(rest) = path
            .strip_prefix(self.current)
            .and_then(|r| r.strip_prefix('.'))
        {
            let (head, tail) = rest.split_once('.').unwrap_or((rest, ""));
            let (_, f) = self.scopes.first()?.iter().find(|(n, _)| n == head)?;
            return if tail.is_empty() {
                Some(f)
            } else {
                f.get(tail)
            };
        }
        for (scope, f) in self.done.iter().rev() {
            if let Some(rest) = path.strip_prefix(scope).and_then(|r| r.strip_prefix('.')) {
                return f.get(rest);
            }
        }
        let (head, rest) = path.split_once('.').unwrap_or((path, ""));
        for scope in self.scopes.iter().rev() {
            if let Some((_, f)) = scope.iter().find(|(n, _)| n == head) {
                return if rest.is_empty() {
                    Some(f)
                } else {
                    f.get(rest)
                };
            }
        }
        None
    }

    fn value(&mut self, t: &Type) -> R<Field> {
        let Some(b) = self.bits.as_mut() else {
            return Err(DecodeError::NoPacket);
        };
        match t {
            Type::Int(i) => Ok(Field::Int(b.int(i)?)),
            Type::Enum(i, labels) => {
                let v = b.int(i)?;
                let label = labels
                    .iter()
                    .find(|(_, lo, hi)| *lo <= v && v <= *hi)
                    .map(|(l, _, _)| l.clone());
                Ok(Field::Enum(v, label))
            }
            Type::Float {
                exp, align, order, ..
            } => {
                b.align(*align)?;
                if *exp == 8 {
                    Ok(Field::Float(f64::from(f32::from_bits(
                        b.uint(32, *order)? as u32
                    ))))
                } else {
                    Ok(Field::Float(f64::from_bits(b.uint(64, *order)?)))
                }
            }
            Type::Str => {
                b.align(8)?;
                let start = (b.pos / 8) as usize;
                let end = (b.end / 8) as usize;
                let bytes = b.data.get(start..end).unwrap_or_default();
                let Some(n) = bytes.iter().position(|&c| c == 0) else {
                    return Err(DecodeError::Unterminated(start));
                };
                b.pos += (n as u64 + 1) * 8;
                Ok(Field::Str(
                    String::from_utf8_lossy(&bytes[..n]).into_owned(),
                ))
            }
            Type::Struct(s) => self.strukt(s),
            Type::Array(elem, len) => {
                let n = match len {
                    Len::Fixed(n) => i128::from(*n),
                    Len::Field(p) => self
                        .lookup(p)
                        .ok_or_else(|| DecodeError::NoLength(p.to_string()))?,
                };
                let (pos, left) = self
                    .bits
                    .as_ref()
                    .map_or((0, 0), |b| (b.pos, b.end.saturating_sub(b.pos)));
                if n < 0 || n > i128::from(left) {
                    return Err(DecodeError::ArrayLength {
                        n,
                        at: pos / 8,
                        left,
                    });
                }
                let mut items = Vec::new();
                for _ in 0..n {
                    items.push(self.value(elem)?);
                }
                Ok(Field::Array(items))
            }
            Type::Variant { tag, options } => {
                let label = match self.lookup_field(tag) {
                    Some(Field::Enum(_, Some(l))) => l.clone(),
                    Some(Field::Enum(v, None)) => {
                        return Err(DecodeError::Unlabelled {
                            tag: tag.to_string(),
                            value: *v,
                        });
                    }
                    _ => {
                        return Err(DecodeError::NoTag(tag.to_string()));
                    }
                };
                let Some((name, ot)) = options.iter().find(|(n, _)| *n == label) else {
                    return Err(DecodeError::NoOption {
                        label,
                        tag: tag.to_string(),
                    });
                };
                let v = self.value(ot)?;
                Ok(Field::Variant(name.clone(), Box::new(v)))
            }
        }
    }

    fn strukt(&mut self, s: &StructType) -> R<Field> {
        if let Some(b) = self.bits.as_mut() {
            b.align(s.align.max(max_align(s)))?;
        }
        self.scopes.push(Vec::new());
        for (name, t) in &s.fields {
            let v = match self.value(t) {
                Ok(v) => v,
                Err(e) => {
                    self.scopes.pop();
                    return Err(e);
                }
            };
            if let Some(top) = self.scopes.last_mut() {
                top.push((name.clone(), v));
            }
        }
        Ok(Field::Struct(self.scopes.pop().unwrap_or_default()))
    }
}

/// A struct's alignment: the largest of its fields'.
fn max_align(s: &StructType) -> u32 {
    fn align(t: &Type) -> u32 {
        match t {
            Type::Int(i) | Type::Enum(i, _) => i.align,
            Type::Float { align, .. } => *align,
            Type::Str => 8,
            Type::Struct(s) => s.align.max(max_align(s)),
            Type::Array(e, _) => align(e),
            Type::Variant { .. } => 1,
        }
    }
    s.fields.iter().map(|(_, t)| align(t)).max().unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ctf::tsdl;

    fn decode_all(metadata: &str, data: &[u8]) -> (Vec<RawEvent>, Option<String>) {
        let md = tsdl::parse(metadata).unwrap();
        let mut d = StreamDecoder::new(&md, data);
        let (mut events, mut error) = (Vec::new(), None);
        while let Some(e) = d.next_event() {
            match e {
                Ok(e) => events.push(e),
                Err(e) => error = Some(e.to_string()),
            }
        }
        (events, error)
    }

    const BITS: &str = "
        typealias integer { size = 3; align = 1; signed = false; } := u3;
        typealias integer { size = 5; align = 1; signed = true; } := s5;
        typealias integer { size = 12; align = 1; signed = false; } := u12;
        typealias integer { size = 16; align = 8; signed = true; byte_order = le; } := s16le;
        trace { major = 1; minor = 8; byte_order = ORDER; };
        event { name = \"e\"; fields := struct { u3 a; s5 b; u12 c; s16le d; }; };";

    /// Bit fields packed from the most significant bit (big-endian) or the least, signed
    /// values sign-extended, a byte-order override, alignment padding.
    #[test]
    fn bit_fields_in_both_byte_orders() {
        let want = Field::Struct(vec![
            ("a".into(), Field::Int(5)),
            ("b".into(), Field::Int(-3)),
            ("c".into(), Field::Int(0xABC)),
            ("d".into(), Field::Int(-2)),
        ]);
        for (order, data) in [
            ("be", [0xBD, 0xAB, 0xC0, 0xFE, 0xFF]),
            ("le", [0xED, 0xBC, 0x0A, 0xFE, 0xFF]),
        ] {
            let (events, error) = decode_all(&BITS.replace("ORDER", order), &data);
            assert_eq!(error, None, "{order}");
            assert_eq!(events.len(), 1, "{order}");
            assert_eq!(events[0].fields.as_ref(), Some(&want), "{order}");
        }
        // One byte short: an error naming the place, not a panic.
        let (events, error) = decode_all(&BITS.replace("ORDER", "le"), &[0xED, 0xBC, 0x0A, 0xFE]);
        assert!(events.is_empty());
        assert_eq!(
            error.as_deref(),
            Some("truncated: 16 bits needed at byte 3, the content ends at byte 4")
        );
    }

    /// Sequence lengths and variant tags by relative and absolute paths, into the current
    /// struct, an enclosing one, or a scope read before (the stream event context).
    #[test]
    fn lengths_and_tags_by_path() {
        let md = "
            typealias integer { size = 8; align = 8; signed = false; } := u8;
            trace { major = 1; minor = 8; byte_order = le; };
            stream { event.context := struct { u8 ctxlen; }; };
            event { name = \"e\"; fields := struct {
                u8 n;
                enum : u8 { none, num } tag;
                struct { u8 a[event.fields.n]; u8 b[n]; u8 c[stream.event.context.ctxlen]; } inner;
                variant <event.fields.tag> { struct { } none; u8 num; } v;
                variant <tag> { struct { } none; struct { u8 x; u8 y[x]; } num; } w;
            }; };";
        // ctxlen, n, tag, inner.a, inner.b, inner.c, v, w.x, w.y
        let data = [1, 2, 1, 10, 20, 30, 40, 99, 1, 2, 5, 6];
        let (events, error) = decode_all(md, &data);
        assert_eq!(error, None);
        let f = events[0].fields.as_ref().unwrap();
        let ints = |path: &str| match f.get(path) {
            Some(Field::Array(v)) => v.iter().filter_map(Field::int).collect::<Vec<_>>(),
            other => panic!("{path}: {other:?}"),
        };
        assert_eq!(ints("inner.a"), [10, 20]);
        assert_eq!(ints("inner.b"), [30, 40]);
        assert_eq!(ints("inner.c"), [99]);
        assert_eq!(
            f.get("v"),
            Some(&Field::Variant("num".into(), Box::new(Field::Int(1))))
        );
        assert_eq!(ints("w.y"), [5, 6]);
        assert_eq!(f.get("w.x"), Some(&Field::Int(2)));
    }

    /// Random bytes under a metadata with every kind of type, and random edits of metadata
    /// text: errors or events, never a panic or a hang.
    #[test]
    fn garbage_never_panics() {
        let metadata = "
            typealias integer { size = 8; align = 8; signed = false; } := uint8_t;
            typealias integer { size = 32; align = 8; signed = false; byte_order = be; } := u32;
            typealias integer { size = 7; align = 1; signed = true; } := s7;
            typealias floating_point { exp_dig = 8; mant_dig = 24; align = 32; } := float;
            trace { major = 1; minor = 8; byte_order = le;
              packet.header := struct { u32 magic; uint8_t stream_id; }; };
            stream { id = 0;
              packet.context := struct { u32 content_size; u32 packet_size; };
              event.header := struct { enum : uint8_t { a = 0, b = 1 } id; variant <id> { uint8_t a; u32 b; } v; }; };
            event { name = \"x\"; id = 0; fields := struct { string s; s7 n; float f; uint8_t len; s7 seq[len]; }; };
            event { name = \"y\"; id = 1; fields := struct { enum : uint8_t { p, q } tag; variant <tag> { string p; struct { uint8_t z; } q; } v; uint8_t arr[3]; }; };";
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        for _ in 0..3000 {
            let len = (next() % 96) as usize;
            let mut data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            // Often a plausible header, so decoding gets past the magic number.
            if next() % 2 == 0 && data.len() > 13 {
                data[..4].copy_from_slice(&0xC1FC_1FC1u32.to_be_bytes());
                data[4] = 0;
                let bits = (data.len() as u32) * 8;
                data[5..9].copy_from_slice(&bits.to_be_bytes());
                data[9..13].copy_from_slice(&bits.to_be_bytes());
            }
            let _ = decode_all(metadata, &data);
        }
        let chars: Vec<char> = metadata.chars().collect();
        for _ in 0..3000 {
            let mut text = chars.clone();
            for _ in 0..(next() % 4 + 1) {
                let i = (next() as usize) % text.len();
                match next() % 3 {
                    0 => {
                        text.remove(i);
                    }
                    1 => text.insert(
                        i,
                        ['{', '}', ';', '<', '"', '9', 'x', '['][(next() % 8) as usize],
                    ),
                    _ => text.truncate(i),
                }
                if text.is_empty() {
                    break;
                }
            }
            let text: String = text.into_iter().collect();
            if let Ok(md) = tsdl::parse(&text) {
                let data: Vec<u8> = (0..64).map(|_| next() as u8).collect();
                let mut d = StreamDecoder::new(&md, &data);
                while let Some(Ok(_)) = d.next_event() {}
            }
        }
    }
}
