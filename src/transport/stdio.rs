//! stdin -> processor -> stdout, as Telegraf's execd processor drives its child.
//!
//! Owns: reading without waiting for a full buffer, flushing the pending step whenever a read
//! returns less than a full buffer (no more input right now: never wait for the next record to
//! answer this one), flushing stdout after every batch, SIGTERM/SIGINT, SIGHUP (handed to the
//! caller's reload between reads), and a closed stdout.
//!
//! A pipe on stdin (Telegraf's execd, `cat file |`) is read in non-blocking mode by the runtime
//! thread itself when the pipe is readable; anything else (a file, a terminal) through tokio's
//! stdin, which reads on a helper thread and hands each read over (two thread wake-ups per
//! read: most of the answer latency of a single record on a busy machine).

use super::{Ending, Hooks};
use crate::telegraf::processor::Processor;
use lineproto::RecordSplitter;
use std::io::Write;
use tokio::io::AsyncReadExt;

const BUF: usize = 64 * 1024;

/// Standard input: the pipe read directly when it is one, tokio's stdin otherwise.
enum Input {
    Pipe(tokio::net::unix::pipe::Receiver),
    Other(tokio::io::Stdin),
}

impl Input {
    fn open() -> Input {
        use std::os::fd::AsFd;
        // A duplicate of fd 0 (the same pipe): the receiver sets it non-blocking and checks that
        // it is a FIFO; on any failure tokio's stdin is used.
        let pipe = std::io::stdin()
            .as_fd()
            .try_clone_to_owned()
            .and_then(tokio::net::unix::pipe::Receiver::from_owned_fd);
        match pipe {
            Ok(r) => Input::Pipe(r),
            Err(_) => Input::Other(tokio::io::stdin()),
        }
    }

    async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            Input::Pipe(r) => r.read(buf).await,
            Input::Other(s) => s.read(buf).await,
        }
    }
}

/// Run until EOF, a signal, or a closed stdout. Pending steps are always evaluated and written.
pub async fn run(proc: &mut Processor, hooks: Hooks<'_>) -> std::io::Result<Ending> {
    let mut stdin = Input::open();
    let mut splitter = RecordSplitter::default();
    let mut buf = vec![0u8; BUF];
    let mut out = Vec::with_capacity(BUF);
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())?;
    let mut sighup = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())?;
    let mut timer = super::timer(&hooks.periodic);
    let Hooks {
        on_hangup,
        mut periodic,
    } = hooks;
    let ending = loop {
        let n = tokio::select! {
            r = stdin.read(&mut buf) => r?,
            _ = super::tick(&mut timer) => {
                if let Some((_, f)) = periodic.as_mut() {
                    f(proc);
                }
                continue;
            }
            _ = sighup.recv() => {
                on_hangup(proc, &mut out);
                if write_out(&mut out).is_err() {
                    return Ok(Ending::OutputClosed);
                }
                continue;
            }
            _ = sigterm.recv() => break Ending::Signal,
            _ = sigint.recv() => break Ending::Signal,
        };
        if n == 0 {
            break Ending::Eof;
        }
        splitter.push(&buf[..n]);
        while let Some(rec) = splitter.next_record() {
            proc.record(&rec, &mut out);
        }
        if n < BUF {
            proc.flush(&mut out);
        }
        if write_out(&mut out).is_err() {
            return Ok(Ending::OutputClosed);
        }
    };
    while let Some(rec) = splitter.finish() {
        proc.record(&rec, &mut out);
    }
    proc.flush(&mut out);
    if write_out(&mut out).is_err() {
        return Ok(Ending::OutputClosed);
    }
    Ok(ending)
}

fn write_out(out: &mut Vec<u8>) -> std::io::Result<()> {
    if out.is_empty() {
        return Ok(());
    }
    let mut stdout = std::io::stdout().lock();
    let r = stdout.write_all(out).and_then(|()| stdout.flush());
    out.clear();
    r
}
