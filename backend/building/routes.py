"""REST view of the building for the admin GUI: module health and the current point values."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from backend.rest.deps import Watcher
from backend.state import app_state

__all__ = ["router"]

router = APIRouter(prefix="/api/building", tags=["building"])


@router.get("")
async def building_state(request: Request, _: Watcher) -> dict[str, Any]:
    """Each module's health (online, round-trip, errors, last error), every point's value and
    where each elevator car is.

    ``enabled`` is false when the site has no modules or the building interface is off.
    """
    building = app_state(request.app).building
    if building is None:
        return {"enabled": False, "modules": [], "points": [], "elevators": []}
    return {
        "enabled": True,
        "modules": building.health(),
        "points": [
            {"module": module, "point": point, "value": value}
            for (module, point), value in sorted(building.values.items())
        ],
        "elevators": [car.model_dump(mode="json") for car in building.elevators.states()],
    }
