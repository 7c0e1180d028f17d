"""Free TCP ports on 127.0.0.1 for processes that take a port number (not port 0).

They are taken below the kernel's ephemeral range (``ip_local_port_range``), where the kernel
never picks a port by itself: between the moment a port is chosen here and the moment the
process it is given to binds it, no connection of a neighbour can take it as its local end
and no ``bind(("127.0.0.1", 0))`` can be handed it (with ports chosen by binding port 0 and
closing, both could, which kept the demo's tests out of the parallel run).

Each process gives out ports from a stretch of its own, which it holds with a lock file
(``flock`` on ``LOCKS/<first port>.lock``) for as long as it runs: the pytest-xdist workers of
one run, two plain ``pytest`` processes started side by side and two runs of ``-n`` at once
never give out the same port. A process starts with the stretch of its pytest-xdist worker
number and takes the next free one when another process holds it; the kernel drops the lock
when the process ends, however it ends. A port that something holds (or that is in
TIME_WAIT) is skipped.
"""

from __future__ import annotations

import atexit
import fcntl
import os
import re
import socket
import tempfile
from pathlib import Path
from typing import IO

__all__ = ["free_block", "free_ports"]

EPHEMERAL = Path("/proc/sys/net/ipv4/ip_local_port_range")
LOCKS = Path(tempfile.gettempdir()) / "guidebot-netports"
"""One lock file per stretch, held by the process that gives out its ports."""
LOWEST = 10_000
"""No port below this is given (well-known services cluster lower)."""
STRETCH = 500
"""Ports per process."""


def _starts() -> list[int]:
    """The first port of every stretch: below the ephemeral range, or above it when it
    starts too low to leave one."""
    try:
        low, high = (int(x) for x in EPHEMERAL.read_text().split())
    except (OSError, ValueError):
        low, high = 32768, 60999  # Linux's default
    if (low - LOWEST) // STRETCH >= 1:
        return list(range(LOWEST, low - STRETCH + 1, STRETCH))
    return list(range(high + 1, 65536 - STRETCH + 1, STRETCH)) or [high + 1]


def _claim() -> tuple[range, IO[str]]:
    """Lock a stretch no other process holds, starting at this pytest-xdist worker's."""
    starts = _starts()
    match = re.fullmatch(r"gw(\d+)", os.environ.get("PYTEST_XDIST_WORKER", ""))
    first = int(match[1]) if match else 0
    LOCKS.mkdir(mode=0o1777, exist_ok=True)
    for i in range(len(starts)):
        start = starts[(first + i) % len(starts)]
        lock = (LOCKS / f"{start}.lock").open("a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # another process gives out these ports
            lock.close()
            continue
        return range(start, min(start + STRETCH, 65536)), lock
    raise RuntimeError(f"every stretch of {STRETCH} ports is held by another process ({LOCKS})")


PORTS, _LOCK = _claim()
atexit.register(_LOCK.close)  # held to the end, then closed: no "unclosed file" at exit
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
