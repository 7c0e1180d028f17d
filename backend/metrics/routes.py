"""``GET /metrics``: the Prometheus text format, for staff tokens or the metrics token."""

from __future__ import annotations

import secrets

from fastapi import APIRouter, HTTPException, Request, Response, status
from prometheus_client import CONTENT_TYPE_LATEST

from backend.auth import Role, bearer_token

__all__ = ["router"]

router = APIRouter(tags=["server"])


@router.get("/metrics", response_class=Response)
async def get_metrics(request: Request) -> Response:
    """Prometheus scrape. A bearer token: admin, operator, or GUIDEBOT_METRICS_TOKEN."""
    token = bearer_token(request.headers.get("authorization"), request.query_params.get("token"))
    metrics_token = request.app.state.settings.metrics_token
    allowed = bool(token and metrics_token and secrets.compare_digest(token, metrics_token))
    if not allowed:
        principal = request.app.state.tokens.lookup(token)
        if principal is None:
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED,
                "missing or unknown bearer token",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if principal.role not in (Role.ADMIN, Role.OPERATOR):
            raise HTTPException(
                status.HTTP_403_FORBIDDEN,
                f"role {principal.role.value!r} may not read metrics "
                "(needs admin, operator or the metrics token)",
            )
    return Response(request.app.state.metrics.render(), media_type=CONTENT_TYPE_LATEST)
