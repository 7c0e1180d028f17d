"""``guidebot bookings add|list|move|cancel|history``: bookings over the server's REST API
with a staff token (docs/server.md, "Bookings")."""

from __future__ import annotations

import json
import sys
from typing import Any

import click
import httpx

__all__ = ["bookings"]

DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")


class Api:
    def __init__(self, server: str, token: str) -> None:
        self.server = server.rstrip("/")
        self.token = token

    def call(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        try:
            answer = httpx.request(
                method,
                f"{self.server}{path}",
                json=body,
                headers={"Authorization": f"Bearer {self.token}"},
                timeout=10,
            )
        except httpx.HTTPError as exc:
            raise click.ClickException(f"cannot reach {self.server}: {exc}") from None
        if answer.status_code >= 400:
            try:
                detail = answer.json().get("detail", answer.text)
            except ValueError:
                detail = answer.text
            raise click.ClickException(f"{answer.status_code}: {_words(detail)}")
        return answer.json()


def _words(detail: Any) -> str:
    if isinstance(detail, list):  # pydantic's list of problems
        return "; ".join(
            f"{'.'.join(str(p) for p in d.get('loc', [])[1:])}: {d.get('msg')}" for d in detail
        )
    return str(detail)


def _line(o: dict[str, Any]) -> str:
    flag = f"  !! {o['flag']}" if o.get("flag") else ""
    every = o["recurrence"]["every"]
    return (
        f"{o.get('local', o['start'])}  {o['id']}  {o['name']} ({o['lang']}, "
        f"{o['group_size']} people) meet at {o['meeting_point_name']}"
        f"{'' if every == 'once' else f'  [{every}]'}"
        f"{'' if o['status'] == 'booked' else '  CANCELLED'}{flag}"
    )


@click.group()
@click.option(
    "--server",
    envvar="GUIDEBOT_SERVER",
    default="http://127.0.0.1:8000",
    show_default=True,
    help="the server's URL (GUIDEBOT_SERVER)",
)
@click.option(
    "--token",
    envvar="GUIDEBOT_TOKEN",
    required=True,
    help="an operator's or admin's token (GUIDEBOT_TOKEN)",
)
@click.pass_context
def bookings(ctx: click.Context, server: str, token: str) -> None:
    """Booked and recurring tours."""
    ctx.obj = Api(server, token)


@bookings.command("add")
@click.option("--tour", help="a tour's id")
@click.option("--poi", help="a single point's id (a visit)")
@click.option("--at", "start", required=True, help="local date and time: 2026-12-01T14:00")
@click.option("--lang", required=True, help="the language of the tour (en, es, de...)")
@click.option("--group", "group_size", type=int, required=True, help="how many people")
@click.option("--note", default="")
@click.option("--meet", "meeting_point", help="meeting point (a point's id; default: first stop)")
@click.option("--private", is_flag=True, help="not shown on visitor screens")
@click.option("--every", type=click.Choice(["once", "daily", "weekly"]), default="once")
@click.option("--days", default="", help="weekly: mon,tue,... (default: the first date's day)")
@click.option("--until", help="last date of a series (YYYY-MM-DD)")
@click.option("--except", "except_dates", multiple=True, help="a date to skip (repeatable)")
@click.pass_obj
def add(api: Api, /, **o: Any) -> None:
    """Book a tour or a visit."""
    days = [d for d in o["days"].split(",") if d]
    if bad := [d for d in days if d not in DAYS]:
        raise click.BadParameter(f"{bad}: days are {', '.join(DAYS)}", param_hint="--days")
    body: dict[str, Any] = {
        k: o[k]
        for k in ("tour", "poi", "start", "lang", "group_size", "note", "meeting_point")
        if o[k] is not None
    }
    body["public"] = not o["private"]
    body["recurrence"] = {
        "every": o["every"],
        "days": days,
        "until": o["until"],
        "except_dates": list(o["except_dates"]),
    }
    click.echo(_line(api.call("POST", "/api/bookings", body)))


@bookings.command("list")
@click.option("--day", help="first local date (default: today)")
@click.option("--to", "end", help="last local date (default: --day)")
@click.option("--json", "as_json", is_flag=True)
@click.pass_obj
def list_(api: Api, day: str | None, end: str | None, as_json: bool) -> None:
    """The occurrences of a day or a period."""
    query = "&".join(f"{k}={v}" for k, v in (("start", day), ("end", end)) if v)
    found = api.call("GET", f"/api/bookings{'?' + query if query else ''}")
    if as_json:
        json.dump(found, sys.stdout, indent=2)
        click.echo()
        return
    click.echo(f"{found['start']} .. {found['end']} ({found['tz']})")
    for occurrence in found["occurrences"]:
        click.echo(_line(occurrence))


@bookings.command("move")
@click.argument("booking")
@click.option("--at", "start", help="new local date and time")
@click.option("--meet", "meeting_point")
@click.option("--group", "group_size", type=int)
@click.option("--note")
@click.pass_obj
def move(api: Api, /, booking: str, **o: Any) -> None:
    """Move a booking (a series: every coming occurrence)."""
    body = {k: v for k, v in o.items() if v is not None}
    click.echo(_line(api.call("POST", f"/api/bookings/{booking}/move", body)))


@bookings.command("cancel")
@click.argument("booking")
@click.option("--date", "occurrence", help="only this date of a series")
@click.option("--reason", default="")
@click.pass_obj
def cancel(api: Api, booking: str, occurrence: str | None, reason: str) -> None:
    """Cancel a booking, or one date of a series."""
    body = {"reason": reason, **({"occurrence": occurrence} if occurrence else {})}
    click.echo(_line(api.call("POST", f"/api/bookings/{booking}/cancel", body)))


@bookings.command("history")
@click.argument("booking")
@click.pass_obj
def history(api: Api, booking: str) -> None:
    """Created, moved, cancelled (by whom), started, missed, flagged."""
    for entry in api.call("GET", f"/api/bookings/{booking}/history"):
        click.echo(f"{entry['at']:.0f}  {entry['action']:<22} {entry['by']:<16} {entry['detail']}")
