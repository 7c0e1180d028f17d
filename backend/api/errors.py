"""How the API answers a mistake: one handler per kind of error, installed on the app once.

Routes raise the service's own exceptions (a ``TaskError`` subclass from the Task Manager) and
never translate them themselves, so the same mistake gets the same status on every route
(docs/server.md, "Status codes"). Validation errors never echo the input back.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request, status
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException

from backend.db.session import UnstorableJson
from backend.rest.deps import role_check
from backend.tasks.model import (
    Held,
    IllegalTransition,
    QueueFull,
    TaskError,
    TaskFinished,
    TaskNotFound,
)

__all__ = ["install_error_handlers", "task_error_status"]


def task_error_status(exc: TaskError) -> tuple[int, str]:
    """One status per kind of task mistake, with the sentence the caller sees."""
    if isinstance(exc, TaskNotFound):
        return status.HTTP_404_NOT_FOUND, "task not found"
    if isinstance(exc, TaskFinished | IllegalTransition):
        return status.HTTP_409_CONFLICT, str(exc)
    if isinstance(exc, QueueFull | Held):
        return status.HTTP_503_SERVICE_UNAVAILABLE, str(exc)
    return status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)


async def _task_error(_: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, TaskError)
    code, detail = task_error_status(exc)
    reason = getattr(exc, "reason", None)  # Held: why the service holds (docs/emergency.md)
    return JSONResponse({"detail": detail, **({"reason": reason} if reason else {})}, code)


def _clean(errors: Any) -> list[dict[str, Any]]:
    """Validation errors as [{loc, msg, type}]: no ``input`` (it may be huge or a secret)."""
    return [
        {"loc": list(err.get("loc", ())), "msg": err.get("msg", ""), "type": err.get("type", "")}
        for err in errors
    ]


async def _token_first(request: Request) -> Response | None:
    """The answer to the route's token check when it refuses the caller (401, 403, 429), else
    None. FastAPI decodes a JSON body before it runs a route's dependencies, so a body that is
    not JSON would otherwise be answered 422 before the token is looked at (docs/server.md,
    "Status codes": the token is checked first)."""
    route = request.scope.get("route")
    check = role_check(route) if isinstance(route, APIRoute) else None
    if check is None:
        return None
    try:
        await check(request)
    except HTTPException as refused:
        return await http_exception_handler(request, refused)
    return None


async def _validation_error(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, RequestValidationError)
    if (refused := await _token_first(request)) is not None:
        return refused
    return JSONResponse(
        {"detail": _clean(exc.errors())}, status_code=status.HTTP_422_UNPROCESSABLE_CONTENT
    )


UNPARSABLE_BODY = "There was an error parsing the body"
"""FastAPI's 400 for a JSON body it cannot even decode as text (bad UTF-8/16/32 bytes)."""


async def _http_error(request: Request, exc: Exception) -> Response:
    """A body that is not JSON text is the same mistake as any other bad JSON: 422
    ``json_invalid``, not an undocumented 400 (found by the stateful fuzz)."""
    assert isinstance(exc, HTTPException)
    if exc.status_code == status.HTTP_400_BAD_REQUEST and exc.detail == UNPARSABLE_BODY:
        if (refused := await _token_first(request)) is not None:
            return refused
        error = {"loc": ["body"], "msg": "the body is not JSON text", "type": "json_invalid"}
        return JSONResponse({"detail": [error]}, status_code=status.HTTP_422_UNPROCESSABLE_CONTENT)
    return await http_exception_handler(request, exc)


async def _unstorable(_: Request, exc: Exception) -> JSONResponse:
    return JSONResponse({"detail": str(exc)}, status_code=status.HTTP_422_UNPROCESSABLE_CONTENT)


def install_error_handlers(app: FastAPI) -> None:
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(HTTPException, _http_error)
    app.add_exception_handler(TaskError, _task_error)
    app.add_exception_handler(UnstorableJson, _unstorable)
