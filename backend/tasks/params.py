"""Strict parameters of each task kind: anything else is refused before a task exists.

The same check serves REST, hub ``task_request`` and building buttons, so a 20 MB ``params``
or a typo (``tuor``) never reaches the queue, the database or a robot.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from backend.tasks.model import InvalidTask

__all__ = ["PARAMS", "validate_params"]

Ref = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")]


class _Params(BaseModel):
    model_config = ConfigDict(extra="forbid")


Lang = Annotated[
    str, Field(min_length=2, max_length=16, pattern=r"^[A-Za-z]{2,3}([-_][A-Za-z0-9]+)?$")
]
"""A language code the site offers (checked against the site by the Task Manager)."""


class TourParams(_Params):
    tour: Ref
    lang: Lang | None = None
    """The language the tour is explained in; None: the site's default language."""


class PoiParams(_Params):
    poi: Ref
    lang: Lang | None = None


class ChargeParams(_Params):
    station: Ref | None = None
    """None: the first charging station of the site."""


class GoToParams(_Params):
    node: Ref


PARAMS: dict[str, type[_Params]] = {
    "tour": TourParams,
    "go_to_poi": PoiParams,
    "charge": ChargeParams,
    "go_to": GoToParams,
}
"""Task kind -> its parameter model (docs/server.md, "Requests")."""


def validate_params(kind: str, params: Any) -> dict[str, Any]:
    """The checked parameters of a ``kind`` task; raises InvalidTask saying what is wrong."""
    model = PARAMS.get(kind)
    if model is None:
        raise InvalidTask(f"unknown task kind {kind!r} (expected one of {sorted(PARAMS)})")
    if not isinstance(params, dict):
        raise InvalidTask(f"params of a {kind} task must be an object")
    try:
        return model.model_validate(params).model_dump(exclude_none=True)
    except ValidationError as exc:
        problems = []
        for err in exc.errors(include_input=False, include_url=False)[:5]:
            where = ".".join(str(p) for p in err["loc"]) or "params"
            problems.append(f"params.{where}: {err['msg']}")
        expected = ", ".join(model.model_fields)
        raise InvalidTask(
            f"bad params for a {kind} task ({'; '.join(problems)}); expected: {expected}"
        ) from None
