"""VDA 5050 3.0.0 zones: one zone set per floor (map) with the site's restricted areas as
``RELEASE`` zones, what is closed as ``BLOCKED``, steps as ``SPEED_LIMIT``, doors and lifts as
``LINE_GUIDED``; and the ``responses`` that answer a vehicle's zone requests (docs/vda5050.md,
"Zones"). Pure functions, no bus, no broker."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from guidebot.site.schema import Site
from guidebot.vda5050.topics import Vehicle

__all__ = [
    "MARGIN_M",
    "STEPS_SPEED_MPS",
    "ZONE_TYPES",
    "Box",
    "area_boxes",
    "inside",
    "responses",
    "zone_sets",
]

MARGIN_M = 1.0
"""A zone is the rectangle around its area's nodes, this much wider on every side: a vehicle
asks before it reaches the area's first node."""


Box = tuple[float, float, float, float]
"""(x0, y0, x1, y1) on one floor's map."""


def area_boxes(site: Site) -> dict[tuple[str, str], Box]:
    """(area, floor) -> the rectangle around the area's nodes on that floor, ``MARGIN_M``
    wider on every side: the area's extent on the map, as its zone says it to a 3.x vehicle,
    and where a vehicle seen inside it is taken to be in it (docs/vda5050.md)."""
    floor_of = {n.id: n.floor for n in site.nodes}
    xy = {n.id: (n.x, n.y) for n in site.nodes}
    out: dict[tuple[str, str], Box] = {}
    for area in site.areas:
        for floor in {floor_of[n] for n in area.nodes if n in floor_of}:
            points = [xy[n] for n in area.nodes if floor_of.get(n) == floor]
            out[(area.id, floor)] = (
                min(p[0] for p in points) - MARGIN_M,
                min(p[1] for p in points) - MARGIN_M,
                max(p[0] for p in points) + MARGIN_M,
                max(p[1] for p in points) + MARGIN_M,
            )
    return out


def inside(box: Box, x: float, y: float) -> bool:
    x0, y0, x1, y1 = box
    return x0 <= x <= x1 and y0 <= y <= y1


ZONE_TYPES = ("RELEASE", "BLOCKED", "SPEED_LIMIT", "LINE_GUIDED")
"""The 3.0.0 zone types GuideBot's site gives (docs/vda5050.md, "Zones"); the others
(COORDINATED_REPLANNING, ACTION, PRIORITY, PENALTY, DIRECTED, BIDIRECTED) have no counterpart:
the Traffic Manager plans every path and a tour stop is an action at its node."""
STEPS_SPEED_MPS = 0.3
"""SPEED_LIMIT on an edge with steps or a slope (the site's ``steps``): the speed a vehicle
keeps there."""
RELEASE_LOSS = "STOP"
"""A RELEASE zone's ``releaseLossBehavior``: a vehicle inside a zone whose grant is revoked
(fire alarm, closure, staff release) stops where it is and says so (the spec's default, said
out loud): nobody is sure the way out is free."""


def _rectangle(box: Box) -> list[dict[str, float]]:
    x0, y0, x1, y1 = box
    return [{"x": x, "y": y} for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]


def _around(x: float, y: float) -> Box:
    return (x - MARGIN_M, y - MARGIN_M, x + MARGIN_M, y + MARGIN_M)


def _along(a: tuple[float, float], b: tuple[float, float]) -> list[dict[str, float]]:
    """The rectangle along the edge a-b, ``MARGIN_M`` beyond its ends and on each side,
    counterclockwise."""
    length = math.dist(a, b)
    if length == 0:
        return _rectangle(_around(*a))
    dx, dy = (b[0] - a[0]) / length, (b[1] - a[1]) / length
    nx, ny = -dy, dx
    m = MARGIN_M
    p = (a[0] - dx * m, a[1] - dy * m)
    q = (b[0] + dx * m, b[1] + dy * m)
    corners = (
        (p[0] - nx * m, p[1] - ny * m),
        (q[0] - nx * m, q[1] - ny * m),
        (q[0] + nx * m, q[1] + ny * m),
        (p[0] + nx * m, p[1] + ny * m),
    )
    return [{"x": round(x, 6), "y": round(y, 6)} for x, y in corners]


