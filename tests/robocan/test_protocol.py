"""Wire protocol codec: frame lengths, the 56-bit velocity command, descriptions."""

from __future__ import annotations

import pytest

from robot_agent.robocan import protocol as p


def test_velocity_command_is_seven_bytes_and_round_trips() -> None:
    frame = p.set_velocity(1, -0.523456, 0.5)
    assert len(frame) == 7 and frame[0] == p.Op.SET_VELOCITY
    element, velocity, accel = p.parse_set_velocity(frame)
    assert (element, velocity, accel) == (1, pytest.approx(-0.523456), pytest.approx(0.5))


def test_encoder_ticks_wrap_like_int32() -> None:
    _, ticks, velocity = p.parse_encoder(p.encoder(0, 2**31 + 5, 0.25))
    assert ticks == -(2**31) + 5 and velocity == pytest.approx(0.25)


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", "empty"),
        (bytes([0x00, 0x01]), "watchdog"),
        (bytes([p.Op.ENCODER, 0, 0]), "needs 8..8"),
        (bytes([0x55]), "unknown opcode"),
        (bytes([p.Op.SET_VELOCITY, 0, 0, 0, 0, 0, 0, 0]), "needs 7..7"),
    ],
)
def test_bad_frames_are_refused_with_a_reason(data: bytes, reason: str) -> None:
    with pytest.raises(p.ProtocolError, match=reason):
        p.check_length(data)


def test_description_round_trip_and_malformed() -> None:
    description = p.Description(
        kind=p.ModuleKind.MOTOR_CONTROLLER,
        name="motor",
        firmware=(2, 1),
        elements=(p.Element(p.ElementKind.PID_VELOCITY, p.Role.AGENT, 1, 0b11),),
    )
    raw = description.encode()
    assert p.Description.decode(raw) == description
    with pytest.raises(p.ProtocolError):
        p.Description.decode(raw[:-1])
    with pytest.raises(p.ProtocolError, match="version"):
        p.Description.decode(bytes([9]) + raw[1:])


def test_module_ids_are_even_and_eleven_bit() -> None:
    assert p.is_module_id(0x02) and p.is_module_id(0x7FE)
    assert not any(p.is_module_id(i) for i in (0x00, 0x01, 0x03, 0x7FF, 0x800))
