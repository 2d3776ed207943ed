//! The binary as a long-running child: write input, wait for given stdout/stderr lines (the
//! readiness signal, never a sleep), send signals, then close stdin and collect everything.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::{Duration, Instant};

use super::BIN;
const PATIENCE: Duration = Duration::from_secs(60);

pub struct LiveChild {
    child: Child,
    stdin: Option<ChildStdin>,
    out_rx: Receiver<String>,
    err_rx: Receiver<String>,
    /// Every stdout / stderr line received so far (with its newline).
    pub out: Vec<String>,
    pub err: Vec<String>,
    /// How long a wait for a line may take before the test fails (`patient`).
    patience: Duration,
}

fn pump(r: impl std::io::Read + Send + 'static) -> Receiver<String> {
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        let mut r = BufReader::new(r);
        loop {
            let mut line = String::new();
            match r.read_line(&mut line) {
                Ok(0) | Err(_) => break,
                Ok(_) => {
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            }
        }
    });
    rx
}

impl LiveChild {
    pub fn spawn(args: &[&str]) -> LiveChild {
        let mut child = Command::new(BIN)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take();
        let out_rx = pump(child.stdout.take().unwrap());
        let err_rx = pump(child.stderr.take().unwrap());
        LiveChild {
            child,
            stdin,
            out_rx,
            err_rx,
            out: Vec::new(),
            err: Vec::new(),
            patience: PATIENCE,
        }
    }

    /// Waits for a line may take up to `d` (default 60 s): for a child with much work before
    /// the line it is waited for, on a machine running other tests beside it.
    pub fn patient(mut self, d: Duration) -> LiveChild {
        self.patience = d;
        self
    }

    pub fn write(&mut self, text: &str) {
        let stdin = self.stdin.as_mut().unwrap();
        stdin.write_all(text.as_bytes()).unwrap();
        stdin.flush().unwrap();
    }

    /// Wait until a stdout line satisfies `pred` (counting lines already received).
    pub fn wait_out(&mut self, what: &str, pred: impl Fn(&str) -> bool) {
        if self.out.iter().any(|l| pred(l)) {
            return;
        }
        let start = Instant::now();
        loop {
            match self.out_rx.recv_timeout(Duration::from_millis(200)) {
                Ok(l) => {
                    let hit = pred(&l);
                    self.out.push(l);
                    if hit {
                        return;
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    self.drain_err();
                    panic!(
                        "stdout closed waiting for {what}; stderr:\n{}",
                        self.err.concat()
                    )
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            if start.elapsed() > self.patience {
                self.drain_err();
                panic!(
                    "no stdout line {what}; got:\n{}\nstderr:\n{}",
                    self.out.concat(),
                    self.err.concat()
                );
            }
        }
    }

    /// Wait until a stderr line satisfies `pred`; returns it. Lines already seen do not count
    /// once `from` of them have been looked at (pass `self.err.len()` before the action).
    pub fn wait_err(&mut self, what: &str, from: usize, pred: impl Fn(&str) -> bool) -> String {
        if let Some(l) = self.err.iter().skip(from).find(|l| pred(l)) {
            return l.clone();
        }
        let start = Instant::now();
        loop {
            match self.err_rx.recv_timeout(Duration::from_millis(200)) {
                Ok(l) => {
                    let hit = pred(&l);
                    self.err.push(l.clone());
                    if hit {
                        return l;
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    panic!("stderr closed waiting for {what}:\n{}", self.err.concat())
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            if start.elapsed() > self.patience {
                panic!("no stderr line {what}; got:\n{}", self.err.concat());
            }
        }
    }

    /// Take every stdout line received so far into `out`, without waiting.
    pub fn drain_out(&mut self) {
        while let Ok(l) = self.out_rx.try_recv() {
            self.out.push(l);
        }
    }

    /// Take every stderr line received so far into `err`, without waiting.
    pub fn drain_err(&mut self) {
        while let Ok(l) = self.err_rx.try_recv() {
            self.err.push(l);
        }
    }

    /// Close stdin (EOF, how Telegraf stops its child) without waiting for the exit.
    pub fn close_stdin(&mut self) {
        drop(self.stdin.take());
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    pub fn signal(&self, sig: &str) {
        let pid = self.child.id().to_string();
        assert!(
            Command::new("kill")
                .args([&format!("-{sig}"), pid.as_str()])
                .status()
                .unwrap()
                .success()
        );
    }

    /// Close stdin (if still open), wait for the exit; all stdout, all stderr, the exit code.
    pub fn finish(mut self) -> (String, String, i32) {
        drop(self.stdin.take());
        let status = self.child.wait().unwrap();
        // The pumps end at EOF of the pipes, which the exit closes.
        for l in self.out_rx.iter() {
            self.out.push(l);
        }
        for l in self.err_rx.iter() {
            self.err.push(l);
        }
        (
            self.out.concat(),
            self.err.concat(),
            status.code().unwrap_or(-1),
        )
    }
}

/// Run the binary over `input` (stdin closed at its end): stdout, stderr, exit code.
pub fn run_all(args: &[&str], input: &str) -> (String, String, i32) {
    let mut c = LiveChild::spawn(args);
    let mut stdin = c.stdin.take().unwrap();
    let input = input.to_string();
    let w = std::thread::spawn(move || {
        let _ = stdin.write_all(input.as_bytes());
    });
    let r = c.finish();
    w.join().unwrap();
    r
}
