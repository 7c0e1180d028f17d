"""What-if planner benchmark: the wall time of a whole day of visitors at one fleet size.

    guidebot bench plan --hours 10 --per-hour 60 --robots 4 --json

Loads the site (the demo museum by default), builds its graph, draws ``--per-hour`` tour
requests for each of ``--hours`` hours (the site's tours in equal shares, a tenth of the
visitors stopping at each "continue?") and simulates the day at ``--robots`` robots with the
Task Manager's own robot choice. Goal (issue 38): a 10-hour day under 3 minutes.

Last line: {"site", "hours", "requests", "robots", "load_s", "sim_s", "wall_s", "goal_s",
"wait_p50_s", "wait_p95_s", "utilisation"}.
"""

from __future__ import annotations

import time
from pathlib import Path

import click

from backend.planning.profile import draw, parse_profile
from backend.planning.sim import simulate
from guidebot.benchutil import print_result
from guidebot.site.graph import SiteGraph
from guidebot.site.yamlio import load_site_file

__all__ = ["main"]

DEMO = Path(__file__).resolve().parents[1] / "sites" / "demo_museum.yaml"
GOAL_S = 180.0


@click.command("plan")
@click.option("--site", "site_path", type=click.Path(dir_okay=False, path_type=Path), default=DEMO)
@click.option("--hours", default=10, show_default=True, type=click.IntRange(1, 24))
@click.option("--per-hour", default=60, show_default=True, type=click.IntRange(1, 100_000))
@click.option("--robots", default=4, show_default=True, type=click.IntRange(1, 200))
@click.option("--json", "as_json", is_flag=True, help="Last line: one JSON object.")
def main(site_path: Path, hours: int, per_hour: int, robots: int, as_json: bool) -> None:
    """Time one simulated day at one fleet size."""
    started = time.perf_counter()
    site = load_site_file(site_path)
    graph = SiteGraph(site)
    profile = parse_profile(
        {
            "hours": [per_hour] * hours,
            "tours": {t.id: 1 for t in site.tours},
            "stop_following": 0.1,
        },
        site,
    )
    requests = draw(profile, site)
    loaded = time.perf_counter()
    outcome = simulate(site, graph, requests, robots=robots, day_s=hours * 3600.0)
    done = time.perf_counter()
    summary = outcome.summary(10)
    result = {
        "site": site.name,
        "hours": hours,
        "requests": len(requests),
        "robots": robots,
        "load_s": round(loaded - started, 3),
        "sim_s": round(done - loaded, 3),
        "wall_s": round(done - started, 3),
        "goal_s": GOAL_S,
        "wait_p50_s": summary["wait_p50_s"],
        "wait_p95_s": summary["wait_p95_s"],
        "utilisation": summary["utilisation"],
    }
    if not as_json:
        click.echo(
            f"{len(requests)} requests over {hours} h at {robots} robots: {result['wall_s']} s"
        )
    print_result(result)
