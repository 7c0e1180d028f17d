"""The soak's bookings (``guidebot bench soak --bookings N``): N one-off booked tours spread over
the run, booked through ``POST /api/bookings`` before the load starts, measured after the drain
(docs/robot.md, "Soak benchmark"; docs/server.md, "Bookings").

On time: the robot started the booked task (its ``started_at``) within ``ON_TIME_S`` of the
booked time. Missed: anything else, with its reason (the scheduler's, the task's failure, or
how late it started); ``told_ahead`` counts the misses staff were told of before their time
(a ``booking_at_risk`` alert raised before it, or a ``booking_missed`` alert)."""

from __future__ import annotations

import datetime as dt
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import httpx

__all__ = ["ON_TIME_S", "SoakBookings", "walk_ups"]

ON_TIME_S = 60.0
"""A booked tour started this long after its time at most is on time."""
FIRST_AFTER_S = 45.0
"""The first booking is this long after the load starts (the schedule needs a few ticks)."""


def walk_ups(tasks: Mapping[str, Any]) -> dict[str, int]:
    """The visitors' own requests (a panel's, not a booking's tour or its way to the meeting
    point, whose requesters start ``booking:``): requested and done."""
    mine = [t for t in tasks.values() if not str(t.requester).startswith("booking:")]
    return {
        "walk_ups_requested": len(mine),
        "walk_ups_done": sum(1 for t in mine if t.state == "done"),
    }


@dataclass
class Booked:
    id: str
    at: float
    tour: str


@dataclass
class SoakBookings:
    url: str
    token: str
    count: int
    site: dict[str, Any]
    booked: list[Booked] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)

    def _headers(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    async def book(self, run_s: float) -> None:
        """``count`` tours between ``FIRST_AFTER_S`` and the end of the run (the server's time
        zone is UTC: the soak sets none), in turn over the site's tours and languages."""
        tours = [t["id"] for t in self.site["tours"]]
        langs = [self.site.get("default_language", "en"), *self.site.get("languages", [])]
        now = dt.datetime.now(dt.UTC)
        span = max(0.0, run_s - FIRST_AFTER_S)
        async with httpx.AsyncClient(timeout=15.0, headers=self._headers()) as http:
            for i in range(self.count):
                at = now + dt.timedelta(seconds=FIRST_AFTER_S + span * i / max(1, self.count))
                body = {
                    "tour": tours[i % len(tours)],
                    "start": at.strftime("%Y-%m-%dT%H:%M:%S"),
                    "lang": langs[i % len(langs)],
                    "group_size": 10,
                    "note": f"soak {i + 1}",
                }
                r = await http.post(f"{self.url}/api/bookings", json=body)
                if r.status_code == 201:
                    data = r.json()
                    self.booked.append(Booked(data["id"], at.timestamp(), body["tour"]))
                else:
                    self.refused.append(f"{r.status_code}: {r.text[:200]}")

    async def measure(self) -> dict[str, Any]:
        """``bookings_on_time_share``, ``bookings_missed`` {reason: count} and the rest."""
        if not self.booked:
            return {"bookings": 0, "bookings_refused": len(self.refused)}
        days = sorted(
            {dt.datetime.fromtimestamp(b.at, dt.UTC).date().isoformat() for b in self.booked}
        )
        async with httpx.AsyncClient(timeout=15.0, headers=self._headers()) as http:
            listed = await http.get(f"{self.url}/api/bookings?start={days[0]}&end={days[-1]}")
            listed.raise_for_status()
            seen = {o["id"]: o for o in listed.json()["occurrences"]}
            alerts = (await http.get(f"{self.url}/api/alerts?include_acked=true")).json()
            missed: Counter[str] = Counter()
            late_s: list[float] = []
            on_time = told = 0
            for booking in self.booked:
                o = seen.get(booking.id)
                why = await self._why(http, o, booking, late_s)
                if why is None:
                    on_time += 1
                    continue
                missed[why] += 1
                if self._told(alerts, booking):
                    told += 1
        return {
            "bookings": len(self.booked),
            "bookings_refused": len(self.refused),
            "bookings_on_time_share": round(on_time / len(self.booked), 3),
            "bookings_missed": dict(missed),
            "bookings_missed_told_ahead": told,
            "bookings_start_late_s_max": round(max(late_s), 1) if late_s else None,
        }

    async def _why(
        self, http: httpx.AsyncClient, o: dict[str, Any] | None, b: Booked, late_s: list[float]
    ) -> str | None:
        """Why the booking was not on time (None: it was)."""
        if o is None:
            return "not listed by the server"
        if o["outcome"] == "missed":
            return f"missed: {o['missed_reason']}"
        if o["outcome"] != "started" or not o["task_id"]:
            return "never started by the scheduler"
        task = (await http.get(f"{self.url}/api/tasks/{o['task_id']}")).json()
        started = task.get("started_at")
        if started is None:
            return f"task {task.get('state')}: {task.get('reason') or 'never started'}"
        late = started - b.at
        late_s.append(late)
        return None if late <= ON_TIME_S else "started more than 60 s late"

    @staticmethod
    def _told(alerts: list[dict[str, Any]], b: Booked) -> bool:
        for alert in alerts:
            if not str(alert.get("subject", "")).startswith(f"{b.id}@"):
                continue
            if alert["kind"] == "booking_missed" or alert["raised_at"] < b.at:
                return True
        return False
