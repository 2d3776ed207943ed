//! The test's ends of UDP mode (the TeSSLa Telegraf Connector's wiring): a socket receiving the
//! child's outputs and a free address for the child to listen on.

use std::net::UdpSocket;
use std::time::Duration;

/// A socket receiving the child's outputs (reads time out after `read_timeout`), its address
/// (for `--udp-send`), and a free address for the child to listen on (`--udp-listen`).
pub fn open(read_timeout: Duration) -> (UdpSocket, String, String) {
    let recv = UdpSocket::bind("127.0.0.1:0").unwrap();
    recv.set_read_timeout(Some(read_timeout)).unwrap();
    let send_to = recv.local_addr().unwrap().to_string();
    (recv, send_to, format!("127.0.0.1:{}", free_udp_port()))
}

/// A free UDP port on 127.0.0.1 (bound, read, released), never one this process was given before:
/// the tests run at once in one process, and a port just released by one may be handed out
/// again before its child has bound it.
fn free_udp_port() -> u16 {
    static GIVEN: std::sync::Mutex<Vec<u16>> = std::sync::Mutex::new(Vec::new());
    let mut given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let port = UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        if !given.contains(&port) {
            given.push(port);
            return port;
        }
    }
}
