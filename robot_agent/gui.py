"""The on-board touch screen: tours and points of interest to request, the current explanation,
and the "continue the tour?" question with its time-out.

A small FastAPI app served by uvicorn in the agent's own event loop at ``--gui-port``:
``GET /`` the page, ``GET /api/screen`` what the screen shows (JSON), ``POST /api/request``
(a tour or a point of interest: a task_request to the Task Manager), ``POST /api/answer`` (the
visitor's answer) and ``WS /ws`` (every change, pushed). The question module lives here too:
ask_continue shows the question; the first answer, or the time-out, sends continue_answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Generator
from importlib import resources
from typing import Any, Literal

import uvicorn
from fastapi import FastAPI, HTTPException, WebSocket, WebSocketDisconnect
from fastapi.responses import HTMLResponse
from pydantic import BaseModel, Field

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from robot_agent.clock import Clock

__all__ = ["OnboardScreen", "ScreenServer"]

log = logging.getLogger(__name__)

WATCHER_QUEUE = 100


class TourRequest(BaseModel):
    kind: Literal["tour", "go_to_poi"]
    tour: str | None = Field(default=None, max_length=64)
    poi: str | None = Field(default=None, max_length=64)


class Answer(BaseModel):
    answer: Literal["yes", "no"]


class OnboardScreen:
    """What the touch screen shows, and the question/answer logic (no HTTP here)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        robot: str,
        *,
        tours: list[dict[str, Any]] | None = None,
        pois: list[dict[str, Any]] | None = None,
        state: Callable[[], dict[str, Any]] | None = None,
        auto_answer: str | None = None,
    ) -> None:
        self.ep = endpoint
        self.auto_answer = auto_answer
        """Demo: a simulated visitor who answers this after 3 robot seconds (None: nobody)."""
        self.clock = clock
        self.robot = robot
        self.tours = tours or []
        self.pois = pois or []
        self.state = state or (lambda: {})
        self.explanation: dict[str, Any] | None = None
        self.speaking: str | None = None
        self.question: dict[str, Any] | None = None
        self.answers: list[str] = []
        self._question_timer: asyncio.TimerHandle | None = None
        self._watchers: set[asyncio.Queue[dict[str, Any]]] = set()
        self._unsubs: list[Callable[[], None]] = []

    def start(self) -> None:
        sub = self.ep.subscribe
        self._unsubs = [
            sub("show_point", self._on_show_point),
            sub("ask_continue", self._on_ask),
            sub("speech_started", self._on_speech),
            sub("speech_ended", self._on_speech),
            sub("task_ended", self._on_task_ended),
        ]

    def stop(self) -> None:
        for unsub in self._unsubs:
            unsub()
        self._unsubs.clear()
        if self._question_timer is not None:
            self._question_timer.cancel()

    # -- what is shown ------------------------------------------------------------------------

    def screen(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "tours": self.tours,
            "pois": self.pois,
            "explanation": self.explanation,
            "speaking": self.speaking,
            "question": self.question,
            "state": self.state(),
        }

    def _push(self, kind: str, data: Any) -> None:
        event = {"kind": kind, "data": data}
        for queue in list(self._watchers):
            if queue.full():  # overflow rule: a slow screen loses its oldest events
                queue.get_nowait()
            queue.put_nowait(event)

    @contextlib.contextmanager
    def watch(self) -> Generator[asyncio.Queue[dict[str, Any]], None, None]:
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=WATCHER_QUEUE)
        self._watchers.add(queue)
        try:
            yield queue
        finally:
            self._watchers.discard(queue)

    def _on_show_point(self, message: Message) -> None:
        self.explanation = {
            "poi": message.payload.get("poi"),
            "text": message.payload.get("text", ""),
            "media": message.payload.get("media", []),
        }
        self._push("show_point", self.explanation)

    def _on_speech(self, message: Message) -> None:
        started = message.type == "speech_started"
        self.speaking = str(message.payload.get("text", "")) if started else None
        self._push(message.type, message.payload)

    def _on_task_ended(self, message: Message) -> None:
        self.explanation = None
        self._close_question(None)
        self._push("task_ended", message.payload)

    # -- the "continue the tour?" question ----------------------------------------------------

    def _on_ask(self, message: Message) -> None:
        timeout_s = float(message.payload.get("timeout_s") or 20.0)
        self._close_question(None)
        self.question = {
            "id": message.id,
            "question": message.payload.get("question") or "Shall we go on with the tour?",
            "timeout_s": timeout_s,
            "deadline_wall_s": self.clock.wall(timeout_s),
        }
        loop = asyncio.get_running_loop()
        self._question_timer = loop.call_later(
            self.clock.wall(timeout_s), self._close_question, "timeout"
        )
        self._push("ask_continue", self.question)
        if self.auto_answer is not None:
            question_id = message.id
            loop.call_later(
                self.clock.wall(min(3.0, timeout_s / 2)), self._simulated_visitor, question_id
            )

    def _simulated_visitor(self, question_id: str) -> None:
        if self.question is not None and self.question["id"] == question_id:
            self._close_question(self.auto_answer)

    def answer(self, answer: str) -> bool:
        """The visitor touched yes or no; False when no question is open."""
        if self.question is None:
            return False
        self._close_question(answer)
        return True

    def _close_question(self, answer: str | None) -> None:
        question, self.question = self.question, None
        if self._question_timer is not None:
            self._question_timer.cancel()
            self._question_timer = None
        if question is None or answer is None:
            return
        self.answers.append(answer)
        self.ep.publish("continue_answer", {"answer": answer}, correlation_id=question["id"])
        self._push("continue_answer", {"answer": answer})

    # -- requests from the screen -------------------------------------------------------------

    def request(self, req: TourRequest) -> Message:
        """A visitor asks for a tour or a point: a task_request for the Task Manager."""
        if req.kind == "tour":
            known = {t["id"] for t in self.tours}
            if not req.tour or (known and req.tour not in known):
                raise ValueError(f"unknown tour {req.tour!r}; known: {sorted(known)}")
            params = {"tour": req.tour}
        else:
            known = {p["id"] for p in self.pois}
            if not req.poi or (known and req.poi not in known):
                raise ValueError(f"unknown point of interest {req.poi!r}; known: {sorted(known)}")
            params = {"poi": req.poi}
        return self.ep.publish(
            "task_request",
            {"kind": req.kind, "params": params, "priority": 5, "requester": self.robot},
        )


