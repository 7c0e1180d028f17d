"""Fault injection for a simulated robot, over HTTP on its touch-screen port.

Served only by ``guidebot robot --simulate`` with simulated RoboCAN modules and a ``--gui-port``
(a robot with real hardware never offers it), so a soak run or a demo can unplug a CAN module
or empty the battery from outside the process (docs/robot.md, "Fault injection"):

    POST /sim/module_plug {"module_id": 2, "plugged": false}   -> module_plug on the bus
    POST /sim/battery     {"level": 0.05}                      -> sim_set_battery on the bus
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

from fastapi import FastAPI, HTTPException
from pydantic import BaseModel, ConfigDict, Field

from guidebot.bus import BusEndpoint

__all__ = ["add_sim_routes"]


class Plug(BaseModel):
    model_config = ConfigDict(extra="forbid")
    module_id: int = Field(ge=0x02, le=0x7FE, description="Even RoboCAN module id (0x02 ...).")
    plugged: bool


class BatteryLevel(BaseModel):
    model_config = ConfigDict(extra="forbid")
    level: float = Field(ge=0.0, le=1.0)


def add_sim_routes(
    app: FastAPI, endpoint: BusEndpoint, modules: Callable[[], Collection[int]]
) -> None:
    """Add the fault-injection routes; each publishes one on-board message and returns.
    ``modules`` gives the simulated module ids (an unknown one answers 404)."""

    @app.post("/sim/module_plug", status_code=202)
    async def module_plug(body: Plug) -> dict[str, Any]:
        known = sorted(modules())
        if body.module_id not in known:
            raise HTTPException(
                404,
                f"no simulated module {body.module_id:#04x}; known: {[f'{m:#04x}' for m in known]}",
            )
        endpoint.publish("module_plug", body.model_dump())
        return body.model_dump()

    @app.post("/sim/battery", status_code=202)
    async def battery(body: BatteryLevel) -> dict[str, Any]:
        endpoint.publish("sim_set_battery", body.model_dump())
        return body.model_dump()
