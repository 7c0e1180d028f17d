"""The site: one venue's map, points of interest, tours, stations, areas, building and robots.

A site is a plain pydantic document. ``Site.model_validate`` checks shapes; cross references
(an edge naming an unknown node, a tour naming an unknown point) are checked by
``backend.site.validate.check_references`` so that every error is reported at once.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from backend.site.building import ID_PATTERN, BuildingModule, Button, Door, Elevator

__all__ = [
    "ChargingStation",
    "Edge",
    "Floor",
    "Node",
    "PointOfInterest",
    "RestrictedArea",
    "RobotConfig",
    "Site",
    "Tour",
    "WaitPoint",
]

Id = str


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _id(**kwargs: Any) -> Any:
    return Field(min_length=1, max_length=64, pattern=ID_PATTERN, **kwargs)


class Floor(StrictModel):
    """One floor: its plan image maps metres to pixels with ``scale_px_per_m``."""

    id: Id = _id()
    name: str = ""
    level: int = 0
    plan_image: str | None = None
    """Floor-plan image (SVG or PNG), relative to the site file's folder."""
    scale_px_per_m: float = Field(default=20.0, gt=0)
    plan_origin: tuple[float, float] = (0.0, 0.0)
    """Site coordinates (metres) of the plan image's bottom-left corner."""


class Node(StrictModel):
    """A topological node: coordinates in metres on its floor."""

    id: Id = _id()
    floor: Id
    x: float
    y: float
    passing_place: bool = False
    """A place wide enough for a robot to wait while another passes (deadlock resolution)."""


class Edge(StrictModel):
    """A corridor between two nodes; length from the coordinates when not given."""

    a: Id
    b: Id
    length_m: float | None = Field(default=None, gt=0)
    one_way: bool = False
    """Only from ``a`` to ``b``."""


class PointOfInterest(StrictModel):
    id: Id = _id()
    name: str = ""
    node: Id
    text: str = ""
    """What the robot says there."""
    media: list[str] = Field(default_factory=list)
    lang: str = "en"


class Tour(StrictModel):
    id: Id = _id()
    name: str = ""
    description: str = ""
    points: list[Id] = Field(min_length=1)


class ChargingStation(StrictModel):
    id: Id = _id()
    node: Id


class WaitPoint(StrictModel):
    id: Id = _id()
    node: Id


class RestrictedArea(StrictModel):
    """Nodes where only one robot may be at a time (narrow corridor, elevator cabin)."""

    id: Id = _id()
    nodes: list[Id] = Field(min_length=1)
    passing_place: Id | None = None
    """Where a robot backs off to when it must yield this area; default: nearest passing place."""


class RobotConfig(StrictModel):
    name: Id = _id()
    token: str = Field(min_length=8, max_length=256)
    start_node: Id | None = None
    max_speed_mps: float = Field(default=0.7, gt=0, le=5)
    battery_low: float = Field(default=0.3, ge=0, le=1)
    battery_panic: float = Field(default=0.1, ge=0, le=1)
    params: dict[str, Any] = Field(default_factory=dict)


class Site(StrictModel):
    """The whole site document (what sites/*.yaml holds)."""

    name: str = Field(min_length=1, max_length=200)
    version: int = Field(default=1, ge=1)
    floors: list[Floor] = Field(min_length=1)
    nodes: list[Node] = Field(min_length=1)
    edges: list[Edge] = Field(default_factory=list)
    pois: list[PointOfInterest] = Field(default_factory=list)
    tours: list[Tour] = Field(default_factory=list)
    charging_stations: list[ChargingStation] = Field(default_factory=list)
    wait_points: list[WaitPoint] = Field(default_factory=list)
    areas: list[RestrictedArea] = Field(default_factory=list)
    doors: list[Door] = Field(default_factory=list)
    elevators: list[Elevator] = Field(default_factory=list)
    modules: list[BuildingModule] = Field(default_factory=list)
    buttons: list[Button] = Field(default_factory=list)
    robots: list[RobotConfig] = Field(default_factory=list)

    def poi(self, poi_id: str) -> PointOfInterest | None:
        return next((p for p in self.pois if p.id == poi_id), None)

    def tour(self, tour_id: str) -> Tour | None:
        return next((t for t in self.tours if t.id == tour_id), None)

    def robot(self, name: str) -> RobotConfig | None:
        return next((r for r in self.robots if r.name == name), None)

    def module(self, module_id: str) -> BuildingModule | None:
        return next((m for m in self.modules if m.id == module_id), None)
