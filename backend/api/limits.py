"""Request body size limits (the error handlers are in backend.api.errors).

``BodyLimit`` is plain ASGI middleware: it refuses a body larger than its limit with 413 before
the route reads it (Content-Length checked up front, a streamed body counted as it arrives), so
a 20 MB ``params`` is never parsed, stored or served. Site uploads get the site file limit.
"""

from __future__ import annotations

from fastapi import status
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from guidebot.site.yamlio import MAX_SITE_BYTES

__all__ = ["BodyLimit", "BodyTooLarge", "limit_for"]

LARGE_BODY_PATHS = ("/api/site", "/api/net-editor")
"""Path prefixes that take a whole site document or a whole net (up to the site file limit;
the net editor's routes keep a tighter limit of their own)."""


def limit_for(path: str, default: int) -> int:
    return MAX_SITE_BYTES if path.startswith(LARGE_BODY_PATHS) else default


class BodyTooLarge(Exception):
    def __init__(self, limit: int) -> None:
        super().__init__(f"request body too large: the limit is {limit} bytes")
        self.limit = limit


class BodyLimit:
    """Refuse request bodies over ``max_bytes`` (413) on every HTTP route."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = limit_for(scope.get("path", ""), self.max_bytes)
        for name, value in scope.get("headers", ()):
            if name == b"content-length":
                try:
                    declared = int(value)
                except ValueError:
                    declared = 0
                if declared > limit:
                    await _too_large(send, limit)
                    return
        seen = 0
        started = False

        async def counting_receive() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise BodyTooLarge(limit)
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, counting_receive, tracking_send)
        except BodyTooLarge:
            if not started:
                await _too_large(send, limit)


async def _too_large(send: Send, limit: int) -> None:
    response = JSONResponse(
        {"detail": f"request body too large: the limit is {limit} bytes"},
        status_code=status.HTTP_413_CONTENT_TOO_LARGE,
        headers={"Connection": "close"},
    )
    await response({"type": "http"}, _nothing, send)


async def _nothing() -> Message:
    return {"type": "http.disconnect"}
