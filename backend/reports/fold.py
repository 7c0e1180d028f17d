"""The fold of the event log into hourly figures: a pure function of the events, in id order.

Each fact is counted in the hour of the event that completes it (a wait in the hour the robot
arrived, a tour's length in the hour it ended). What spans events (a task under way, a robot's
activity, a lock asked for and not yet granted) is the fold's ``state``, a JSON document kept
with the rollups' cursor so the next fold goes on where this one stopped (docs/reports.md).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["BUCKET_STEP", "ROBOT_STATES", "Fold", "Positions", "bucket", "hour_of"]

HOUR = 3600
BUCKET_STEP = 1.05
"""Histogram buckets (waits, tour lengths) grow by 5 %: a percentile read from them is at most
5 % low."""
ROBOT_STATES = ("touring", "errand", "charging", "idle", "faulted", "offline", "down")
"""``down``: the server was not running (from its ``server_stopped``, or after a crash from the
last event it logged, to its next ``server_started``): what the robots did is unknown."""
VISITOR_KINDS = ("tour", "go_to_poi")
"""Tasks for visitors: a robot running one is touring."""
OPEN_TASK_S = 7 * 86400.0
"""A task still open in the fold after this long is forgotten (its end was pruned or lost)."""
FINAL = ("done", "failed", "cancelled")

Positions = Mapping[str, tuple[str, float, float]]
"""Node -> (floor, x, y) in metres: the current site's, for distances."""


