"""The soak's referee: reads the server while faults fly and counts what went wrong.

- Safety invariants (guidebot/invariants.py) on the event log (GET /api/events), which is in
  causal order and survives server restarts, each event at its time (a robot's ``node_reached``
  at the robot's own time: it may arrive late, after a link outage). A robot whose process was
  killed restarts at its dock: its position is unknown from the kill on (``forget``).
- Tasks: every task ever listed is remembered; one that disappears from the server, or that
  failed without a reason a person can read, is lost.
- Locks: one held by an offline robot for longer than the grace period plus a margin must be
  shown to staff (an active ``lock_holder_offline`` alert naming its area, GET /api/alerts).
- Logs: every ``Traceback`` (or unretrieved task exception) in any process's log.
- Memory: each process's RSS, sampled.
"""

from __future__ import annotations

import re
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import psutil

from bench.soak_measures import Measures
from guidebot.invariants import InvariantChecker

__all__ = ["Watch", "unhandled_errors"]

FINAL = {"done", "failed", "cancelled"}
UNHANDLED = re.compile(
    r"Traceback \(most recent call last\)|exception was never retrieved|Unhandled exception"
)


def _seen(t: dict[str, Any]) -> TaskSeen:
    return TaskSeen(
        str(t["state"]),
        str(t.get("reason") or ""),
        t["requester"],
        t.get("robot"),
        str(t.get("cancelled_by") or ""),
        str(t.get("kind") or ""),
    )


def unhandled_errors(logs: list[Path]) -> list[str]:
    """One line per unhandled error found: ``file: the line after the traceback header``."""
    found = []
    for path in logs:
        if not path.exists():
            continue
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        for i, line in enumerate(lines):
            if UNHANDLED.search(line):
                # The exception itself is the first unindented line after the stack.
                tail = next(
                    (x for x in lines[i + 1 : i + 80] if x and not x.startswith((" ", "\t"))),
                    line,
                )
                found.append(f"{path.name}:{i + 1}: {tail.strip()[:300]}")
    return found


@dataclass
class TaskSeen:
    state: str
    reason: str
    requester: str
    robot: str | None = None
    cancelled_by: str = ""
    kind: str = ""


