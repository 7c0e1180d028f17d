"""``guidebot replay``: a past period of a server's event log written to a file that the
console's Reports view opens (docs/reports.md, "Replay"), so a venue can send it on."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import click
import orjson

from backend.db import make_engine, make_sessionmaker
from backend.reports.period import BadPeriod, parse_period
from backend.reports.replay import replay

__all__ = ["replay_command"]


async def export(db_url: str, start: str, end: str, tz: str) -> dict[str, Any]:
    """The replay of ``start``..``end`` read from the database at ``db_url``."""
    period = parse_period(start=start, end=end, tz=tz)
    engine = make_engine(db_url)
    try:
        return await replay(make_sessionmaker(engine), period)
    finally:
        await engine.dispose()


@click.command("replay")
@click.option(
    "--from", "db_url", required=True, help="The server's database URL (GUIDEBOT_DB_URL)."
)
@click.option("--start", required=True, help="ISO 8601 date and time.")
@click.option("--end", required=True, help="ISO 8601 date and time (excluded; at most 24 h on).")
@click.option("--tz", default="UTC", show_default=True, help="IANA time zone of start and end.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True)
def replay_command(db_url: str, start: str, end: str, tz: str, out: Path) -> None:
    """Write a period of the event log (at most 24 hours) to a replay file (JSON)."""
    try:
        played = asyncio.run(export(db_url, start, end, tz))
    except BadPeriod as exc:
        raise click.BadParameter(str(exc)) from None
    out.write_bytes(orjson.dumps({"guidebot_replay": 1, **played}))
    click.echo(f"{out}: {len(played['events'])} events from {played['period']['start']}", err=True)
