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

/// A free UDP port on 127.0.0.1, never one this process was given before (see
/// [`super::servers::fresh_port`]).
fn free_udp_port() -> u16 {
    super::servers::fresh_port(|| {
        UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    })
}
