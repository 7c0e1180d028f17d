"""A live or virtual run's row adds up: every request is exactly one of served, refused,
abandoned, failed, skipped or unfinished (docs/planning.md, its JSON keys). The 300-visitor
virtual day once reported 120 requests, 99 served and nothing else: 21 tours had ended with
their first point skipped (a door out of order on the way) and were counted nowhere."""

from __future__ import annotations

from typing import Any

from backend.planning.live import FATES, LiveOptions, _Driver, _outcome
from backend.planning.profile import Request
from guidebot.site.yamlio import load_site_file
from tests.planning.test_sim import DEMO


def _tour(task: str, at: float, *stages: tuple[str, float]) -> list[tuple[float, str, str, dict]]:
    events = [(at, "task_created", "task_manager", {"task_id": task, "kind": "tour"})]
    for kind, when in stages:
        events.append((when, kind, "task_manager", {"task_id": task}))
    return events


def test_every_request_is_counted_once_whatever_became_of_it() -> None:
    site = load_site_file(DEMO)
    requests = [Request(float(i), "ground", 5) for i in range(8)]
    driver = _Driver(None, "", "", "", [], requests, LiveOptions())  # type: ignore[arg-type]
    driver.task_of = {"served": 0, "gave-up": 2, "failed": 3, "skipped": 4, "queued": 5}
    driver.task_of["served-then-failed"] = 7
    driver.refused, driver.abandoned = [1], [2]
    # Request 6 was never asked: the run stopped first.
    events: list[Any] = [
        *_tour("served", 0.0, ("task_point 1/5 arrived", 30.0), ("task_done", 200.0)),
        *_tour("gave-up", 2.0, ("task_cancelled", 600.0)),
        *_tour("failed", 3.0, ("task_failed", 40.0)),
        # Its robot skipped the first point (a door out of order) and guided from the second.
        *_tour("skipped", 4.0, ("task_point 1/5 skipped", 50.0), ("task_point 2/5 arrived", 60.0)),
        (70.0, "task_done", "task_manager", {"task_id": "skipped"}),
        *_tour("queued", 5.0),
        *_tour("served-then-failed", 7.0, ("task_point 1/5 arrived", 90.0)),
        (120.0, "task_failed", "task_manager", {"task_id": "served-then-failed"}),
    ]
    row = _outcome(
        events, site, driver, robots=1, day_s=900.0, t0=0.0, t_end=900.0, scale=1.0, wall_s=0.0
    ).summary(10.0)
    assert {fate: row[fate] for fate in FATES} == {
        "served": 2,
        "refused": 1,
        "abandoned": 1,
        "failed": 1,
        "skipped": 1,
        "unfinished": 2,
    }
    assert sum(row[fate] for fate in FATES) == row["requests"] == 8
