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

import click

from backend.planning.live import LiveOptions, run_live
from backend.planning.measure import read_events, tour_waits
from backend.planning.recorded import read_day
from backend.planning.sim import quantile, simulate
from backend.planning.virtual import run_virtual
from backend.reports.period import parse_period
from guidebot.benchutil import print_result
from guidebot.site.graph import SiteGraph
from guidebot.site.yamlio import load_site_file

__all__ = ["main"]


async def measured(db_url: str, date: str, tz: str) -> tuple[dict[str, float], set[str]]:
    """Each tour's measured wait (task id -> seconds) and the robots that connected."""
    period = parse_period(day=date, tz=tz)
    waits, _, robots = tour_waits(await read_events(db_url, period.start, period.end))
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
@click.option(
    "--live",
    is_flag=True,
    help="Plan on the real server with simulated robots (guidebot plan --live), not the model.",
)
@click.option(
    "--virtual",
    is_flag=True,
    help="--live in one process on virtual time (guidebot plan --live --virtual).",
)
@click.option("--time-scale", default=5.0, show_default=True, type=click.FloatRange(min=0.1))
@click.option("--no-can", is_flag=True, help="--live: bare simulated robots (as demo --no-can).")
@click.option("--workdir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Last line: one JSON object.")
def main(
    site_path: Path,
    db_url: str,
    date: str,
    tz: str,
    live: bool,
    virtual: bool,
    time_scale: float,
    no_can: bool,
    workdir: Path | None,
    as_json: bool,
) -> None:
    """Compare a recorded period's waits with the plan of the same requests."""
    site = load_site_file(site_path)
    waits, robots = asyncio.run(measured(db_url, date, tz))
    day = asyncio.run(read_day(db_url, date, tz, site, stop_following=0.0, seed=1))
    size = max(1, len(robots))
    if virtual:
        options = LiveOptions(
            virtual=True,
            can=False,
            workdir=workdir,
            log=lambda line: click.echo(f"plan-check: {line}", err=True),
        )
        outcome = run_virtual(
            site_path, site, day.requests, robots=size, day_s=day.day_s, options=options
        )
    elif live:
        options = LiveOptions(
            scale=time_scale,
            can=not no_can,
            workdir=workdir,
            log=lambda line: click.echo(f"plan-check: {line}", err=True),
        )
        outcome = asyncio.run(
            run_live(site_path, site, day.requests, robots=size, day_s=day.day_s, options=options)
        )
    else:
        outcome = simulate(
            site, SiteGraph(site), day.requests, robots=size, day_s=day.day_s, pace=day.pace
        )
    pairs = [
        (waits[req.ref], outcome.wait_of[i])
        for i, req in enumerate(day.requests)
        if req.ref in waits and i in outcome.wait_of
    ]
    seen, plan = _stats([m for m, _ in pairs]), _stats([p for _, p in pairs])
    error = {
        key: None
        if seen[f"{key}_s"] in (None, 0) or plan[f"{key}_s"] is None
        else round(plan[f"{key}_s"] / seen[f"{key}_s"] - 1, 3)  # type: ignore[operator]
        for key in ("p50", "p95")
    }
    result = {
        "requests": len(day.requests),
        "compared": len(pairs),
        "robots": size,
        "measured": seen,
        "planned": plan,
        "error": error,
        "pace": {"move": day.pace.move, "talk": day.pace.talk},
        "mode": "virtual" if virtual else "live" if live else "model",
        **({"time_scale": time_scale} if live and not virtual else {}),
        **({"wall_s": round(outcome.wall_s, 1)} if live or virtual else {}),
        **({"cpu_s": outcome.extra.get("cpu_s")} if virtual else {}),
    }
    if not as_json:
        click.echo(f"measured {seen}, planned {plan}, error {error}")
    print_result(result)
