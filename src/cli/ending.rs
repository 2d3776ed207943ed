//! How a run on the step loop starts and ends as a process: the runtime the transports run
//! on, the reason it stopped and the summary, and handing the stdout and stderr pipes over to
//! their reader before exiting ([`wait_until_read`]), so that Telegraf gets the last lines.

use super::error::{CliError, CliResult};
use crate::processor::Processor;
use crate::step_loop::Ending;
use std::time::{Duration, Instant};

/// The single-threaded runtime the transports run on.
pub fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::io(format!("cannot start the runtime: {e}")))
}

/// The end of a run: say why it stopped, log the summary, leave the runtime.
pub fn finish(
    rt: tokio::runtime::Runtime,
    result: std::io::Result<Ending>,
    proc: &Processor,
) -> CliResult {
    if result.as_ref().is_ok_and(|e| *e == Ending::OutputClosed) {
        log_info!("stdout was closed by its reader; stopping");
    }
    log_info!("{}", proc.summary());
    if matches!(result, Ok(Ending::Eof | Ending::Signal)) {
        wait_until_read(DRAIN_BOUND);
    }
    // The blocking stdin reader thread may still wait for input: leave without joining it.
    rt.shutdown_background();
    result
        .map(|_| ())
        .map_err(|e| CliError::io(format!("I/O error: {e}")))
}

/// The longest wait at the end for the reader of our stdout pipe ([`wait_until_read`]): well
/// inside the 5 s Telegraf waits after closing our stdin before it sends SIGTERM.
const DRAIN_BOUND: Duration = Duration::from_secs(2);

/// At a normal end, wait (at most `bound`) until the reader has read everything we wrote to
/// the pipes on stdout and stderr. Telegraf's `processors.execd` closes its ends of the pipes
/// once the child has exited (`Cmd.Wait`), so lines still unread when we exit would be lost:
/// the last outputs, and the summary on stderr. Polls the bytes unread in each pipe
/// (`FIONREAD`), first every 0.2 ms, backing off to every 10 ms; a stream that is no pipe, or
/// whose count cannot be read, is not waited for. Once both are read, the pipes are handed over (`hand_over_pipes`).
pub fn wait_until_read(bound: Duration) {
    use rustix::fs::FileType;
    let is_pipe = |fd: &dyn std::os::fd::AsFd| {
        rustix::fs::fstat(fd).is_ok_and(|st| FileType::from_raw_mode(st.st_mode) == FileType::Fifo)
    };
    let stdout = std::io::stdout();
    let stderr = std::io::stderr();
    let (out_pipe, err_pipe) = (is_pipe(&stdout), is_pipe(&stderr));
    if !out_pipe && !err_pipe {
        return;
    }
    let unread = |fd: &dyn std::os::fd::AsFd, pipe: bool| {
        if pipe {
            rustix::io::ioctl_fionread(fd).unwrap_or(0)
        } else {
            0
        }
    };
    let start = Instant::now();
    let mut pause = Duration::from_micros(200);
    loop {
        let (out_left, err_left) = (unread(&stdout, out_pipe), unread(&stderr, err_pipe));
        if out_left + err_left == 0 {
            hand_over_pipes(out_pipe, err_pipe);
            return;
        }
        if start.elapsed() >= bound {
            log_warn!(
                "{}: {} bytes still unread by the reader after {} s; exiting anyway",
                if out_left > 0 { "stdout" } else { "stderr" },
                if out_left > 0 { out_left } else { err_left },
                bound.as_secs_f64()
            );
            return;
        }
        std::thread::sleep(pause);
        pause = (pause * 2).min(Duration::from_millis(10));
    }
}

/// How long [`hand_over_pipes`] waits after closing them: Telegraf's readers parse the last
/// chunk they read, read again and see the end of the pipe.
const READER_GRACE: Duration = Duration::from_millis(50);

/// Close our ends of the stdout and stderr pipes (each replaced by `/dev/null`, so a late
/// write goes nowhere instead of failing) while we still run, then wait [`READER_GRACE`]:
/// Telegraf's readers see the end of each pipe and finish before we exit. Exiting with the
/// pipes open makes the end of the pipe and `Cmd.Wait`'s close race, and a reader that loses
/// logs "read |0: file already closed" (measured at about one stop in three on 1.33.3 and
/// 1.39.3 before this).
fn hand_over_pipes(out_pipe: bool, err_pipe: bool) {
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    let Ok(null) = std::fs::OpenOptions::new().write(true).open("/dev/null") else {
        return;
    };
    if out_pipe {
        let _ = rustix::stdio::dup2_stdout(&null);
    }
    if err_pipe {
        let _ = rustix::stdio::dup2_stderr(&null);
    }
    std::thread::sleep(READER_GRACE);
}
