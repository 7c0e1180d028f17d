"""Scripted scenarios for demos: a YAML list of timed actions run against a simulator.

    - {at: 2.0, press: button_entrance, ms: 400}
    - {at: 5.0, fault: otb_first, kind: offline}
    - {at: 9.0, fault: otb_first, kind: none}
    - {at: 12.0, set: {module: otb_ground, point: lift_here, value: 1}}

``at`` is seconds from the start of the scenario, divided by the simulator's time scale.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, model_validator

from building_sim._modbus import FaultKind
from building_sim.simulator import BuildingSimulator
from guidebot.site.building import IORef

__all__ = ["ScenarioError", "Step", "load_scenario", "run_scenario"]


class ScenarioError(ValueError):
    """A scenario file that cannot be run; the message says which step and why."""


class SetPoint(IORef):
    value: int = Field(ge=0, le=0xFFFF)


class Step(BaseModel):
    model_config = ConfigDict(extra="forbid")

    at: float = Field(ge=0)
    press: str | None = None
    ms: float = Field(default=300.0, gt=0)
    fault: str | None = None
    kind: FaultKind = FaultKind.none
    delay_ms: float = Field(default=0.0, ge=0)
    code: int = Field(default=4, ge=1, le=11)
    set: SetPoint | None = None

    @model_validator(mode="after")
    def _one_action(self) -> Step:
        actions = [a for a in (self.press, self.fault, self.set) if a is not None]
        if len(actions) != 1:
            raise ValueError("each step needs exactly one of press, fault, set")
        return self


def load_scenario(path: str | Path, sim: BuildingSimulator | None = None) -> list[Step]:
    """Read and check a scenario; with ``sim``, every named button/module must exist."""
    try:
        data: Any = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
        steps = TypeAdapter(list[Step]).validate_python(data)
    except OSError as exc:
        raise ScenarioError(f"cannot read scenario {path}: {exc.strerror}") from exc
    except (yaml.YAMLError, ValidationError) as exc:
        raise ScenarioError(f"scenario {path} is invalid: {exc}") from exc
    if sim is not None:
        for index, step in enumerate(steps):
            if step.press is not None and step.press not in sim.buttons:
                raise ScenarioError(f"scenario step {index}: no button {step.press!r}")
            if step.fault is not None and step.fault not in sim.stores:
                raise ScenarioError(f"scenario step {index}: no module {step.fault!r}")
    return sorted(steps, key=lambda s: s.at)


async def run_scenario(sim: BuildingSimulator, steps: list[Step]) -> int:
    """Play the steps at their times; returns how many ran."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    for step in steps:
        await asyncio.sleep(max(0.0, start + step.at / sim.time_scale - loop.time()))
        if step.press is not None:
            sim.press(step.press, step.ms)
        elif step.fault is not None:
            await sim.set_fault(step.fault, step.kind, delay_ms=step.delay_ms, code=step.code)
        elif step.set is not None:
            sim.write(IORef(module=step.set.module, point=step.set.point), step.set.value)
    return len(steps)
