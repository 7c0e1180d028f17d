"""REST of the fire alarm: read the state (anyone), declare and resume (operator or admin)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException, Request, status
from pydantic import BaseModel, ConfigDict, Field

from backend.emergency.service import EmergencyService
from backend.emergency.state import EmergencyError, IllegalMove, ResumeRefused
from backend.rest.deps import Anyone, Staff
from backend.state import app_state
from guidebot.site.emergency import AlarmZone

__all__ = ["router"]

router = APIRouter(prefix="/api/emergency", tags=["emergency"])


class Declare(BaseModel):
    model_config = ConfigDict(extra="forbid")
    zone: AlarmZone = Field(default_factory=AlarmZone)
    """``{}`` the whole site, ``{"floors": [..]}`` or ``{"areas": [..]}``."""
    reason: str = Field(min_length=1, max_length=300)


def _service(request: Request) -> EmergencyService:
    service = app_state(request.app).emergency
    if not isinstance(service, EmergencyService):
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "emergency service not running")
    return service


@router.get("")
async def emergency_state(request: Request, _: Anyone) -> dict[str, Any]:
    """The emergency state: normal, alarm or input_clear (the inputs read normal, a person
    must resume), the zones held, who declared it, each robot's evacuation, the alarm inputs."""
    return _service(request).snapshot()


@router.post("/declare")
async def declare(request: Request, who: Staff, body: Declare) -> dict[str, Any]:
    """Declare a fire alarm for a zone (default: the whole site). 422 for a zone the site does
    not have."""
    try:
        return _service(request).declare(body.zone, reason=body.reason, by=who.name)
    except IllegalMove as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    except EmergencyError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None


@router.post("/resume")
async def resume(request: Request, who: Staff) -> dict[str, Any]:
    """Resume service. 409, saying why, while an alarm input still reads alarm (or cannot be
    read), or when there is no emergency."""
    try:
        return _service(request).resume(by=who.name)
    except (ResumeRefused, IllegalMove) as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
