"""The conformance kit's raw master: a probe that sends frames as a master would and records
every frame of the module under test, and the measurements the checks make with it (periods,
frame matchers, expected ACK statuses). conformance.py holds the checks themselves.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import can

from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState

__all__ = [
    "PERIOD_TOLERANCE",
    "SILENCE_S",
    "CheckFailed",
    "Frame",
    "Probe",
    "battery_charging",
    "expect_status",
    "frame_is",
    "median_interval",
    "near",
    "periods",
    "servo_at",
]

SILENCE_S = 0.3  # how long "no answer" is watched for
PERIOD_TOLERANCE = 0.3  # a measured period may be off by this fraction


class CheckFailed(AssertionError):
    """A module did not behave as the spec says; the message says how."""


@dataclass
class Frame:
    t: float  # wall-clock time stamp (time.time), as python-can stamps frames
    can_id: int
    data: bytes


@dataclass
class Probe:
    """A raw master: sends on M + 1 (or 0x001) and records every frame from M."""

    bus: can.BusABC
    module_id: int
    frames: list[Frame] = field(default_factory=list)
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def on_batch(self, batch: list[can.Message]) -> None:
        for msg in batch:
            if msg.arbitration_id == self.module_id and not msg.is_extended_id:
                # the bus's own time stamp (wall clock): no event-loop latency in the periods
                stamp = msg.timestamp or time.time()
                self.frames.append(Frame(stamp, msg.arbitration_id, bytes(msg.data)))
        self.changed.set()

    def send(self, data: bytes, *, can_id: int | None = None, extended: bool = False) -> None:
        target = self.module_id + 1 if can_id is None else can_id
        self.bus.send(can.Message(arbitration_id=target, data=data, is_extended_id=extended))

    def mark(self) -> int:
        return len(self.frames)

    def since(self, mark: int, op: int | None = None) -> list[Frame]:
        return [
            f
            for f in self.frames[mark:]
            if op is None or (f.data and (f.data[0] == op or (op == 0 and f.data[0] <= 0x0F)))
        ]

    async def expect(
        self, mark: int, match: Callable[[bytes], bool], timeout: float, what: str
    ) -> Frame:
        """The first frame from ``mark`` on that matches; CheckFailed after ``timeout``."""
        deadline = time.monotonic() + timeout
        seen = mark
        while True:
            for frame in self.frames[seen:]:
                if match(frame.data):
                    return frame
            seen = len(self.frames)
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise CheckFailed(f"no {what} within {timeout:.2f} s")
            self.changed.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(remaining):
                    await self.changed.wait()

    async def command(self, data: bytes, timeout: float = 0.5) -> int:
        """Send a command that is acknowledged; return the ACK's status byte. The ACK must
        repeat the opcode and element (0xFF for SET_CHARGING)."""
        element = p.MODULE if data[0] == p.Op.SET_CHARGING else data[1]
        mark = self.mark()
        self.send(data)
        frame = await self.expect(
            mark,
            lambda d: len(d) == 4 and d[0] == p.Op.ACK and d[1] == data[0] and d[2] == element,
            timeout,
            f"ACK to 0x{data[0]:02X} element {element}",
        )
        return frame.data[3]

    async def silence(self, mark: int, ignore_watchdogs: bool = True) -> list[bytes]:
        """Frames (other than watchdogs) the module sent during SILENCE_S from ``mark``."""
        await asyncio.sleep(SILENCE_S)
        return [f.data for f in self.frames[mark:] if not (ignore_watchdogs and f.data[0] <= 0x0F)]

    async def query(self, *, drop: int | None = None, pause_after: int | None = None) -> bytes:
        """QUERY and receive the DESCRIPTION as a receiver would. ``drop``: ignore that data
        frame the first time (a gap: ask again from it). ``pause_after``: a first window of
        that many frames, then 300 ms of silence, then the rest in one window."""
        mark = self.mark()
        self.send(bytes([p.Op.QUERY]))
        start = await self.expect(
            mark, lambda d: d[0] == p.Op.BLOCK_START, 1.0, "BLOCK_START after QUERY"
        )
        receiver = BlockReceiver(start.data, types=(p.BlockType.DESCRIPTION,))
        if receiver.state is BlockState.FAILED:
            raise CheckFailed(f"description block refused: {receiver.error}")
        first = receiver.first_reply()
        if receiver.state is not BlockState.ACTIVE:
            return receiver.data
        if pause_after is not None:
            first = bytes([p.Op.BLOCK_FLOW, p.FlowStatus.CONTINUE, 1, pause_after])
        mark = self.mark()
        self.send(first)
        dropped = False
        received = 0
        while receiver.state is BlockState.ACTIVE:
            frame = await self.expect(
                mark, lambda d: d[0] == p.Op.BLOCK_DATA, 1.0, "BLOCK_DATA of the description"
            )
            mark = self.frames.index(frame, mark) + 1
            if drop is not None and frame.data[1] == drop and not dropped:
                dropped = True
                continue
            replies = receiver.on_data(frame.data)
            received += 1
            if pause_after is not None and received == pause_after:
                await asyncio.sleep(SILENCE_S)
                if [f for f in self.since(mark) if f.data[0] == p.Op.BLOCK_DATA]:
                    raise CheckFailed("sent beyond the window the flow frame allowed")
                replies = [bytes([p.Op.BLOCK_FLOW, p.FlowStatus.CONTINUE, received + 1, 0])]
                pause_after = None
            for reply in replies:
                self.send(reply)
        if receiver.state is BlockState.FAILED:
            raise CheckFailed(f"description transfer failed: {receiver.error}")
        return receiver.data

    async def send_block(
        self, block_type: int, data: bytes, *, drop: int | None = None, stall: int | None = None
    ) -> int:
        """Send a block to the module; return its BLOCK_END status. ``drop``: that data frame
        is not sent the first time (the module must ask for it). ``stall``: stop after that
        frame until the module asks again on its own time-out."""
        sender = BlockSender(block_type, data)
        mark = self.mark()
        self.send(sender.start())
        while sender.state is BlockState.ACTIVE:
            reply = await self.expect(
                mark,
                lambda d: d[0] in (p.Op.BLOCK_FLOW, p.Op.BLOCK_END),
                1.0,
                "BLOCK_FLOW or BLOCK_END from the receiving module",
            )
            mark = self.frames.index(reply, mark) + 1
            asked = time.time()
            for frame in sender.on_frame(reply.data):
                if frame[1] == drop:
                    drop = None
                    continue
                self.send(frame)
                if frame[1] == stall:
                    stall = None
                    again = await self.expect(
                        mark, lambda d: d[0] == p.Op.BLOCK_FLOW, 1.0, "a re-request on time-out"
                    )
                    waited = again.t - asked
                    if not 0.15 <= waited <= 0.6:
                        raise CheckFailed(f"re-request after {waited * 1000:.0f} ms, not ~250")
                    break
        return sender.end_status if sender.end_status is not None else -1


def expect_status(got: int, want: p.AckStatus, what: str) -> None:
    if got != want:
        name = p.AckStatus(got).name if got <= max(p.AckStatus) else str(got)
        raise CheckFailed(f"{what}: ACK {name}, expected {want.name}")


async def periods(probe: Probe, op: int, element: int | None, count: int, timeout: float) -> float:
    """Median interval between ``count`` + 1 frames of an opcode (and element)."""
    mark = probe.mark()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        times = [
            f.t
            for f in probe.since(mark, op)
            if element is None or (len(f.data) > 1 and f.data[1] == element)
        ]
        if len(times) > count:
            return median_interval(times)
        await asyncio.sleep(0.02)
    raise CheckFailed(f"fewer than {count + 1} frames 0x{op:02X} in {timeout:.1f} s")


def median_interval(times: list[float]) -> float:
    return statistics.median(b - a for a, b in itertools.pairwise(times))


def frame_is(op: int, element: int) -> Callable[[bytes], bool]:
    """Matches a frame with this opcode naming this element."""
    return lambda d: len(d) > 1 and d[0] == op and d[1] == element


def battery_charging(on: int) -> Callable[[bytes], bool]:
    return lambda d: len(d) == 5 and d[0] == p.Op.BATTERY and d[4] & 1 == on


def servo_at(element: int, target: float) -> Callable[[bytes], bool]:
    """Matches the SERVO frame of servo 0 of ``element`` in position at ``target``."""

    def match(d: bytes) -> bool:
        if len(d) != 6 or d[0] != p.Op.SERVO or d[1] != element:
            return False
        _, index, position, in_position = p.parse_servo(d)
        return index == 0 and in_position and abs(position - target) < 0.05

    return match


def near(measured: float, expected: float, what: str) -> None:
    if abs(measured - expected) > expected * PERIOD_TOLERANCE:
        raise CheckFailed(
            f"{what}: period {measured * 1000:.0f} ms, expected {expected * 1000:.0f}"
        )
