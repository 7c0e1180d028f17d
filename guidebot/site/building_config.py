"""The building section of a site, checked as a whole before anything connects.

The models of single items live in guidebot.site.building (owned by the site schema); this
module groups them and refuses a building whose references or addresses do not make sense,
with an error that names the module, point or device at fault.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from pydantic import ConfigDict, Field, ValidationError

from guidebot.site.building import (
    BuildingModule,
    Button,
    Door,
    Elevator,
    IOPoint,
    IORef,
    PointKind,
)
from guidebot.site.index import Indexed
from guidebot.site.io_rules import Role, kind_problem

__all__ = [
    "BuildingConfig",
    "BuildingConfigError",
    "load_building",
    "load_building_file",
]

BUILDING_KEYS = ("modules", "doors", "elevators", "buttons")


class BuildingConfigError(ValueError):
    """A site whose building part cannot work; the message says where and why."""


class BuildingConfig(Indexed):
    """Every Modbus module of the venue and the devices bound to their points."""

    model_config = ConfigDict(extra="forbid")

    modules: list[BuildingModule] = Field(default_factory=list)
    doors: list[Door] = Field(default_factory=list)
    elevators: list[Elevator] = Field(default_factory=list)
    buttons: list[Button] = Field(default_factory=list)

    def module(self, module_id: str) -> BuildingModule:
        """The module ``module_id`` (O(1): guidebot/site/index.py); KeyError when unknown."""
        module = self._find("modules", self.modules, _module_id, module_id)
        if module is None:
            raise KeyError(module_id)
        return module

    def resolve(self, ref: IORef) -> tuple[BuildingModule, IOPoint]:
        module = self.module(ref.module)
        point = module.point(ref.point)
        if point is None:
            raise KeyError(f"{ref.module}.{ref.point}")
        return module, point

    def check(self) -> BuildingConfig:
        """Raise BuildingConfigError on the first inconsistency; returns self when sound."""
        _check(self)
        return self

    def check_production(self) -> BuildingConfig:
        """What a real venue needs beyond ``check``: real ports (0 is for simulators)."""
        for module in self.modules:
            if module.port == 0:
                raise BuildingConfigError(
                    f"module {module.id!r}: port 0 only suits a simulator (port_zero);"
                    " a real module needs its Modbus/TCP port"
                )
        return self


def _check(config: BuildingConfig) -> None:
    ids: set[str] = set()
    for module in config.modules:
        if module.id in ids:
            raise BuildingConfigError(f"module {module.id!r} is defined twice")
        ids.add(module.id)
        names: set[str] = set()
        addresses: dict[tuple[PointKind, int], str] = {}
        for point in module.points:
            if point.name in names:
                raise BuildingConfigError(
                    f"module {module.id!r}: point name {point.name!r} is used twice"
                )
            names.add(point.name)
            other = addresses.get((point.kind, point.address))
            if other is not None:
                raise BuildingConfigError(
                    f"module {module.id!r}: point {point.name!r} has address {point.address},"
                    f" already used by {other!r} ({point.kind.value})"
                )
            addresses[(point.kind, point.address)] = point.name

    def ref(owner: str, ref: IORef, role: Role) -> None:
        field = role.value.split(" ", 1)[1]  # "door open" -> "open": the owner says "door"
        if ref.module not in ids:
            raise BuildingConfigError(f"{owner}: {field} names unknown module {ref.module!r}")
        point = config.module(ref.module).point(ref.point)
        if point is None:
            raise BuildingConfigError(
                f"{owner}: {field} names unknown point {ref.point!r} of module {ref.module!r}"
            )
        problem = kind_problem(role, point.kind, f"{ref.module}.{ref.point}")
        if problem is not None:
            raise BuildingConfigError(f"{owner}: {problem}")

    for kind_name, items in (
        ("door", config.doors),
        ("elevator", config.elevators),
        ("button", config.buttons),
    ):
        seen: set[str] = set()
        for item in items:
            if item.id in seen:
                raise BuildingConfigError(f"{kind_name} {item.id!r} is defined twice")
            seen.add(item.id)
    for door in config.doors:
        ref(f"door {door.id!r}", door.open, Role.door_open)
        if door.is_open is not None:
            ref(f"door {door.id!r}", door.is_open, Role.door_is_open)
    for elevator in config.elevators:
        floors: set[str] = set()
        for stop in elevator.stops:
            if stop.floor in floors:
                raise BuildingConfigError(
                    f"elevator {elevator.id!r}: floor {stop.floor!r} listed twice"
                )
            floors.add(stop.floor)
            owner = f"elevator {elevator.id!r} floor {stop.floor!r}"
            ref(owner, stop.call, Role.elevator_call)
            ref(owner, stop.in_position, Role.elevator_in_position)
    for button in config.buttons:
        ref(f"button {button.id!r}", button.input, Role.button_input)
        if button.led is not None:
            ref(f"button {button.id!r}", button.led, Role.button_led)


def load_building(data: Mapping[str, Any]) -> BuildingConfig:
    """Build and check the building part of a site mapping.

    Accepts a whole site (the building keys at top level or under ``building``); other site
    sections are ignored here.
    """
    section = data.get("building", data)
    if not isinstance(section, Mapping):
        raise BuildingConfigError("the site's 'building' section must be a mapping")
    picked = {key: section[key] for key in BUILDING_KEYS if section.get(key) is not None}
    try:
        config = BuildingConfig.model_validate(picked)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"])
        raise BuildingConfigError(
            f"site building section, at {where}: {first['msg']}"
            + (f" ({exc.error_count()} errors)" if exc.error_count() > 1 else "")
        ) from exc
    return config.check()


def load_building_file(path: str | Path) -> BuildingConfig:
    """Read a YAML (or JSON) site file and return its checked building part."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise BuildingConfigError(f"cannot read site file {path}: {exc.strerror}") from exc
    except yaml.YAMLError as exc:
        raise BuildingConfigError(f"site file {path} is not valid YAML: {exc}") from exc
    if not isinstance(data, Mapping):
        raise BuildingConfigError(f"site file {path} must hold a mapping at top level")
    return load_building(data)


def _module_id(module: BuildingModule) -> str:
    return module.id
