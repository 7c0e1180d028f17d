"""The OpenAPI document as a third-party client must read it: each operation lists the statuses
it can answer, and only those a route of its kind can answer.

Every router is included with the common error statuses (``deps.ERRORS``); a public operation
(no token check: ``/media/``) cannot answer 401, 403 or the sign-in 429, so they are taken out
of its entry (docs/server.md, "REST API and roles").
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.routing import APIRoute, iter_route_contexts

from backend.rest.deps import role_check

__all__ = ["TOKEN_STATUSES", "install_contract_openapi"]

TOKEN_STATUSES = ("401", "403", "429")
"""What only a token check answers."""


def _public_operations(app: FastAPI) -> set[tuple[str, str]]:
    public = set()
    for context in iter_route_contexts(app.routes):
        route = getattr(context, "original_route", context)
        if isinstance(route, APIRoute) and role_check(route) is None:
            if (route.openapi_extra or {}).get("x-sign-in"):
                continue  # takes credentials itself: its 401, 403 and 429 are real
            public |= {(route.path_format, m.lower()) for m in route.methods or ()}
    return public


def install_contract_openapi(app: FastAPI) -> None:
    """Make ``app.openapi()`` answer the document with public operations' statuses trimmed."""
    generate = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = generate()
        for path, method in _public_operations(app):
            operation = schema.get("paths", {}).get(path, {}).get(method)
            if operation is not None:
                for code in TOKEN_STATUSES:
                    operation.get("responses", {}).pop(code, None)
        return schema

    app.openapi = openapi  # type: ignore[method-assign]
