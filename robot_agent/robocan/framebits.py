"""Exact CAN 2.0A frame lengths in bits, stuff bits included (for the bandwidth study).

A data frame is SOF, 11-bit ID, RTR, IDE, r0, 4-bit DLC, data, 15-bit CRC (the stuffed part:
34 + 8n bits), then CRC delimiter, ACK slot, ACK delimiter, 7-bit EOF and the 3-bit interframe
space (13 bits, never stuffed). A stuff bit follows every run of five equal bits.
"""

from __future__ import annotations

__all__ = [
    "EFFICIENCY_CEILING",
    "crc15",
    "frame_bits",
    "stuff_bits",
    "unstuffed_bits",
    "worst_case_bits",
]

TAIL_BITS = 1 + 1 + 1 + 7 + 3  # CRC delimiter, ACK slot, ACK delimiter, EOF, interframe space
EFFICIENCY_CEILING = 64 / 111  # the paper's 57.66 %: 8 data bytes over the unstuffed frame


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def crc15(bits: list[int]) -> int:
    """The CAN CRC-15 (polynomial 0x4599) over the bit stream from SOF to the end of data."""
    crc = 0
    for bit in bits:
        top = ((crc >> 14) & 1) ^ bit
        crc = (crc << 1) & 0x7FFF
        if top:
            crc ^= 0x4599
    return crc


def stuffable_bits(can_id: int, data: bytes, *, remote: bool = False) -> list[int]:
    """SOF through CRC: the bits the transmitter stuffs."""
    if not 0 <= can_id <= 0x7FF:
        raise ValueError(f"0x{can_id:X} is not an 11-bit identifier")
    if len(data) > 8:
        raise ValueError("CAN 2.0 frames carry at most 8 data bytes")
    bits = [0, *_bits(can_id, 11), 1 if remote else 0, 0, 0, *_bits(len(data), 4)]
    if not remote:
        for byte in data:
            bits += _bits(byte, 8)
    return bits + _bits(crc15(bits), 15)


def stuff_bits(bits: list[int]) -> int:
    """Stuff bits a transmitter inserts: one after five equal bits; it counts in the run."""
    count, run, last = 0, 0, -1
    for bit in bits:
        if bit == last:
            run += 1
        else:
            last, run = bit, 1
        if run == 5:
            count += 1
            last, run = 1 - bit, 1  # the stuff bit starts a new run
    return count


def frame_bits(can_id: int, data: bytes, *, remote: bool = False) -> int:
    """Exact length on the wire, stuff bits and the 3-bit interframe space included."""
    bits = stuffable_bits(can_id, data, remote=remote)
    return len(bits) + stuff_bits(bits) + TAIL_BITS


def unstuffed_bits(n: int) -> int:
    """8n + 47: the length without stuff bits (interframe space included)."""
    return 8 * n + 47


def worst_case_bits(n: int) -> int:
    """8n + 47 + floor((34 + 8n - 1) / 4) = 10n + 55 (the Linux kernel's can_frame_bits)."""
    return 8 * n + 47 + (34 + 8 * n - 1) // 4
