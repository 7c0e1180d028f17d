"""One handler answers every Task Manager mistake, on any route that lets it through."""

from __future__ import annotations

import httpx
import pytest
from fastapi import FastAPI

from backend.api.deps import Tasks
from backend.api.errors import install_error_handlers
from backend.tasks.model import (
    IllegalTransition,
    InvalidTask,
    QueueFull,
    TaskError,
    TaskFinished,
    TaskNotFound,
)

CASES = [
    (TaskNotFound("T9"), 404, "task not found"),
    (TaskFinished("task T1 is already done"), 409, "task T1 is already done"),
    (IllegalTransition("done -> running"), 409, "done -> running"),
    (QueueFull("the queue holds 1000 tasks"), 503, "the queue holds 1000 tasks"),
    (InvalidTask("unknown tour 'x'"), 422, "unknown tour 'x'"),
    (TaskError("anything else"), 422, "anything else"),
]


@pytest.mark.parametrize(("error", "code", "detail"), CASES)
async def test_a_task_error_becomes_its_status_with_its_sentence(
    error: TaskError, code: int, detail: str
) -> None:
    app = FastAPI()
    install_error_handlers(app)

    @app.get("/boom")
    async def boom() -> None:
        raise error

    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://test") as client:
        r = await client.get("/boom")
    assert r.status_code == code
    assert r.json() == {"detail": detail}


async def test_a_route_without_its_service_fails_loudly_not_with_none() -> None:
    """A route whose component did not start answers 500 naming the missing service."""
    app = FastAPI()

    @app.get("/tasks")
    async def tasks(manager: Tasks) -> int:
        return len(manager.tasks)

    transport = httpx.ASGITransport(app=app, raise_app_exceptions=True)
    async with httpx.AsyncClient(transport=transport, base_url="http://test") as client:
        with pytest.raises(RuntimeError, match=r"app\.state\.task_manager is not a TaskManager"):
            await client.get("/tasks")
