"""What the bench scripts that need a nats-server share (bench/fleet_checkpoint.py,
bench/spec_rollout.py): a free loopback port, and a nats-server with JetStream started on one and
stopped again.

Usage (from a script in bench/, which Python puts on the import path):

    import servers
    server, port = servers.start_nats(store_dir)
    try:
        ...  # nats://127.0.0.1:{port}
    finally:
        servers.stop(server)
"""
import shutil, signal, socket, subprocess, sys, time


def free_port():
    """A loopback port free now (the OS's pick)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def start_nats(store_dir, timeout=10.0):
    """A nats-server with JetStream (its store in `store_dir`) on a free loopback port, once it
    accepts connections: (the process, its port). Exits with a message if nats-server is not
    installed or does not start."""
    binary = shutil.which("nats-server")
    if not binary:
        sys.exit("nats-server is needed (apt-get install nats-server)")
    port = free_port()
    server = subprocess.Popen([binary, "-js", "-a", "127.0.0.1", "-p", str(port), "-sd", store_dir],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    end = time.time() + timeout
    while time.time() < end:
        try:
            socket.create_connection(("127.0.0.1", port), 0.1).close()
            return server, port
        except OSError:
            if server.poll() is not None:
                break
            time.sleep(0.05)
    stop(server)
    sys.exit(f"nats-server did not start on port {port} within {timeout} s")


def stop(server):
    """Stop a server started here (SIGTERM, then SIGKILL after 10 s)."""
    if server.poll() is not None:
        return
    server.send_signal(signal.SIGTERM)
    try:
        server.wait(timeout=10)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait()
