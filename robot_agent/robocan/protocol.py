"""The RoboCAN wire protocol: identifiers, opcodes and frame layouts (docs/robocan.md).

Pure functions over bytes, no I/O: the master and the simulated firmware share them, so the
two sides cannot drift apart. Every multi-byte integer is little-endian.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, field

__all__ = [
    "BROADCAST_ID",
    "BROADCAST_OPS",
    "DATA_KINDS",
    "MASTER_OPS",
    "MAX_BLOCK",
    "MAX_MODULE_ID",
    "Description",
    "Element",
    "ElementKind",
    "ModuleKind",
    "Op",
    "Param",
    "ProtocolError",
    "SlaveState",
    "is_module_id",
]

BROADCAST_ID = 0x01
MAX_MODULE_ID = 0x7FE
PROTOCOL_VERSION = 1
MAX_BLOCK = 1024  # bytes in one block transfer (4 in the start frame, 6 per data frame)

WATCHDOG_PERIOD_S = 0.100  # default, configurable per module with Param.WATCHDOG_MS
LOST_TIMEOUT_FACTOR = 3.5  # a module is lost after 3.5 watchdog periods without any frame
COMMAND_TIMEOUT_S = 0.250  # master waits this long for an ACK, then retries
COMMAND_RETRIES = 3
BLOCK_TIMEOUT_S = 0.250  # block transfer: max gap between frames / before a flow frame
BLOCK_RETRIES = 3  # retransmission requests per block before it is aborted
BLOCK_SIZE = 8  # data frames between two flow-control frames
MOTOR_COMMAND_TIMEOUT_S = 1.0  # a motor controller stops when velocity commands stop


class ProtocolError(ValueError):
    """A frame that does not follow the wire protocol (wrong length, unknown opcode...)."""


class Op(enum.IntEnum):
    """Byte 0 of every frame. 0x00-0x0F are watchdog frames (low nibble = SlaveState)."""

    # slave -> master, on the module's even ID
    WATCHDOG = 0x00
    ACK = 0x10
    ENCODER = 0x20
    BUMPERS = 0x21
    SONAR = 0x22
    SERVO = 0x23
    INPUTS = 0x24
    BATTERY = 0x25
    FAULT = 0x26
    # master -> slave, on ID + 1 (or broadcast 0x01)
    QUERY = 0x80
    SET_PARAM = 0x81
    SET_MODE = 0x82
    ENABLE = 0x83
    MASTER_START = 0x84
    SET_VELOCITY = 0x90
    SET_SERVO = 0x91
    SET_OUTPUT = 0x92
    SET_CHARGING = 0x93
    STOP = 0x94
    # block transfer, either direction
    BLOCK_START = 0xF0
    BLOCK_DATA = 0xF1
    BLOCK_FLOW = 0xF2
    BLOCK_END = 0xF3


# Exact data length (DLC) of each opcode; None = variable, checked by its decoder.
FRAME_LENGTH: dict[int, tuple[int, int]] = {
    Op.ACK: (4, 4),
    Op.ENCODER: (8, 8),
    Op.BUMPERS: (4, 4),
    Op.SONAR: (4, 8),
    Op.SERVO: (6, 6),
    Op.INPUTS: (4, 4),
    Op.BATTERY: (5, 5),
    Op.FAULT: (3, 3),
    Op.QUERY: (1, 1),
    Op.SET_PARAM: (7, 7),
    Op.SET_MODE: (3, 3),
    Op.ENABLE: (3, 3),
    Op.MASTER_START: (1, 1),
    Op.SET_VELOCITY: (7, 7),
    Op.SET_SERVO: (7, 7),
    Op.SET_OUTPUT: (4, 4),
    Op.SET_CHARGING: (2, 2),
    Op.STOP: (1, 1),
    Op.BLOCK_START: (4, 8),
    Op.BLOCK_DATA: (3, 8),
    Op.BLOCK_FLOW: (4, 4),
    Op.BLOCK_END: (3, 3),
}


MASTER_OPS = frozenset(range(0x80, 0xF0))
"""Opcodes only a master sends (0x80-0xEF). On a slave's even ID they are bad frames: counted,
dropped, and never the first frame of a module entry."""


BROADCAST_OPS = frozenset({Op.MASTER_START, Op.STOP})  # the only opcodes on ID 0x001


class SlaveState(enum.IntEnum):
    """Announced in the low nibble of every watchdog frame."""

    DISABLED = 0  # powered, not publishing data (power-on state)
    ENABLED = 1  # publishing data, accepting commands


class AckStatus(enum.IntEnum):
    OK = 0
    UNKNOWN_ELEMENT = 1
    BAD_PARAM = 2
    BAD_VALUE = 3
    UNSUPPORTED = 4


class FlowStatus(enum.IntEnum):
    CONTINUE = 0  # send from next_seq, block_size frames (0 = all the rest)
    WAIT = 1  # receiver busy: wait for another flow frame
    ABORT = 2


class EndStatus(enum.IntEnum):
    OK = 0
    SEQUENCE = 1  # too many lost frames
    TIMEOUT = 2
    TOO_LONG = 3
    BUSY = 4  # a block is already in transfer
    UNKNOWN_TYPE = 5
    REFUSED = 6  # arrived whole, but its content is not acceptable (a bad CONFIG)


class BlockType(enum.IntEnum):
    DESCRIPTION = 0x01  # slave -> master, the answer to QUERY
    CONFIG = 0x02  # master -> slave: element, param, raw bytes (e.g. a firing sequence)


class ModuleKind(enum.IntEnum):
    MOTOR_CONTROLLER = 1
    SONAR_RING = 2
    HEAD_IO = 3
    BATTERY_MONITOR = 4
    OTHER = 0xFF


class ElementKind(enum.IntEnum):
    """Kinds of components and agents; drivers are registered under the lower-case names."""

    MOTOR = 1  # component: motor and quadrature encoder
    PID_VELOCITY = 2  # agent: velocity (or position) PID
    BUMPER = 3  # component
    SONAR = 4  # component
    FIRING_SEQUENCE = 5  # agent: sonar firing sequence
    SERVO = 6  # component: RC servos
    TOUCH = 7  # component: capacitive touch inputs
    LED = 8  # component: outputs (eye LEDs)
    BATTERY = 9  # component: battery monitor and charger contact


DATA_KINDS: dict[int, frozenset[int]] = {
    Op.ENCODER: frozenset({ElementKind.MOTOR}),
    Op.BUMPERS: frozenset({ElementKind.BUMPER}),
    Op.SONAR: frozenset({ElementKind.SONAR}),
    Op.SERVO: frozenset({ElementKind.SERVO}),
    Op.INPUTS: frozenset({ElementKind.TOUCH}),
    Op.BATTERY: frozenset({ElementKind.BATTERY}),
    Op.FAULT: frozenset(ElementKind),
}
"""Data frames and the element kinds they may name. Byte 1 is the element number, except in
BATTERY, which belongs to the module's first battery element."""


