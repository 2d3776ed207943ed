//! Stepping one read's records on one thread or spread over several (`Shards`).
//!
//! With `--threads N` and `--instance-by`, instances are spread over N threads: each read's
//! records are routed by instance key (one instance always to the same thread), every thread
//! steps its records, and the read's outputs are written once all threads are done (the sink
//! writes the workers' outputs behind the reader's, not copied), so a record is still answered
//! before the next read's records are stepped (the next read itself may be taken meanwhile:
//! `Shards::process` runs the loop's read-ahead while a worker finishes). Each instance's
//! outputs keep their order; the order between instances within one read follows the threads.
//! The records are handed over in one reused byte buffer per thread (no allocation per record).
//! A thread waiting for the other side spins briefly before it sleeps (`SPIN`): waking a
//! sleeping thread costs more than the wait between two reads while records flow.

use crate::processor::Processor;
use crate::processor::clock::Wall;
use crate::processor::instance_table::shard_of;
use crate::watchdog::Watch;
use lineproto::RecordRef;
use std::sync::mpsc;

/// With worker threads, a pipe on stdin is enlarged to this and read this much at a time (see
/// [`super::Source::read_size`]); a batch that held more than four times this gives its memory
/// back.
pub const THREADS_BUF: usize = 1024 * 1024;

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
pub(super) struct Shards {
    instance_by: Vec<String>,
    workers: Vec<Worker>,
    batches: Vec<Batch>,
    outs: Vec<Vec<u8>>,
    done: mpsc::Receiver<Done>,
}

/// Why the `--threads` workers could not start.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    /// The operating system refused a thread.
    #[error("cannot start a worker thread: {0}")]
    Spawn(std::io::Error),
    /// A worker's processor could not be built (the same annotations as the first: not in
    /// practice).
    #[error(transparent)]
    Sibling(#[from] crate::telegraf::binding::BindingError),
}

impl Shards {
    /// `threads` as `cli/config.rs` decided it (at least 1). `--max-instances` stays the total:
    /// each shard keeps its even part of it.
    pub(super) fn new(
        proc: &mut Processor,
        threads: usize,
        watch: &Watch,
    ) -> Result<Shards, ShardError> {
        let total = proc.max_instances().max(1);
        // Not a rule, a guard: no shard without a thread, no division by zero.
        let threads = threads.max(1);
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
                            p.end_of_read();
                        }
                        if done_tx.send((shard, p, batch, out)).is_err() {
                            break;
                        }
                    }
                })
                .map_err(ShardError::Spawn)?;
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
    pub(super) fn route(&mut self, rec: RecordRef<'_>) {
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

    /// Step the routed records (then end the read on every shard when `flush`): shard 0's
    /// outputs are appended to `out`, the workers' kept in `outs` for the sink.
    pub(super) fn process(
        &mut self,
        proc: &mut Processor,
        flush: bool,
        wall: Wall,
        out: &mut Vec<u8>,
        meanwhile: &mut dyn FnMut(),
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
            proc.end_of_read();
        }
        meanwhile();
        for _ in 0..self.workers.len() {
            let (shard, p, batch, o) = recv(&self.done, true).map_err(|_| lost())?;
            self.workers.get_mut(shard - 1).ok_or_else(lost)?.proc = Some(p);
            *self.batches.get_mut(shard).ok_or_else(lost)? = batch;
            *self.outs.get_mut(shard).ok_or_else(lost)? = o;
        }
        Ok(())
    }

    /// How many threads step records (the calling one included).
    pub(super) fn threads(&self) -> usize {
        self.workers.len() + 1
    }

    /// The workers' outputs of the last read, in shard order, for the sink to write behind the
    /// calling thread's.
    pub(super) fn outs_mut(&mut self) -> &mut [Vec<u8>] {
        self.outs.get_mut(1..).unwrap_or_default()
    }

    /// Every worker's processor (all are at home between reads).
    pub(super) fn each(&mut self, mut f: impl FnMut(&mut Processor)) {
        for w in &mut self.workers {
            if let Some(p) = w.proc.as_mut() {
                f(p);
            }
        }
    }

    /// `first` and every worker's processor (all are at home between reads).
    pub(super) fn all<'a>(&'a mut self, first: &'a mut Processor) -> Vec<&'a mut Processor> {
        let mut v = vec![first];
        v.extend(
            self.workers
                .iter_mut()
                .filter_map(|w| w.proc.as_deref_mut()),
        );
        v
    }

    /// The earliest wall-clock deadline of any thread's instances (see
    /// [`Processor::next_deadline`]).
    pub(super) fn next_deadline(&self, proc: &Processor) -> Option<std::time::Instant> {
        self.workers
            .iter()
            .filter_map(|w| w.proc.as_ref()?.next_deadline())
            .chain(proc.next_deadline())
            .min()
    }

    /// Stop the workers and add their counters to `proc`'s (the summary covers every thread).
    pub(super) fn finish(mut self, proc: &mut Processor) {
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
