//! Logging to stderr in the form Telegraf's execd plugin understands.
//!
//! Owns: the level prefixes (`E! `, `W! `, `I! `, `D! `: `processors.execd` maps them to its log
//! levels since Telegraf 1.37.0; older versions log every stderr line, the summary included, as an
//! error `stderr: "<line>"`), the `--log-level` filter (a default run writes only the summary),
//! the line cap, masking the login of any URL in a line ([`mask`]: no secret reaches a log), and rate limiting of repeated warnings: each kind of warning is printed the
//! first 10 times, then once per 1000 occurrences with the running count.
//!
//! The cap: Telegraf reads the child's stderr with a `bufio.Scanner` of the default 64 KiB
//! buffer. A longer line does not just get dropped: the scanner fails and Telegraf stops reading
//! stderr for good, so once the pipe fills every later write here would block the monitor. Every
//! line is therefore cut (on a char boundary) to at most [`MAX_LINE`] bytes plus the prefix and the
//! truncation mark, well under 64 KiB.

use std::collections::HashMap;
use std::io::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU8, Ordering};

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
#[repr(u8)]
pub enum Level {
    Error,
    Warn,
    #[default]
    Info,
    Debug,
}

/// The `--log-level` filter, as `Level as u8`: read on every message, so an atomic, not a lock.
static LEVEL: AtomicU8 = AtomicU8::new(Level::Info as u8);
static COUNTS: Mutex<Option<HashMap<&'static str, u64>>> = Mutex::new(None);

/// Longest message text of one stderr line, in bytes (see the module doc).
pub const MAX_LINE: usize = 60 * 1024;

pub fn set_level(level: Level) {
    LEVEL.store(level as u8, Ordering::Relaxed);
}

/// Whether a message at `level` passes the `--log-level` filter: the macros ask this before they
/// format anything.
#[inline]
pub fn enabled(level: Level) -> bool {
    level as u8 <= LEVEL.load(Ordering::Relaxed)
}

/// Print one message at `level` if the filter lets it pass (every line of a multi-line message
/// gets the prefix). The message is already built: prefer [`log_error!`](crate::log_error) and
/// its siblings, which format only a message that will be printed.
pub fn log(level: Level, msg: &str) {
    if !enabled(level) {
        return;
    }
    // A URL in a message never shows its password (the book, "Security").
    let masked;
    let msg = if msg.contains(":/") && msg.contains('@') {
        masked = crate::log::mask(msg);
        masked.as_str()
    } else {
        msg
    };
    let _ = std::io::stderr()
        .lock()
        .write_all(format(level, msg).as_bytes());
}

/// Log at a [`Level`] given as a value: checks the level first, formats the
/// [`format!`] arguments only when the message will be printed.
///
/// ```
/// tessla_telegraf::log_at!(tessla_telegraf::log::Level::Debug, "not built at {}", "info");
/// ```
#[macro_export]
macro_rules! log_at {
    ($level:expr, $($arg:tt)+) => {{
        let level: $crate::log::Level = $level;
        if $crate::log::enabled(level) {
            $crate::log::log(level, &::std::format!($($arg)+));
        }
    }};
}

/// An `E! ` line: `log_error!("{x} failed")`, formatted only if errors are shown.
#[macro_export]
macro_rules! log_error {
    ($($arg:tt)+) => {
        if $crate::log::enabled($crate::log::Level::Error) {
            $crate::log::log($crate::log::Level::Error, &::std::format!($($arg)+));
        }
    };
}

/// A `W! ` line: `log_warn!("{x} skipped")`, formatted only if warnings are shown.
#[macro_export]
macro_rules! log_warn {
    ($($arg:tt)+) => {
        if $crate::log::enabled($crate::log::Level::Warn) {
            $crate::log::log($crate::log::Level::Warn, &::std::format!($($arg)+));
        }
    };
}

/// An `I! ` line: `log_info!("{x} loaded")`, formatted only if info is shown.
#[macro_export]
macro_rules! log_info {
    ($($arg:tt)+) => {
        if $crate::log::enabled($crate::log::Level::Info) {
            $crate::log::log($crate::log::Level::Info, &::std::format!($($arg)+));
        }
    };
}

/// A `D! ` line: `log_debug!("{x}")`, formatted only with `--log-level debug`.
#[macro_export]
macro_rules! log_debug {
    ($($arg:tt)+) => {
        if $crate::log::enabled($crate::log::Level::Debug) {
            $crate::log::log($crate::log::Level::Debug, &::std::format!($($arg)+));
        }
    };
}

/// The stderr text of one message: each line prefixed, cut (on a char boundary) to stay under
/// the 64 KiB line Telegraf's stderr reader can take.
fn format(level: Level, msg: &str) -> String {
    let prefix = match level {
        Level::Error => "E! ",
        Level::Warn => "W! ",
        Level::Info => "I! ",
        Level::Debug => "D! ",
    };
    let mut out = String::with_capacity(msg.len() + 8);
    for line in msg.lines() {
        let mut end = line.len().min(MAX_LINE);
        while !line.is_char_boundary(end) {
            end -= 1;
        }
        out.push_str(prefix);
        out.push_str(&line[..end]);
        if end < line.len() {
            out.push_str(" …(truncated)");
        }
        out.push('\n');
    }
    out
}

/// A warning of kind `kind`, rate-limited per kind. Returns whether it was printed.
pub fn warn_limited(kind: &'static str, msg: impl FnOnce() -> String) -> bool {
    limited(Level::Warn, kind, msg)
}

/// An error of kind `kind`, rate-limited per kind as [`warn_limited`] is.
pub fn error_limited(kind: &'static str, msg: impl FnOnce() -> String) -> bool {
    limited(Level::Error, kind, msg)
}