class Param(enum.IntEnum):
    """SET_PARAM parameter numbers (value: int32)."""

    WATCHDOG_MS = 0x01  # element 0xFF (module)
    PUBLISH_MS = 0x02  # data publishing period of an element
    COMMAND_TIMEOUT_MS = 0x03  # pid: stop when no velocity command arrives for this long
    TICKS_PER_M = 0x04  # motor: encoder resolution
    KP = 0x10  # pid gains x 1000
    KI = 0x11
    KD = 0x12
    MAX_ACCEL = 0x13  # pid: mm/s^2


MODULE = 0xFF  # element number meaning "the whole module"

PARAM_RANGES: dict[int, tuple[int, int]] = {
    Param.WATCHDOG_MS: (10, 10_000),
    Param.PUBLISH_MS: (10, 60_000),
    Param.COMMAND_TIMEOUT_MS: (50, 10_000),  # the motor safety cannot be switched off
    Param.TICKS_PER_M: (1, 10_000_000),
    Param.KP: (0, 1_000_000),  # gains x 1000: 0 .. 1000
    Param.KI: (0, 1_000_000),
    Param.KD: (0, 1_000_000),
    Param.MAX_ACCEL: (1, 20_000),  # mm/s^2
}
"""Values a slave accepts (inclusive); outside them it answers BAD_VALUE."""

ELEMENT_PARAMS: dict[int, frozenset[int]] = {
    ElementKind.MOTOR: frozenset({Param.PUBLISH_MS, Param.TICKS_PER_M}),
    ElementKind.PID_VELOCITY: frozenset(
        {Param.COMMAND_TIMEOUT_MS, Param.KP, Param.KI, Param.KD, Param.MAX_ACCEL}
    ),
    ElementKind.SONAR: frozenset({Param.PUBLISH_MS}),
    ElementKind.BATTERY: frozenset({Param.PUBLISH_MS}),
}
"""Parameters each element kind has; any other is answered BAD_PARAM. Module-wide (element
0xFF): WATCHDOG_MS only."""

DEFAULT_PUBLISH_MS: dict[int, int] = {
    ElementKind.MOTOR: 100,
    ElementKind.SONAR: 500,
    ElementKind.BATTERY: 1000,
}
"""Publishing period of the periodic data elements until the master sets PUBLISH_MS."""

