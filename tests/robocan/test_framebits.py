"""Frame lengths against known values: the worst-case formula, the CAN CRC check value, and
hand-counted stuffing."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from robot_agent.robocan.framebits import (
    EFFICIENCY_CEILING,
    _bits,
    crc15,
    frame_bits,
    stuff_bits,
    unstuffed_bits,
    worst_case_bits,
)


def test_worst_case_matches_the_kernel_formula() -> None:
    assert [worst_case_bits(n) for n in (0, 2, 4, 6, 8)] == [55, 75, 95, 115, 135]
    assert all(worst_case_bits(n) == 10 * n + 55 for n in range(9))


def test_unstuffed_length_and_the_papers_ceiling() -> None:
    assert unstuffed_bits(0) == 47
    assert unstuffed_bits(8) == 111
    assert round(100 * EFFICIENCY_CEILING, 2) == 57.66


def test_crc15_check_value() -> None:
    bits: list[int] = []
    for byte in b"123456789":
        bits += _bits(byte, 8)
    assert crc15(bits) == 0x059E  # the CRC-15/CAN check value


def test_stuffing_counts_runs_including_stuff_bits() -> None:
    assert stuff_bits([0] * 4) == 0
    assert stuff_bits([0] * 5) == 1
    assert stuff_bits([0] * 10) == 2
    # five zeros, a stuff one, then four ones make another run of five
    assert stuff_bits([0] * 5 + [1] * 4) == 2


def test_all_zero_frame_by_hand() -> None:
    # ID 0, DLC 0: 19 zero bits and a zero CRC = 34 zeros; a stuff bit after every 5: 6.
    assert frame_bits(0x000, b"") == 34 + 6 + 13


@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_exact_length_lies_between_unstuffed_and_worst_case(can_id: int, data: bytes) -> None:
    bits = frame_bits(can_id, data)
    assert unstuffed_bits(len(data)) <= bits <= worst_case_bits(len(data))
