"""Handover: a tour taken from its robot in the middle (a fault, a lost robot, a battery panic,
out of service, its agent restarted) goes on with another robot from the stop the visitor is at,
not from the start (docs/server.md, "Handover").

The visitor is at the last stop the robot reported (``tour_progress``, arrived or explained).
The task keeps that stop (``Task.resume_from``) and a ``handover`` record; the next robot is
given the tour's points from that stop on (their ``index`` and ``total`` unchanged, so the panel
still says "stop 3 of 5"), drives to the visitor's stop and explains it again, and the record is
closed when that robot reports it arrived there (``handover_s``: break to the robot at the
visitor). Every ``task_event`` carries the record (docs/protocol.md, "Handover").
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from backend.tasks.model import Task

if TYPE_CHECKING:
    from backend.tasks.eta import EtaEstimator

__all__ = ["arrived", "note_break", "resumed_points"]


def note_break(task: Task, estimator: EtaEstimator, reason: str) -> None:
    """``task`` is taken from its robot (before it leaves it): a tour past its first arrival
    remembers the stop the visitor is at; a tour not started anywhere yet starts again."""
    if task.kind != "tour" or task.robot is None:
        return
    progress = estimator.progress_view(task)
    index = progress.get("index") if progress else None
    if isinstance(index, int) and index >= 1:
        task.resume_from = index
        stop_name = progress.get("name") if progress else None
        poi = progress.get("poi") if progress else None
        total = progress.get("total") if progress else None
    elif task.resume_from is not None and task.handover is not None:
        # Taken again before the new robot reached the visitor: the same stop.
        stop_name, poi, total = (task.handover.get(k) for k in ("name", "poi", "total"))
    else:
        return
    task.handover = {
        "from_robot": task.robot,
        "stop": task.resume_from,
        "total": total,
        "poi": poi,
        "name": stop_name,
        "reason": reason,
        "at": time.time(),
        "arrived_after_s": None,
    }


def resumed_points(params: dict[str, Any], resume_from: int | None) -> dict[str, Any]:
    """What a handed-over tour's net is given: the points from the visitor's stop on (a new
    dict: ``params`` may be shared by every task of the same tour)."""
    points = params.get("points")
    if not resume_from or resume_from <= 1 or not isinstance(points, list):
        return params
    rest = [p for p in points if isinstance(p, dict) and p.get("index", 0) >= resume_from]
    return {**params, "points": rest or points[-1:]}


def arrived(task: Task, index: int, stage: str) -> bool:
    """A robot reported ``index``/``stage`` on a handed-over tour: True when it is the new
    robot reaching the visitor (the record is closed with the seconds it took)."""
    record = task.handover
    if record is None or record.get("arrived_after_s") is not None:
        return False
    if index < (task.resume_from or 1):
        return False
    record["arrived_after_s"] = round(max(0.0, time.time() - float(record["at"])), 1)
    return True
