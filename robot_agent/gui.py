"""The on-board touch screen: tours and points of interest to request, the current explanation
with its picture, the "continue the tour?" question with its time-out, and the robot's state
(charging, going to the next point, link to the server lost); during a fire alarm, the
evacuation screen with the site's words in the screen's language, and requests refused with
them (docs/emergency.md).

A small FastAPI app served by uvicorn in the agent's own event loop at ``--gui-port``:
``GET /`` the page, ``GET /api/screen?lang=`` what the screen shows (JSON, texts in that
language), ``POST /api/request`` (a tour or a point of interest: a task_request to the Task
Manager), ``POST /api/answer`` (the visitor's answer) and ``WS /ws`` (every change, pushed). The
page shares the visitor panel's look and language files (``web/lib``, ``web/lang``,
``web/visitor/visitor.css``, served from the same web folder) and the site's pictures. The
question module lives here too: ask_continue shows the question; the first answer, or the
time-out, sends continue_answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable, Generator
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import uvicorn
from fastapi import FastAPI, HTTPException, Query, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field, StrictBool

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.next_tours import in_language
from guidebot.pace import PaceName, pace_of
from guidebot.paths import WEB_DIR
from guidebot.payloads.bookings import NextTour, NextTours
from guidebot.payloads.emergency import EmergencyChanged, Evacuate, EvacuationState
from guidebot.payloads.petri import ContinueAnswer
from guidebot.payloads.tasks import TaskAssigned, VisitorService
from guidebot.service import Service
from guidebot.site.access import graph_of, step_free_skips, steps_only_nodes
from guidebot.site.i18n import fallbacks, poi_texts, resolve_language, site_languages, tour_texts
from guidebot.site.media import MEDIA_HEADERS, MEDIA_TYPES, SERVED_TYPES, media_file, video_url
from guidebot.site.schema import Site
from guidebot.task_kinds import KINDS, VISITOR_KINDS
from robot_agent.clock import Clock

__all__ = ["AlarmHolds", "OnboardScreen", "ScreenServer", "VisitorAnswer"]

log = logging.getLogger(__name__)

WATCHER_QUEUE = 100
SCREEN_EVENT = "screen_event"
"""On-board only: what the screen's page is pushed (docs/messages.md)."""
PAGE_POLICY = (
    "default-src 'self'; script-src 'self'; img-src 'self' data:; style-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
VISITOR_NETS = frozenset(KINDS[kind].net for kind in VISITOR_KINDS)
"""Main tasks a visitor follows on the screen (the others keep the menu up)."""
SHARED_FOLDERS = ("lib", "lang", "vendor", "visitor")
"""Folders of the server's web/ the touch screen serves too: one look, one set of texts."""


VisitorAnswer = Literal["yes", "no"]
"""What a visitor answers to "continue the tour?" (without an answer: "timeout")."""


class LinkDown(RuntimeError):
    """A request while the link to the server is down and requests are refused."""


class AlarmHolds(RuntimeError):
    """A request while a fire alarm holds the service: the site's words say why (REST 503,
    reason ``emergency``, as the server answers it)."""

    reason = "emergency"


class TourRequest(BaseModel):
    kind: Literal["tour", "go_to_poi"]
    tour: str | None = Field(default=None, max_length=64)
    poi: str | None = Field(default=None, max_length=64)
    lang: str | None = Field(default=None, max_length=16)
    pace: PaceName | None = None
    """``slow``: a slower tour (guidebot/pace.py)."""
    step_free: StrictBool | None = None
    """A tour or a visit over no steps (docs/visitor.md, "A step-free tour")."""


class Answer(BaseModel):
    answer: VisitorAnswer


class OnboardScreen(Service):
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
        auto_answer: VisitorAnswer | None = None,
        site: Site | None = None,
        site_file: Path | None = None,
        link_up: Callable[[], bool] | None = None,
        offline_requests: Literal["queue", "refuse"] = "queue",
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.auto_answer = auto_answer
        """Demo: a simulated visitor who answers this after 3 robot seconds (None: nobody)."""
        self.clock = clock
        self.robot = robot
        self.tours = tours or []
        self.pois = pois or []
        self.state = state or (lambda: {})
        self.site = site
        """With a site, tours and points come in every language it offers."""
        self.site_file = site_file
        self.link_up = link_up
        """None: the robot has no link to a server (standalone)."""
        self.offline_requests = offline_requests
        """Link down: "queue" sends requests when it is back, "refuse" says no at once."""
        self.lang: str | None = None
        """The language of the tour running now (the screen follows it)."""
        self.task: dict[str, Any] | None = None
        self.going = False
        self.explanation: dict[str, Any] | None = None
        self.skipped: list[dict[str, Any]] = []
        """Stops the running tour skipped (closed off): index, name, poi, reason."""
        self.speaking: dict[str, Any] | None = None
        """The words being said (the captions): {text, lang, started_at: Unix time of its
        speech_started}; None when the robot is silent."""
        self.question: dict[str, Any] | None = None
        self.answers: list[str] = []
        self._question_timer: asyncio.TimerHandle | None = None
        self.next_tours: list[NextTour] = []
        """Today's coming public booked tours (the server's ``next_tours``)."""
        self.service: str | None = None
        """What a new visitor request would be told (the server's ``visitor_service``:
        ``paused`` while staff pause the fleet); None before the server said."""
        self.alarm: dict[str, Any] | None = None
        """While a fire alarm holds the service: {words: {lang: text}, evacuation: this
        robot's own state (stopped, moving, safe, stuck) or None}; None otherwise."""

    async def on_start(self) -> None:
        self.subscribe_all(
            self.ep,
            {
                "show_point": self._on_show_point,
                "point_skipped": self._on_point_skipped,
                "ask_continue": self._on_ask,
                "speech_started": self._on_speech,
                "speech_ended": self._on_speech,
                "task_ended": self._on_task_ended,
                "navigate_to": self._on_going,
                "goal_reached": self._on_going,
                "navigation_failed": self._on_going,
                "robot_state": self._on_robot_state,
            },
        )
        self.on(self.ep, TaskAssigned, self._on_task_assigned)
        self.on(self.ep, EmergencyChanged, self._on_emergency)
        self.on(self.ep, Evacuate, self._on_evacuate)
        self.on(self.ep, EvacuationState, self._on_evacuation_state)
        self.subscribe(self.ep, "next_tours", self._on_next_tours)
        self.on(self.ep, VisitorService, self._on_service)

    async def on_stop(self) -> None:
        if self._question_timer is not None:
            self._question_timer.cancel()

    # -- what is shown ------------------------------------------------------------------------

    def screen(self, lang: str | None = None) -> dict[str, Any]:
        """What the screen shows; tours and points in ``lang`` (else the running tour's)."""
        site = self.site
        chosen = resolve_language(site, lang or self.lang) if site else (lang or "en")
        return {
            "robot": self.robot,
            "lang": chosen,
            "tour_lang": self.lang,
            "languages": site_languages(site) if site else [chosen],
            "tours": self._tours(chosen),
            "pois": self._pois(chosen),
            "next_tours": in_language(site, self.next_tours, chosen) if site else [],
            "service": self.service,
            "task": self.task,
            "going": self.going,
            "explanation": self.explanation,
            "skipped": self.skipped,
            "speaking": self.speaking,
            "question": self.question,
            "state": self.state(),
            "link": {
                "up": None if self.link_up is None else self.link_up(),
                "offline_requests": self.offline_requests,
            },
            "alarm": None
            if self.alarm is None
            else {"words": self.alarm_words(chosen), "evacuation": self.alarm["evacuation"]},
        }

    def alarm_words(self, lang: str | None) -> str:
        """The site's alarm words in ``lang``, else in the site's default language, else in the
        first language given; empty when none came."""
        words: dict[str, str] = (self.alarm or {}).get("words") or {}
        default = self.site.default_language if self.site is not None else None
        for tag in (lang, default):
            if tag in words:
                return words[tag]
        return next(iter(words.values()), "")

    def _tours(self, lang: str) -> list[dict[str, Any]]:
        site = self.site
        if site is None:
            return self.tours
        graph = graph_of(site)
        return [
            {
                "id": t.id,
                "points": t.points,
                **tour_texts(site, t, lang),
                "fallback": fallbacks(site, t, lang),
                # what a step-free tour skips (the building as built: guidebot/site/access.py)
                "step_free_skips": step_free_skips(site, graph, t),
            }
            for t in site.tours
        ]

    def _pois(self, lang: str) -> list[dict[str, Any]]:
        site = self.site
        if site is None:
            return self.pois
        out = []
        cut = steps_only_nodes(graph_of(site))
        for p in site.pois:
            texts = poi_texts(site, p, lang)
            out.append(
                {
                    "id": p.id,
                    "node": p.node,
                    "name": texts["name"],
                    "description": texts["description"],
                    "media": [media_link(m) for m in texts["media"]],
                    "fallback": fallbacks(site, p, lang),
                    "steps_only": p.node in cut,  # a step-free visit is refused
                }
            )
        return out

    def _on_next_tours(self, message: Message) -> None:
        try:
            self.next_tours = message.typed(NextTours).tours
        except ValueError:
            log.warning("next_tours not understood: %r", message.payload)
            return
        self._push("next_tours", None)

    def _on_service(self, message: Message, news: VisitorService) -> None:
        """The fleet's service changed (staff paused it, resumed): the screen says so."""
        if news.service != self.service:
            self.service = news.service
            self._push("service", {"service": news.service})

    def _push(self, kind: str, data: Any) -> None:
        self.ep.publish(SCREEN_EVENT, {"kind": kind, "data": data})

    def watch(self) -> contextlib.AbstractAsyncContextManager[AsyncIterator[Message]]:
        """Every change, as screen_event messages (payload: kind, data): a bus subscription,
        so bounded; a slow screen loses its oldest events."""
        return self.ep.subscription(SCREEN_EVENT, maxsize=WATCHER_QUEUE)

    def _on_task_assigned(self, message: Message, assigned: TaskAssigned) -> None:
        if assigned.net not in VISITOR_NETS:
            return  # charging, going to a wait point: the menu stays
        if self.task is not None and self.task["id"] != assigned.task_id:
            return  # one task at a time: the robot refuses this one, the running tour stays
        params = assigned.params
        lang = params.get("lang")
        self.lang = lang if isinstance(lang, str) else None
        self.task = {
            "id": assigned.task_id,
            "tour": params.get("tour"),
            "pace": pace_of(params).name,  # a slower tour: the screen says so
            "step_free": params.get("step_free") is True,
            "handover": assigned.handover,  # taken up from another robot
        }
        self.skipped = list(params.get("skipped") or [])  # first stops only steps lead to
        self._push("task_assigned", {"task": self.task, "lang": self.lang})

    # -- the fire alarm ---------------------------------------------------------------------

    def _on_emergency(self, message: Message, changed: EmergencyChanged) -> None:
        """The server's state: an alarm anywhere holds new requests (docs/emergency.md)."""
        if changed.state == "normal":
            self.alarm = None
        else:
            words = changed.words
            evacuation = (self.alarm or {}).get("evacuation")
            self.alarm = {"words": dict(words), "evacuation": evacuation}
        self._push("emergency", {"alarm": self.alarm})

    def _on_evacuate(self, message: Message, order: Evacuate) -> None:
        """This robot's order to leave (it may come without emergency_changed: a robot that
        connected during the alarm)."""
        if message.destination not in (None, self.robot):
            return
        words = order.words or (self.alarm or {}).get("words") or {}
        self.alarm = {"words": dict(words), "evacuation": (self.alarm or {}).get("evacuation")}
        self._push("emergency", {"alarm": self.alarm})

    def _on_evacuation_state(self, message: Message, report: EvacuationState) -> None:
        if self.alarm is not None:
            self.alarm["evacuation"] = report.state
            self._push("emergency", {"alarm": self.alarm})

    def _on_robot_state(self, message: Message) -> None:
        self._push("state", {})  # battery, mode and the link change without other events

    def _on_going(self, message: Message) -> None:
        self.going = message.type == "navigate_to" and self.task is not None
        self._push("going", {"going": self.going})

    def _on_show_point(self, message: Message) -> None:
        point = message.payload.get("point")
        point = point if isinstance(point, dict) else {}
        poi = message.payload.get("poi")
        # A single point (go_to_poi) comes without its texts: its name and pictures from the
        # site, in the task's language; never its id.
        site_texts = self._poi_texts(poi) if not point.get("name") else None
        self.explanation = {
            "poi": poi,
            "name": point.get("name") or (site_texts or {}).get("name") or poi,
            "text": message.payload.get("text", ""),
            "media": [
                media_link(m) for m in point.get("media") or (site_texts or {}).get("media") or []
            ],
            "index": point.get("index"),
            "total": point.get("total"),
            "lang": message.payload.get("lang"),
            # The language the text really is in (the site's default when not translated).
            "text_lang": point.get("lang") or (site_texts or {}).get("lang"),
            # The text in sign language, where the site has a video of it.
            "sign_video": video_url(
                point.get("sign_video") or (site_texts or {}).get("sign_video")
            ),
        }
        self._push("show_point", self.explanation)

    def _on_point_skipped(self, message: Message) -> None:
        point = message.payload.get("point")
        point = point if isinstance(point, dict) else {}
        skip = {
            "index": point.get("index"),
            "poi": point.get("poi"),
            "name": point.get("name") or point.get("poi"),
            "reason": message.payload.get("reason", ""),
        }
        self.skipped.append(skip)
        self._push("point_skipped", skip)

    def _check_step_free(self, req: TourRequest) -> None:
        """A step-free visit to a point only steps lead to is refused here, as the server
        would (guidebot/site/access.py)."""
        site = self.site
        poi = site.poi(req.poi) if site is not None and req.step_free and req.poi else None
        if site is not None and poi is not None and poi.node in steps_only_nodes(graph_of(site)):
            raise ValueError(f"only steps lead to point {poi.id!r}: no step-free visit")

    def _poi_texts(self, poi: object) -> dict[str, Any] | None:
        """A point's texts from the site in the running task's language (None: unknown)."""
        site = self.site
        found = site.poi(poi) if site is not None and isinstance(poi, str) else None
        if site is None or found is None:
            return None
        return poi_texts(site, found, resolve_language(site, self.lang))

    def _on_speech(self, message: Message) -> None:
        started = message.type == "speech_started"
        self.speaking = (
            {
                "text": str(message.payload.get("text", "")),
                "lang": message.payload.get("lang"),
                "started_at": message.timestamp,
            }
            if started
            else None
        )
        self._push(message.type, message.payload)

    def _on_task_ended(self, message: Message) -> None:
        if message.payload.get("outcome") == "refused":
            return  # a task it did not take: the running tour stays on the screen
        self.explanation = None
        self.skipped = []
        self.task = None
        self.lang = None
        self.going = False
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
            # Unix time the question closes: the page counts down to it.
            "deadline_at": time.time() + self.clock.wall(timeout_s),
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

    def answer(self, answer: VisitorAnswer) -> bool:
        """The visitor touched yes or no; False when no question is open."""
        if self.question is None:
            return False
        self._close_question(answer)
        return True

    def _close_question(self, answer: VisitorAnswer | Literal["timeout"] | None) -> None:
        question, self.question = self.question, None
        if self._question_timer is not None:
            self._question_timer.cancel()
            self._question_timer = None
        if question is None or answer is None:
            return
        self.answers.append(answer)
        self.ep.publish(ContinueAnswer(answer=answer), correlation_id=question["id"])
        self._push("continue_answer", {"answer": answer})

    # -- requests from the screen -------------------------------------------------------------

    def request(self, req: TourRequest) -> Message:
        """A visitor asks for a tour or a point: a task_request for the Task Manager.
        Raises LinkDown when the server cannot be reached and requests are refused."""
        if self.alarm is not None:
            raise AlarmHolds(
                self.alarm_words(req.lang) or "fire alarm: no request until it is over"
            )
        if self.link_up is not None and not self.link_up() and self.offline_requests == "refuse":
            raise LinkDown("no connection to the server: requests are refused until it is back")
        if req.kind == "tour":
            known = {t["id"] for t in self.tours}
            if not req.tour or (known and req.tour not in known):
                raise ValueError(f"unknown tour {req.tour!r}; known: {sorted(known)}")
            params: dict[str, Any] = {"tour": req.tour}
        else:
            known = {p["id"] for p in self.pois}
            if not req.poi or (known and req.poi not in known):
                raise ValueError(f"unknown point of interest {req.poi!r}; known: {sorted(known)}")
            params = {"poi": req.poi}
            self._check_step_free(req)
        if req.lang:
            params["lang"] = req.lang
        if req.pace and req.pace != "normal":
            params["pace"] = req.pace
        if req.step_free:
            params["step_free"] = True
        return self.ep.publish(
            "task_request",
            {"kind": req.kind, "params": params, "priority": 5, "requester": self.robot},
        )


def media_link(name: str) -> dict[str, str | None]:
    """A media item as the pages take it: its name and, for a picture, where to load it."""
    suffix = Path(name).suffix.lower()
    return {"name": name, "url": f"/media/{name}" if suffix in MEDIA_TYPES else None}


def create_screen_app(
    screen: OnboardScreen,
    web_dir: Path = WEB_DIR,
    metrics: Callable[[], bytes] | None = None,
    *,
    extra: Callable[[FastAPI], None] | None = None,
) -> FastAPI:
    """The touch screen's app; ``extra`` adds routes (the simulator's fault injection)."""
    app = FastAPI(title=f"GuideBot {screen.robot} touch screen", docs_url=None, redoc_url=None)
    if extra is not None:
        extra(app)
    if metrics is not None:
        render = metrics

        @app.get("/metrics", response_class=Response)
        async def get_metrics() -> Response:
            """Prometheus text format (docs/metrics.md)."""
            return Response(render(), media_type="text/plain; version=0.0.4; charset=utf-8")

    files = resources.files("robot_agent")
    page = files.joinpath("gui_page.html").read_text(encoding="utf-8")
    script = files.joinpath("gui_page.js").read_text(encoding="utf-8")
    headers = {"Content-Security-Policy": PAGE_POLICY, "X-Content-Type-Options": "nosniff"}

    @app.get("/", response_class=HTMLResponse)
    async def index() -> HTMLResponse:
        return HTMLResponse(page, headers=headers)

    @app.get("/gui_page.js")
    async def page_script() -> Response:
        return Response(script, media_type="text/javascript", headers=headers)

    @app.get("/api/screen")
    async def get_screen(lang: str | None = Query(default=None, max_length=16)) -> dict[str, Any]:
        return screen.screen(lang)

    @app.post("/api/request", status_code=202, response_model=None)
    async def post_request(req: TourRequest) -> dict[str, Any] | JSONResponse:
        try:
            message = screen.request(req)
        except AlarmHolds as exc:
            return JSONResponse({"detail": str(exc), "reason": AlarmHolds.reason}, status_code=503)
        except LinkDown as exc:
            raise HTTPException(status_code=503, detail=str(exc)) from None
        except ValueError as exc:
            raise HTTPException(status_code=422, detail=str(exc)) from None
        queued = screen.link_up is not None and not screen.link_up()
        return {
            "request_id": message.id,
            "kind": req.kind,
            "queued_offline": queued,
            **message.payload["params"],
        }

    @app.get("/media/{name:path}")
    async def media(name: str) -> FileResponse:
        path = media_file(screen.site_file, name)
        if path is None:
            raise HTTPException(status_code=404, detail=f"media {name!r} not found")
        return FileResponse(
            path, media_type=SERVED_TYPES[path.suffix.lower()], headers=MEDIA_HEADERS
        )

    for folder in SHARED_FOLDERS:
        if (web_dir / folder).is_dir():
            app.mount(f"/{folder}", StaticFiles(directory=web_dir / folder), name=folder)

    @app.post("/api/answer")
    async def post_answer(body: Answer) -> dict[str, Any]:
        if not screen.answer(body.answer):
            raise HTTPException(status_code=409, detail="no question is open")
        return {"answer": body.answer}

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        await websocket.accept()
        async with screen.watch() as events:
            lang = websocket.query_params.get("lang")
            await websocket.send_json({"kind": "screen", "data": screen.screen(lang)})

            async def push() -> None:
                async for event in events:
                    await websocket.send_json(event.payload)

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


class ScreenServer(Service):
    """uvicorn serving the screen app on 127.0.0.1 (port 0: any free port, read back)."""

    def __init__(
        self,
        screen: OnboardScreen,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        metrics: Callable[[], bytes] | None = None,
        extra: Callable[[FastAPI], None] | None = None,
    ) -> None:
        super().__init__()
        self.screen = screen
        self.metrics = metrics
        self.extra = extra
        self.host = host
        self.port = port
        self._server: _QuietServer | None = None
        self._task: asyncio.Task[None] | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    async def on_start(self) -> None:
        config = uvicorn.Config(
            create_screen_app(self.screen, metrics=self.metrics, extra=self.extra),
            host=self.host,
            port=self.port,
            log_level="warning",
            lifespan="off",
            ws="websockets-sansio",
            timeout_graceful_shutdown=2,
        )
        self._server = _QuietServer(config)
        self._task = asyncio.create_task(self._server.serve(), name="screen-server")
        self.on_cleanup(self._shut_down)
        async with asyncio.timeout(20):
            while not self._server.started:
                if self._task.done():
                    self._task.result()
                    raise RuntimeError("the screen server stopped at start-up")
                await asyncio.sleep(0.01)
        sockets = self._server.servers[0].sockets
        self.port = sockets[0].getsockname()[1]

    async def _shut_down(self) -> None:
        """Graceful: uvicorn closes its connections itself (a cancel would cut them)."""
        if self._server is not None and self._task is not None:
            self._server.should_exit = True
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