/// A message at `level` of kind `kind`: the first ten, then every thousandth with the count.
fn limited(level: Level, kind: &'static str, msg: impl FnOnce() -> String) -> bool {
    let n = match COUNTS.lock() {
        Ok(mut c) => {
            let n = c.get_or_insert_with(HashMap::new).entry(kind).or_insert(0);
            *n += 1;
            *n
        }
        Err(_) => 1,
    };
    if n <= 10 {
        log_at!(level, "{}", msg());
        if n == 10 {
            log_at!(
                level,
                "{kind}: further messages of this kind are rate-limited"
            );
        }
        true
    } else if n % 1000 == 0 {
        log_at!(level, "{kind}: {n} so far; latest: {}", msg());
        true
    } else {
        false
    }
}

/// `text` with the user-info of every `scheme://USERINFO@` (or `scheme:/USERINFO@`) replaced: `USER:***@`, or `***@`
/// for a token. For anything shown to a person (messages, logs) that may hold a URL.
pub fn mask(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    // `scheme:/` too: a path that went through normalisation loses one of the two slashes.
    while let Some(i) = rest.find(":/") {
        let slashes = rest[i + 1..].bytes().take_while(|&b| b == b'/').count();
        let (head, tail) = rest.split_at(i + 1 + slashes);
        out.push_str(head);
        // The authority ends at the first `/`, `?`, `#` or white space; its user-info at its
        // last `@`.
        let end = tail
            .find(|c: char| {
                c == '/'
                    || c == '?'
                    || c == '#'
                    || c.is_whitespace()
                    || c == '\''
                    || c == '"'
                    || c == '`'
            })
            .unwrap_or(tail.len());
        let authority = &tail[..end];
        match authority.rfind('@') {
            Some(at) => {
                let info = &authority[..at];
                match info.split_once(':') {
                    Some((user, _)) => {
                        out.push_str(user);
                        out.push_str(":***");
                    }
                    None => out.push_str("***"),
                }
                out.push_str(&authority[at..]);
            }
            None => out.push_str(authority),
        }
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

/// `s` at most `max` bytes long, cut at a character boundary and followed by "… (N bytes)" when
/// longer: a warning about a 1 MB value stays one readable line.
pub fn cut(s: &str, max: usize) -> std::borrow::Cow<'_, str> {
    if s.len() <= max {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    std::borrow::Cow::Owned(format!("{}… ({} bytes)", &s[..end], s.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_line_is_prefixed() {
        assert_eq!(format(Level::Warn, "a\nb"), "W! a\nW! b\n");
        assert_eq!(format(Level::Error, "x"), "E! x\n");
        assert_eq!(format(Level::Debug, "x"), "D! x\n");
    }

    #[test]
    fn long_lines_are_cut_under_64_kib_on_a_char_boundary() {
        let msg = "é".repeat(40 * 1024);
        let out = format(Level::Info, &msg);
        assert!(out.len() < 64 * 1024, "{}", out.len());
        assert!(out.starts_with("I! é"));
        assert!(out.ends_with(" …(truncated)\n"));
    }

    #[test]
    fn every_cut_line_fits_telegrafs_64_kib_reader() {
        // Telegraf's scanner needs the line and its newline in 64 KiB.
        for msg in [
            "x".repeat(200_000),
            "€".repeat(70_000),
            "a\n".repeat(3) + &"b".repeat(MAX_LINE),
        ] {
            for line in format(Level::Error, &msg).split_inclusive('\n') {
                assert!(line.len() < 64 * 1024, "{}", line.len());
            }
        }
        // A line up to the cap is kept whole.
        let exact = "y".repeat(MAX_LINE);
        assert_eq!(format(Level::Info, &exact), format!("I! {exact}\n"));
    }

    #[test]
    fn the_filter_admits_levels_up_to_the_set_one() {
        // The only test that sets the level: the others format, they do not print.
        set_level(Level::Warn);
        assert!(enabled(Level::Error) && enabled(Level::Warn));
        assert!(!enabled(Level::Info) && !enabled(Level::Debug));
        // A filtered message's arguments are never formatted.
        struct Boom;
        impl std::fmt::Display for Boom {
            fn fmt(&self, _: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                panic!("formatted a filtered message")
            }
        }
        log_debug!("{}", Boom);
        log_info!("{}", Boom);
        set_level(Level::Debug);
        assert!(enabled(Level::Debug));
        set_level(Level::Info);
    }

    #[test]
    fn levels_order_from_error_to_debug() {
        assert!(
            Level::Error < Level::Warn && Level::Warn < Level::Info && Level::Info < Level::Debug
        );
    }

    #[test]
    fn mask_hides_user_info_in_any_text() {
        assert_eq!(
            mask("x 'nats://u:pw@h:1,h:2/b?lease=p0' and mqtt://tok@h/ and nats://h/b"),
            "x 'nats://u:***@h:1,h:2/b?lease=p0' and mqtt://***@h/ and nats://h/b"
        );
        assert_eq!(mask("nats://u:p@ss@h/b"), "nats://u:***@h/b");
        assert_eq!(mask("`nats:/u:pw@h:1/b`"), "`nats:/u:***@h:1/b`");
        assert_eq!(mask("a: /x and 12:30"), "a: /x and 12:30");
    }

    #[test]
    fn a_long_text_is_cut_at_a_character_boundary_with_its_size() {
        assert_eq!(cut("short", 10), "short");
        assert_eq!(cut("ééé", 3), "é… (6 bytes)");
        let long = "x".repeat(1_000_000);
        assert_eq!(cut(&long, 4), "xxxx… (1000000 bytes)");
    }
}
