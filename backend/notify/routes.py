"""REST of the notifications (docs/server.md, "Notifications"): the settings are the admin's
(``manage_notifications``), the delivery log is read by staff too (``read_notifications``).
Secrets are never in an answer."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends, HTTPException, Path, Query, Request, status

from backend.actions import require_action
from backend.auth import Principal
from backend.notify.model import DAYS, SEVERITIES, ChannelIn, Smtp
from backend.notify.service import LOG_SIZE, Notifier
from backend.rest.deps import not_found
from backend.state import app_state

__all__ = ["router"]

router = APIRouter(prefix="/api/notifications", tags=["notifications"])

Manager = Annotated[Principal, Depends(require_action("manage_notifications"))]
Reader = Annotated[Principal, Depends(require_action("read_notifications"))]
ChannelId = Annotated[str, Path(min_length=1, max_length=40)]


def _notifier(request: Request) -> Notifier:
    notifier = app_state(request.app).notify
    if not isinstance(notifier, Notifier):
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "notifications not running")
    return notifier


Notify = Annotated[Notifier, Depends(_notifier)]


@router.get("")
async def settings(_: Manager, notifier: Notify) -> dict[str, Any]:
    """The SMTP server and every channel with its rules (secrets: only whether one is set)."""
    return {
        "smtp": None if notifier.smtp is None else notifier.smtp.view(),
        "channels": [c.view() for c in notifier.channels.values()],
        "severities": list(SEVERITIES),
        "days": list(DAYS),
    }


@router.put("/smtp")
async def set_smtp(_: Manager, notifier: Notify, body: Annotated[Smtp, Body()]) -> dict[str, Any]:
    """Set the venue's SMTP server; a password left out keeps the stored one (same user)."""
    return (await notifier.set_smtp(body)).view()


@router.post("/channels", status_code=status.HTTP_201_CREATED)
async def create_channel(
    _: Manager, notifier: Notify, body: Annotated[ChannelIn, Body()]
) -> dict[str, Any]:
    """A new channel (``kind`` email or webhook) with its rules."""
    return (await notifier.put_channel(body)).view()


@router.put("/channels/{channel_id}")
async def replace_channel(
    _: Manager, notifier: Notify, channel_id: ChannelId, body: Annotated[ChannelIn, Body()]
) -> dict[str, Any]:
    """Replace a channel's rules; a webhook secret left out keeps the stored one."""
    try:
        return (await notifier.put_channel(body, channel_id)).view()
    except KeyError:
        raise not_found(f"channel {channel_id!r}") from None


@router.delete("/channels/{channel_id}")
async def delete_channel(_: Manager, notifier: Notify, channel_id: ChannelId) -> dict[str, Any]:
    try:
        await notifier.delete_channel(channel_id)
    except KeyError:
        raise not_found(f"channel {channel_id!r}") from None
    return {"deleted": channel_id}


@router.post("/channels/{channel_id}/test")
async def test_channel(who: Manager, notifier: Notify, channel_id: ChannelId) -> dict[str, Any]:
    """Send a test message now (the rules aside); answers after its first attempt (at most
    30 s): ``status`` sent, or retrying with ``error`` (it is retried like any delivery)."""
    try:
        delivery = await notifier.test(channel_id, who.name)
    except KeyError:
        raise not_found(f"channel {channel_id!r}") from None
    return delivery.view()


@router.get("/deliveries")
async def deliveries(
    _: Reader, notifier: Notify, limit: Annotated[int, Query(ge=1, le=LOG_SIZE)] = 100
) -> list[dict[str, Any]]:
    """The delivery log, newest first: status, attempts, the last error."""
    return notifier.deliveries(limit)