@dataclass
class Watch:
    url: str
    token: str
    checker: InvariantChecker
    lock_grace_s: float
    after_id: int = 0
    tasks: dict[str, TaskSeen] = field(default_factory=dict)
    vanished: set[str] = field(default_factory=set)
    offline_since: dict[tuple[str, str], float] = field(default_factory=dict)
    lock_violations: list[str] = field(default_factory=list)
    rss_mb: dict[str, float] = field(default_factory=dict)
    rss_first: dict[str, float] = field(default_factory=dict)
    rss_last: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    measures: Measures = field(default_factory=Measures)
    """Tours done, handovers, skipped stops, touring time per robot (bench/soak_measures.py)."""

    def _headers(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    async def poll(self, http: httpx.AsyncClient) -> bool:
        """One round over events, tasks and locks; False when the server did not answer."""
        try:
            await self.poll_events(http)
            await self.poll_tasks(http)
            await self.poll_locks(http)
        except (httpx.HTTPError, ValueError):
            return False
        return True

    async def poll_events(self, http: httpx.AsyncClient) -> None:
        while True:
            r = await http.get(
                f"{self.url}/api/events",
                params={"after_id": self.after_id, "limit": 1000},
                headers=self._headers(),
            )
            r.raise_for_status()
            page = r.json()
            self.checker.feed_events(page["events"])
            for event in page["events"]:
                at = event.get("at")
                at = float(at) if isinstance(at, int | float) else None
                self.measures.feed_event(str(event["kind"]), event.get("data") or {}, at)
            self.after_id = page["next_after_id"]
            if len(page["events"]) < 1000:
                return

    async def listed_tasks(self, http: httpx.AsyncClient) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        offset = 0
        while True:
            r = await http.get(
                f"{self.url}/api/tasks",
                params={"limit": 1000, "offset": offset, "include_internal": "false"},
                headers=self._headers(),
            )
            r.raise_for_status()
            page = r.json()
            out.update({t["id"]: t for t in page["tasks"]})
            offset += len(page["tasks"])
            if not page["tasks"] or offset >= page["total"]:
                return out

    async def poll_tasks(self, http: httpx.AsyncClient) -> None:
        listed = await self.listed_tasks(http)
        for task_id, t in listed.items():
            self.tasks[task_id] = _seen(t)
            self.measures.feed_task(task_id, t)
        for task_id in set(self.tasks) - set(listed) - self.vanished:
            # Not in this listing (pages shift while tasks change): ask for it by id.
            r = await http.get(f"{self.url}/api/tasks/{task_id}", headers=self._headers())
            if r.status_code == 404:
                self.vanished.add(task_id)
                self.notes.append(f"task {task_id} vanished (404 after it was acknowledged)")
            elif r.status_code == 200:
                t = r.json()
                self.tasks[task_id] = _seen(t)
                self.measures.feed_task(task_id, t)
            else:
                r.raise_for_status()

    async def poll_histories(self, http: httpx.AsyncClient) -> None:
        """Each tour's history, for the stops it skipped (once, at the end)."""
        for task_id, t in self.tasks.items():
            if t.kind != "tour":
                continue
            r = await http.get(f"{self.url}/api/tasks/{task_id}/history", headers=self._headers())
            if r.status_code == 200:
                rows = r.json()
                self.measures.feed_history(task_id, rows if isinstance(rows, list) else [])

    def expect(self, task_id: str, requester: str) -> None:
        """A task the server acknowledged (201): it must never vanish."""
        self.tasks.setdefault(task_id, TaskSeen("queued", "", requester))

    async def poll_locks(self, http: httpx.AsyncClient) -> None:
        locks = await http.get(f"{self.url}/api/locks", headers=self._headers())
        alerts = await http.get(
            f"{self.url}/api/alerts", params={"include_acked": "true"}, headers=self._headers()
        )
        locks.raise_for_status()
        alerts.raise_for_status()
        shown = {
            a["subject"]
            for a in alerts.json()
            if a["kind"] == "lock_holder_offline" and a["resolved_at"] is None
        }
        now = time.monotonic()
        current = set()
        for lock in locks.json():
            if lock["state"] != "holder_offline":
                continue
            key = (str(lock["area"]), str(lock["holder"]))
            current.add(key)
            since = self.offline_since.setdefault(key, now)
            late = now - since > self.lock_grace_s + 15.0
            if late and key[0] not in shown:
                self.lock_violations.append(
                    f"area {key[0]} held by offline {key[1]} for {now - since:.0f} s, "
                    "no staff alert"
                )
                self.offline_since[key] = now  # once per grace period, not every poll
        for key in set(self.offline_since) - current:
            del self.offline_since[key]

    def sample_rss(self, pids: dict[str, int | None]) -> None:
        for name, pid in pids.items():
            if pid is None:
                continue
            try:
                mb = psutil.Process(pid).memory_info().rss / 2**20
            except psutil.Error:
                continue
            self.rss_mb[name] = round(max(self.rss_mb.get(name, 0.0), mb), 1)
            self.rss_first.setdefault(name, round(mb, 1))
            self.rss_last[name] = round(mb, 1)

    def task_counts(self) -> dict[str, int]:
        """requested/done/cancelled/failed/lost over the visitors' tasks."""
        states = [t.state for t in self.tasks.values()]
        unreadable = [
            i for i, t in self.tasks.items() if t.state == "failed" and len(t.reason.strip()) < 3
        ]
        for task_id in unreadable:
            self.notes.append(f"task {task_id} failed without a reason")
        return {
            "tasks_requested": len(self.tasks),
            "tasks_done": states.count("done"),
            "tasks_cancelled": states.count("cancelled"),
            "tasks_failed": states.count("failed"),
            "tasks_lost": len(self.vanished) + len(unreadable),
        }

    def failure_reasons(self) -> dict[str, int]:
        """Failed tasks by reason, most frequent first; numbers (robots, seconds, metres) are
        blurred to "#" so that like reasons count together."""
        kinds = Counter(
            re.sub(r"\d+(?:\.\d+)?", "#", t.reason.strip()) or "(no reason)"
            for t in self.tasks.values()
            if t.state == "failed"
        )
        return dict(kinds.most_common())

    def open_tasks(self) -> dict[str, TaskSeen]:
        return {i: t for i, t in self.tasks.items() if t.state not in FINAL}
