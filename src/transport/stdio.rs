//! stdin -> processor -> stdout, as Telegraf's execd processor drives its child.
//!
//! Owns: reading without waiting for a full buffer (every record is answered within the read
//! that brought it), the wall clock of each read, waking when an instance's `delay` falls due
//! while the input is silent ([`Processor::advance_wall`]), flushing stdout after every batch,
//! SIGTERM/SIGINT, SIGHUP (handed to the caller's reload between reads), and a closed stdout.
//!
//! With `--threads N` and `--instance-by`, instances are spread over N threads ([`Shards`]): each
//! read's records are routed by instance key (one instance always to the same thread), every
//! thread steps its records, and the read's outputs are written once all threads are done (one
//! `writev`, the workers' outputs not copied behind the reader's), so a record is still
//! answered before the next read. Each instance's outputs keep their order; the order between
//! instances within one read follows the threads. The records are handed over
//! in one reused byte buffer per thread (no allocation per record). A thread waiting for the
//! other side spins briefly before it sleeps ([`SPIN`]): waking a sleeping thread costs more
//! than the wait between two reads while records flow.
//!
//! On one thread the records are stepped straight from the read buffer as the splitter finds
//! them (pass-through copies them from there).
//!
//! A pipe on stdin (Telegraf's execd, `cat file |`) is read in non-blocking mode by the runtime
//! thread itself when the pipe is readable; anything else (a file, a terminal) through tokio's
//! stdin, which reads on a helper thread and hands each read over (two thread wake-ups per
//! read: most of the answer latency of a single record on a busy machine).

use super::{Ending, Hooks};
use crate::processor::Processor;
use crate::processor::clock::Wall;
use crate::processor::instances::shard_of;
use crate::watchdog::{Phase, Watch};
use lineproto::{RecordRef, RecordSplitter};
use std::io::Write;
use std::sync::mpsc;
use tokio::io::AsyncReadExt;

const BUF: usize = 64 * 1024;
/// With worker threads, a pipe on stdin is enlarged to this (`F_SETPIPE_SZ`; Linux allows up to
/// 1 MiB without privileges) and read this much at a time: each read ends with every thread
/// waiting for the slowest, and how many of the read's records each thread got varies from
/// read to read, so fewer, larger reads lose less to that wait and to the wake-ups. One thread
/// keeps 64 KiB reads (larger ones made it slower: the buffers leave the caches).
const THREADS_BUF: usize = 1024 * 1024;

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

    async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            Input::Pipe(r) => r.read(buf).await,
            Input::Other(s) => s.read(buf).await,
        }
    }
}

/// One shard's records of a read, their bytes back to back. Kept from read to read, so the
/// hand-over allocates nothing per record (each record was its own allocation, freed on the
/// other thread).
#[derive(Default)]
struct Batch {
    bytes: Vec<u8>,
    /// Each record: its byte range in `bytes`, first line, oversized.
    recs: Vec<(usize, usize, u64, bool)>,
}

impl Batch {
    fn push(&mut self, rec: RecordRef<'_>) {
        let start = self.bytes.len();
        self.bytes.extend_from_slice(rec.bytes);
        self.recs
            .push((start, self.bytes.len(), rec.line, rec.oversized));
    }

    /// Step every record on `p`, then empty the batch (keeping its capacity).
    fn step(&mut self, p: &mut Processor, out: &mut Vec<u8>) {
        for &(start, end, line, oversized) in &self.recs {
            let rec = RecordRef {
                bytes: self.bytes.get(start..end).unwrap_or_default(),
                line,
                oversized,
            };
            p.record_ref(rec, out);
        }
        // A batch that held a very long record does not keep its memory (a read's worth of
        // records, up to 1 MiB, it keeps).
        if self.bytes.capacity() > 4 * THREADS_BUF {
            self.bytes = Vec::new();
        }
        self.bytes.clear();
        self.recs.clear();
    }
}

