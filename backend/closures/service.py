"""ClosureService: the closures in force, kept, logged and told (docs/server.md, "Building
modes and trouble").

Staff add and remove closures (REST, ``backend/closures/routes.py``); trouble comes from the
building's ``command_failed`` (``trouble.py``). Whenever the set of closed nodes changes (a
closure added or removed, a time window starting or ending, trouble raised or lifted) robots
and consoles get ``closures_changed`` with the closed nodes: a robot whose path ahead crosses
one plans again, and a robot never plans on board while nodes are closed (the Traffic
Manager's ``get_path`` answers around them). Each change is in the event log with who did it.
"""

from __future__ import annotations

import asyncio
import logging
import secrets
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from backend.closure import (
    Closure,
    ClosureError,
    ClosureRequest,
    closed_nodes,
    element_nodes,
)
from backend.closures.store import ClosureStore
from backend.closures.trouble import TROUBLE_HOLD_S, hold_for, trouble_of
from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.traffic import ClosuresChanged
from guidebot.service import Service
from guidebot.site.schema import Site

__all__ = ["ClosureService"]

log = logging.getLogger(__name__)

TICK_S = 1.0
"""How often time windows are looked at (a closure starts or ends within this)."""


class EventSink(Protocol):
    def record_event(self, kind: str, source: str, data: dict[str, Any]) -> None: ...


