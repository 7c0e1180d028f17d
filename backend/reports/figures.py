"""The report figures of a period, read from the hourly rollups with SQL sums (one GROUP BY per
figure), plus the robots' time since their last event (``Rollups.tail``)."""

from __future__ import annotations

import bisect
import time
from collections.abc import Awaitable, Callable
from typing import Any

from sqlalchemy import func, select

from backend.db.models import ReportDayRow, ReportRollupRow
from backend.reports.fold import ROBOT_STATES
from backend.reports.period import Period
from backend.reports.rollup import Rollups, Tally

__all__ = ["FIGURES", "Reports", "percentile"]

TASK_STATES = ("requested", "done", "failed", "cancelled")
INCIDENTS = ("faults", "door_blocks", "elevator_wait", "lock_wait", "alarms")
HEAT = {"node_visits": "node", "door_opened": "door", "area_granted": "area"}
DAY = 86400


def percentile(histogram: dict[str, int], share: float) -> float | None:
    """The lower bound of the bucket holding the ``share`` quantile (None: no values)."""
    total = sum(histogram.values())
    if total == 0:
        return None
    seen = 0
    for lower in sorted(histogram, key=float):
        seen += histogram[lower]
        if seen >= share * total:
            return float(lower)
    return float(max(histogram, key=float))


def _r(value: float | None, digits: int = 1) -> float | None:
    return None if value is None else round(value, digits)


