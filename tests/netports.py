"""Free TCP ports on 127.0.0.1 for processes that take a port number (not port 0).

They are taken below the kernel's ephemeral range (``ip_local_port_range``), where the kernel
never picks a port by itself: between the moment a port is chosen here and the moment the
process it is given to binds it, no connection of a neighbour can take it as its local end
and no ``bind(("127.0.0.1", 0))`` can be handed it (with ports chosen by binding port 0 and
closing, both could, which kept the demo's tests out of the parallel run). Each pytest-xdist
worker takes ports from a stretch of its own, so two workers never give out the same one; a
port that something holds (or that is in TIME_WAIT) is skipped.
"""

from __future__ import annotations

import os
import re
import socket
from pathlib import Path

__all__ = ["free_block", "free_ports"]

EPHEMERAL = Path("/proc/sys/net/ipv4/ip_local_port_range")
LOWEST = 10_000
"""No port below this is given (well-known services cluster lower)."""
STRETCH = 500
"""Ports per pytest-xdist worker."""


def _stretch() -> range:
    """This process's ports: below the ephemeral range, a stretch per pytest-xdist worker."""
    try:
        low, high = (int(x) for x in EPHEMERAL.read_text().split())
    except (OSError, ValueError):
        low, high = 32768, 60999  # Linux's default
    match = re.fullmatch(r"gw(\d+)", os.environ.get("PYTEST_XDIST_WORKER", ""))
    worker = int(match[1]) if match else 0
    stretches = (low - LOWEST) // STRETCH
    if stretches >= 1:
        start = LOWEST + (worker % stretches) * STRETCH
    else:  # an ephemeral range that starts low: above it instead
        start = high + 1 + (worker % max(1, (65535 - high) // STRETCH)) * STRETCH
    return range(start, min(start + STRETCH, 65536))


PORTS = _stretch()
_next = 0


def _is_free(port: int) -> bool:
    with socket.socket() as sock:
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_block(count: int) -> int:
    """The first of ``count`` consecutive free ports (for a program that takes ``PORT``,
    ``PORT + 1``, ..., as the demo's robots' touch screens do)."""
    global _next
    for _ in range(len(PORTS)):
        if _next + count > len(PORTS):
            _next = 0
        first = PORTS[_next]
        _next += 1
        if all(_is_free(port) for port in range(first, first + count)):
            _next += count - 1  # the next caller starts after the block
            return first
    raise RuntimeError(f"no {count} consecutive free ports in {PORTS}")


def free_ports(count: int) -> list[int]:
    """``count`` distinct ports free now."""
    return [free_block(1) for _ in range(count)]