class ClosureService(Service):
    """One per server (backend.closures.component, ``app.state.closures``)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        site: Callable[[], Site],
        store: ClosureStore | None,
        events: EventSink | None,
        *,
        trouble_hold_s: float = TROUBLE_HOLD_S,
        clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self._site = site
        self.store = store
        self.events = events
        self.trouble_hold_s = trouble_hold_s
        """The longest hold of trouble (``hold_for``)."""
        self.clock = clock
        self._failures: dict[str, int] = {}
        """Trouble closure id -> its device's failures in a row (not seen working since)."""
        self.closures: dict[str, Closure] = {}
        self._closed: dict[str, Closure] = {}
        self._site_seen: Site | None = None

    # -- life cycle --------------------------------------------------------------------------

    async def restore(self) -> None:
        """Staff closures kept by the last server life (those over are dropped)."""
        if self.store is None:
            return
        for closure in await self.store.load(self.clock()):
            self.closures[closure.id] = closure
        if self.closures:
            log.warning("closures kept from the last server life: %s", self._names())
        self._recompute()

    async def on_start(self) -> None:
        self.subscribe(self.endpoint, "command_failed", self._on_command_failed, tap=True)
        self.subscribe(self.endpoint, "door_opened", self._on_working, tap=True)
        self.subscribe(self.endpoint, "elevator_in_position", self._on_working, tap=True)
        self.subscribe(self.endpoint, "building_module_health", self._on_module_health, tap=True)
        self.subscribe(self.endpoint, "robot_connected", self._on_robot_connected)
        self.spawn(self._tick(), name="closures-tick")

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(TICK_S)
            self.refresh()

    # -- queries ------------------------------------------------------------------------------

    @property
    def closed(self) -> Mapping[str, Closure]:
        """Node -> the closure that takes it out, now (what paths avoid)."""
        if self._site_seen is not self._site():
            self._recompute()  # a publish: the elements' nodes may have moved
        return self._closed

    def view(self) -> dict[str, Any]:
        return {"closures": self._views(), "closed_nodes": sorted(self.closed)}

    def _views(self) -> list[dict[str, Any]]:
        """Each closure as shown, with the nodes it closes now (``closed_nodes``)."""
        now = self.clock()
        by: dict[str, list[str]] = {}
        for node, closure in self._closed.items():
            by.setdefault(closure.id, []).append(node)
        views = []
        for closure in sorted(self.closures.values(), key=_order):
            view = closure.view(now)
            view["closed_nodes"] = sorted(by.get(closure.id, []))
            views.append(view)
        return views

    # -- staff ----------------------------------------------------------------------------------

    async def add(self, request: ClosureRequest, *, by: str) -> Closure:
        """Close an element (ClosureError: the site has no such element)."""
        element_nodes(self._site(), request.kind, request.target, request.nodes)
        now = self.clock()
        if request.end is not None and request.end <= now:
            raise ClosureError("end is already past")
        closure = Closure(
            id=f"c{secrets.token_hex(4)}",
            kind=request.kind,
            target=request.target,
            nodes=request.nodes,
            reason=request.reason,
            start=request.start,
            end=request.end,
            by=by,
            created_at=now,
        )
        if self.store is not None:
            await self.store.save(closure)
        self.closures[closure.id] = closure
        self._log("closure_added", closure, by)
        log.info("closure %s: %s closed by %s (%s)", closure.id, closure.what(), by, closure.reason)
        self.refresh(force=True)
        return closure

    async def remove(self, closure_id: str, *, by: str) -> Closure:
        """Reopen (KeyError: no such closure)."""
        closure = self.closures[closure_id]
        if self.store is not None and closure.source == "staff":
            await self.store.delete(closure_id)
        del self.closures[closure_id]
        self._log("closure_removed", closure, by)
        log.info("closure %s: %s reopened by %s", closure_id, closure.what(), by)
        self.refresh(force=True)
        return closure

    # -- trouble ----------------------------------------------------------------------------------

    def _on_command_failed(self, message: Message) -> None:
        p = message.payload
        trouble = trouble_of(
            str(p.get("command") or ""),
            p.get("target"),
            str(p.get("reason") or ""),
            self.clock(),
            self.trouble_hold_s,
        )
        if trouble is None:
            return
        try:
            element_nodes(self._site(), trouble.kind, trouble.target, [])
        except ClosureError:
            return
        known = trouble.id in self.closures
        # A failure while it is closed (another robot's) is the same one; one after its hold
        # ended, not seen working since, is the next in a row: held twice as long.
        failures = self._failures.get(trouble.id, 0) + (0 if known else 1)
        self._failures[trouble.id] = failures
        trouble.end = trouble.created_at + hold_for(failures, self.trouble_hold_s)
        self.closures[trouble.id] = trouble  # again: held on from now
        if not known:
            log.warning("trouble: %s; robots re-plan around it", trouble.reason)
            self._log("trouble_raised", trouble, "building")
            self.refresh(force=True)

    def _on_working(self, message: Message) -> None:
        p = message.payload
        if message.type == "door_opened":
            key = f"trouble-door-{p.get('door')}"
        elif p.get("door_open", True):
            key = f"trouble-elevator-{p.get('elevator')}"
        else:
            return
        self._failures.pop(key, None)  # working: its next failure is a first one again
        trouble = self.closures.pop(key, None)
        if trouble is not None:
            log.info("trouble over: %s works again", trouble.what())
            self._log("trouble_cleared", trouble, "building", why="seen working")
            self.refresh(force=True)

    def _on_module_health(self, message: Message) -> None:
        """A module back online: the doors and lifts that failed only because it was offline
        work again. Nobody would see them work (no robot asks a closed door to open), so
        they stayed closed for the whole hold: a 7 s Modbus outage closed the lift and the
        gallery door for 120 s in the fault soak (issue 36)."""
        p = message.payload
        if not p.get("online"):
            return
        offline = f"module {p.get('module')} is offline"
        gone = [c for c in self.closures.values() if c.source == "trouble" and offline in c.reason]
        for trouble in gone:
            del self.closures[trouble.id]
            self._failures.pop(trouble.id, None)
            log.info("trouble over: %s, its module is back online", trouble.what())
            self._log("trouble_cleared", trouble, "building", why="its module is back online")
        if gone:
            self.refresh(force=True)

    def _on_robot_connected(self, message: Message) -> None:
        robot = message.payload.get("robot")
        if isinstance(robot, str) and self._closed:
            self.endpoint.publish(self._news(), destination=robot)

    # -- changes ------------------------------------------------------------------------------

    def refresh(self, *, force: bool = False) -> None:
        """Drop what is over, recompute the closed nodes, tell everyone when they changed."""
        now = self.clock()
        for closure in [c for c in self.closures.values() if c.over(now)]:
            del self.closures[closure.id]
            kind = "trouble_cleared" if closure.source == "trouble" else "closure_ended"
            self._log(kind, closure, closure.by, why="its time is over")
            if self.store is not None and closure.source == "staff":
                self.spawn(self.store.delete(closure.id), name="closure-delete")
            force = True
        before = set(self._closed)
        self._recompute()
        if force or set(self._closed) != before:
            self.endpoint.publish(self._news())

    def _recompute(self) -> None:
        site = self._site()
        self._site_seen = site
        self._closed = closed_nodes(site, sorted(self.closures.values(), key=_order), self.clock())

    def _news(self) -> ClosuresChanged:
        return ClosuresChanged(nodes=sorted(self._closed), closures=self._views())

    def _log(self, kind: str, closure: Closure, by: str, why: str = "") -> None:
        if self.events is None:
            return
        data: dict[str, Any] = {
            "closure": closure.id,
            "what": closure.what(),
            "kind": closure.kind,
            "target": closure.target,
            "reason": closure.reason,
            "by": by,
        }
        if closure.nodes:
            data["nodes"] = closure.nodes[:50]
        if closure.start is not None:
            data["start"] = closure.start
        if closure.end is not None:
            data["end"] = closure.end
        if why:
            data["why"] = why
        self.events.record_event(kind, "closures", data)

    def _names(self) -> str:
        return ", ".join(c.what() for c in self.closures.values())


def _order(closure: Closure) -> tuple[float, str]:
    return (closure.created_at, closure.id)
