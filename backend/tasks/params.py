"""Strict parameters of each task kind: anything else is refused before a task exists.

The same check serves REST, hub ``task_request`` and building buttons, so a 20 MB ``params``
or a typo (``tuor``) never reaches the queue, the database or a robot. The models and the check
are the task-kind table's (guidebot.task_kinds); here they raise the Task Manager's InvalidTask.
"""

from __future__ import annotations

from typing import Any

from backend.tasks.model import InvalidTask
from guidebot.task_kinds import BadParams, check_params

__all__ = ["validate_params"]


def validate_params(kind: str, params: Any) -> dict[str, Any]:
    """The checked parameters of a ``kind`` task; raises InvalidTask saying what is wrong."""
    try:
        return check_params(kind, params)
    except BadParams as exc:
        raise InvalidTask(str(exc)) from None
