"""Free TCP ports on 127.0.0.1 for processes that take a port number (not port 0)."""

from __future__ import annotations

import socket


def free_ports(count: int) -> list[int]:
    """Distinct ports free now (held together while chosen, so never the same twice)."""
    sockets = [socket.socket() for _ in range(count)]
    for sock in sockets:
        sock.bind(("127.0.0.1", 0))
    ports = [int(s.getsockname()[1]) for s in sockets]
    for sock in sockets:
        sock.close()
    return ports
