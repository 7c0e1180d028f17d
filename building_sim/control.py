"""The simulator's control API (HTTP on 127.0.0.1): press buttons, inject faults, read state.

POST /buttons/{button}/press   {"ms": 300}
POST /modules/{module}/fault   {"kind": "offline" | "slow" | "exception" | "none",
                                "delay_ms": 0, "code": 4}
POST /doors/{door}/jam         {"jammed": true}  (a door that does not open)
POST /elevators/{elevator}/stuck {"stuck": true} (an elevator that never arrives)
POST /points/{module}/{point}  {"value": 1}      (force an input, e.g. a door sensor)
GET  /state
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Generator
from typing import Any

import uvicorn
from fastapi import FastAPI, HTTPException
from pydantic import BaseModel, ConfigDict, Field

from building_sim._modbus import FaultKind
from building_sim.simulator import BuildingSimulator, SimulatorError
from guidebot.site.building import IORef

__all__ = ["control_app", "serve_control"]


class Press(BaseModel):
    model_config = ConfigDict(extra="forbid")
    ms: float = Field(default=300.0, gt=0, le=600_000)


class Fault(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: FaultKind
    delay_ms: float = Field(default=0.0, ge=0, le=60_000)
    code: int = Field(default=4, ge=1, le=11)


class Jam(BaseModel):
    model_config = ConfigDict(extra="forbid")
    jammed: bool = True


class Stuck(BaseModel):
    model_config = ConfigDict(extra="forbid")
    stuck: bool = True


class PointValue(BaseModel):
    model_config = ConfigDict(extra="forbid")
    value: int = Field(ge=0, le=0xFFFF)


def control_app(sim: BuildingSimulator) -> FastAPI:
    """A small FastAPI app bound to one running simulator."""
    app = FastAPI(title="GuideBot building simulator")

    @app.get("/state")
    async def state() -> dict[str, Any]:
        return sim.state()

    @app.post("/buttons/{button}/press")
    async def press(button: str, body: Press | None = None) -> dict[str, Any]:
        try:
            sim.press(button, (body or Press()).ms)
        except SimulatorError as exc:
            raise HTTPException(404, str(exc)) from None
        return {"button": button, "ms": (body or Press()).ms}

    @app.post("/modules/{module}/fault")
    async def fault(module: str, body: Fault) -> dict[str, Any]:
        try:
            await sim.set_fault(module, body.kind, delay_ms=body.delay_ms, code=body.code)
        except SimulatorError as exc:
            raise HTTPException(404, str(exc)) from None
        return {"module": module, **body.model_dump(mode="json")}

    @app.post("/doors/{door}/jam")
    async def jam(door: str, body: Jam | None = None) -> dict[str, Any]:
        jammed = (body or Jam()).jammed
        try:
            sim.jam_door(door, jammed)
        except SimulatorError as exc:
            raise HTTPException(404, str(exc)) from None
        return {"door": door, "jammed": jammed}

    @app.post("/elevators/{elevator}/stuck")
    async def stuck(elevator: str, body: Stuck | None = None) -> dict[str, Any]:
        value = (body or Stuck()).stuck
        try:
            sim.stick_elevator(elevator, value)
        except SimulatorError as exc:
            raise HTTPException(404, str(exc)) from None
        return {"elevator": elevator, "stuck": value}

    @app.post("/points/{module}/{point}")
    async def set_point(module: str, point: str, body: PointValue) -> dict[str, Any]:
        try:
            sim.write(IORef(module=module, point=point), body.value)
        except SimulatorError as exc:
            raise HTTPException(404, str(exc)) from None
        return {"module": module, "point": point, "value": body.value}

    return app


class _Server(uvicorn.Server):
    """uvicorn without its own signal handlers: the CLI or the test owns Ctrl-C."""

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield


@contextlib.asynccontextmanager
async def serve_control(
    sim: BuildingSimulator, *, port: int = 0, start_timeout: float = 20.0
) -> AsyncIterator[str]:
    """Serve the control API on 127.0.0.1; yields its base URL (real port read back)."""
    config = uvicorn.Config(
        control_app(sim), host="127.0.0.1", port=port, log_level="warning", lifespan="off"
    )
    server = _Server(config)
    task = asyncio.create_task(server.serve(), name="building-sim-control")
    try:
        async with asyncio.timeout(start_timeout):
            while not server.started:
                if task.done():
                    task.result()
                    raise RuntimeError(f"control API could not start on port {port}")
                await asyncio.sleep(0.01)
        bound = server.servers[0].sockets[0].getsockname()[1]
        yield f"http://127.0.0.1:{bound}"
    finally:
        server.should_exit = True
        await asyncio.gather(task, return_exceptions=True)
