//! The TeSSLa Telegraf Connector's transport: line protocol over UDP.
//!
//! Owns: receiving datagrams (several lines each; every line parsed alone, so one bad line costs
//! only itself; each record evaluated at once, as on stdin), the wall clock of each datagram and
//! waking for `delay`s that fall due while no datagram arrives, and sending outputs packed
//! into datagrams of at most `max_datagram` bytes without splitting a line. Input records are
//! never echoed in this mode (see `run`'s options): Telegraf already sends the robot metric to
//! its other outputs.

use super::{Ending, Hooks};
use crate::processor::Processor;
use crate::processor::clock::Wall;
use crate::watchdog::Phase;
use lineproto::RecordSplitter;
use tokio::net::UdpSocket;

/// Run until SIGTERM/SIGINT. `listen`/`send`: socket addresses such as `127.0.0.1:1653`.
pub async fn run(
    proc: &mut Processor,
    listen: &str,
    send: &str,
    max_datagram: usize,
    hooks: Hooks<'_>,
) -> std::io::Result<Ending> {
    let sock = UdpSocket::bind(listen).await?;
    let out_sock = UdpSocket::bind(if send.starts_with('[') {
        "[::]:0"
    } else {
        "0.0.0.0:0"
    })
    .await?;
    out_sock.connect(send).await?;
    crate::log::log(
        crate::log::Level::Info,
        &format!(
            "udp: listening on {}, sending to {send}",
            sock.local_addr()?
        ),
    );
    let mut buf = vec![0u8; 65_536];
    let mut out = Vec::new();
    let mut signals = super::Signals::new()?;
    let (on_hangup, mut ticker, watch) = hooks.split();
    loop {
        let deadline = proc.next_deadline();
        let n = tokio::select! {
            // Biased, in this order (see `Signals`): a signal is never starved by input, and a
            // delay falls due by the wall clock only when no input is waiting (input not read yet
            // is not silence).
            biased;
            _ = signals.term.recv() => break,
            _ = signals.int.recv() => break,
            _ = signals.hup.recv() => {
                on_hangup(proc, &mut out);
                let _busy = watch.enter(Phase::Reload);
                send_packed(&out_sock, &out, max_datagram).await;
                out.clear();
                continue;
            }
            _ = ticker.tick() => {
                ticker.run(proc);
                continue;
            }
            r = sock.recv(&mut buf) => r?,
            _ = super::sleep_until(deadline) => {
                let _busy = watch.enter(Phase::Delays);
                super::advance_silent(proc, Wall::now(), &mut out);
                send_packed(&out_sock, &out, max_datagram).await;
                out.clear();
                continue;
            }
        };
        let _busy = watch.enter(Phase::Records);
        proc.set_wall(Wall::now());
        let mut splitter = RecordSplitter::default();
        splitter.push(buf.get(..n).unwrap_or_default());
        while let Some(rec) = splitter.next_record() {
            proc.record(&rec, &mut out);
        }
        while let Some(rec) = splitter.finish() {
            proc.record(&rec, &mut out);
        }
        proc.flush(&mut out);
        send_packed(&out_sock, &out, max_datagram).await;
        out.clear();
    }
    proc.flush(&mut out);
    send_packed(&out_sock, &out, max_datagram).await;
    Ok(Ending::Signal)
}

/// Send whole lines, packing as many as fit into one datagram. A single line longer than the
/// limit goes alone (the OS may still refuse it; that is reported).
async fn send_packed(sock: &UdpSocket, out: &[u8], max: usize) {
    let mut start = 0;
    let mut end = 0;
    let mut pos = 0;
    while pos < out.len() {
        let line_end = out[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(out.len(), |i| pos + i + 1);
        if line_end - start > max && end > start {
            send_one(sock, &out[start..end]).await;
            start = end;
        }
        end = line_end;
        pos = line_end;
    }
    if end > start {
        send_one(sock, &out[start..end]).await;
    }
}

async fn send_one(sock: &UdpSocket, bytes: &[u8]) {
    if let Err(e) = sock.send(bytes).await {
        crate::log::warn_limited("udp send", || {
            format!("udp: sending {} bytes failed: {e}", bytes.len())
        });
    }
}
