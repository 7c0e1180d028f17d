"""One handler answers every Task Manager mistake, on any route that lets it through."""

from __future__ import annotations

import httpx
import pytest
from fastapi import FastAPI, HTTPException

from backend.api.errors import install_error_handlers
from backend.rest.deps import Tasks
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


async def test_a_body_that_is_not_json_text_is_a_422_like_any_bad_json() -> None:
    """Bytes that no UTF encoding decodes made FastAPI answer an undocumented 400 (the
    stateful fuzz found it); other HTTP errors keep their status and headers."""
    app = FastAPI()
    install_error_handlers(app)

    @app.post("/priority")
    async def priority(body: dict[str, int]) -> dict[str, int]:
        return body

    @app.get("/teapot")
    async def teapot() -> None:
        raise HTTPException(418, "short and stout", headers={"X-Kind": "teapot"})

    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://test") as client:
        bad = await client.post(
            "/priority", content=b"\xff\xfe\x00", headers={"content-type": "application/json"}
        )
        good = await client.post("/priority", json={"priority": 3})
        other = await client.get("/teapot")
    assert bad.status_code == 422 and bad.json()["detail"][0]["type"] == "json_invalid"
    assert good.status_code == 200 and good.json() == {"priority": 3}
    assert other.status_code == 418 and other.headers["X-Kind"] == "teapot"
    assert other.json() == {"detail": "short and stout"}
