"""The site's ``emergency`` part: fire alarm inputs, safe spots, escape routes and their words.

Models only, plus the checks ``guidebot site check`` runs on them (``emergency_problems``):
the server's EmergencyService (backend/emergency) and the robots read the same models, so a
site the checker accepts is one every part can act on when the alarm sounds (docs/emergency.md).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable
from typing import TYPE_CHECKING, Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

from guidebot.site.building import ID_PATTERN, IORef

if TYPE_CHECKING:
    from guidebot.site.schema import Site

__all__ = [
    "Alarm",
    "AlarmZone",
    "Emergency",
    "emergency_problems",
    "nearest_safe_spot",
    "safety_table",
    "zone_nodes",
]

Id = Annotated[str, Field(min_length=1, max_length=64, pattern=ID_PATTERN)]
LANG = r"^[a-z]{2,3}(-[A-Za-z0-9]{2,8})?$"
SourceHash = Annotated[str, Field(pattern=r"^[0-9a-f]{16}$")]
"""The first 16 hex digits of the SHA-256 of a source text (UTF-8): what a translation was
made from, so that an editor can tell it is older than its source (docs/config.md,
"Translations")."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class AlarmZone(_Strict):
    """Where an alarm holds: ``{}`` the whole site, else the given floors or restricted areas."""

    floors: list[Id] = Field(default_factory=list)
    areas: list[Id] = Field(default_factory=list)

    @model_validator(mode="after")
    def _one_kind(self) -> AlarmZone:
        if self.floors and self.areas:
            raise ValueError("a zone is floors or areas, not both")
        return self

    @property
    def whole_site(self) -> bool:
        return not self.floors and not self.areas

    def describe(self) -> str:
        if self.floors:
            return "floors " + ", ".join(self.floors)
        if self.areas:
            return "areas " + ", ".join(self.areas)
        return "whole site"


class Alarm(_Strict):
    """One fire alarm input (a relay wired to a Modbus input point, role ``fire_alarm``)."""

    id: Id
    input: IORef
    active_when: int = Field(default=1, ge=0, le=1)
    """The value that means "alarm"; 0 for a relay's normally-closed contact (a cut wire alarms)."""
    zone: AlarmZone = Field(default_factory=AlarmZone)


class Emergency(_Strict):
    """What an emergency means on this site (docs/emergency.md)."""

    alarms: list[Alarm] = Field(default_factory=list)
    safe_spots: list[Id] = Field(default_factory=list)
    """Nodes where a robot waits out an alarm, out of everyone's way."""
    escape_routes: list[Id] = Field(default_factory=list)
    """Restricted-area ids robots must leave at once and not enter while an alarm lasts."""
    words: dict[Annotated[str, Field(pattern=LANG)], str] = Field(default_factory=dict)
    """What robots say and pages show, per language."""
    words_source_hash: dict[Annotated[str, Field(pattern=LANG)], SourceHash] = Field(
        default_factory=dict
    )
    """Per language but the default: the hash of the default language's words it was translated
    from (none: taken as current)."""

    def words_in(self, lang: str | None, default: str = "en") -> str:
        """The words in ``lang``, else the site's default language, else any."""
        for key in (lang, default):
            if key and key in self.words:
                return self.words[key]
        return next(iter(self.words.values()), "Fire alarm. Please follow the exit signs.")


def zone_nodes(site: Site, zone: AlarmZone) -> set[str]:
    """The node ids an alarm zone holds."""
    if zone.floors:
        floors = set(zone.floors)
        return {n.id for n in site.nodes if n.floor in floors}
    if zone.areas:
        areas = set(zone.areas)
        return {node for a in site.areas if a.id in areas for node in a.nodes}
    return {n.id for n in site.nodes}


def _walk_edges(site: Site) -> dict[str, list[tuple[str, float]]]:
    """Adjacency over the site's corridors only (no elevator ride), reversed for a search
    from the safe spots: ``out[b]`` lists ``(a, length)`` for every edge a robot drives a->b."""
    pos = {n.id: n for n in site.nodes}
    out: dict[str, list[tuple[str, float]]] = {n.id: [] for n in site.nodes}
    for e in site.edges:
        if e.a not in pos or e.b not in pos:
            continue
        a, b = pos[e.a], pos[e.b]
        length = e.length_m or ((a.x - b.x) ** 2 + (a.y - b.y) ** 2) ** 0.5 or 0.01
        out[e.b].append((e.a, length))
        if not e.one_way:
            out[e.a].append((e.b, length))
    return out


def _to_safety(
    site: Site, spots: Iterable[str], avoid: set[str]
) -> dict[str, tuple[float, str, str | None]]:
    """For every node: (distance, safe spot, next node) of its nearest safe spot without an
    elevator, entering no node of ``avoid`` (a robot already inside may still leave it)."""
    back = _walk_edges(site)
    best: dict[str, tuple[float, str, str | None]] = {}
    heap: list[tuple[float, str, str, str | None]] = [(0.0, s, s, None) for s in spots if s in back]
    heapq.heapify(heap)
    while heap:
        d, node, spot, nxt = heapq.heappop(heap)
        if node in best:
            continue
        best[node] = (d, spot, nxt)
        for prev, length in back[node]:
            # a robot at ``prev`` may drive into ``node`` unless node is in an escape route
            if prev not in best and (node not in avoid or node == spot):
                heapq.heappush(heap, (d + length, prev, spot, node))
    return best