/// One step of a worker thread: its processor, its records, its output buffer, whether to flush
/// afterwards, the read's wall clock.
type Job = (Box<Processor>, Batch, Vec<u8>, bool, Wall);
/// A worker's answer: its shard, its processor back, the emptied batch, its output.
type Done = (usize, Box<Processor>, Batch, Vec<u8>);

struct Worker {
    tx: Option<mpsc::Sender<Job>>,
    proc: Option<Box<Processor>>,
    handle: Option<std::thread::JoinHandle<()>>,
}

/// The caller's processor (shard 0, stepped on the calling thread) and `threads - 1` worker
/// threads, each owning the processor of its shard between jobs.
struct Shards {
    instance_by: Vec<String>,
    workers: Vec<Worker>,
    batches: Vec<Batch>,
    outs: Vec<Vec<u8>>,
    done: mpsc::Receiver<Done>,
}

impl Shards {
    /// `--max-instances` stays the total: each shard keeps its even part of it (so never more
    /// threads than that total).
    fn new(proc: &mut Processor, threads: usize, watch: &Watch) -> Result<Shards, String> {
        let total = proc.max_instances().max(1);
        let threads = if proc.instance_by().is_empty() {
            1
        } else {
            threads.clamp(1, total)
        };
        let share = |shard: usize| total / threads + usize::from(shard < total % threads);
        proc.keep_instances(share(0));
        let (done_tx, done) = mpsc::channel::<Done>();
        let mut workers = Vec::new();
        for shard in 1..threads {
            let (tx, rx) = mpsc::channel::<Job>();
            let done_tx = done_tx.clone();
            let handle = std::thread::Builder::new()
                .name(format!("shard-{shard}"))
                .spawn(move || {
                    // Spin for the next read only while records are flowing.
                    let mut flowing = false;
                    while let Ok((mut p, mut batch, mut out, flush, wall)) = recv(&rx, flowing) {
                        flowing = !flush;
                        p.set_wall(wall);
                        batch.step(&mut p, &mut out);
                        if flush {
                            p.flush(&mut out);
                        }
                        if done_tx.send((shard, p, batch, out)).is_err() {
                            break;
                        }
                    }
                })
                .map_err(|e| format!("cannot start a worker thread: {e}"))?;
            let mut sibling = proc.sibling()?;
            sibling.keep_instances(share(shard));
            sibling.watch_with(watch.lane());
            // The wiring diagnostics watch the first thread's records only: closed before a
            // record is seen, a worker's check reports nothing (its first 1,000 records would
            // cost it 239k instructions each, and every thread would warn about the same input).
            sibling.finish_wiring();
            workers.push(Worker {
                tx: Some(tx),
                proc: Some(Box::new(sibling)),
                handle: Some(handle),
            });
        }
        Ok(Shards {
            instance_by: proc.instance_by().to_vec(),
            workers,
            batches: (0..threads).map(|_| Batch::default()).collect(),
            outs: (0..threads).map(|_| Vec::new()).collect(),
            done,
        })
    }

    /// Put `rec` into its shard's batch. A record spanning several lines that does not parse
    /// is routed line by line, as the processor would take it apart.
    fn route(&mut self, rec: RecordRef<'_>) {
        let n = self.batches.len();
        let spans = rec
            .bytes
            .split_last()
            .is_some_and(|(_, head)| memchr::memchr(b'\n', head).is_some());
        if spans && !rec.oversized && lineproto::parse_record(rec.bytes).is_err() {
            for (line, part) in (rec.line..).zip(rec.bytes.split_inclusive(|&b| b == b'\n')) {
                self.route(RecordRef {
                    bytes: part,
                    line,
                    oversized: false,
                });
            }
            return;
        }
        let s = if rec.oversized {
            0
        } else {
            shard_of(rec.bytes, &self.instance_by, n)
        };
        if let Some(b) = self.batches.get_mut(s) {
            b.push(rec);
        }
    }

