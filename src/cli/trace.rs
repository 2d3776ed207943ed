//! `tessla-telegraf trace SPEC [TRACE]`: run a spec over a TeSSLa input trace (file or stdin,
//! read line by line) and print TeSSLa's output format as outputs are produced. Exit 1 on a
//! runtime or trace error (outputs before it are printed, the error goes to stderr), 2 on a
//! spec error or an option that does not fit the spec, 3 when the trace cannot be read; 0 also
//! when stdout is closed by the reader. The options are TeSSLa's `interpreter` command's; with
//! `--ctf` the trace is a CTF trace directory (see `tessla_trace::ctf`).

use super::args::TraceArgs;
use super::error::{CliError, CliResult};
use super::spec_options::{load_options, require_outputs};
use crate::trace::{ErrorKind, Format, Options, run_stream_with};
use std::cell::RefCell;
use std::io::{BufReader, BufWriter, IsTerminal, Read, StdoutLock, Write};
use std::rc::Rc;

type Out = Rc<RefCell<BufWriter<StdoutLock<'static>>>>;

/// The size of the trace's read buffer and of the output buffer: a trace is read, and outputs
/// written, in blocks of this size (std's default of 8 KiB made a read and a write system call
/// per 8 KiB of a fast trace on stdin, the outputs being flushed before each read).
const BUFFER: usize = 64 * 1024;

/// The output writer, shared with [`FlushBeforeRead`].
struct SharedOut(Out);

impl Write for SharedOut {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.borrow_mut().flush()
    }
}

/// Stdin that flushes the outputs before each read (the `BufReader` around it reads only when
/// its buffer is empty, i.e. when the trace may have to wait for its producer).
struct FlushBeforeRead {
    inner: std::io::Stdin,
    out: Out,
}

impl Read for FlushBeforeRead {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        // A failed flush (closed stdout) shows up again at the next output write.
        let _ = self.out.borrow_mut().flush();
        self.inner.read(buf)
    }
}

pub fn run(args: TraceArgs) -> CliResult {
    let mut options =
        load_options(&args.spec_options).map_err(|e| CliError::spec(format!("error: {e}")))?;
    // As TeSSLa's interpreter: without a base time, a time literal (`2 s`) is an error.
    if args.spec_options.base_time.is_none() {
        options.base_time = None;
        options.time_units_need_base = true;
    }
    let loaded =
        tessla_engine::load_file(&args.spec, &options).map_err(|e| CliError::spec(e.render()))?;
    if !loaded.warnings.is_empty() {
        let color = std::io::stderr().is_terminal();
        eprint!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, color)
        );
    }
    require_outputs(&loaded.program, &args.spec.display().to_string())
        .map_err(|e| CliError::spec(format!("error: {e}")))?;
    let options = Options {
        format: if args.csv {
            Format::Csv
        } else {
            Format::Tessla
        },
        reject_undeclared: args.reject_undeclared_inputs,
        stop_on: args.stop_on.clone(),
        abort_at: args.abort_at,
    };
    let stdout = std::io::stdout();
    let result = match &args.trace {
        // As TeSSLa's interpreter: a CTF trace is a directory, never stdin.
        None if args.ctf => {
            return Err(CliError::spec(
                "error: --ctf needs a trace (a CTF trace directory); stdin is not supported",
            ));
        }
        Some(p) if args.ctf => tessla_trace::ctf::run_dir(
            &loaded.program,
            p,
            &mut BufWriter::with_capacity(BUFFER, stdout.lock()),
            &options,
        ),
        // A trace file is read as fast as possible: outputs are block-buffered.
        Some(p) => match std::fs::File::open(p) {
            Ok(f) => run_stream_with(
                &loaded.program,
                &p.display().to_string(),
                BufReader::with_capacity(BUFFER, f),
                &mut BufWriter::with_capacity(BUFFER, stdout.lock()),
                &options,
            ),
            Err(e) => {
                return Err(CliError::io(format!(
                    "error: cannot read {}: {e}",
                    p.display()
                )));
            }
        },
        // A trace on stdin may arrive slowly (a live feed): outputs are block-buffered but
        // flushed whenever reading would wait for more input.
        None => {
            let out = Rc::new(RefCell::new(BufWriter::with_capacity(
                BUFFER,
                stdout.lock(),
            )));
            let input = BufReader::with_capacity(
                BUFFER,
                FlushBeforeRead {
                    inner: std::io::stdin(),
                    out: out.clone(),
                },
            );
            run_stream_with(
                &loaded.program,
                "<stdin>",
                input,
                &mut SharedOut(out),
                &options,
            )
        }
    };
    match result {
        Ok(()) => Ok(()),
        Err(e) if e.kind == ErrorKind::OutputClosed => Ok(()),
        Err(e) if e.kind == ErrorKind::Io => Err(CliError::io(e.to_string())),
        Err(e) if e.kind == ErrorKind::Usage => Err(CliError::spec(e.to_string())),
        Err(e) => Err(CliError::runtime(e.to_string())),
    }
}
