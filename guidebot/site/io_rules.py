"""Which Modbus point kinds each building role may use: ONE table for the whole product.

The site checker (guidebot.site.validate), the building check run by the server's
BuildingInterface (guidebot.site.building_config), the interface's ``set_output`` and the
building simulator (building_sim) all ask this module, so a site one of them accepts the others
accept too. It imports nothing from the project.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["ROLE_KINDS", "PointKind", "Role", "allowed", "kind_problem"]


class PointKind(StrEnum):
    """The four Modbus data tables."""

    discrete_input = "discrete_input"
    coil = "coil"
    input_register = "input_register"
    holding_register = "holding_register"


class Role(StrEnum):
    """What a point does for a device (the site field that names it)."""

    door_open = "door open"
    door_is_open = "door is_open"
    elevator_call = "elevator call"
    elevator_in_position = "elevator in_position"
    elevator_floor = "elevator floor register"
    elevator_door = "elevator door register"
    button_input = "button input"
    button_led = "button led"
    output = "set_output target"
    fire_alarm = "fire_alarm input"


_BITS_IN = frozenset({PointKind.discrete_input, PointKind.coil})

ROLE_KINDS: dict[Role, frozenset[PointKind]] = {
    # Outputs the BuildingInterface sets to 0/1: a coil (the simulator drives devices from it).
    Role.door_open: frozenset({PointKind.coil}),
    Role.elevator_call: frozenset({PointKind.coil}),
    Role.button_led: frozenset({PointKind.coil}),
    # Sensors read as 0/1: a discrete input, or a coil a device mirrors its state on.
    Role.door_is_open: _BITS_IN,
    Role.elevator_in_position: _BITS_IN,
    Role.button_input: _BITS_IN,
    # A fire alarm relay's contact (docs/emergency.md), read like a button.
    Role.fire_alarm: _BITS_IN,
    # The optional position registers ``<elevator>_floor`` / ``<elevator>_door``.
    Role.elevator_floor: frozenset({PointKind.input_register}),
    Role.elevator_door: frozenset({PointKind.input_register}),
    # set_output writes anything writable.
    Role.output: frozenset({PointKind.coil, PointKind.holding_register}),
}


def allowed(role: Role, kind: PointKind | str) -> bool:
    return PointKind(kind) in ROLE_KINDS[role]


def kind_problem(role: Role, kind: PointKind | str, point: str) -> str | None:
    """None when ``point`` (module.point) of ``kind`` may serve ``role``, else why not."""
    if allowed(role, kind):
        return None
    wanted = " or ".join(sorted(k.value for k in ROLE_KINDS[role]))
    return f"{role.value} {point} is a {PointKind(kind).value}; it must be a {wanted}"
