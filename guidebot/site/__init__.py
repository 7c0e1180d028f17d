"""The site: schema (pydantic), YAML import/export, validation with every error and its place."""

from guidebot.site.building import (
    BuildingModule,
    Button,
    ButtonTask,
    Door,
    Elevator,
    ElevatorStop,
    IOPoint,
    IORef,
    PointKind,
)
from guidebot.site.schema import (
    ChargingStation,
    Edge,
    Floor,
    Node,
    PointOfInterest,
    RestrictedArea,
    RobotConfig,
    Site,
    Tour,
    WaitPoint,
)
from guidebot.site.validate import SiteInvalid, SiteIssue, validate_site
from guidebot.site.yamlio import dump_site, load_site_file, load_site_text

__all__ = [
    "BuildingModule",
    "Button",
    "ButtonTask",
    "ChargingStation",
    "Door",
    "Edge",
    "Elevator",
    "ElevatorStop",
    "Floor",
    "IOPoint",
    "IORef",
    "Node",
    "PointKind",
    "PointOfInterest",
    "RestrictedArea",
    "RobotConfig",
    "Site",
    "SiteInvalid",
    "SiteIssue",
    "Tour",
    "WaitPoint",
    "dump_site",
    "load_site_file",
    "load_site_text",
    "validate_site",
]