PARAM_DEFAULTS: dict[int, int] = {
    Param.COMMAND_TIMEOUT_MS: 1000,
    Param.TICKS_PER_M: 20000,
    Param.MAX_ACCEL: 2000,
}


class Role(enum.IntEnum):
    COMPONENT = 0
    AGENT = 1


def is_module_id(can_id: int) -> bool:
    """Slaves publish on even IDs 0x002..0x7FE."""
    return 2 <= can_id <= MAX_MODULE_ID and can_id % 2 == 0


def check_length(data: bytes | bytearray) -> int:
    """The opcode of a frame whose length fits it; raises ProtocolError otherwise."""
    if not data:
        raise ProtocolError("empty frame")
    op = data[0]
    if op <= 0x0F:
        if len(data) != 1:
            raise ProtocolError(f"watchdog frame must be 1 byte, got {len(data)}")
        return Op.WATCHDOG
    bounds = FRAME_LENGTH.get(op)
    if bounds is None:
        raise ProtocolError(f"unknown opcode 0x{op:02X}")
    low, high = bounds
    if not low <= len(data) <= high:
        raise ProtocolError(f"opcode 0x{op:02X} needs {low}..{high} bytes, got {len(data)}")
    return op


# --- frame builders and parsers -----------------------------------------------------------


def watchdog(state: SlaveState) -> bytes:
    return bytes([Op.WATCHDOG | int(state)])


def ack(op: int, element: int, status: AckStatus = AckStatus.OK) -> bytes:
    return bytes([Op.ACK, op, element, status])


def set_param(element: int, param: int, value: int) -> bytes:
    return struct.pack("<BBBi", Op.SET_PARAM, element, param, value)


def parse_set_param(data: bytes) -> tuple[int, int, int]:
    _, element, param, value = struct.unpack("<BBBi", data)
    return element, param, value


def set_mode(element: int, mode: int) -> bytes:
    return bytes([Op.SET_MODE, element, mode])


def enable(element: int, on: bool) -> bytes:
    return bytes([Op.ENABLE, element, 1 if on else 0])


def set_velocity(element: int, velocity_m_s: float, max_accel_m_s2: float = 0.0) -> bytes:
    """The paper's 56-bit velocity command: op, element, int32 um/s, uint8 accel (0.05 m/s^2)."""
    um_s = max(-(2**31), min(2**31 - 1, round(velocity_m_s * 1e6)))
    accel = max(0, min(255, round(max_accel_m_s2 / 0.05)))
    return struct.pack("<BBiB", Op.SET_VELOCITY, element, um_s, accel)


def parse_set_velocity(data: bytes) -> tuple[int, float, float]:
    _, element, um_s, accel = struct.unpack("<BBiB", data)
    return element, um_s / 1e6, accel * 0.05


def encoder(element: int, ticks: int, velocity_m_s: float) -> bytes:
    ticks = ((ticks + 2**31) % 2**32) - 2**31  # the counter wraps like a real int32
    mm_s = max(-32768, min(32767, round(velocity_m_s * 1000)))
    return struct.pack("<BBih", Op.ENCODER, element, ticks, mm_s)


def parse_encoder(data: bytes) -> tuple[int, int, float]:
    _, element, ticks, mm_s = struct.unpack("<BBih", data)
    return element, ticks, mm_s / 1000


def mask_frame(op: int, element: int, mask: int) -> bytes:
    return struct.pack("<BBH", op, element, mask & 0xFFFF)


def parse_mask(data: bytes) -> tuple[int, int]:
    _, element, mask = struct.unpack("<BBH", data)
    return element, mask


SONAR_UNIT_M = 0.02  # one range byte = 2 cm: 0 .. 254 = 0 .. 5.08 m
SONAR_NOTHING = 255  # no echo: nothing in range (None on board)


def sonar(element: int, first: int, ranges_m: list[float | None]) -> bytes:
    """``None``, or a range beyond 5.08 m, is sent as 255 = nothing in range."""
    if not 1 <= len(ranges_m) <= 5:
        raise ProtocolError("a sonar frame carries 1..5 ranges")
    raw = [
        SONAR_NOTHING
        if r is None or round(r / SONAR_UNIT_M) >= SONAR_NOTHING
        else max(0, round(r / SONAR_UNIT_M))
        for r in ranges_m
    ]
    return bytes([Op.SONAR, element, first, *raw])


def parse_sonar(data: bytes) -> tuple[int, int, list[float | None]]:
    """Ranges in metres; 255 = nothing in range = None (not 5.1 m)."""
    return (
        data[1],
        data[2],
        [None if b == SONAR_NOTHING else b * SONAR_UNIT_M for b in data[3:]],
    )


