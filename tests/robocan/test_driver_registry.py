"""The driver registry: the built-in table alone brings a robot up (a checkout that is not
installed), a hardware maker's entry point adds a kind or replaces a built-in one, and a broken
entry point is a clear error for its own kind only."""

from __future__ import annotations

import itertools
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from guidebot.bus import Bus
from guidebot.cli import main
from robot_agent.robocan.drivers import BUILTIN_DRIVERS, Driver, DriverRegistry, UnknownDriver
from robot_agent.robocan.entities import BaseDriver, BatteryDriver, SonarDriver
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch

_plugins = itertools.count()
BUILT_IN_CLASSES = {
    "BaseDriver",
    "BumperDriver",
    "SonarDriver",
    "HeadDriver",
    "IoDriver",
    "BatteryDriver",
}


@pytest.fixture
def plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A hardware maker's package, installed as a real distribution on sys.path: it adds
    ``custom``, replaces ``sonar``, and ships three broken entry points."""
    name = f"robocan_plugin_{next(_plugins)}"
    (tmp_path / f"{name}.py").write_text(
        textwrap.dedent(
            """
            from robot_agent.robocan.drivers import Driver
            from robot_agent.robocan.entities import SonarDriver

            class LoudSonar(SonarDriver):
                pass

            class Custom(Driver):
                kinds = ("custom",)

            class NotADriver:
                pass
            """
        )
    )
    dist = tmp_path / f"{name}-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(
        "[guidebot.robocan_drivers]\n"
        f"sonar = {name}:LoudSonar\n"
        f"custom = {name}:Custom\n"
        f"not_a_driver = {name}:NotADriver\n"
        "missing_module = no_such_robocan_module:Driver\n"
        f"battery = {name}:NoSuchClass\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    return name


def test_the_built_in_table_needs_no_entry_points() -> None:
    registry = DriverRegistry(use_entry_points=False)
    assert registry.kinds == sorted(BUILTIN_DRIVERS)
    for kind in registry.kinds:
        cls = registry.driver_class(kind)
        assert issubclass(cls, Driver) and cls.__name__ in BUILT_IN_CLASSES
        assert registry.source(kind) == "built-in"
    assert registry.driver_class("pid_velocity") is BaseDriver


async def test_the_bellbot_comes_online_on_the_built_in_table_alone(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    registry = DriverRegistry(use_entry_points=False)
    async with RoboCanStack(
        onboard.endpoint("robocan"), [channel], time_scale=10.0, registry=registry
    ) as stack:
        await stack.wait_online()
        (master,) = stack.masters
        assert {cls.__name__ for cls in master.drivers} == BUILT_IN_CLASSES


def test_an_entry_point_adds_and_overrides_and_a_broken_one_is_a_clear_error(
    plugin: str,
) -> None:
    registry = DriverRegistry()
    assert registry.driver_class("sonar").__name__ == "LoudSonar"
    assert plugin in registry.source("sonar")
    assert registry.driver_class("custom").__name__ == "Custom"
    with pytest.raises(UnknownDriver, match=r"'not_a_driver'.*not a subclass"):
        registry.driver_class("not_a_driver")
    with pytest.raises(UnknownDriver, match=r"'missing_module'.*ModuleNotFoundError"):
        registry.driver_class("missing_module")
    with pytest.raises(UnknownDriver, match=r"'battery'.*NoSuchClass"):
        registry.driver_class("battery")
    # the other kinds are not affected
    assert registry.driver_class("motor") is BaseDriver
    assert registry.driver_class("firing_sequence") is SonarDriver
    assert DriverRegistry(use_entry_points=False).driver_class("battery") is BatteryDriver


async def test_a_broken_driver_does_not_stop_the_others(
    plugin: str, onboard: Bus, channel: str, watch: Watch
) -> None:
    """The plug-in's battery entry point is broken: the battery module still comes online
    (an element without a driver is logged), every other module gets its drivers."""
    async with RoboCanStack(
        onboard.endpoint("robocan"), [channel], time_scale=10.0, registry=DriverRegistry()
    ) as stack:
        await stack.wait_online()
        (master,) = stack.masters
        names = {cls.__name__ for cls in master.drivers}
        # sonar elements get the plug-in's LoudSonar, firing_sequence elements the built-in
        assert names == BUILT_IN_CLASSES - {"BatteryDriver"} | {"LoudSonar"}
        assert "online" == {r["module_id"]: r for r in stack.module_table()}[0x08]["state"]
        await watch.wait("odometry", timeout=10)  # the base still works


def test_the_drivers_command_lists_sources_and_broken_drivers(plugin: str) -> None:
    result = CliRunner().invoke(main, ["robocan", "drivers"])
    assert result.exit_code == 1
    assert "custom: " in result.output and plugin in result.output
    assert "missing_module: BROKEN" in result.output
    assert "pid_velocity: robot_agent.robocan.entities.BaseDriver (critical) [built-in]" in (
        result.output
    )
