"""``guidebot plan``: how many robots, and which policy, for a day of visitors
(docs/planning.md). Prints a table per fleet size and policy; with ``--json`` stdout is one
JSON object on one line (the table goes to stderr)."""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from backend.planning.live import LiveOptions, run_live
from backend.planning.profile import Pace, PlanError, draw, load_profile
from backend.planning.sim import POLICIES, simulate
from backend.planning.virtual import run_virtual
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file

__all__ = ["parse_robots", "plan", "plan_command"]

MAX_ROBOTS = 200


def parse_robots(text: str) -> list[int]:
    """``3``, ``2..8`` or ``2,4,6``: the fleet sizes to try (PlanError if not)."""
    try:
        if ".." in text:
            low_text, _, high_text = text.partition("..")
            low, high = int(low_text), int(high_text)
            sizes = list(range(low, high + 1))
        else:
            low = high = 0
            sizes = sorted({int(part) for part in text.split(",")})
    except ValueError:
        raise PlanError(
            f"--robots {text!r}: give a number, a range like 2..8, or a list like 2,4,6"
        ) from None
    if high < low:
        raise PlanError(f"--robots {text}: the range ends below its start (try {high}..{low})")
    if not sizes or sizes[0] < 1 or sizes[-1] > MAX_ROBOTS:
        raise PlanError(f"--robots {text}: fleet sizes must be from 1 to {MAX_ROBOTS}")
    return sizes


def plan(
    site: Site,
    requests: list[Any],
    *,
    day_s: float,
    sizes: list[int],
    policies: list[str],
    within_min: float,
    patience_s: float | None = None,
    queue_limit: int | None = None,
    pace: Pace = Pace(),
    live: LiveOptions | None = None,
    site_path: Path | None = None,
) -> list[dict[str, Any]]:
    """One summary per fleet size and policy (the same requests for each), from the model;
    with ``live``, then one per fleet size from the real fleet (``backend.planning.live``)."""
    graph = SiteGraph(site)
    rows = []
    for policy in policies:
        for size in sizes:
            outcome = simulate(
                site,
                graph,
                requests,
                robots=size,
                policy=policy,
                day_s=day_s,
                patience_s=patience_s,
                queue_limit=queue_limit,
                pace=pace,
            )
            rows.append({"mode": "model", **outcome.summary(within_min)})
    if live is None:
        return rows
    assert site_path is not None
    for size in sizes:
        if live.virtual:
            outcome = run_virtual(
                site_path,
                site,
                requests,
                robots=size,
                day_s=day_s,
                patience_s=patience_s,
                queue_limit=queue_limit,
                options=live,
            )
        else:
            outcome = asyncio.run(
                run_live(
                    site_path,
                    site,
                    requests,
                    robots=size,
                    day_s=day_s,
                    patience_s=patience_s,
                    queue_limit=queue_limit,
                    options=live,
                )
            )
        rows.append({"mode": "live", **outcome.summary(within_min)})
    return rows


def _table(rows: list[dict[str, Any]]) -> str:
    head = (
        f"{'run':<8}{'policy':<13}{'robots':>6}{'served':>8}{'refused':>8}{'left':>6}{'lost':>6}"
        f"{'wait p50':>10}{'wait p95':>10}{'within':>8}{'busy':>7}"
    )
    lines = [head]
    for r in rows:

        def minutes(v: float | None) -> str:
            return "-" if v is None else f"{v / 60:.1f} min"

        share = r["served_within_share"]
        # Failed, skipped and unfinished tours (a live or virtual run's): the row adds up.
        lost = r["requests"] - r["served"] - r["refused"] - r["abandoned"]
        lines.append(
            f"{r['mode']:<8}{r['policy']:<13}{r['robots']:>6}{r['served']:>8}{r['refused']:>8}"
            f"{r['abandoned']:>6}{lost:>6}{minutes(r['wait_p50_s']):>10}{minutes(r['wait_p95_s']):>10}"
            f"{'-' if share is None else f'{share:.0%}':>8}{r['utilisation']:>7.0%}"
        )
    return "\n".join(lines)


