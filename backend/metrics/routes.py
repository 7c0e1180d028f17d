"""``GET /metrics``: the Prometheus text format, for staff tokens or the metrics token."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Request, Response, status
from prometheus_client import CONTENT_TYPE_LATEST

from backend.actions import require_action
from backend.auth import bearer_token

__all__ = ["router"]

router = APIRouter(tags=["server"])

_STAFF = require_action("read_metrics")


async def _metrics_reader(request: Request) -> None:
    """The metrics token, else a token the ``read_metrics`` rule lets through (401, 403)."""
    token = bearer_token(request.headers.get("authorization"), request.query_params.get("token"))
    metrics_token = request.app.state.settings.metrics_token
    if token and metrics_token and secrets.compare_digest(token, metrics_token):
        return
    try:
        await _STAFF(request)
    except HTTPException as exc:
        if exc.status_code != status.HTTP_403_FORBIDDEN:
            raise
        raise HTTPException(
            exc.status_code, f"{exc.detail} or the metrics token", headers=exc.headers
        ) from None


_metrics_reader.roles = _STAFF.roles  # type: ignore[attr-defined]
_metrics_reader.action = _STAFF.action  # type: ignore[attr-defined]


@router.get("/metrics", response_class=Response)
async def get_metrics(request: Request, _: Annotated[None, Depends(_metrics_reader)]) -> Response:
    """Prometheus scrape. A bearer token: admin, operator, or GUIDEBOT_METRICS_TOKEN."""
    return Response(request.app.state.metrics.render(), media_type=CONTENT_TYPE_LATEST)
