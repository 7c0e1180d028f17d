"""The suite's own order (tests/conftest.py): the files it starts first exist, and the free
ports it gives out (tests/netports.py) are ports the kernel never picks by itself."""

from __future__ import annotations

from conftest import LONGEST, ROOT
from netports import EPHEMERAL, PORTS, free_block, free_ports


def test_every_file_named_to_start_first_exists() -> None:
    assert sorted(path for path in LONGEST if not (ROOT / path).is_file()) == []


def test_free_ports_lie_outside_the_kernels_ephemeral_range_and_are_distinct() -> None:
    low, high = (int(x) for x in EPHEMERAL.read_text().split())
    ports = free_ports(5) + [free_block(3) + i for i in range(3)]
    assert len(set(ports)) == len(ports)
    assert all(port in PORTS and not low <= port <= high for port in ports)
