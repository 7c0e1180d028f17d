"""The soak venue: the demo museum with one robot (and its own charging dock) per soak robot.

The shipped site (sites/demo_museum.yaml: two floors, a door on each, the elevator and the
corridor as restricted areas, two buttons) keeps every fault meaningful; the docks hang off the
entrance so idle robots each have a station to go to.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ["PANELS", "soak_site", "with_ports"]

ROOT = Path(__file__).resolve().parent.parent
DEMO_SITE = ROOT / "sites" / "demo_museum.yaml"

PANELS = {"panel_hall": "soak-panel-hall-token", "panel_first": "soak-panel-first-token"}
"""Panel name -> bearer token (given to the server as GUIDEBOT_TOKENS)."""


def robot_token(name: str) -> str:
    return f"soak-{name}-robot-token"


def soak_site(robots: int) -> dict[str, Any]:
    """The demo site with robots R1..Rn, each starting at its own dock off the entrance."""
    site: dict[str, Any] = yaml.safe_load(DEMO_SITE.read_text(encoding="utf-8"))
    site["name"] = "Soak museum"
    site["robots"] = []
    for i in range(1, robots + 1):
        dock = f"dock_{i}"
        site["nodes"].append({"id": dock, "floor": "F0", "x": -4.0, "y": 2.0 * i})
        site["edges"].append({"a": dock, "b": "entrance"})
        site["charging_stations"].append({"id": f"station_{i}", "node": dock})
        name = f"R{i}"
        site["robots"].append({"name": name, "token": robot_token(name), "start_node": dock})
    return site


def with_ports(site: dict[str, Any], ports: dict[str, int]) -> dict[str, Any]:
    """The site with its Modbus modules on the simulator's real ports."""
    for module in site["modules"]:
        module["port"] = ports[module["id"]]
    return site
