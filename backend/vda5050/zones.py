"""VDA 5050 3.0.0 zones: the site's restricted areas as ``RELEASE`` zones, one zone set per
floor (map), and the ``responses`` that answer a vehicle's zone requests (docs/vda5050.md,
"Zones"). Pure functions, no bus, no broker."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

from guidebot.site.schema import Site
from guidebot.vda5050.topics import Vehicle

__all__ = ["MARGIN_M", "responses", "zone_sets"]

MARGIN_M = 1.0
"""A zone is the rectangle around its area's nodes, this much wider on every side: a vehicle
asks before it reaches the area's first node."""


def zone_sets(site: Site, map_ids: Mapping[str, str]) -> dict[str, dict[str, Any]]:
    """Floor id -> its zone set ({mapId, zoneSetId, zoneSetDescriptor, zones}) with one
    ``RELEASE`` zone per restricted area on that floor (zoneId the area's id). The zoneSetId
    ends with a digest of the zones: a changed set gets a new id (a vehicle refuses a set
    whose id it already has)."""
    floor_of = {n.id: n.floor for n in site.nodes}
    xy = {n.id: (n.x, n.y) for n in site.nodes}
    out: dict[str, dict[str, Any]] = {}
    for floor in site.floors:
        zones = []
        for area in site.areas:
            points = [xy[n] for n in area.nodes if floor_of.get(n) == floor.id]
            if not points:
                continue
            x0, x1 = min(p[0] for p in points) - MARGIN_M, max(p[0] for p in points) + MARGIN_M
            y0, y1 = min(p[1] for p in points) - MARGIN_M, max(p[1] for p in points) + MARGIN_M
            zones.append(
                {
                    "zoneId": area.id,
                    "zoneType": "RELEASE",
                    "zoneDescriptor": f"GuideBot restricted area {area.id}",
                    "vertices": [
                        {"x": x, "y": y} for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
                    ],
                }
            )
        if not zones:
            continue
        map_id = map_ids.get(floor.id, floor.id)
        digest = hashlib.sha256(json.dumps([map_id, zones], sort_keys=True).encode()).hexdigest()
        out[floor.id] = {
            "mapId": map_id,
            "zoneSetId": f"guidebot-{floor.id}-{digest[:12]}",
            "zoneSetDescriptor": f"GuideBot restricted areas, {floor.name}",
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