def escape_nodes(site: Site, emergency: Emergency) -> set[str]:
    routes = set(emergency.escape_routes)
    return {node for a in site.areas if a.id in routes for node in a.nodes}


def closed_nodes(site: Site, emergency: Emergency) -> set[str]:
    """What a way to safety never enters: escape routes, and automatic doors (fire doors
    close in an alarm and the BuildingInterface opens none in its zone)."""
    return escape_nodes(site, emergency) | {d.node for d in site.doors}


SafetyTable = dict[str, tuple[float, str, str | None]]
"""node -> (distance, its nearest safe spot, the next node on the way there)."""


def safety_table(site: Site, emergency: Emergency) -> SafetyTable:
    """One search from every safe spot at once, for every robot's way (``nearest_safe_spot``):
    compute it once per site and alarm, not once per robot."""
    return _to_safety(site, emergency.safe_spots, closed_nodes(site, emergency))


def nearest_safe_spot(
    site: Site, emergency: Emergency, start: str, table: SafetyTable | None = None
) -> list[str] | None:
    """The path (start first, safe spot last) to the nearest safe spot without an elevator,
    entering no escape route and no door node (leaving one the robot stands on by the shortest
    way); None when there is no such way. ``table``: ``safety_table`` of the same site."""
    if table is None:
        table = safety_table(site, emergency)
    if start not in table:
        return None
    path = [start]
    while (step := table[path[-1]][2]) is not None:
        path.append(step)
    return path


Problem = tuple[tuple[str | int, ...], str]


def emergency_problems(site: Site, points: dict[tuple[str, str], str]) -> list[Problem]:
    """What ``guidebot site check`` refuses in the emergency part (locs under ``emergency``).

    ``points`` maps (module, point) to the point's kind, as the building check reads them."""
    from guidebot.site.io_rules import Role, kind_problem

    em = site.emergency
    if em is None:
        return []
    p: list[Problem] = []
    floors = {f.id for f in site.floors}
    nodes = {n.id: n for n in site.nodes}
    areas = {a.id for a in site.areas}
    seen: set[str] = set()
    for i, alarm in enumerate(em.alarms):
        loc = ("emergency", "alarms", i)
        if alarm.id in seen:
            p.append(((*loc, "id"), f"duplicate id {alarm.id!r}"))
        seen.add(alarm.id)
        ref = alarm.input
        kind = points.get((ref.module, ref.point))
        if kind is None:
            known = sorted({m for m, _ in points})
            p.append(
                (
                    (*loc, "input"),
                    f"unknown building point {ref.module!r}/{ref.point!r}"
                    f" (modules: {', '.join(known) or 'none'})",
                )
            )
        elif problem := kind_problem(Role.fire_alarm, kind, f"{ref.module}/{ref.point}"):
            p.append(((*loc, "input"), problem))
        for j, floor in enumerate(alarm.zone.floors):
            if floor not in floors:
                p.append(((*loc, "zone", "floors", j), f"unknown floor {floor!r}"))
        for j, area in enumerate(alarm.zone.areas):
            if area not in areas:
                p.append(((*loc, "zone", "areas", j), f"unknown area {area!r}"))
    escape = escape_nodes(site, em)
    for j, route in enumerate(em.escape_routes):
        if route not in areas:
            p.append((("emergency", "escape_routes", j), f"unknown area {route!r}"))
    for j, spot in enumerate(em.safe_spots):
        loc = ("emergency", "safe_spots", j)
        if spot not in nodes:
            p.append((loc, f"safe spot {spot!r} is not a node of the site"))
        elif spot in escape:
            p.append((loc, f"safe spot {spot!r} lies in an escape route"))
        elif door := next((d.id for d in site.doors if d.node == spot), None):
            p.append((loc, f"safe spot {spot!r} is the node of door {door}: robots would block it"))
    for lang in em.words:
        if lang != site.default_language and lang not in site.languages:
            p.append((("emergency", "words", lang), f"language {lang!r} is not offered"))
    if site.default_language not in em.words:
        p.append(
            (("emergency", "words"), f"no words in the default language {site.default_language!r}")
        )
    if all(e.a in nodes and e.b in nodes for e in site.edges):  # else the graph is reported
        p += _floors_without_safety(site, em, closed_nodes(site, em))
    return p


def _floors_without_safety(site: Site, em: Emergency, closed: set[str]) -> list[Problem]:
    """A floor where robots live (start node, charging station, wait point) must reach a safe
    spot from every node an edge joins (a robot can be there) without an elevator, a door or
    an escape route."""
    floor_of = {n.id: n.floor for n in site.nodes}
    lived = {
        floor_of[node]
        for node in (
            *(r.start_node for r in site.robots if r.start_node),
            *(c.node for c in site.charging_stations),
            *(w.node for w in site.wait_points),
        )
        if node in floor_of
    }
    table = _to_safety(site, [s for s in em.safe_spots if s in floor_of], closed)
    joined = {node for e in site.edges for node in (e.a, e.b)}  # a node no edge joins: no robot
    p: list[Problem] = []
    for i, floor in enumerate(site.floors):
        if floor.id not in lived:
            continue
        cut = [
            n.id for n in site.nodes if n.floor == floor.id and n.id not in table and n.id in joined
        ]
        if cut:
            shown = ", ".join(cut[:5]) + (f" and {len(cut) - 5} more" if len(cut) > 5 else "")
            p.append(
                (
                    ("floors", i),
                    f"floor {floor.id} has robots but no safe spot reachable without an"
                    f" elevator, a door or an escape route from {shown}",
                )
            )
    return p