def zone_sets(
    site: Site,
    map_ids: Mapping[str, str],
    *,
    closed: Collection[str] = (),
    supported: Collection[str] | None = None,
) -> dict[str, dict[str, Any]]:
    """Floor id -> its zone set ({mapId, zoneSetId, zoneSetDescriptor, zones}):
    - ``RELEASE``: each restricted area (zoneId the area's id), asked for through the lock
      table (``releaseLossBehavior`` STOP);
    - ``BLOCKED``: what is closed to robots now (``closed``: the closed nodes; a closed
      area's whole extent, zoneId ``closed:<area>``; any other node, ``closed:<node>``);
    - ``SPEED_LIMIT``: each edge with steps (``steps:<a>:<b>``, STEPS_SPEED_MPS);
    - ``LINE_GUIDED``: each door's node and each elevator stop (``door:<id>``,
      ``lift:<id>:<node>``): through a doorway or into a cabin a vehicle follows its edge.
    Only the zone types in ``supported`` (the vehicle's factsheet), when given. The
    zoneSetId ends with a digest of the zones: a changed set gets a new id (a vehicle
    refuses a set whose id it already has)."""
    boxes = area_boxes(site)
    floor_of = {n.id: n.floor for n in site.nodes}
    xy = {n.id: (n.x, n.y) for n in site.nodes}
    closed_set = set(closed)
    out: dict[str, dict[str, Any]] = {}
    for floor in site.floors:
        zones: list[dict[str, Any]] = []
        covered: set[str] = set()
        for area in site.areas:
            if (area.id, floor.id) not in boxes:
                continue
            vertices = _rectangle(boxes[(area.id, floor.id)])
            zones.append(
                {
                    "zoneId": area.id,
                    "zoneType": "RELEASE",
                    "zoneDescriptor": f"GuideBot restricted area {area.id}",
                    "vertices": vertices,
                    "releaseLossBehavior": RELEASE_LOSS,
                }
            )
            if closed_set & set(area.nodes):
                covered.update(area.nodes)
                zones.append(
                    {
                        "zoneId": f"closed:{area.id}",
                        "zoneType": "BLOCKED",
                        "zoneDescriptor": f"GuideBot: area {area.id} closed to robots",
                        "vertices": vertices,
                    }
                )
        for node in sorted(closed_set - covered):
            if floor_of.get(node) == floor.id:
                zones.append(
                    {
                        "zoneId": f"closed:{node}",
                        "zoneType": "BLOCKED",
                        "zoneDescriptor": f"GuideBot: node {node} closed to robots",
                        "vertices": _rectangle(_around(*xy[node])),
                    }
                )
        for edge in site.edges:
            if edge.steps and floor_of.get(edge.a) == floor_of.get(edge.b) == floor.id:
                zones.append(
                    {
                        "zoneId": f"steps:{edge.a}:{edge.b}",
                        "zoneType": "SPEED_LIMIT",
                        "zoneDescriptor": f"GuideBot: steps between {edge.a} and {edge.b}",
                        "vertices": _along(xy[edge.a], xy[edge.b]),
                        "maximumSpeed": STEPS_SPEED_MPS,
                    }
                )
        guided = [(f"door:{d.id}", d.node) for d in site.doors]
        guided += [(f"lift:{e.id}:{s.node}", s.node) for e in site.elevators for s in e.stops]
        for zone_id, node in guided:
            if floor_of.get(node) == floor.id:
                zones.append(
                    {
                        "zoneId": zone_id,
                        "zoneType": "LINE_GUIDED",
                        "zoneDescriptor": f"GuideBot: {zone_id.split(':')[0]} at {node}",
                        "vertices": _rectangle(_around(*xy[node])),
                    }
                )
        if supported is not None:
            zones = [z for z in zones if z["zoneType"] in supported]
        if not zones:
            continue
        map_id = map_ids.get(floor.id, floor.id)
        digest = hashlib.sha256(json.dumps([map_id, zones], sort_keys=True).encode()).hexdigest()
        out[floor.id] = {
            "mapId": map_id,
            "zoneSetId": f"guidebot-{floor.id}-{digest[:12]}",
            "zoneSetDescriptor": f"GuideBot zones, {floor.name}",
            "zones": zones,
        }
    return out


def responses(
    vehicle: Vehicle, header_id: int, answers: Sequence[tuple[str, str]]
) -> dict[str, Any]:
    """``responses`` of (requestId, grantType) pairs: GRANTED, QUEUED, REVOKED, REJECTED."""
    return {
        **vehicle.header(header_id),
        "responses": [{"requestId": r, "grantType": g} for r, g in answers],
    }
