"""The site: one venue's map, points of interest, tours, stations, areas, building and robots.

A site is a plain pydantic document. ``Site.model_validate`` checks shapes; cross references
(an edge naming an unknown node, a tour naming an unknown point) are checked by
``guidebot.site.validate.check_references`` so that every error is reported at once.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt

from guidebot.site.building import ID_PATTERN, BuildingModule, Button, Door, Elevator
from guidebot.site.emergency import Emergency, SourceHash
from guidebot.site.index import Indexed

__all__ = [
    "ChargingStation",
    "Edge",
    "Floor",
    "Node",
    "PoiText",
    "PointOfInterest",
    "RestrictedArea",
    "RobotConfig",
    "Site",
    "Tour",
    "TourText",
    "WaitPoint",
]

Id = str

MQTT_NAME = r"^[A-Za-z0-9_.-]+$"
"""A name that goes into an MQTT topic level (no ``/``, ``+`` or ``#``)."""


class StrictModel(BaseModel):
    """Unknown keys are refused, and numbers and flags are taken as such only (``true`` is not
    1, ``"2"`` not 2): a site arrives from files and from the REST API alike."""

    model_config = ConfigDict(extra="forbid")


def _id(**kwargs: Any) -> Any:
    return Field(min_length=1, max_length=64, pattern=ID_PATTERN, **kwargs)


class Floor(StrictModel):
    """One floor: its plan image maps metres to pixels with ``scale_px_per_m``."""

    id: Id = _id()
    name: str = ""
    level: StrictInt = 0
    plan_image: str | None = None
    """Floor-plan image (SVG or PNG), relative to the site file's folder."""
    scale_px_per_m: StrictFloat = Field(default=20.0, gt=0)
    plan_origin: tuple[StrictFloat, StrictFloat] = (0.0, 0.0)
    """Site coordinates (metres) of the plan image's bottom-left corner."""


class Node(StrictModel):
    """A topological node: coordinates in metres on its floor."""

    id: Id = _id()
    floor: Id
    x: StrictFloat
    y: StrictFloat
    passing_place: StrictBool = False
    """A place wide enough for a robot to wait while another passes (deadlock resolution)."""


class Edge(StrictModel):
    """A corridor between two nodes; length from the coordinates when not given."""

    a: Id
    b: Id
    length_m: StrictFloat | None = Field(default=None, gt=0)
    one_way: StrictBool = False
    """Only from ``a`` to ``b``."""
    steps: StrictBool = False
    """Steps or a slope a wheelchair user cannot take: a step-free tour does not use it
    (robots still may; docs/visitor.md, "A step-free tour")."""


LANG_PATTERN = r"^[a-z]{2,3}(-[A-Za-z0-9]{2,8})?$"
"""A BCP 47 language tag, short form: ``en``, ``es``, ``pt-BR``."""
Lang = Annotated[str, Field(pattern=LANG_PATTERN)]


class PoiText(StrictModel):
    """A point's texts in one more language; what is left out falls back to the default."""

    name: str | None = None
    description: str | None = None
    text: str | None = None
    media: list[str] | None = None
    sign_video: str | None = None
    """The text in this language's sign language (a video; see ``PointOfInterest``)."""
    source_hash: dict[Literal["name", "description", "text"], SourceHash] = Field(
        default_factory=dict
    )
    """Per field: the hash of the source text it was translated from (none: taken as current)."""


class TourText(StrictModel):
    """A tour's texts in one more language."""

    name: str | None = None
    description: str | None = None
    source_hash: dict[Literal["name", "description"], SourceHash] = Field(default_factory=dict)
    """Per field: the hash of the source text it was translated from (none: taken as current)."""


class PointOfInterest(StrictModel):
    id: Id = _id()
    name: str = ""
    node: Id
    description: str = ""
    """One or two lines for the visitor panel (the spoken ``text`` when empty)."""
    text: str = ""
    """What the robot says there."""
    media: list[str] = Field(default_factory=list)
    """File names in the site's media folder (served at /media/<name>)."""
    sign_video: str | None = None
    """A video of ``text`` in sign language (.mp4 or .webm in the site's folder), shown on the
    touch screen and the visitor's phone during the stop (docs/accessibility.md)."""
    lang: str | None = Field(default=None, pattern=LANG_PATTERN)
    """Language of name/description/text above; None: the site's ``default_language``."""
    translations: dict[Lang, PoiText] = Field(default_factory=dict)
    """Per language tag: the same texts in that language (docs/visitor.md, "Languages")."""


class Tour(StrictModel):
    id: Id = _id()
    name: str = ""
    description: str = ""
    points: list[Id] = Field(min_length=1)
    translations: dict[Lang, TourText] = Field(default_factory=dict)


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
    max_speed_mps: StrictFloat = Field(default=0.7, gt=0, le=5)
    battery_low: StrictFloat = Field(default=0.3, ge=0, le=1)
    battery_panic: StrictFloat = Field(default=0.1, ge=0, le=1)
    params: dict[str, Any] = Field(default_factory=dict)
    interface: Literal["guidebot", "vda5050"] = "guidebot"
    """How the robot joins the fleet: GuideBot's own agent over the hub, or a vehicle of
    another maker speaking VDA 5050 over MQTT (docs/vda5050.md)."""
    manufacturer: str | None = Field(default=None, min_length=1, max_length=64, pattern=MQTT_NAME)
    """VDA 5050: the vehicle's manufacturer, as in its topics."""
    serial_number: str | None = Field(default=None, min_length=1, max_length=64, pattern=MQTT_NAME)
    """VDA 5050: the vehicle's serial number, as in its topics."""
    mqtt_interface: str = Field(default="uagv", min_length=1, max_length=64, pattern=MQTT_NAME)
    """VDA 5050: the first level of its topics (the spec's ``interfaceName``)."""
    vda_version: Literal["2.1.0", "3.0.0"] = "2.1.0"
    """VDA 5050: the version the vehicle speaks (its topics carry the major, ``v2``)."""
    map_ids: dict[Id, str] = Field(default_factory=dict)
    """VDA 5050: floor id -> the vehicle's ``mapId`` there (default: the floor id)."""


class Site(StrictModel, Indexed):
    """The whole site document (what sites/*.yaml holds).

    ``poi``, ``tour``, ``robot`` and ``module`` look up by id in O(1) (guidebot/site/index.py).
    """

    name: str = Field(min_length=1, max_length=200)
    version: StrictInt = Field(default=1, ge=1)
    default_language: str = Field(default="en", pattern=LANG_PATTERN)
    """The language of the texts given without a translation, and the fallback."""
    languages: list[Lang] = Field(default_factory=list)
    """Languages offered to visitors besides the default (``site check`` warns of gaps)."""
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
    emergency: Emergency | None = None
    """Fire alarm inputs, safe spots, escape routes and their words (docs/emergency.md)."""

    def poi(self, poi_id: str) -> PointOfInterest | None:
        return self._find("pois", self.pois, _id_of, poi_id)

    def tour(self, tour_id: str) -> Tour | None:
        return self._find("tours", self.tours, _id_of, tour_id)

    def robot(self, name: str) -> RobotConfig | None:
        return self._find("robots", self.robots, _name_of, name)

    def module(self, module_id: str) -> BuildingModule | None:
        return self._find("modules", self.modules, _id_of, module_id)


def _id_of(item: Any) -> str:
    return str(item.id)


def _name_of(item: RobotConfig) -> str:
    return item.name
