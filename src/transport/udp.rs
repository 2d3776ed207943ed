//! The TeSSLa Telegraf Connector's transport: line protocol over UDP, a [`Source`] and a
//! [`Sink`] for the [`crate::step_loop`].
//!
//! Owns: receiving datagrams (several lines each; a datagram's last line ends with it, so one
//! bad line costs only itself), and sending outputs packed into datagrams of at most
//! `max_datagram` bytes without splitting a line. Input records are never echoed in this mode
//! (see `run`'s options): Telegraf already sends the robot metric to its other outputs. The run
//! ends on SIGTERM/SIGINT only.

use crate::processor::Processor;
use crate::step_loop::{self, Ending, Setup, Sink, Source};
use tokio::net::UdpSocket;

/// Run `proc` on UDP until SIGTERM/SIGINT. `listen`/`send`: socket addresses such as
/// `127.0.0.1:1653`.
pub async fn run(
    proc: &mut Processor,
    listen: &str,
    send: &str,
    max_datagram: usize,
    setup: Setup<'_>,
) -> std::io::Result<Ending> {
    let sock = UdpSocket::bind(listen).await?;
    let out_sock = UdpSocket::bind(if send.starts_with('[') {
        "[::]:0"
    } else {
        "0.0.0.0:0"
    })
    .await?;
    out_sock.connect(send).await?;
    log_info!(
        "udp: listening on {}, sending to {send}",
        sock.local_addr()?
    );
    let mut sink = Datagrams {
        sock: out_sock,
        max: max_datagram,
    };
    step_loop::run(proc, &mut Received(sock), &mut sink, setup).await
}

/// The datagrams received.
struct Received(UdpSocket);

impl Source for Received {
    async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<Option<usize>> {
        self.0.recv(buf).await.map(Some)
    }

    fn whole_reads(&self) -> bool {
        true
    }
}

/// The datagrams sent.
struct Datagrams {
    sock: UdpSocket,
    max: usize,
}

impl Sink for Datagrams {
    async fn write(&mut self, out: &mut Vec<u8>, more: &mut [Vec<u8>]) -> std::io::Result<()> {
        send_packed(&self.sock, out, self.max).await;
        out.clear();
        for o in more {
            send_packed(&self.sock, o, self.max).await;
            o.clear();
        }
        Ok(())
    }
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
