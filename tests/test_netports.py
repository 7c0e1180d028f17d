"""The free ports tests give programs that take a port number (tests/netports.py) are ports
the kernel never picks by itself, never the same twice, and never the same as another pytest
process's running at the same time."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from netports import EPHEMERAL, PORTS, free_block, free_ports

TESTS = Path(__file__).resolve().parent
HOLD = f"""
import sys
sys.path.insert(0, {str(TESTS)!r})
import netports
print(netports.PORTS.start, netports.PORTS.stop, *netports.free_ports(3), flush=True)
sys.stdin.read()  # holds its stretch until the test lets it go
"""


def test_free_ports_lie_outside_the_kernels_ephemeral_range_and_are_distinct() -> None:
    low, high = (int(x) for x in EPHEMERAL.read_text().split())
    ports = free_ports(5) + [free_block(3) + i for i in range(3)]
    assert len(set(ports)) == len(ports)
    assert all(port in PORTS and not low <= port <= high for port in ports)


def test_two_pytest_processes_at_once_give_out_ports_of_their_own() -> None:
    """Two `pytest` processes side by side with the same worker number (as two plain runs,
    which both count as worker 0; gw40 here, which this suite's own workers do not take
    first): each gives out ports of a stretch of its own, and the stretch of one that ended
    is free for the next."""
    env = {**os.environ, "PYTEST_XDIST_WORKER": "gw40"}

    def holder() -> subprocess.Popen[str]:
        return subprocess.Popen(
            [sys.executable, "-c", HOLD],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=env,
        )

    def stretch(process: subprocess.Popen[str]) -> tuple[range, list[int]]:
        assert process.stdout is not None
        start, stop, *ports = (int(word) for word in process.stdout.readline().split())
        return range(start, stop), ports

    with holder() as first, holder() as second:
        (one, given_one), (two, given_two) = stretch(first), stretch(second)
        assert set(one).isdisjoint(two), f"both processes give out ports of {one} and {two}"
        assert set(given_one) <= set(one) and set(given_two) <= set(two)
        first.communicate()  # it ends, and its lock with it
        with holder() as third:
            again, _ = stretch(third)
            third.communicate()
        second.communicate()
    assert (first.returncode, second.returncode, third.returncode) == (0, 0, 0)
    assert again == one