def servo(element: int, index: int, position_deg: float, in_position: bool) -> bytes:
    tenth = max(-32768, min(32767, round(position_deg * 10)))
    return struct.pack("<BBBhB", Op.SERVO, element, index, tenth, 1 if in_position else 0)


def parse_servo(data: bytes) -> tuple[int, int, float, bool]:
    _, element, index, tenth, flags = struct.unpack("<BBBhB", data)
    return element, index, tenth / 10, bool(flags & 1)


def set_servo(element: int, index: int, position_deg: float, speed_deg_s: float) -> bytes:
    tenth = max(-32768, min(32767, round(position_deg * 10)))
    speed = max(0, min(65535, round(speed_deg_s * 10)))
    return struct.pack("<BBBhH", Op.SET_SERVO, element, index, tenth, speed)


def parse_set_servo(data: bytes) -> tuple[int, int, float, float]:
    _, element, index, tenth, speed = struct.unpack("<BBBhH", data)
    return element, index, tenth / 10, speed / 10


def set_output(element: int, index: int, value: int) -> bytes:
    return bytes([Op.SET_OUTPUT, element, index, max(0, min(255, value))])


def battery(level: float, voltage_v: float, charging: bool) -> bytes:
    half_percent = max(0, min(200, round(level * 200)))
    mv = max(0, min(65535, round(voltage_v * 1000)))
    return struct.pack("<BBHB", Op.BATTERY, half_percent, mv, 1 if charging else 0)


def parse_battery(data: bytes) -> tuple[float, float, bool]:
    _, half_percent, mv, flags = struct.unpack("<BBHB", data)
    return half_percent / 200, mv / 1000, bool(flags & 1)


# --- the module description (block type DESCRIPTION) ------------------------------------


@dataclass(frozen=True)
class Element:
    """One component or agent of a module; its index in the description is its element number."""

    kind: int
    role: Role
    count: int = 1
    modes: int = 0  # bit i set = working mode i supported

    @property
    def kind_name(self) -> str:
        try:
            return ElementKind(self.kind).name.lower()
        except ValueError:
            return f"kind_{self.kind}"


@dataclass(frozen=True)
class Description:
    kind: int
    name: str
    firmware: tuple[int, int] = (1, 0)
    elements: tuple[Element, ...] = field(default_factory=tuple)

    def numbering(self, kind: int) -> dict[int, tuple[int, int]]:
        """Element number -> (first, count) of its instances when the module's instances of
        ``kind`` are numbered across its elements of that kind, in element order (a second
        touch element's first input follows the first element's last)."""
        out, total = {}, 0
        for number, element in enumerate(self.elements):
            if element.kind == kind:
                out[number] = (total, element.count)
                total += element.count
        return out

    def data_element(self, op: int, data: bytes) -> int | None:
        """The element a data frame belongs to, or None when it names no element of a kind
        that sends it (a bad frame)."""
        kinds = DATA_KINDS[op]
        if op == Op.BATTERY:
            return next((i for i, e in enumerate(self.elements) if e.kind in kinds), None)
        number = data[1]
        if number < len(self.elements) and self.elements[number].kind in kinds:
            return number
        return None

    def encode(self) -> bytes:
        name = self.name.encode("ascii")
        if len(name) > 32 or len(self.elements) > 32:
            raise ProtocolError("module name and element list are limited to 32")
        out = bytearray([PROTOCOL_VERSION, self.kind, *self.firmware, len(name)])
        out += name
        out.append(len(self.elements))
        for e in self.elements:
            out += bytes([e.kind, e.role, e.count, e.modes])
        return bytes(out)

    @classmethod
    def decode(cls, data: bytes) -> Description:
        try:
            version, kind, major, minor, name_len = data[:5]
            if version != PROTOCOL_VERSION:
                raise ProtocolError(f"protocol version {version}, expected {PROTOCOL_VERSION}")
            name = data[5 : 5 + name_len].decode("ascii")
            count = data[5 + name_len]
            raw = data[6 + name_len :]
            if len(raw) != 4 * count or len(name) != name_len:
                raise ProtocolError("description length does not match its element count")
            elements = tuple(
                Element(raw[i], Role(raw[i + 1]), raw[i + 2], raw[i + 3])
                for i in range(0, len(raw), 4)
            )
        except (IndexError, UnicodeDecodeError, ValueError) as exc:
            if isinstance(exc, ProtocolError):
                raise
            raise ProtocolError(f"malformed description: {exc}") from None
        return cls(kind=kind, name=name, firmware=(major, minor), elements=elements)
