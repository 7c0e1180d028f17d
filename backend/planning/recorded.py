"""A recorded day's tour requests, read from a server's event log (its ``task_created``
events), to replay them over other fleets (docs/planning.md, "A recorded day")."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path
from typing import Any

from sqlalchemy import or_, select

from backend.db import make_engine, make_sessionmaker
from backend.db.models import EventRow
from backend.planning.profile import Pace, PlanError, Request, follow_count
from backend.planning.sim import nominal_segments
from backend.reports.period import BadPeriod, parse_period
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site

__all__ = ["Recording", "learn_pace", "read_day", "read_replay", "requests_of"]


def learn_pace(rows: list[tuple[float, str, dict[str, Any]]], site: Site) -> Pace:
    """Real over nominal seconds of the legs between points (explained i-1 to arrived i) and of
    the explanations (arrived i to explained i) the recording's tours took, as the ETA model
    learns them (nominal where the recording has none)."""
    graph = SiteGraph(site)
    tour_of: dict[str, str] = {}
    marks: dict[str, dict[tuple[int, str], float]] = {}
    for at, kind, d in rows:
        task = str(d.get("task_id"))
        if kind == "task_created" and d.get("kind") == "tour" and site.tour(str(d.get("tour"))):
            tour_of[task] = str(d.get("tour"))
        elif kind.startswith("task_point") and task in tour_of:
            index, stage = d.get("index"), d.get("stage")
            if isinstance(index, int) and stage in ("arrived", "explained"):
                marks.setdefault(task, {}).setdefault((index, str(stage)), at)
    sums = {"move": [0.0, 0.0], "talk": [0.0, 0.0]}
    nominal: dict[str, dict[tuple[int, str], float]] = {}
    for task, seen in marks.items():
        tour = tour_of[task]
        if tour not in nominal:
            nominal[tour] = {
                (s.index, s.kind): s.nominal_s for s in nominal_segments(site, graph, tour, None)
            }
        for (index, stage), at in seen.items():
            if stage == "explained" and (index, "arrived") in seen:
                kind, began = "talk", seen[(index, "arrived")]
            elif stage == "arrived" and (index - 1, "explained") in seen:
                kind, began = "move", seen[(index - 1, "explained")]
            else:
                continue
            predicted = nominal[tour].get((index, kind))
            if predicted and at > began:
                sums[kind][0] += at - began
                sums[kind][1] += predicted
    move, talk = (sums[k][0] / sums[k][1] if sums[k][1] else 1.0 for k in ("move", "talk"))
    return Pace(move=round(move, 3), talk=round(talk, 3))


class Recording:
    """The requests of a recorded day, shifted so the first hour with one is hour 0."""

    def __init__(
        self, requests: list[Request], day_s: float, skipped: int, start: float, pace: Pace
    ) -> None:
        self.requests = requests
        self.pace = pace
        """How much slower than nominal the recorded tours went (``learn_pace``)."""
        self.day_s = day_s
        self.skipped = skipped
        """Tour requests for tours the site no longer has (left out)."""
        self.start = start
        """Epoch seconds of the hour the day's requests start from."""


def requests_of(
    rows: list[tuple[float, str, dict[str, Any]]], site: Site, stop_following: float, seed: int
) -> Recording:
    """The tour requests among ``(at, kind, data)`` of task events, in time order. How many
    points a group followed is the recording's (its last ``explained`` point) where it says;
    else drawn with ``stop_following``."""
    rng = random.Random(seed)
    followed: dict[str, int] = {}
    for _, kind, d in rows:
        if kind.startswith("task_point") and d.get("stage") == "explained":
            index, task = d.get("index"), str(d.get("task_id"))
            if isinstance(index, int) and index > followed.get(task, 0):
                followed[task] = index
    tours = [
        (at, str(d.get("tour")), str(d.get("task_id")))
        for at, kind, d in rows
        if kind == "task_created" and d.get("kind") == "tour"
    ]
    kept = sorted(t for t in tours if site.tour(t[1]) is not None)
    if not kept:
        raise PlanError("the recording holds no tour request for a tour of this site")
    start = kept[0][0] // 3600 * 3600
    day_s = max(3600.0, math.ceil((kept[-1][0] - start + 1) / 3600) * 3600)
    requests = [
        Request(
            at - start,
            tour,
            followed.get(task) or follow_count(rng, site, tour, stop_following),
            task,
        )
        for at, tour, task in kept
    ]
    return Recording(requests, day_s, len(tours) - len(kept), start, learn_pace(rows, site))


async def read_day(
    db_url: str, date: str, tz: str, site: Site, *, stop_following: float, seed: int
) -> Recording:
    """The tour requests of day ``date`` (in ``tz``) from the event log at ``db_url``."""
    try:
        period = parse_period(day=date, tz=tz)
    except BadPeriod as exc:
        raise PlanError(str(exc)) from None
    engine = make_engine(db_url)
    try:
        query = (
            select(EventRow.at, EventRow.kind, EventRow.data)
            .where(
                EventRow.at >= period.start,
                EventRow.at < period.end,
                or_(EventRow.kind == "task_created", EventRow.kind.like("task_point %")),
            )
            .order_by(EventRow.at, EventRow.id)
        )
        async with make_sessionmaker(engine)() as session:
            rows = (await session.execute(query)).all()
    finally:
        await engine.dispose()
    found = [(at, kind, data if isinstance(data, dict) else {}) for at, kind, data in rows]
    return requests_of(found, site, stop_following, seed)


def read_replay(path: Path, site: Site, *, stop_following: float, seed: int) -> Recording:
    """The tour requests of a replay file (``guidebot replay --out``, docs/reports.md): its
    ``task_created`` and ``task_point`` events; PlanError saying why a file is not one."""
    try:
        loaded = json.loads(path.read_bytes())
    except OSError as exc:
        raise PlanError(f"--replay {path}: {exc.strerror or exc}") from None
    except ValueError:
        raise PlanError(f"--replay {path}: not a replay file (not JSON)") from None
    if not isinstance(loaded, dict) or loaded.get("guidebot_replay") != 1:
        raise PlanError(f'--replay {path}: not a replay file (no "guidebot_replay": 1)')
    events = loaded.get("events")
    if not isinstance(events, list):
        raise PlanError(f"--replay {path}: not a replay file (no events)")
    found: list[tuple[float, str, dict[str, Any]]] = []
    for e in events:
        if not isinstance(e, dict) or not isinstance(e.get("kind"), str):
            continue
        kind, at, data = e["kind"], e.get("at"), e.get("data")
        if isinstance(at, int | float) and (
            kind == "task_created" or kind.startswith("task_point")
        ):
            found.append((float(at), kind, data if isinstance(data, dict) else {}))
    if not any(kind == "task_created" for _, kind, _ in found):
        raise PlanError(
            f"--replay {path}: it holds no tour request (a file written before replays "
            "carried task_created: export it again)"
        )
    return requests_of(found, site, stop_following, seed)
