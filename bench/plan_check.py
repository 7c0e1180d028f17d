"""Is the planner trustworthy? A recorded period of a live fleet (a ``guidebot demo --scenario
busy`` run, say) against the plan of the same requests at the same fleet size.

    guidebot bench plan-check --site sites/demo_museum.yaml --db DB_URL --date D --json

Measured: each tour's wait from ``task_created`` to its first ``task_point 1/n arrived``. Planned:
``guidebot plan --day`` over the same requests (how far each group followed: the log's) with as
many robots as connected in the log. Both over the requests the live fleet served, nearest-rank
p50 and p95. Last line: {"requests", "compared", "robots", "measured": {p50_s, p95_s},
"planned": {p50_s, p95_s}, "error": {p50, p95}} (relative: planned / measured - 1).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import click
from sqlalchemy import or_, select

from backend.db import make_engine, make_sessionmaker
from backend.db.models import EventRow
from backend.planning.recorded import read_day
from backend.planning.sim import quantile, simulate
from backend.reports.period import parse_period
from guidebot.benchutil import print_result
from guidebot.site.graph import SiteGraph
from guidebot.site.yamlio import load_site_file

__all__ = ["main"]


async def measured(db_url: str, date: str, tz: str) -> tuple[dict[str, float], set[str]]:
    """Each tour's measured wait (task id -> seconds) and the robots that connected."""
    period = parse_period(day=date, tz=tz)
    engine = make_engine(db_url)
    try:
        query = (
            select(EventRow.at, EventRow.kind, EventRow.data)
            .where(
                EventRow.at >= period.start,
                EventRow.at < period.end,
                or_(
                    EventRow.kind.in_(("task_created", "robot_connected")),
                    EventRow.kind.like("task_point 1/% arrived"),
                ),
            )
            .order_by(EventRow.at, EventRow.id)
        )
        async with make_sessionmaker(engine)() as session:
            rows = (await session.execute(query)).all()
    finally:
        await engine.dispose()
    created: dict[str, float] = {}
    waits: dict[str, float] = {}
    robots: set[str] = set()
    for at, kind, data in rows:
        d: dict[str, Any] = data if isinstance(data, dict) else {}
        task = str(d.get("task_id"))
        if kind == "robot_connected" and isinstance(d.get("robot"), str):
            robots.add(d["robot"])
        elif kind == "task_created" and d.get("kind") == "tour":
            created[task] = at
        elif task in created and task not in waits:
            waits[task] = at - created[task]
    return waits, robots


def _stats(values: list[float]) -> dict[str, float | None]:
    ordered = sorted(values)
    p50, p95 = quantile(ordered, 0.5), quantile(ordered, 0.95)
    return {
        "p50_s": None if p50 is None else round(p50, 1),
        "p95_s": None if p95 is None else round(p95, 1),
    }


@click.command("plan-check")
@click.option("--site", "site_path", required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--db", "db_url", required=True, help="The live run's database URL.")
@click.option("--date", required=True, help="The recorded day (YYYY-MM-DD).")
@click.option("--tz", default="UTC", show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Last line: one JSON object.")
def main(site_path: Path, db_url: str, date: str, tz: str, as_json: bool) -> None:
    """Compare a recorded period's waits with the plan of the same requests."""
    site = load_site_file(site_path)
    waits, robots = asyncio.run(measured(db_url, date, tz))
    day = asyncio.run(read_day(db_url, date, tz, site, stop_following=0.0, seed=1))
    size = max(1, len(robots))
    outcome = simulate(
        site, SiteGraph(site), day.requests, robots=size, day_s=day.day_s, pace=day.pace
    )
    pairs = [
        (waits[req.ref], outcome.wait_of[i])
        for i, req in enumerate(day.requests)
        if req.ref in waits and i in outcome.wait_of
    ]
    live, plan = _stats([m for m, _ in pairs]), _stats([p for _, p in pairs])
    error = {
        key: None
        if live[f"{key}_s"] in (None, 0) or plan[f"{key}_s"] is None
        else round(plan[f"{key}_s"] / live[f"{key}_s"] - 1, 3)  # type: ignore[operator]
        for key in ("p50", "p95")
    }
    result = {
        "requests": len(day.requests),
        "compared": len(pairs),
        "robots": size,
        "measured": live,
        "planned": plan,
        "error": error,
        "pace": {"move": day.pace.move, "talk": day.pace.talk},
    }
    if not as_json:
        click.echo(f"measured {live}, planned {plan}, error {error}")
    print_result(result)
