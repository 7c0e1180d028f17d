"""The free ports tests give programs that take a port number (tests/netports.py) are ports
the kernel never picks by itself, and never the same twice."""

from __future__ import annotations

from netports import EPHEMERAL, PORTS, free_block, free_ports


def test_free_ports_lie_outside_the_kernels_ephemeral_range_and_are_distinct() -> None:
    low, high = (int(x) for x in EPHEMERAL.read_text().split())
    ports = free_ports(5) + [free_block(3) + i for i in range(3)]
    assert len(set(ports)) == len(ports)
    assert all(port in PORTS and not low <= port <= high for port in ports)