@click.command("plan")
@click.option("--site", "site_path", required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--visitors",
    "profile_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="A visitor profile (YAML: tour requests per hour).",
)
@click.option("--day", "db_url", help="A server's database URL: replay a recorded day's requests.")
@click.option("--date", help="With --day: the day (YYYY-MM-DD).")
@click.option("--tz", default="UTC", show_default=True, help="With --day: the date's time zone.")
@click.option(
    "--replay",
    "replay_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="A replay file (guidebot replay --out): its tour requests.",
)
@click.option(
    "--robots",
    "robots_text",
    default="1..6",
    show_default=True,
    help="Fleet sizes: 3, 2..8 or 2,4,6.",
)
@click.option(
    "--policy",
    "policy_name",
    default="nearest",
    show_default=True,
    type=click.Choice([*POLICIES, "all"]),
    help="Robot choice; all: each in turn.",
)
@click.option(
    "--within",
    "within_min",
    default=10.0,
    show_default=True,
    type=click.FloatRange(0),
    help="Report the share of requests served within this many minutes.",
)
@click.option(
    "--stop-following",
    default=None,
    type=click.FloatRange(0, 1),
    help="Share answering no at each 'continue?' (default: the profile's, or 0).",
)
@click.option("--seed", default=None, type=int, help="Override the profile's seed.")
@click.option(
    "--live",
    is_flag=True,
    help="Also play the day on the real server, Task Manager and Traffic Manager with "
    "simulated robots and building, per fleet size.",
)
@click.option(
    "--time-scale",
    default=10.0,
    show_default=True,
    type=click.FloatRange(min=0.1),
    help="--live: robots and building run this many times faster than the wall clock.",
)
@click.option(
    "--virtual",
    is_flag=True,
    help="--live in one process on virtual time: exact simulated seconds, as fast as the CPU "
    "allows; bare simulated robots (no battery).",
)
@click.option(
    "--no-can",
    is_flag=True,
    help="--live: bare simulated robots (lighter; no battery, so no charging).",
)
@click.option(
    "--workdir",
    type=click.Path(file_okay=False, path_type=Path),
    help="--live: keep each run's logs, site and database here.",
)
@click.option(
    "--html",
    "html_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write a report page with plots here.",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object on stdout (the table on stderr).",
)
def plan_command(
    site_path: Path,
    profile_path: Path | None,
    db_url: str | None,
    date: str | None,
    tz: str,
    replay_path: Path | None,
    robots_text: str,
    policy_name: str,
    within_min: float,
    stop_following: float | None,
    seed: int | None,
    live: bool,
    time_scale: float,
    virtual: bool,
    no_can: bool,
    workdir: Path | None,
    html_path: Path | None,
    as_json: bool,
) -> None:
    """Simulate a day of visitors over fleets of several sizes: waits, refusals, utilisation."""
    started = time.perf_counter()
    options = None
    if live or virtual:
        options = LiveOptions(
            scale=time_scale,
            can=not no_can and not virtual,
            virtual=virtual,
            workdir=workdir,
            log=lambda line: click.echo(f"plan: {line}", err=True),
        )
    try:
        result = _run(
            site_path,
            _Source(profile_path, db_url, date, tz, replay_path),
            robots_text,
            policy_name,
            within_min,
            stop_following,
            seed,
            options,
        )
    except PlanError as exc:
        raise click.UsageError(str(exc)) from None
    result["wall_s"] = round(time.perf_counter() - started, 3)
    click.echo(_table(result["fleets"]), err=as_json)  # with --json, stdout is the JSON alone
    if html_path is not None:
        from backend.planning.html import write_report

        write_report(result, html_path)
        click.echo(f"plan: report written to {html_path}", err=True)
    if as_json:
        click.echo(json.dumps(result))


@dataclass(frozen=True)
class _Source:
    """Where the visitors come from: a profile, a recorded day, or a replay file."""

    profile: Path | None
    db_url: str | None
    date: str | None
    tz: str
    replay: Path | None


def _run(
    site_path: Path,
    src: _Source,
    robots_text: str,
    policy_name: str,
    within_min: float,
    stop_following: float | None,
    seed: int | None,
    live: LiveOptions | None = None,
) -> dict[str, Any]:
    if sum(x is not None for x in (src.profile, src.db_url, src.replay)) != 1:
        raise PlanError(
            "give one source of visitors: --visitors PROFILE, --day DB_URL --date D "
            "or --replay FILE"
        )
    if src.db_url is not None and not src.date:
        raise PlanError("--day needs --date YYYY-MM-DD")
    sizes = parse_robots(robots_text)
    try:
        site = load_site_file(site_path)
    except OSError as exc:
        raise PlanError(f"--site {site_path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise PlanError(f"--site {site_path}: {exc}") from None
    policies = list(POLICIES) if policy_name == "all" else [policy_name]
    source: dict[str, Any]
    patience_s: float | None = None
    queue_limit: int | None = None
    if src.profile is not None:
        profile = load_profile(src.profile, site)
        if stop_following is not None or seed is not None:
            profile = _with(profile, stop_following, seed)
        requests = draw(profile, site)
        day_s = len(profile.hours) * 3600.0
        patience_s = None if profile.patience_min is None else profile.patience_min * 60
        queue_limit = profile.queue_limit
        pace = profile.pace
        source = {"profile": profile.name, "hours": len(profile.hours), "seed": profile.seed}
    else:
        from backend.planning.recorded import read_day, read_replay

        if src.replay is not None:
            recording = read_replay(
                src.replay, site, stop_following=stop_following or 0.0, seed=seed or 1
            )
            source = {"replay": str(src.replay)}
        else:
            assert src.db_url is not None and src.date is not None
            recording = asyncio.run(
                read_day(
                    src.db_url,
                    src.date,
                    src.tz,
                    site,
                    stop_following=stop_following or 0.0,
                    seed=seed or 1,
                )
            )
            source = {"date": src.date, "tz": src.tz}
        requests, day_s, pace = recording.requests, recording.day_s, recording.pace
        source.update({"skipped": recording.skipped, "from": recording.start})
    rows = plan(
        site,
        requests,
        day_s=day_s,
        sizes=sizes,
        policies=policies,
        within_min=within_min,
        patience_s=patience_s,
        queue_limit=queue_limit,
        pace=pace,
        live=live,
        site_path=site_path,
    )
    source["pace"] = {"move": pace.move, "talk": pace.talk}
    return {
        "site": site.name,
        "source": source,
        "requests": len(requests),
        "day_h": day_s / 3600,
        "fleets": rows,
    }


def _with(profile: Any, stop_following: float | None, seed: int | None) -> Any:
    from dataclasses import replace

    changes: dict[str, Any] = {}
    if stop_following is not None:
        changes["stop_following"] = stop_following
    if seed is not None:
        changes["seed"] = seed
    return replace(profile, **changes)