def create_screen_app(
    screen: OnboardScreen, *, extra: Callable[[FastAPI], None] | None = None
) -> FastAPI:
    """The touch screen's app; ``extra`` adds routes (the simulator's fault injection)."""
    app = FastAPI(title=f"GuideBot {screen.robot} touch screen", docs_url=None, redoc_url=None)
    if extra is not None:
        extra(app)
    page = resources.files("robot_agent").joinpath("gui_page.html").read_text(encoding="utf-8")

    @app.get("/", response_class=HTMLResponse)
    async def index() -> str:
        return page

    @app.get("/api/screen")
    async def get_screen() -> dict[str, Any]:
        return screen.screen()

    @app.post("/api/request", status_code=202)
    async def post_request(req: TourRequest) -> dict[str, Any]:
        try:
            message = screen.request(req)
        except ValueError as exc:
            raise HTTPException(status_code=422, detail=str(exc)) from None
        return {"request_id": message.id, "kind": req.kind, **message.payload["params"]}

    @app.post("/api/answer")
    async def post_answer(body: Answer) -> dict[str, Any]:
        if not screen.answer(body.answer):
            raise HTTPException(status_code=409, detail="no question is open")
        return {"answer": body.answer}

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        await websocket.accept()
        with screen.watch() as queue:
            await websocket.send_json({"kind": "screen", "data": screen.screen()})

            async def push() -> None:
                while True:
                    await websocket.send_json(await queue.get())

            async def until_closed() -> None:
                with contextlib.suppress(WebSocketDisconnect):
                    while True:
                        await websocket.receive_text()  # the screen sends nothing; see the close

            pusher = asyncio.create_task(push())
            try:
                await until_closed()
            finally:
                pusher.cancel()
                with contextlib.suppress(asyncio.CancelledError, WebSocketDisconnect, RuntimeError):
                    await pusher

    return app


class _QuietServer(uvicorn.Server):
    """No signal handlers: the agent process owns Ctrl-C."""

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield


class ScreenServer:
    """uvicorn serving the screen app on 127.0.0.1 (port 0: any free port, read back)."""

    def __init__(
        self,
        screen: OnboardScreen,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        extra: Callable[[FastAPI], None] | None = None,
    ) -> None:
        self.screen = screen
        self.extra = extra
        self.host = host
        self.port = port
        self._server: _QuietServer | None = None
        self._task: asyncio.Task[None] | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    async def start(self) -> None:
        config = uvicorn.Config(
            create_screen_app(self.screen, extra=self.extra),
            host=self.host,
            port=self.port,
            log_level="warning",
            lifespan="off",
            ws="websockets-sansio",
            timeout_graceful_shutdown=2,
        )
        self._server = _QuietServer(config)
        self._task = asyncio.create_task(self._server.serve(), name="screen-server")
        async with asyncio.timeout(20):
            while not self._server.started:
                if self._task.done():
                    self._task.result()
                    raise RuntimeError("the screen server stopped at start-up")
                await asyncio.sleep(0.01)
        sockets = self._server.servers[0].sockets
        self.port = sockets[0].getsockname()[1]

    async def stop(self) -> None:
        if self._server is not None and self._task is not None:
            self._server.should_exit = True
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
