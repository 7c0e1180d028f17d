"""Task kinds, each described in one place: its Petri net, its expected duration, where it
starts (its target on the site), its parameters and their validation, and who may ask for it.

Every process reads this table: the Task Manager (net, duration, target, manual kinds), the
REST API and the ``task_request`` payload (the kinds, the parameters), the site validator (a
button's task), the visitor panel and the robot's touch screen (the visitor kinds). Adding a
kind is one entry here (plus its net in petri_nets/library and its robot-side parameters in
``net_params`` in backend/tasks/targets.py).
"""

from __future__ import annotations

from collections.abc import Callable, Container, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, StrictBool, ValidationError

from guidebot.pace import PaceName

if TYPE_CHECKING:
    from guidebot.site.schema import Site

__all__ = [
    "KINDS",
    "MANUAL_KINDS",
    "VISITOR_KINDS",
    "BadParams",
    "ChargeParams",
    "GoToParams",
    "KindSpec",
    "PoiParams",
    "TaskKind",
    "TourParams",
    "UnknownTarget",
    "check_params",
]

TaskKind = Literal["tour", "go_to_poi", "charge", "go_to"]
"""The kinds as a type (API schema, payloads); must name exactly the keys of ``KINDS``."""

Ref = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")]
Lang = Annotated[
    str, Field(min_length=2, max_length=16, pattern=r"^[A-Za-z]{2,3}([-_][A-Za-z0-9]+)?$")
]
"""A language code the site offers (checked against the site by the Task Manager)."""


class _Params(BaseModel):
    model_config = ConfigDict(extra="forbid")


class TourParams(_Params):
    tour: Ref
    lang: Lang | None = None
    """The language the tour is explained in; None: the site's default language."""
    pace: PaceName | None = None
    """``slow``: a slower tour (guidebot/pace.py); None: the normal pace."""
    step_free: StrictBool | None = None
    """True: over no edge with steps; a stop only steps lead to is skipped (docs/visitor.md,
    "A step-free tour")."""


class PoiParams(_Params):
    poi: Ref
    lang: Lang | None = None
    pace: PaceName | None = None
    step_free: StrictBool | None = None
    """True: a step-free visit, refused for a point only steps lead to (docs/visitor.md, "A
    step-free visit to one point")."""


class ChargeParams(_Params):
    station: Ref | None = None
    """None: the first charging station of the site."""


class GoToParams(_Params):
    node: Ref


class UnknownTarget(ValueError):
    """A task's parameters name something the site does not have."""

    def __init__(self, param: str, what: str, value: object) -> None:
        super().__init__(f"unknown {what} {value!r}")
        self.param = param
        self.what = what
        self.value = value


def _tour_target(site: Site, params: Mapping[str, Any], nodes: Container[str]) -> str:
    tour = site.tour(str(params.get("tour")))
    if tour is None:
        raise UnknownTarget("tour", "tour", params.get("tour"))
    poi = site.poi(tour.points[0])
    if poi is None:
        raise UnknownTarget("tour", "point of interest", tour.points[0])
    return poi.node


def _poi_target(site: Site, params: Mapping[str, Any], nodes: Container[str]) -> str:
    poi = site.poi(str(params.get("poi")))
    if poi is None:
        raise UnknownTarget("poi", "point of interest", params.get("poi"))
    return poi.node


def _node_target(site: Site, params: Mapping[str, Any], nodes: Container[str]) -> str:
    node = params.get("node")
    if not isinstance(node, str) or node not in nodes:
        raise UnknownTarget("node", "node", node)
    return node


def _station_target(site: Site, params: Mapping[str, Any], nodes: Container[str]) -> str:
    stations = {s.id: s.node for s in site.charging_stations}
    station = params.get("station")
    if station is None and stations:
        return next(iter(stations.values()))
    if station not in stations:
        raise UnknownTarget("station", "charging station", station)
    return stations[str(station)]


Target = Callable[["Site", Mapping[str, Any], Container[str]], str]


@dataclass(frozen=True)
class KindSpec:
    """One task kind."""

    name: str
    net: str
    """The Petri net the robot runs (petri_nets/library)."""
    duration_s: float
    """Expected duration until the Task Manager has measured some (ETA, robot choice)."""
    params: type[BaseModel]
    """Its parameters, strict: anything else is refused before a task exists."""
    target: Target
    """The node where the task starts (path cost), from the site, its node ids and the
    parameters; raises UnknownTarget when they name what the site does not have."""
    manual: bool = False
    """Staff may still send it to an out-of-service robot (pinned to it): moving it by hand."""
    visitor: bool = False
    """Visitor-facing requesters (panels, robot screens) may ask for it."""


KINDS: dict[str, KindSpec] = {
    "tour": KindSpec("tour", "give_tour", 600.0, TourParams, _tour_target, visitor=True),
    "go_to_poi": KindSpec("go_to_poi", "go_to_poi", 120.0, PoiParams, _poi_target, visitor=True),
    "charge": KindSpec("charge", "battery_charge", 1800.0, ChargeParams, _station_target, True),
    "go_to": KindSpec("go_to", "navigate_to_point", 60.0, GoToParams, _node_target, True),
}
"""Task kind -> its description (docs/server.md, "Requests")."""
if set(get_args(TaskKind)) != set(KINDS):  # pragma: no cover - a broken edit of this file
    raise RuntimeError("TaskKind and KINDS name different task kinds")

MANUAL_KINDS = frozenset(k for k, spec in KINDS.items() if spec.manual)
VISITOR_KINDS = frozenset(k for k, spec in KINDS.items() if spec.visitor)


class BadParams(ValueError):
    """A task request of an unknown kind, or with parameters its kind does not take."""


def check_params(kind: str, params: Any) -> dict[str, Any]:
    """The checked parameters of a ``kind`` task (unset optional ones left out); raises
    BadParams saying what is wrong and what the kind expects."""
    spec = KINDS.get(kind)
    if spec is None:
        raise BadParams(f"unknown task kind {kind!r} (expected one of {sorted(KINDS)})")
    if not isinstance(params, dict):
        raise BadParams(f"params of a {kind} task must be an object")
    try:
        return spec.params.model_validate(params).model_dump(exclude_none=True)
    except ValidationError as exc:
        problems = []
        for err in exc.errors(include_input=False, include_url=False)[:5]:
            where = ".".join(str(p) for p in err["loc"]) or "params"
            problems.append(f"params.{where}: {err['msg']}")
        expected = ", ".join(spec.params.model_fields)
        raise BadParams(
            f"bad params for a {kind} task ({'; '.join(problems)}); expected: {expected}"
        ) from None
