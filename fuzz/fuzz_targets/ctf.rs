//! Fuzz target: the CTF trace reader of `trace --ctf` (tessla-trace's `ctf` module). The input is
//! a trace folded into one buffer: two bytes (little endian) giving the length of the `metadata`
//! file, that file (TSDL text or metadata packets), then one data stream file. Metadata bytes go
//! through `metadata_text` and the TSDL parser; when they parse, the stream is decoded event by
//! event (at most 10,000 events) and each event's fields are looked up by a few of the key forms
//! `CTF.getInt`/`CTF.getString` take. Checks: no panic, no hang, no runaway allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessla_telegraf::trace::ctf::{decode::StreamDecoder, tsdl};

fuzz_target!(|data: &[u8]| {
    let Some((len, rest)) = data.split_first_chunk::<2>() else {
        return;
    };
    let len = usize::from(u16::from_le_bytes(*len)).min(rest.len());
    let (metadata, stream) = rest.split_at(len);
    let Ok(text) = tsdl::metadata_text(metadata) else {
        return;
    };
    let Ok(md) = tsdl::parse(&text) else {
        return;
    };
    let mut decoder = StreamDecoder::new(&md, stream);
    for _ in 0..10_000 {
        match decoder.next_event() {
            Some(Ok(event)) => {
                if let Some(fields) = &event.fields {
                    for key in ["value", "a.b", "_str"] {
                        let _ = fields.get(key);
                    }
                }
            }
            Some(Err(_)) | None => break,
        }
    }
});
