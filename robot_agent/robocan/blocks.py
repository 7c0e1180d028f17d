"""Block transfer: data longer than 8 bytes in several frames, with sequence numbers and flow
control (docs/robocan.md, "Block transfer").

Sans-I/O state machines: they take received frames and return the frames to send, so the
master and the simulated firmware share one implementation and tests can drop frames at will.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable, Collection

from robot_agent.robocan.protocol import (
    BLOCK_RETRIES,
    BLOCK_SIZE,
    MAX_BLOCK,
    EndStatus,
    FlowStatus,
    Op,
    ProtocolError,
)

__all__ = ["BlockReceiver", "BlockSender", "BlockState", "frame_count"]

FIRST_BYTES = 4  # data bytes in the start frame
DATA_BYTES = 6  # data bytes in each data frame


class BlockState(enum.Enum):
    ACTIVE = "active"
    DONE = "done"
    FAILED = "failed"


def frame_count(length: int) -> int:
    """Data frames after the start frame for a block of ``length`` bytes."""
    rest = max(0, length - FIRST_BYTES)
    return (rest + DATA_BYTES - 1) // DATA_BYTES


def flow(status: FlowStatus, next_seq: int, block_size: int = BLOCK_SIZE) -> bytes:
    return bytes([Op.BLOCK_FLOW, status, next_seq, block_size])


def end(status: EndStatus, block_type: int) -> bytes:
    return bytes([Op.BLOCK_END, status, block_type])


class BlockSender:
    """Sends one block: the start frame, then data frames as flow-control frames allow."""

    def __init__(self, block_type: int, data: bytes) -> None:
        if len(data) > MAX_BLOCK:
            raise ProtocolError(f"block of {len(data)} bytes exceeds {MAX_BLOCK}")
        self.block_type = block_type
        self.data = data
        self.frames = frame_count(len(data))
        self.state = BlockState.ACTIVE
        self.end_status: EndStatus | None = None

    def start(self) -> bytes:
        head = struct.pack("<BBH", Op.BLOCK_START, self.block_type, len(self.data))
        return head + self.data[:FIRST_BYTES]

    def data_frame(self, seq: int) -> bytes:
        offset = FIRST_BYTES + (seq - 1) * DATA_BYTES
        return bytes([Op.BLOCK_DATA, seq]) + self.data[offset : offset + DATA_BYTES]

    def on_frame(self, frame: bytes) -> list[bytes]:
        """Feed a BLOCK_FLOW or BLOCK_END frame from the receiver; returns frames to send."""
        if self.state is not BlockState.ACTIVE:
            return []
        if frame[0] == Op.BLOCK_END:
            known = frame[1] <= max(EndStatus)
            self.end_status = EndStatus(frame[1]) if known else EndStatus.SEQUENCE
            self.state = BlockState.DONE if frame[1] == EndStatus.OK else BlockState.FAILED
            return []
        if frame[0] != Op.BLOCK_FLOW or len(frame) != 4:
            raise ProtocolError("expected a flow or end frame")
        status, next_seq, size = frame[1], frame[2], frame[3]
        if status == FlowStatus.ABORT:
            self.state = BlockState.FAILED
            return []
        if status == FlowStatus.WAIT:
            return []
        if not 1 <= next_seq <= self.frames:
            raise ProtocolError(f"flow asks for frame {next_seq} of {self.frames}")
        last = self.frames if size == 0 else min(self.frames, next_seq + size - 1)
        return [self.data_frame(seq) for seq in range(next_seq, last + 1)]


class BlockReceiver:
    """Receives one block announced by a start frame; detects lost and repeated frames."""

    def __init__(
        self,
        start: bytes,
        *,
        block_size: int = BLOCK_SIZE,
        types: Collection[int] | None = None,
        accept: Callable[[int, bytes], bool] | None = None,
    ) -> None:
        """``types``: the block types this receiver takes (None = any); another is refused
        with BLOCK_END UNKNOWN_TYPE. ``accept(type, data)`` judges a block that arrived whole:
        False = BLOCK_END REFUSED instead of OK (bad content)."""
        self.accept = accept
        if len(start) < 4 or start[0] != Op.BLOCK_START:
            raise ProtocolError("not a block start frame")
        _, self.block_type, self.length = struct.unpack("<BBH", start[:4])
        self.block_size = block_size
        self.buffer = bytearray(start[4:])
        self.frames = frame_count(self.length)
        self.expected = 1
        self.retries = 0
        self.state = BlockState.ACTIVE
        self.error: EndStatus | None = None
        self.window_end = 0
        self.resync = False  # a resend was asked for: drop frames until the missing one comes
        if types is not None and self.block_type not in types:
            self._fail(EndStatus.UNKNOWN_TYPE)
        elif self.length > MAX_BLOCK:
            self._fail(EndStatus.TOO_LONG)
        elif len(start) - 4 != min(FIRST_BYTES, self.length):
            raise ProtocolError("block start frame length does not match the block length")

    def _fail(self, status: EndStatus) -> bytes:
        self.state = BlockState.FAILED
        self.error = status
        return end(status, self.block_type)

    def first_reply(self) -> bytes:
        """The answer to the start frame: flow control, or END when the block is empty/refused."""
        if self.state is BlockState.FAILED:
            return end(self.error or EndStatus.TOO_LONG, self.block_type)
        if self.frames == 0:
            return self._complete()
        return self._continue()

    def _complete(self) -> bytes:
        """Every byte is here: OK, or REFUSED when the content is not acceptable."""
        if self.accept is not None and not self.accept(self.block_type, bytes(self.buffer)):
            return self._fail(EndStatus.REFUSED)
        self.state = BlockState.DONE
        return end(EndStatus.OK, self.block_type)

    def _continue(self) -> bytes:
        self.window_end = (
            self.frames if self.block_size == 0 else self.expected + self.block_size - 1
        )
        return flow(FlowStatus.CONTINUE, self.expected, self.block_size)

    def on_data(self, frame: bytes) -> list[bytes]:
        """Feed a BLOCK_DATA frame; returns the frames to answer with (flow or end)."""
        if self.state is not BlockState.ACTIVE:
            return []
        seq = frame[1]
        if seq < self.expected:
            return []  # a repeat of a frame we already hold: ignore
        if seq > self.expected:
            # A frame was lost: ask once per gap for a resend from the missing one.
            if self.resync:
                return []
            self.resync = True
            return self._retry()
        self.resync = False
        remaining = self.length - len(self.buffer)
        payload = frame[2:]
        if len(payload) != min(DATA_BYTES, remaining):
            return [self._fail(EndStatus.SEQUENCE)]
        self.buffer += payload
        self.expected += 1
        if self.expected > self.frames:
            return [self._complete()]
        if seq == self.window_end:
            return [self._continue()]
        return []

    def _retry(self, give_up: EndStatus = EndStatus.SEQUENCE) -> list[bytes]:
        """Ask again from the missing frame. The count is per block: the fourth request in
        one block (gap or time-out) ends it instead, with ``give_up`` as the status."""
        self.retries += 1
        if self.retries > BLOCK_RETRIES:
            return [self._fail(give_up)]
        return [self._continue()]

    def on_timeout(self) -> list[bytes]:
        """No data frame for BLOCK_TIMEOUT_S: ask again from the missing frame, or give up
        with BLOCK_END TIMEOUT."""
        if self.state is not BlockState.ACTIVE:
            return []
        return self._retry(EndStatus.TIMEOUT)

    @property
    def data(self) -> bytes:
        return bytes(self.buffer)
