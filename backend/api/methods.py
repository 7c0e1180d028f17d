"""What ``/api`` answers for a method a route does not take, or a path no route has.

Without this the web files mounted at ``/`` answer them: 405 ``Allow: GET, HEAD`` for a
``GET /api/nets/kill`` (the files' methods, not the route's) and an HTML 404 for a path that
does not exist. Here: 405 with the route's own ``Allow``, ``OPTIONS`` answered 204 with it, and
a JSON 404 (docs/server.md, "Status codes").
"""

from __future__ import annotations

from fastapi import FastAPI, Request, Response, status
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute, iter_route_contexts

__all__ = ["API_METHODS", "install_method_answers", "methods_of"]

API_METHODS = ["GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"]
_CATCH_ALL = "/api/{rest:path}"


def methods_of(app: FastAPI, path: str) -> set[str]:
    """The methods the app's routes take on ``path`` (HEAD with GET); empty: no route."""
    methods: set[str] = set()
    for context in iter_route_contexts(app.routes):
        route = getattr(context, "original_route", context)
        if isinstance(route, APIRoute) and route.path_regex.match(path):
            methods |= route.methods or set()
    if "GET" in methods:
        methods.add("HEAD")
    return methods


def install_method_answers(app: FastAPI) -> None:
    """Answer, after every route of ``app``, the ``/api`` requests none of them took."""

    async def unmatched(request: Request) -> Response:
        methods = methods_of(app, request.url.path)
        if not methods:
            return JSONResponse({"detail": "Not Found"}, status_code=status.HTTP_404_NOT_FOUND)
        allow = ", ".join(sorted(methods | {"OPTIONS"}))
        if request.method == "OPTIONS":
            return Response(status_code=status.HTTP_204_NO_CONTENT, headers={"Allow": allow})
        return JSONResponse(
            {"detail": "Method Not Allowed"},
            status_code=status.HTTP_405_METHOD_NOT_ALLOWED,
            headers={"Allow": allow},
        )

    # A plain Starlette route: nothing of FastAPI's request handling to set up, so the start-up
    # warm-up (backend/api/warmup.py), which ends here, can route through it too.
    app.add_route(_CATCH_ALL, unmatched, methods=API_METHODS, include_in_schema=False)
