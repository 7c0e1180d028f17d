"""Unknown query parameters are refused, not ignored.

A client that misspells a filter (``GET /api/tasks?states=done``) would otherwise get every
task back and take it for the answer; FastAPI ignores query parameters a route does not
declare. Each ``/api`` route answers 422 ``extra_forbidden`` naming the parameter and the ones
it takes (docs/server.md, "Status codes"); the token is still checked first (errors.py).
"""

from __future__ import annotations

from fastapi.dependencies.models import Dependant
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from starlette.requests import HTTPConnection

__all__ = ["OPEN_QUERY", "known_query", "query_names"]

EVERY_ROUTE = frozenset({"token"})
"""Taken on every route: the bearer token as ``?token=`` (browsers; docs/security.md)."""

OPEN_QUERY = "x-open-query"
"""An operation whose caller is another party's redirect, which may add parameters of its own
(an OpenID provider's ``iss``, ``session_state``): ``openapi_extra={OPEN_QUERY: True}``."""

_NAMES = "_guidebot_query_names"
"""The attribute a route keeps its names in, found once (APIRoute is not hashable)."""


def query_names(route: APIRoute) -> frozenset[str]:
    """The query parameters ``route`` takes: those it declares (by their alias), through its
    dependencies, and the token."""
    names: frozenset[str] | None = getattr(route, _NAMES, None)
    if names is None:
        names = EVERY_ROUTE | _query_aliases(route.dependant)
        setattr(route, _NAMES, names)
    return names


def _query_aliases(dependant: Dependant) -> set[str]:
    names = {field.alias for field in dependant.query_params}
    for sub in dependant.dependencies:
        names |= _query_aliases(sub)
    return names


async def known_query(request: HTTPConnection) -> None:
    """Router dependency: 422 for a query parameter the matched route does not declare (a
    WebSocket route, which is no APIRoute, is left alone: the hub's /ws ignores what it does
    not take, docs/protocol.md "Connecting")."""
    route = request.scope.get("route")
    if not request.query_params or not isinstance(route, APIRoute):
        return
    if (route.openapi_extra or {}).get(OPEN_QUERY):
        return
    names = query_names(route)
    unknown = sorted(set(request.query_params.keys()) - names)
    if unknown:
        takes = ", ".join(sorted(names)) or "no query parameters"
        raise RequestValidationError(
            [
                {
                    "loc": ("query", name),
                    "msg": f"unknown query parameter; {route.path} takes {takes}",
                    "type": "extra_forbidden",
                }
                for name in unknown
            ]
        )
