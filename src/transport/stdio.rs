//! Standard input and output, as Telegraf's `processors.execd` drives its child: a [`Source`]
//! and a [`Sink`] for the [`crate::step_loop`].
//!
//! Owns: reading without waiting for a full buffer (every record is answered within the read
//! that brought it), and writing each read's outputs with one `writev` and a flush.
//!
//! A pipe on stdin (Telegraf's execd, `cat file |`) is read in non-blocking mode by the runtime
//! thread itself when the pipe is readable; anything else (a file, a terminal) through tokio's
//! stdin, which reads on a helper thread and hands each read over (two thread wake-ups per
//! read: most of the answer latency of a single record on a busy machine).

use crate::processor::Processor;
use crate::step_loop::shards::THREADS_BUF;
use crate::step_loop::{self, Ending, Setup, Sink, Source};
use std::io::Write;
use tokio::io::AsyncReadExt;

const BUF: usize = 64 * 1024;

/// Run `proc` on stdin and stdout (see [`step_loop::run`]).
pub async fn run(proc: &mut Processor, setup: Setup<'_>) -> std::io::Result<Ending> {
    step_loop::run(proc, &mut Input::open(), &mut Stdout, setup).await
}

/// Standard input: the pipe read directly when it is one, tokio's stdin otherwise.
pub enum Input {
    Pipe(tokio::net::unix::pipe::Receiver),
    Other(tokio::io::Stdin),
}

impl Input {
    pub fn open() -> Input {
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

    /// Enlarge a pipe to `size` bytes; returns the read size that means "the pipe was full":
    /// its new capacity (at most `size`), or [`BUF`] when stdin is not a pipe or cannot be
    /// enlarged (a user over the kernel's pipe-buffer quota, an older kernel).
    fn grow(&self, size: usize) -> usize {
        match self {
            Input::Pipe(r) => rustix::pipe::fcntl_setpipe_size(r, size)
                .map(|cap| cap.clamp(BUF, size))
                .unwrap_or(BUF),
            Input::Other(_) => BUF,
        }
    }
}

impl Source for Input {
    async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<Option<usize>> {
        let n = match self {
            Input::Pipe(r) => r.read(buf).await?,
            Input::Other(s) => s.read(buf).await?,
        };
        Ok((n > 0).then_some(n))
    }

    /// A pipe's waiting bytes (tokio tries the read only while it still counts the pipe
    /// readable, as it does after a read that filled the buffer).
    fn read_ahead(&mut self, buf: &mut [u8]) -> Option<usize> {
        match self {
            Input::Pipe(r) => r.try_read(buf).ok().filter(|&n| n > 0),
            Input::Other(_) => None,
        }
    }

    /// `BUF` on one thread (larger reads made it slower: the buffers leave the caches);
    /// with worker threads, a pipe enlarged to [`THREADS_BUF`] and read that much at a time:
    /// each read ends with every thread waiting for the slowest, and how many of the read's
    /// records each thread got varies from read to read, so fewer, larger reads lose less to
    /// that wait and to the wake-ups.
    fn read_size(&mut self, threads: usize) -> usize {
        if threads > 1 {
            self.grow(THREADS_BUF)
        } else {
            BUF
        }
    }
}

/// Standard output.
pub struct Stdout;

impl Sink for Stdout {
    /// `out` and then the workers' outputs with one `writev`, and a flush (the workers' outputs
    /// are not copied behind `out` first).
    async fn write(&mut self, out: &mut Vec<u8>, more: &mut [Vec<u8>]) -> std::io::Result<()> {
        write_out(out, more)
    }
}

fn write_out(out: &mut Vec<u8>, outs: &mut [Vec<u8>]) -> std::io::Result<()> {
    use std::io::IoSlice;
    let mut slices: Vec<IoSlice<'_>> = std::iter::once(out.as_slice())
        .chain(outs.iter().map(Vec::as_slice))
        .filter(|s| !s.is_empty())
        .map(IoSlice::new)
        .collect();
    let mut r = Ok(());
    if !slices.is_empty() {
        let mut stdout = std::io::stdout().lock();
        let mut rest = slices.as_mut_slice();
        while !rest.is_empty() {
            match stdout.write_vectored(rest) {
                Ok(0) => {
                    r = Err(std::io::ErrorKind::WriteZero.into());
                    break;
                }
                Ok(n) => IoSlice::advance_slices(&mut rest, n),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    r = Err(e);
                    break;
                }
            }
        }
        r = r.and_then(|()| stdout.flush());
    }
    drop(slices);
    out.clear();
    for o in outs.iter_mut() {
        o.clear();
    }
    r
}