def hour_of(at: float) -> int:
    return int(at // HOUR) * HOUR


def bucket(value: float) -> str:
    """The histogram bucket of ``value`` (seconds): its lower bound, a power of BUCKET_STEP."""
    if value < 1.0:
        return "0"
    lower = BUCKET_STEP ** math.floor(math.log(value) / math.log(BUCKET_STEP) + 1e-9)
    return f"{lower:.4g}"


def _new_state() -> dict[str, Any]:
    return {"robots": {}, "tasks": {}, "locks": {}, "calls": {}}


class Fold:
    """Folds events into ``tally``: (metric, hour, key) -> [n, total]."""

    def __init__(self, state: dict[str, Any] | None, positions: Positions) -> None:
        self.state = state if state else _new_state()
        for part in ("robots", "tasks", "locks", "calls"):
            self.state.setdefault(part, {})
        self.positions = positions
        self.tally: dict[tuple[str, int, str], list[float]] = {}

    # --- output ----------------------------------------------------------------------------
    def count(self, metric: str, at: float, key: str = "", total: float = 0.0) -> None:
        cell = self.tally.setdefault((metric, hour_of(at), key[:160]), [0, 0.0])
        cell[0] += 1
        cell[1] += total

    def _add_time(self, robot: str, state: str, start: float, end: float) -> None:
        """Seconds from ``start`` to ``end`` in ``state``, split at the hours."""
        key = f"{robot}|{state}"
        while end > start:
            hour = hour_of(start)
            stop = min(end, hour + HOUR)
            cell = self.tally.setdefault(("robot_time", hour, key[:160]), [0, 0.0])
            cell[1] += stop - start
            start = stop

    # --- robots ----------------------------------------------------------------------------
    def _robot(self, name: str, at: float) -> dict[str, Any]:
        robot = self.state["robots"].get(name)
        if robot is None:
            robot = {"activity": "idle", "since": at, "online": False, "faults": [], "task": None}
            self.state["robots"][name] = robot
        return robot

    def _shown(self, robot: Mapping[str, Any]) -> str:
        if self.state.get("down"):
            return "down"
        if not robot["online"]:
            return "offline"
        if robot["faults"]:
            return "faulted"
        return str(robot["activity"])

    def _change(self, name: str, at: float, **changes: Any) -> None:
        """Credit the robot's time so far to what it was doing, then apply ``changes``."""
        robot = self._robot(name, at)
        if at > robot["since"]:
            self._add_time(name, self._shown(robot), robot["since"], at)
            robot["since"] = at
        robot.update(changes)

    def close(self, at: float) -> None:
        """Credit every robot's time up to ``at`` (a report's 'now'; not kept)."""
        for name in list(self.state["robots"]):
            self._change(name, at)

    # --- events ----------------------------------------------------------------------------
    def feed(self, events: Iterable[tuple[float, str, str, Any]]) -> None:
        for at, kind, source, data in events:
            self.add(at, kind, source, data if isinstance(data, dict) else {})

    def add(self, at: float, kind: str, source: str, data: dict[str, Any]) -> None:
        if kind == "server_started":  # before ``last_at`` moves: a crash ends there
            self._server_started(at, source, data)
        if at > self.state.get("last_at", 0.0):
            self.state["last_at"] = at
        if kind.startswith("task_"):
            self._task(at, kind[5:], data)
            return
        handler = _HANDLERS.get(kind)
        if handler is not None:
            handler(self, at, source, data)

    def _task(self, at: float, event: str, data: dict[str, Any]) -> None:
        task_id = data.get("task_id")
        if not isinstance(task_id, str):
            return
        tasks = self.state["tasks"]
        if event == "created":
            kind = str(data.get("kind") or "")
            tasks[task_id] = {
                "kind": kind,
                "created": at,
                "tour": data.get("tour"),
                "lang": data.get("lang") or "",
                "arrived": False,
                "explained": 0,
                "total": 0,
                "poi": None,
            }
            self.count("requested", at, kind or "unknown")
            self._forget_old(at)
            return
        task = tasks.get(task_id)
        if task is None:
            return  # created before the log's start (or pruned): not in the figures
        robot = data.get("robot")
        state = data.get("state")
        if event.startswith("point "):
            self._progress(at, task, data, event)
        elif state == "running" and isinstance(robot, str):
            task["robot"] = robot
            self._change(robot, at, activity=_activity(task["kind"]), task=task_id, online=True)
        elif state in FINAL or state == "queued":
            holder = task.get("robot")
            if isinstance(holder, str) and self._robot(holder, at)["task"] == task_id:
                self._change(holder, at, activity="idle", task=None)
            task["robot"] = None
        if state in FINAL:
            self._ended(at, task, str(state), str(data.get("reason") or ""))
            del tasks[task_id]

    def _progress(self, at: float, task: dict[str, Any], data: dict[str, Any], event: str) -> None:
        stage, index, total = data.get("stage"), data.get("index"), data.get("total")
        if stage is None:  # an older row: "point 2/5 explained" in the kind only
            words = event.split()
            if len(words) == 3 and "/" in words[1]:
                first, _, second = words[1].partition("/")
                index, total, stage = int(first), int(second), words[2]
        if not isinstance(index, int) or not isinstance(total, int):
            return
        poi = data.get("poi")
        if stage == "arrived" and not task["arrived"]:
            self._arrived(at, task)
        elif stage == "explained":
            task["explained"] = max(task["explained"], index)
            task["total"] = total
            task["poi"] = poi
            self.count("listened", at, str(poi or f"#{index}"))

    def _arrived(self, at: float, task: dict[str, Any]) -> None:
        """The robot is at the first stop, with the visitor: the wait from the request ends
        here (visitor tasks only)."""
        if task["kind"] not in VISITOR_KINDS:
            return
        task["arrived"] = True
        wait = max(0.0, at - task["created"])
        self.count("wait", at, task["kind"], wait)
        self.count("wait_hist", at, bucket(wait))

    def _ended(self, at: float, task: dict[str, Any], state: str, reason: str) -> None:
        kind = task["kind"] or "unknown"
        self.count(state, at, kind)
        if kind == "go_to_poi" and state == "done" and not task["arrived"]:
            self._arrived(at, task)  # a point visit without progress: there when done
        if state == "failed":
            self.count("failed_reason", at, reason or "no reason given")
        if kind != "tour" or state != "done":
            return
        length = max(0.0, at - task["created"])
        self.count("tour_length", at, "", length)
        self.count("tour_length_hist", at, bucket(length))
        tour, lang = str(task.get("tour") or "?"), task["lang"] or "default"
        stopped = 0 < task["explained"] < task["total"]
        for key in (f"tour:{tour}", f"lang:{lang}"):
            self.count("tours_ended", at, key)
            if stopped:
                self.count("stopped", at, key)
        if stopped:
            self.count("stopped", at, f"stop:{task['poi'] or '#' + str(task['explained'])}")

    def _forget_old(self, at: float) -> None:
        tasks = self.state["tasks"]
        if len(tasks) < 1000:
            return
        for task_id in [t for t, task in tasks.items() if at - task["created"] > OPEN_TASK_S]:
            del tasks[task_id]

    # --- other kinds -----------------------------------------------------------------------
    def _connected(self, at: float, source: str, data: dict[str, Any]) -> None:
        if isinstance(robot := data.get("robot"), str):
            self._change(robot, at, online=True)

    def _disconnected(self, at: float, source: str, data: dict[str, Any]) -> None:
        if isinstance(robot := data.get("robot"), str):
            self._change(robot, at, online=False)

    def _server_stopped(self, at: float, source: str, data: dict[str, Any]) -> None:
        """A clean stop: from here to the next start, the server is down."""
        self.close(at)
        self.state["down"] = True

    def _server_started(self, at: float, source: str, data: dict[str, Any]) -> None:
        """A new server life. Without a ``server_stopped`` before it the last one crashed: it
        was down from the last event it logged (the time since is unknown)."""
        if not self.state.get("down") and self.state.get("last_at"):
            self.close(min(at, self.state["last_at"]))
            self.state["down"] = True
        self.close(at)
        self.state["down"] = False
        for name in list(self.state["robots"]):
            self._change(name, at, online=False)  # they connect again to the new life

    def _alert(self, at: float, source: str, data: dict[str, Any], raised: bool) -> None:
        kind, subject = data.get("kind"), data.get("subject")
        if not isinstance(kind, str) or not isinstance(subject, str):
            return
        if raised and data.get("count", 1) == 1:
            self.count("alarms", at, kind)
            if kind == "building_command_failed":
                command, _, target = subject.partition(":")
                if "door" in command:
                    self.count("door_blocks", at, target)
        if kind != "robot_fault":
            return
        name = subject.partition("/")[0]
        faults = list(self._robot(name, at)["faults"])
        if raised and subject not in faults:
            faults.append(subject)
        elif not raised and subject in faults:
            faults.remove(subject)
        self._change(name, at, faults=faults)

    def _fault(self, at: float, source: str, data: dict[str, Any]) -> None:
        self.count("faults", at, f"{data.get('robot') or source}|{data.get('kind') or 'fault'}")

    def _node(self, at: float, source: str, data: dict[str, Any]) -> None:
        robot, node = data.get("robot") or source, data.get("node")
        if not isinstance(node, str) or not isinstance(robot, str):
            return
        self.count("node_visits", at, node)
        here = self.positions.get(node)
        state = self._robot(robot, at)
        before = self.positions.get(state.get("node") or "")
        state["node"] = node
        if here is not None and before is not None and here[0] == before[0]:
            self.count("distance", at, robot, math.hypot(here[1] - before[1], here[2] - before[2]))

    def _requested(self, at: float, source: str, data: dict[str, Any]) -> None:
        robot, area = data.get("robot"), data.get("area")
        if isinstance(robot, str) and isinstance(area, str):
            self.state["locks"].setdefault(f"{robot}|{area}", at)

    def _granted(self, at: float, source: str, data: dict[str, Any]) -> None:
        robot, area = data.get("robot"), data.get("area")
        if not isinstance(robot, str) or not isinstance(area, str):
            return
        self.count("area_granted", at, area)
        asked = self.state["locks"].pop(f"{robot}|{area}", None)
        if asked is not None:
            self.count("lock_wait", at, area, max(0.0, at - asked))

    def _call(self, at: float, source: str, data: dict[str, Any]) -> None:
        elevator, floor = data.get("elevator"), data.get("floor")
        if isinstance(elevator, str) and isinstance(floor, str):
            self.state["calls"].setdefault(f"{elevator}|{floor}", at)

    def _in_position(self, at: float, source: str, data: dict[str, Any]) -> None:
        elevator, floor = data.get("elevator"), data.get("floor")
        if not isinstance(elevator, str):
            return
        called = self.state["calls"].pop(f"{elevator}|{floor}", None)
        if called is not None:
            self.count("elevator_wait", at, elevator, max(0.0, at - called))

    def _door(self, at: float, source: str, data: dict[str, Any]) -> None:
        if isinstance(door := data.get("door"), str):
            self.count("door_opened", at, door)

    def _emergency(self, at: float, source: str, data: dict[str, Any]) -> None:
        self.count("alarms", at, "fire_alarm")


def _activity(kind: str) -> str:
    if kind in VISITOR_KINDS:
        return "touring"
    return "charging" if kind == "charge" else "errand"


_HANDLERS: dict[str, Any] = {
    "robot_connected": Fold._connected,
    "robot_disconnected": Fold._disconnected,
    "server_stopped": Fold._server_stopped,
    "alert_raised": lambda f, at, s, d: f._alert(at, s, d, True),
    "alert_resolved": lambda f, at, s, d: f._alert(at, s, d, False),
    "robot_fault": Fold._fault,
    "node_reached": Fold._node,
    "area_requested": Fold._requested,
    "area_granted": Fold._granted,
    "call_elevator": Fold._call,
    "elevator_in_position": Fold._in_position,
    "door_opened": Fold._door,
    "emergency_declared": Fold._emergency,
}