class Reports:
    """Each figure of a period as a JSON document with ``rows`` (what the CSV holds)."""

    def __init__(self, rollups: Rollups, flush: Callable[[], Awaitable[None]] | None = None):
        self.rollups = rollups
        self.flush = flush
        """Writes the events still queued in memory (DbStore.flush) before a report."""

    async def _fresh(self) -> None:
        if self.flush is not None:
            await self.flush()
        await self.rollups.catch_up()

    async def _sums(
        self, period: Period, metrics: tuple[str, ...]
    ) -> dict[str, dict[str, list[Any]]]:
        """metric -> key -> [n, total] over the period: its whole UTC days from the daily
        rollups, the hours before the first and after the last from the hourly ones."""
        first_day = -(-int(period.start) // DAY) * DAY
        last_day = int(period.end) // DAY * DAY
        h, d = ReportRollupRow, ReportDayRow
        if last_day > first_day:
            edges = [(period.start, first_day), (last_day, period.end)]
        else:
            edges = [(period.start, period.end)]
        queries = (
            [
                select(d.metric, d.key, func.sum(d.n), func.sum(d.total))
                .where(d.metric.in_(metrics), d.day >= first_day, d.day < last_day)
                .group_by(d.metric, d.key)
            ]
            if last_day > first_day
            else []
        )
        queries += [
            select(h.metric, h.key, func.sum(h.n), func.sum(h.total))
            .where(h.metric.in_(metrics), h.hour >= start, h.hour < end)
            .group_by(h.metric, h.key)
            for start, end in edges
            if end > start
        ]
        out: dict[str, dict[str, list[Any]]] = {m: {} for m in metrics}
        async with self.rollups.sessionmaker() as session:
            for query in queries:
                for metric, key, n, total in await session.execute(query):
                    cell = out[metric].setdefault(key, [0, 0.0])
                    cell[0] += int(n or 0)
                    cell[1] += float(total or 0.0)
        if "robot_time" in metrics:
            for (metric, hour, key), cell in (await self._tail(period)).items():
                if metric == "robot_time" and period.start <= hour < period.end:
                    into = out[metric].setdefault(key, [0, 0.0])
                    into[1] += cell[1]
        return out

    async def _tail(self, period: Period) -> Tally:
        now = time.time()
        if now <= period.start:
            return {}
        return await self.rollups.tail(min(now, period.end))

    async def _series(
        self, period: Period, metrics: tuple[str, ...], key: str | None = None
    ) -> dict[float, dict[str, list[Any]]]:
        """bin start -> metric -> [n, total], the bins in the venue's time (days on UTC: from
        the daily rollups; otherwise from the hours)."""
        t: Any = ReportDayRow if period.utc_days() else ReportRollupRow
        when = t.day if t is ReportDayRow else t.hour
        query = select(t.metric, when, func.sum(t.n), func.sum(t.total)).where(
            t.metric.in_(metrics), when >= period.start, when < period.end
        )
        if key is not None:
            query = query.where(t.key == key)
        query = query.group_by(t.metric, when)
        starts = period.bins()
        bins: dict[float, dict[str, list[Any]]] = {
            b: {m: [0, 0.0] for m in metrics} for b in starts
        }
        async with self.rollups.sessionmaker() as session:
            for metric, hour, n, total in await session.execute(query):
                cell = bins[starts[bisect.bisect_right(starts, hour) - 1]][metric]
                cell[0] += int(n or 0)
                cell[1] += float(total or 0.0)
        return bins

    # --- figures ---------------------------------------------------------------------------
    async def tasks(self, period: Period) -> dict[str, Any]:
        """Tours requested, done, failed (and why), cancelled: totals by kind, tours per bin."""
        await self._fresh()
        sums = await self._sums(period, (*TASK_STATES, "failed_reason"))
        series = await self._series(period, TASK_STATES, key="tour")
        now = time.time()  # bins that have not begun have no counts (null), not zeros
        kinds = sorted({k for m in TASK_STATES for k in sums[m]})
        return {
            "period": period.as_dict(),
            "by_kind": [
                {"kind": k, **{m: sums[m].get(k, [0])[0] for m in TASK_STATES}} for k in kinds
            ],
            "failed_by_reason": sorted(
                ({"reason": r, "count": c[0]} for r, c in sums["failed_reason"].items()),
                key=lambda row: -int(row["count"]),
            ),
            "rows": [
                {
                    "start": period.label(b),
                    **{m: cells[m][0] if b <= now else None for m in TASK_STATES},
                }
                for b, cells in series.items()
            ],
        }

    async def waits(self, period: Period) -> dict[str, Any]:
        """Visitor waits (request to the robot at the first stop) and tour lengths."""
        await self._fresh()
        sums = await self._sums(period, ("wait", "wait_hist", "tour_length", "tour_length_hist"))
        series = await self._series(period, ("wait", "tour_length"))
        now = time.time()
        waits = {k: c[0] for k, c in sums["wait_hist"].items()}
        lengths = {k: c[0] for k, c in sums["tour_length_hist"].items()}
        n_wait = sum(c[0] for c in sums["wait"].values())
        n_len = sum(c[0] for c in sums["tour_length"].values())

        def mean(cell: list[Any]) -> float | None:
            return _r(cell[1] / cell[0]) if cell[0] else None

        return {
            "period": period.as_dict(),
            "wait_s": {
                "count": n_wait,
                "p50": percentile(waits, 0.5),
                "p95": percentile(waits, 0.95),
                "mean": mean([n_wait, sum(c[1] for c in sums["wait"].values())]),
            },
            "tour_length_s": {
                "count": n_len,
                "p50": percentile(lengths, 0.5),
                "p95": percentile(lengths, 0.95),
                "mean": mean([n_len, sum(c[1] for c in sums["tour_length"].values())]),
            },
            "rows": [
                {
                    "start": period.label(b),
                    "waits": cells["wait"][0] if b <= now else None,
                    "wait_mean_s": mean(cells["wait"]),
                    "tours_done": cells["tour_length"][0] if b <= now else None,
                    "tour_length_mean_s": mean(cells["tour_length"]),
                }
                for b, cells in series.items()
            ],
        }

    async def following(self, period: Period) -> dict[str, Any]:
        """Tours whose visitors stopped following before the last stop: per tour, per language
        and per stop (where they left)."""
        await self._fresh()
        sums = await self._sums(period, ("tours_ended", "stopped"))
        ended = sum(c[0] for k, c in sums["tours_ended"].items() if k.startswith("tour:"))
        rows = []
        for key in sorted(set(sums["tours_ended"]) | set(sums["stopped"])):
            by, _, name = key.partition(":")
            tours = sums["tours_ended"].get(key, [0])[0] if by != "stop" else ended
            stopped = sums["stopped"].get(key, [0])[0]
            share = round(stopped / tours, 3) if tours else None
            rows.append(
                {"by": by, "name": name, "tours": tours, "stopped": stopped, "share": share}
            )
        stopped_all = sum(c[0] for k, c in sums["stopped"].items() if k.startswith("tour:"))
        return {
            "period": period.as_dict(),
            "tours": ended,
            "stopped": stopped_all,
            "share": round(stopped_all / ended, 3) if ended else None,
            "rows": rows,
        }

    async def stops(self, period: Period) -> dict[str, Any]:
        """The stops most listened to (explanations finished)."""
        await self._fresh()
        sums = await self._sums(period, ("listened",))
        rows = [{"stop": k, "listened": c[0]} for k, c in sums["listened"].items()]
        rows.sort(key=lambda row: (-int(row["listened"]), str(row["stop"])))
        return {"period": period.as_dict(), "rows": rows}

    async def robots(self, period: Period) -> dict[str, Any]:
        """Each robot's seconds touring, on errands, charging, idle, faulted, offline, and its
        distance in metres (between the nodes it reported)."""
        await self._fresh()
        sums = await self._sums(period, ("robot_time", "distance"))
        names = {k.partition("|")[0] for k in sums["robot_time"]} | set(sums["distance"])
        rows = []
        for name in sorted(names):
            row: dict[str, Any] = {"robot": name}
            for state in ROBOT_STATES:
                row[f"{state}_s"] = round(sums["robot_time"].get(f"{name}|{state}", [0, 0.0])[1])
            row["distance_m"] = round(sums["distance"].get(name, [0, 0.0])[1], 1)
            rows.append(row)
        return {"period": period.as_dict(), "rows": rows}

    async def incidents(self, period: Period) -> dict[str, Any]:
        """Faults (robot|kind), door blocks (door), elevator waits (elevator), lock waits (area)
        and alarms (alert kind, fire_alarm): counts and, for waits, seconds."""
        await self._fresh()
        sums = await self._sums(period, INCIDENTS)
        rows = []
        for metric in INCIDENTS:
            for key, (n, total) in sorted(sums[metric].items(), key=lambda kv: -kv[1][0]):
                waits = metric.endswith("_wait")
                rows.append(
                    {
                        "type": metric,
                        "name": key,
                        "count": n,
                        "wait_total_s": round(total, 1) if waits else None,
                        "wait_mean_s": round(total / n, 1) if waits and n else None,
                    }
                )
        return {"period": period.as_dict(), "rows": rows}

    async def heat(self, period: Period) -> dict[str, Any]:
        """How busy each node (robots reaching it), door (openings) and area (grants) was."""
        await self._fresh()
        sums = await self._sums(period, tuple(HEAT))
        rows = [
            {"kind": HEAT[metric], "name": key, "count": cell[0]}
            for metric in HEAT
            for key, cell in sorted(sums[metric].items(), key=lambda kv: -kv[1][0])
        ]
        return {"period": period.as_dict(), "rows": rows}


FIGURES: dict[str, Callable[[Reports, Period], Awaitable[dict[str, Any]]]] = {
    "tasks": Reports.tasks,
    "waits": Reports.waits,
    "following": Reports.following,
    "stops": Reports.stops,
    "robots": Reports.robots,
    "incidents": Reports.incidents,
    "heat": Reports.heat,
}
"""Figure name -> its method: one REST route each (docs/reports.md)."""
