"""Build every route before the server serves: recent FastAPI builds an included router's routes
(their dependencies and models) on the first request that reaches them, 12-16 ms on the event
loop (measured), which would otherwise fall on the first requests after a start (a site
publish among them, for every robot and GUI connected)."""

from __future__ import annotations

import contextlib

from fastapi import FastAPI
from starlette.exceptions import HTTPException
from starlette.types import Message, Scope

__all__ = ["WARM_UP_PATH", "warm_routes"]

WARM_UP_PATH = "/api/.warm-up"
"""A path no route answers: matching it walks every route (it ends as the JSON 404 of
``backend/api/methods.py``)."""


async def warm_routes(app: FastAPI) -> None:
    """Route one GET of ``WARM_UP_PATH`` through the app's router, answer discarded (the web
    files' 404 is raised, as the app's error handlers would turn it into a response)."""
    scope: Scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "GET",
        "scheme": "http",
        "path": WARM_UP_PATH,
        "raw_path": WARM_UP_PATH.encode(),
        "root_path": "",
        "query_string": b"",
        "headers": [],
        "client": ("127.0.0.1", 0),
        "server": ("127.0.0.1", 0),
    }

    async def receive() -> Message:
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message: Message) -> None:
        return None

    with contextlib.suppress(HTTPException):
        await app.router(scope, receive, send)