    /// Step the routed records (then flush every shard when `flush`): shard 0's outputs are
    /// appended to `out`, the workers' kept in `outs` for [`write_out`].
    fn process(
        &mut self,
        proc: &mut Processor,
        flush: bool,
        wall: Wall,
        out: &mut Vec<u8>,
    ) -> std::io::Result<()> {
        let lost = || std::io::Error::other("a worker thread stopped");
        for (i, w) in self.workers.iter_mut().enumerate() {
            let batch = std::mem::take(self.batches.get_mut(i + 1).ok_or_else(lost)?);
            let o = std::mem::take(self.outs.get_mut(i + 1).ok_or_else(lost)?);
            let p = w.proc.take().ok_or_else(lost)?;
            w.tx.as_ref()
                .ok_or_else(lost)?
                .send((p, batch, o, flush, wall))
                .map_err(|_| lost())?;
        }
        proc.set_wall(wall);
        if let Some(b) = self.batches.first_mut() {
            b.step(proc, out);
        }
        if flush {
            proc.flush(out);
        }
        for _ in 0..self.workers.len() {
            let (shard, p, batch, o) = recv(&self.done, true).map_err(|_| lost())?;
            self.workers.get_mut(shard - 1).ok_or_else(lost)?.proc = Some(p);
            *self.batches.get_mut(shard).ok_or_else(lost)? = batch;
            *self.outs.get_mut(shard).ok_or_else(lost)? = o;
        }
        Ok(())
    }

    /// Every worker's processor (all are at home between reads).
    fn each(&mut self, mut f: impl FnMut(&mut Processor)) {
        for w in &mut self.workers {
            if let Some(p) = w.proc.as_mut() {
                f(p);
            }
        }
    }

    /// The earliest wall-clock deadline of any thread's instances (see
    /// [`Processor::next_deadline`]).
    fn next_deadline(&self, proc: &Processor) -> Option<std::time::Instant> {
        self.workers
            .iter()
            .filter_map(|w| w.proc.as_ref()?.next_deadline())
            .chain(proc.next_deadline())
            .min()
    }

    /// Stop the workers and add their counters to `proc`'s (the summary covers every thread).
    fn finish(mut self, proc: &mut Processor) {
        for w in &mut self.workers {
            w.tx = None;
            if let Some(h) = w.handle.take() {
                let _ = h.join();
            }
            if let Some(p) = &w.proc {
                proc.counters.add(&p.counters);
            }
        }
        self.workers.clear();
    }
}

/// How long a thread waiting for the other side spins before it sleeps: a sleeping thread
/// takes 20 to 50 µs to run again once woken on a 2-core VM, a tenth of a 64 KiB read's work.
/// The workers spin for the next read only while records are flowing (the last read filled the
/// buffer); the reader always spins for the workers' answers.
const SPIN: std::time::Duration = std::time::Duration::from_micros(100);

/// Receive from `rx`, spinning up to [`SPIN`] first when `spin`.
fn recv<T>(rx: &mpsc::Receiver<T>, spin: bool) -> Result<T, mpsc::RecvError> {
    if spin {
        let start = std::time::Instant::now();
        loop {
            match rx.try_recv() {
                Ok(v) => return Ok(v),
                Err(mpsc::TryRecvError::Disconnected) => return Err(mpsc::RecvError),
                Err(mpsc::TryRecvError::Empty) => {}
            }
            if start.elapsed() >= SPIN {
                break;
            }
            for _ in 0..32 {
                std::hint::spin_loop();
            }
        }
    }
    rx.recv()
}

/// Run until EOF, a signal, or a closed stdout. Pending steps are always evaluated and written.
/// `threads` > 1 spreads `--instance-by` instances over that many threads.
pub async fn run(
    proc: &mut Processor,
    hooks: Hooks<'_>,
    threads: usize,
) -> std::io::Result<Ending> {
    let mut shards = Shards::new(proc, threads, &hooks.watch).map_err(std::io::Error::other)?;
    let r = run_shards(proc, hooks, &mut shards).await;
    shards.finish(proc);
    r
}

