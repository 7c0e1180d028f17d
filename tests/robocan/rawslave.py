"""Test helpers written from docs/robocan.md alone: a raw slave (frames by hand, no simulator
code) and a tap that watches every frame on a virtual channel."""

from __future__ import annotations

import asyncio

import can

from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState
from robot_agent.robocan.busopen import open_bus


class RawSlave:
    """A slave that sends and receives raw frames on ``module_id`` / ``module_id + 1``."""

    def __init__(self, channel: str, module_id: int) -> None:
        self.module_id = module_id
        self.bus = open_bus(channel)
        self.bus.set_filters(
            [
                {"can_id": module_id + 1, "can_mask": 0x7FF, "extended": False},
                {"can_id": p.BROADCAST_ID, "can_mask": 0x7FF, "extended": False},
            ]
        )
        self.reader = can.AsyncBufferedReader()
        self.notifier = can.Notifier(
            self.bus, [self.reader], timeout=0.05, loop=asyncio.get_running_loop()
        )

    def send(self, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=self.module_id, data=data, is_extended_id=False))

    async def expect(self, op: int, timeout: float = 5.0) -> bytes:
        """The next frame to us with this opcode (others, e.g. MASTER_START, are skipped)."""
        async with asyncio.timeout(timeout):
            while True:
                msg = await self.reader.get_message()
                if msg.data[0] == op:
                    return bytes(msg.data)

    async def bring_up(self, description: p.Description, timeout: float = 10.0) -> bytes:
        """Announce ourselves, answer QUERY with ``description``, acknowledge every parameter
        and mode with OK, take CONFIG blocks, and return the ENABLE frame (not acknowledged:
        the caller does that)."""
        self.send(p.watchdog(p.SlaveState.DISABLED))
        sender: BlockSender | None = None
        receiver: BlockReceiver | None = None
        async with asyncio.timeout(timeout):
            while True:
                data = bytes((await self.reader.get_message()).data)
                op = data[0]
                if op == p.Op.QUERY:
                    sender = BlockSender(p.BlockType.DESCRIPTION, description.encode())
                    self.send(sender.start())
                elif op in (p.Op.BLOCK_FLOW, p.Op.BLOCK_END) and sender is not None:
                    for frame in sender.on_frame(data):
                        self.send(frame)
                elif op == p.Op.BLOCK_START:
                    receiver = BlockReceiver(data)
                    self.send(receiver.first_reply())
                elif op == p.Op.BLOCK_DATA and receiver is not None:
                    for frame in receiver.on_data(data):
                        self.send(frame)
                    if receiver.state is not BlockState.ACTIVE:
                        receiver = None
                elif op in (p.Op.SET_PARAM, p.Op.SET_MODE):
                    self.send(p.ack(op, data[1]))
                elif op == p.Op.ENABLE:
                    return data

    async def close(self) -> None:
        await asyncio.to_thread(self.notifier.stop, 1.0)
        self.bus.shutdown()


class Tap:
    """Every frame on a channel, as the wire carries it; wait for one by ID and opcode."""

    def __init__(self, channel: str) -> None:
        self.bus = open_bus(channel)
        self.frames: list[can.Message] = []
        self.notifier = can.Notifier(self.bus, [self.frames.append], timeout=0.05)

    def send(self, can_id: int, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def of(self, can_id: int, op: int | None = None, start: int = 0) -> list[bytes]:
        return [
            bytes(m.data)
            for m in self.frames[start:]
            if m.arbitration_id == can_id and (op is None or (m.data and m.data[0] == op))
        ]

    async def expect(self, can_id: int, op: int, start: int = 0, timeout: float = 5.0) -> bytes:
        """The first frame on ``can_id`` with opcode ``op`` seen from index ``start`` on."""
        async with asyncio.timeout(timeout):
            while True:
                found = self.of(can_id, op, start)
                if found:
                    return found[0]
                await asyncio.sleep(0.01)

    def close(self) -> None:
        self.notifier.stop(1.0)
        self.bus.shutdown()
