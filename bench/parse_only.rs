//! The parser's ceiling for `make bench`: stdin cut into records and parsed exactly as
//! `tessla-telegraf run` does (crates/lineproto: `RecordSplitter` on 64 KiB reads, then
//! `parse_record_into` with one reused metric), with nothing evaluated or written but the counts
//! at the end.
//!
//! Run: `cargo run --release --example parse_only < FILE` prints `records metrics fields errors`.

use lineproto::{Metric, RecordSplitter, parse_record_into};
use std::io::Read;

fn main() {
    let mut stdin = std::io::stdin().lock();
    let mut splitter = RecordSplitter::default();
    let mut buf = vec![0u8; 64 * 1024];
    let (mut records, mut metrics, mut fields, mut errors) = (0u64, 0u64, 0u64, 0u64);
    let mut m = Metric::default();
    let mut count = |rec: &lineproto::Record| {
        records += 1;
        match parse_record_into(&rec.bytes, &mut m) {
            Ok(true) => {
                metrics += 1;
                fields += m.fields.len() as u64;
            }
            Ok(false) => {}
            Err(_) => errors += 1,
        }
    };
    loop {
        let n = match stdin.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                eprintln!("parse_only: read error: {e}");
                std::process::exit(3);
            }
        };
        splitter.push(buf.get(..n).unwrap_or_default());
        while let Some(rec) = splitter.next_record() {
            count(&rec);
        }
    }
    while let Some(rec) = splitter.finish() {
        count(&rec);
    }
    println!("{records} {metrics} {fields} {errors}");
}