async fn run_shards(
    proc: &mut Processor,
    hooks: Hooks<'_>,
    shards: &mut Shards,
) -> std::io::Result<Ending> {
    let mut stdin = Input::open();
    let mut splitter = RecordSplitter::default();
    let size = if shards.workers.is_empty() {
        BUF
    } else {
        stdin.grow(THREADS_BUF)
    };
    let mut buf = vec![0u8; size];
    let mut out = Vec::with_capacity(BUF);
    let mut signals = super::Signals::new()?;
    let (on_hangup, mut ticker, watch) = hooks.split();
    let ending = loop {
        // A record partly read is input arriving, not silence.
        let deadline = shards.next_deadline(proc).filter(|_| !splitter.in_record());
        let n = tokio::select! {
            // Biased, in this order (see `Signals`): a signal is never starved by input, and a
            // delay falls due by the wall clock only when no input is waiting (input not read yet
            // is not silence).
            biased;
            _ = signals.term.recv() => break Ending::Signal,
            _ = signals.int.recv() => break Ending::Signal,
            _ = signals.hup.recv() => {
                on_hangup(proc, &mut out);
                shards.each(|p| on_hangup(p, &mut out));
                let _busy = watch.enter(Phase::Reload);
                if write_out(&mut out, &mut shards.outs).is_err() {
                    return Ok(Ending::OutputClosed);
                }
                continue;
            }
            _ = ticker.tick() => {
                ticker.run(proc);
                continue;
            }
            r = stdin.read(&mut buf) => r?,
            _ = super::sleep_until(deadline) => {
                // Silent input: the instances whose delays fell due move on by the wall clock.
                let _busy = watch.enter(Phase::Delays);
                let wall = Wall::now();
                super::advance_silent(proc, wall, &mut out);
                shards.each(|p| super::advance_silent(p, wall, &mut out));
                watch.set(Phase::Writing);
                if write_out(&mut out, &mut shards.outs).is_err() {
                    return Ok(Ending::OutputClosed);
                }
                continue;
            }
        };
        if n == 0 {
            break Ending::Eof;
        }
        let _busy = watch.enter(Phase::Records);
        let wall = Wall::now();
        let bytes = buf.get(..n).unwrap_or_default();
        if shards.workers.is_empty() {
            // One thread: each record straight from the read buffer (no copy per record).
            proc.set_wall(wall);
            splitter.push_with(bytes, |rec| proc.record_ref(rec, &mut out));
            if n < size {
                proc.flush(&mut out);
            }
        } else {
            splitter.push_with(bytes, |rec| shards.route(rec));
            shards.process(proc, n < size, wall, &mut out)?;
        }
        watch.set(Phase::Writing);
        if write_out(&mut out, &mut shards.outs).is_err() {
            return Ok(Ending::OutputClosed);
        }
    };
    let _busy = watch.enter(Phase::Records);
    while let Some(rec) = splitter.finish() {
        shards.route(rec.view());
    }
    shards.process(proc, true, Wall::now(), &mut out)?;
    watch.set(Phase::Writing);
    if write_out(&mut out, &mut shards.outs).is_err() {
        return Ok(Ending::OutputClosed);
    }
    Ok(ending)
}

/// Write `out` and then the workers' outputs (`outs[1..]`) with one `writev`, and flush;
/// empties them all (the workers' outputs are not copied behind `out` first).
fn write_out(out: &mut Vec<u8>, outs: &mut [Vec<u8>]) -> std::io::Result<()> {
    use std::io::IoSlice;
    let mut slices: Vec<IoSlice<'_>> = std::iter::once(out.as_slice())
        .chain(outs.iter().skip(1).map(Vec::as_slice))
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
    for o in outs.iter_mut().skip(1) {
        o.clear();
    }
    r
}
