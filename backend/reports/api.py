"""REST routes of the reports: one per figure, JSON or CSV (docs/reports.md, docs/server.md)."""

from __future__ import annotations

import csv
import io
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response

from backend.actions import require_action
from backend.auth import Principal
from backend.reports.figures import FIGURES, Reports
from backend.reports.period import BadPeriod, Period, parse_period
from backend.reports.replay import replay
from backend.rest.deps import app_service

__all__ = ["router"]

router = APIRouter(prefix="/api/reports", tags=["reports"])

Reader = Annotated[Principal, Depends(require_action("read_reports"))]
Figure = Literal["tasks", "waits", "following", "stops", "robots", "incidents", "heat"]


def reports(request: Request) -> Reports:
    return app_service(request, "reports", Reports)


async def period(
    day: Annotated[str | None, Query(max_length=10, description="YYYY-MM-DD")] = None,
    week: Annotated[str | None, Query(max_length=10, description="its first day")] = None,
    start: Annotated[str | None, Query(max_length=40, description="ISO 8601")] = None,
    end: Annotated[str | None, Query(max_length=40, description="ISO 8601, excluded")] = None,
    tz: Annotated[str, Query(max_length=64, description="IANA time zone")] = "UTC",
    bin: Annotated[Literal["hour", "day"] | None, Query()] = None,
) -> Period:
    try:
        return parse_period(day=day, week=week, start=start, end=end, tz=tz, bin=bin)
    except BadPeriod as exc:
        raise HTTPException(422, str(exc)) from None


Service = Annotated[Reports, Depends(reports)]
Asked = Annotated[Period, Depends(period)]


@router.get("")
async def summary(_: Reader, service: Service, asked: Asked) -> dict[str, Any]:
    """Every figure of the period in one answer (the console's view and daily summary)."""
    figures = {name: await method(service, asked) for name, method in FIGURES.items()}
    return {"period": asked.as_dict(), **figures}


@router.get("/replay")
async def replay_period(_: Reader, service: Service, asked: Asked) -> dict[str, Any]:
    """What robots, doors, locks and elevators did in the period (at most 24 hours), and where
    they were when it started: the console plays it back."""
    if service.flush is not None:
        await service.flush()
    try:
        return await replay(service.rollups.sessionmaker, asked)
    except BadPeriod as exc:
        raise HTTPException(422, str(exc)) from None


@router.get("/{figure}", response_model=None)
async def figure(
    _: Reader,
    service: Service,
    asked: Asked,
    figure: Figure,
    format: Annotated[Literal["json", "csv"], Query()] = "json",
) -> dict[str, Any] | Response:
    """One figure of the period; ``format=csv``: its rows as a CSV file."""
    answer = await FIGURES[figure](service, asked)
    if format == "json":
        return answer
    name = f"guidebot-{figure}-{answer['period']['start'][:10]}.csv"
    return Response(
        to_csv(answer["rows"]),
        media_type="text/csv; charset=utf-8",
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )


def to_csv(rows: list[dict[str, Any]]) -> str:
    """Rows (dicts with the same keys) as CSV with a header; empty values for None."""
    out = io.StringIO()
    if rows:
        writer = csv.DictWriter(out, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return out.getvalue()
