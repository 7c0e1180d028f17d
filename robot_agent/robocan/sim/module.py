"""Firmware skeleton every simulated module shares: watchdog, query and description,
parameters, modes, enable, blocks, and the deliberate flaws the conformance checks must catch.
"""

from __future__ import annotations

import logging
import time

import can

from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState
from robot_agent.robocan.sim.host import DUE_EPS_S, SimHost, next_slot

__all__ = ["BLOCK_OPS", "FLAWS", "SimModule"]

log = logging.getLogger(__name__)

BLOCK_OPS = frozenset({p.Op.BLOCK_START, p.Op.BLOCK_DATA, p.Op.BLOCK_FLOW, p.Op.BLOCK_END})
FLAWS: dict[str, str] = {
    "accepts_any_value": "SET_PARAM takes values outside their range (no BAD_VALUE)",
    "no_command_timeout": "a motor keeps its last velocity when the commands stop",
    "answers_broadcast": "acts on any opcode sent to the broadcast ID 0x001",
    "no_state_on_enable": "no BUMPERS / INPUTS frame after the ACK to ENABLE",
}
"""Deliberate defects a simulated module can be built with (``flaws=``), to prove that the
conformance checks catch them."""


class SimModule:
    """Firmware skeleton: watchdog, query/description, parameters, modes, enable, blocks."""

    description: p.Description

    def __init__(
        self,
        bus_spec: str,
        module_id: int,
        *,
        time_scale: float = 1.0,
        flaws: frozenset[str] = frozenset(),
    ) -> None:
        if not p.is_module_id(module_id):
            raise ValueError(f"module id 0x{module_id:X} is not an even ID in 0x02..0x7FE")
        unknown = set(flaws) - set(FLAWS)
        if unknown:
            raise ValueError(f"unknown flaws {sorted(unknown)}; known: {', '.join(FLAWS)}")
        self.flaws = frozenset(flaws)
        self.bus_spec = bus_spec
        self.module_id = module_id
        self.time_scale = time_scale
        self.state = p.SlaveState.DISABLED
        self.watchdog_s = p.WATCHDOG_PERIOD_S
        self.params: dict[tuple[int, int], int] = {}
        self.modes: dict[int, int] = {}
        self.configs: dict[tuple[int, int], bytes] = {}
        self.frames_tx = 0
        self.drop_block_frames: set[int] = set()  # fault injection: data frames never sent
        self.host: SimHost | None = None
        self._own_host = False
        self._sender: BlockSender | None = None
        self._receiver: BlockReceiver | None = None
        self._receiver_seen = 0.0  # last frame of the block being received (its time-out)
        self._last_step = 0.0
        self.next_watchdog = 0.0
        self.running = False

    # --- life cycle -------------------------------------------------------------------

    async def start(self, host: SimHost | None = None) -> None:
        """Power on: join the bus (``host``'s, or a connection of its own) and send WATCHDOG
        at once."""
        if self.running:
            return
        if host is None:
            host, self._own_host = SimHost(self.bus_spec), True
        self.host = host
        await host.start()
        self._last_step = time.monotonic()
        self.next_watchdog = 0.0  # at once
        self.running = True
        host.attach(self)

    async def stop(self) -> None:
        """Power off (unplug): silence at once."""
        if not self.running:
            return
        self.running = False
        host = self.host
        if host is not None:
            host.detach(self)
            if self._own_host:
                await host.stop()

    def send(self, data: bytes) -> None:
        if not self.running or self.host is None:
            return
        if self.host.send(self.module_id, data):
            self.frames_tx += 1

    def poke(self) -> None:
        """State changed outside a received frame (a test hook): reschedule at once."""
        if self.running and self.host is not None:
            self.host.poke()

    # --- scheduling (called by the host) ----------------------------------------------

    def tick(self, now: float) -> None:
        """Send the watchdog if due, advance the physics to ``now`` and publish what is due."""
        if now + DUE_EPS_S >= self.next_watchdog:
            self.send(p.watchdog(self.state))
            self.next_watchdog = next_slot(self.next_watchdog, self.watchdog_s, now)
        receiver = self._receiver
        if receiver is not None and now + DUE_EPS_S >= self._receiver_seen + p.BLOCK_TIMEOUT_S:
            self._receiver_seen = now  # no data frame for 250 ms: ask again, or give up
            for frame in receiver.on_timeout():
                self.send(frame)
            self._finish_block()
        self.advance(now)

    def advance(self, now: float) -> None:
        dt = now - self._last_step
        self._last_step = now
        self.step(now, max(0.0, dt) * self.time_scale)

    def next_due(self) -> float:
        """The monotonic time of the next frame this module owes without being asked."""
        if self._receiver is not None:
            return min(self.next_watchdog, self._receiver_seen + p.BLOCK_TIMEOUT_S)
        return self.next_watchdog

    @property
    def active(self) -> bool:
        """Something moves: the physics must be stepped every TICK_S."""
        return False

    def due(self, deadline: float, now: float) -> bool:
        return now + DUE_EPS_S >= deadline

    # --- what a concrete module does --------------------------------------------------

    def step(self, now: float, dt_sim: float) -> None:
        """Advance the physics by ``dt_sim`` simulated seconds and publish what is due."""

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        """A module-specific command; return an ACK status to acknowledge it, None for none."""
        return None

    def on_param(self, element: int, param: int, value: int) -> p.AckStatus:
        return p.AckStatus.OK

    def on_stop(self) -> None:
        """Broadcast STOP or MASTER_START: stop every actuator."""

    def on_enabled(self) -> None:
        """Just enabled (after the ACK): report the state of BUMPERS / INPUTS elements."""

    def accept_config(self, element: int, number: int, data: bytes) -> bool:
        """Judge a CONFIG block that arrived whole (False = BLOCK_END REFUSED)."""
        return False

    def param(self, element: int, param: int) -> int:
        """A parameter's value: set by the master, or its power-on default."""
        value = self.params.get((element, param))
        if value is not None:
            return value
        if param == p.Param.PUBLISH_MS:
            return p.DEFAULT_PUBLISH_MS[self.description.elements[element].kind]
        return p.PARAM_DEFAULTS.get(param, 0)

    def publish_period(self, element: int) -> float:
        return self.param(element, p.Param.PUBLISH_MS) / 1000

    @property
    def enabled(self) -> bool:
        return self.state is p.SlaveState.ENABLED

    # --- receive path -----------------------------------------------------------------

    def _on_can(self, msg: can.Message, broadcast: bool = False) -> None:
        if not self.running or msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            return
        data = bytes(msg.data)
        try:
            op = p.check_length(data)
        except p.ProtocolError:
            return  # firmware ignores what it cannot parse
        if op not in p.MASTER_OPS and op not in BLOCK_OPS:
            return  # a slave opcode sent to a slave
        if broadcast and op not in p.BROADCAST_OPS and "answers_broadcast" not in self.flaws:
            return  # only MASTER_START and STOP are broadcast; anything else there is ignored
        try:
            self.advance(time.monotonic())  # the physics up to now, under the old command
            self._dispatch(op, data)
        except Exception:
            log.exception("sim 0x%02X: frame 0x%02X failed", self.module_id, op)

    def _dispatch(self, op: int, data: bytes) -> None:
        if op == p.Op.QUERY:
            self._sender = BlockSender(p.BlockType.DESCRIPTION, self.description.encode())
            self.send(self._sender.start())
        elif op in (p.Op.BLOCK_FLOW, p.Op.BLOCK_END):
            if self._sender is not None and self._sender.state is BlockState.ACTIVE:
                for frame in self._sender.on_frame(data):
                    if frame[1] in self.drop_block_frames:
                        self.drop_block_frames.discard(frame[1])
                        continue
                    self.send(frame)
        elif op == p.Op.BLOCK_START:
            self._receiver = BlockReceiver(
                data, types=(p.BlockType.CONFIG,), accept=self._accept_block
            )
            self._receiver_seen = time.monotonic()
            self.send(self._receiver.first_reply())
            self._finish_block()
        elif op == p.Op.BLOCK_DATA:
            if self._receiver is not None:
                self._receiver_seen = time.monotonic()
                for frame in self._receiver.on_data(data):
                    self.send(frame)
                self._finish_block()
        elif op == p.Op.SET_PARAM:
            element, param, value = p.parse_set_param(data)
            status = self._set_param(element, param, value)
            self.send(p.ack(op, element, status))
        elif op == p.Op.SET_MODE:
            element, mode = data[1], data[2]
            status = self._set_mode(element, mode)
            if status is p.AckStatus.OK:
                self.modes[element] = mode
            self.send(p.ack(op, element, status))
        elif op == p.Op.ENABLE:
            self._enable(data[1], data[2])
        elif op == p.Op.MASTER_START:
            self.state = p.SlaveState.DISABLED
            self.on_stop()
        elif op == p.Op.STOP:
            self.on_stop()
        elif op == p.Op.SET_CHARGING:
            reply = self.on_command(op, data)
            self.send(p.ack(op, p.MODULE, p.AckStatus.UNSUPPORTED if reply is None else reply))
        else:
            self.on_command(op, data)  # actuator commands are not acknowledged

    def _enable(self, element: int, on: int) -> None:
        """ENABLE of the module; one element alone is not supported by our firmware."""
        if element != p.MODULE:
            known = element < len(self.description.elements)
            status = p.AckStatus.UNSUPPORTED if known else p.AckStatus.UNKNOWN_ELEMENT
            self.send(p.ack(p.Op.ENABLE, element, status))
            return
        self.state = p.SlaveState.ENABLED if on else p.SlaveState.DISABLED
        if not on:
            self.on_stop()
        self.send(p.ack(p.Op.ENABLE, element))
        if on and "no_state_on_enable" not in self.flaws:
            self.on_enabled()

    def _set_mode(self, element: int, mode: int) -> p.AckStatus:
        if element >= len(self.description.elements):
            return p.AckStatus.UNKNOWN_ELEMENT
        modes = self.description.elements[element].modes
        if not modes:
            return p.AckStatus.UNSUPPORTED
        return p.AckStatus.OK if mode < 8 and modes & (1 << mode) else p.AckStatus.BAD_VALUE

    def _set_param(self, element: int, param: int, value: int) -> p.AckStatus:
        if element == p.MODULE:
            if param != p.Param.WATCHDOG_MS:
                return p.AckStatus.BAD_PARAM
            low, high = p.PARAM_RANGES[param]
            if not low <= value <= high:
                return p.AckStatus.BAD_VALUE
            self.watchdog_s = value / 1000
            return p.AckStatus.OK
        if element >= len(self.description.elements):
            return p.AckStatus.UNKNOWN_ELEMENT
        if param not in p.ELEMENT_PARAMS.get(self.description.elements[element].kind, ()):
            return p.AckStatus.BAD_PARAM
        low, high = p.PARAM_RANGES[param]
        if not low <= value <= high and "accepts_any_value" not in self.flaws:
            return p.AckStatus.BAD_VALUE
        status = self.on_param(element, param, value)
        if status is p.AckStatus.OK:
            self.params[(element, param)] = value
        return status

    def _accept_block(self, block_type: int, data: bytes) -> bool:
        return len(data) >= 2 and self.accept_config(data[0], data[1], data[2:])

    def _finish_block(self) -> None:
        receiver = self._receiver
        if receiver is None or receiver.state is BlockState.ACTIVE:
            return
        self._receiver = None
        if receiver.state is BlockState.DONE and receiver.block_type == p.BlockType.CONFIG:
            data = receiver.data
            if len(data) >= 2:
                self.configs[(data[0], data[1])] = data[2:]
