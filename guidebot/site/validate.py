"""Site checks beyond shapes: every reference must resolve, every id be unique.

All problems are collected and returned together, each with its place (a dotted path into the
document, and a line number when the site came from a YAML file).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from guidebot.site.building import IORef, PointKind
from guidebot.site.bulk import prevalidate
from guidebot.site.emergency import emergency_problems
from guidebot.site.io_rules import Role, kind_problem
from guidebot.site.schema import Site
from guidebot.task_kinds import KINDS, BadParams, UnknownTarget, check_params

__all__ = ["SiteInvalid", "SiteIssue", "cabin_through_ways", "check_references", "validate_site"]


@dataclass(frozen=True)
class SiteIssue:
    """One problem: where (``loc`` like ``edges[3].b``, ``line`` in the file) and what."""

    loc: str
    message: str
    line: int | None = None

    def __str__(self) -> str:
        where = f"line {self.line}: " if self.line is not None else ""
        return f"{where}{self.loc}: {self.message}"

    def as_dict(self) -> dict[str, Any]:
        return {"loc": self.loc, "msg": self.message, "line": self.line}


class SiteInvalid(ValueError):
    """A site refused as a whole; ``issues`` lists every problem found."""

    def __init__(self, issues: list[SiteIssue]) -> None:
        self.issues = issues
        lines = "\n".join(f"  {issue}" for issue in issues)
        super().__init__(f"site refused, {len(issues)} problem(s):\n{lines}")

    def file_lines(self, path: object) -> list[str]:
        """One ``file:line: loc: message`` line per problem (what editors jump to)."""
        return [f"{path}:{i.line or 0}: {i.loc}: {i.message}" for i in self.issues]


def format_loc(parts: Iterable[str | int]) -> str:
    out = ""
    for part in parts:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out or "(document)"


def validate_site(data: Any, *, lines: Any = None) -> Site:
    """Parse and check a site document; raises SiteInvalid with every problem.

    ``lines`` is an optional callable mapping a loc tuple to a line number.
    """

    def line_of(loc: tuple[str | int, ...]) -> int | None:
        return lines(loc) if lines is not None else None

    try:
        site = Site.model_validate(prevalidate(data))
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        issues = [
            SiteIssue(format_loc(err["loc"]), err["msg"], line_of(tuple(err["loc"])))
            for err in errors
        ]
        issues += [
            SiteIssue(format_loc(loc), msg, line_of(loc)) for loc, msg in _salvaged(data, errors)
        ]
        raise SiteInvalid(issues) from None
    problems = check_references(site)
    if problems:
        raise SiteInvalid([SiteIssue(format_loc(loc), msg, line_of(loc)) for loc, msg in problems])
    return site


def _salvaged(data: Any, errors: list[Any]) -> list[Problem]:
    """Reference problems among the items whose shape is sound, so one pass shows them too.

    Items with shape errors are left out; references to their ids are not reported (they
    exist, only broken), and item indexes are mapped back to the file's."""
    if not isinstance(data, dict):
        return []
    bad: dict[str, set[int]] = {}
    for err in errors:
        loc = err["loc"]
        if len(loc) >= 2 and isinstance(loc[1], int):
            bad.setdefault(str(loc[0]), set()).add(loc[1])
        elif loc:
            return []  # a whole section or top-level field is broken: nothing sound to check
    doc = dict(data)
    index_maps: dict[str, list[int]] = {}
    dropped_ids: set[str] = set()
    for section, indexes in bad.items():
        items = doc.get(section)
        if not isinstance(items, list):
            return []
        kept = [i for i in range(len(items)) if i not in indexes]
        for i in indexes:
            if i < len(items) and isinstance(items[i], dict):
                for key in ("id", "name"):
                    if isinstance(items[i].get(key), str):
                        dropped_ids.add(items[i][key])
        index_maps[section] = kept
        doc[section] = [items[i] for i in kept]
    try:
        site = Site.model_validate(doc)
    except ValidationError:
        return []
    out: list[Problem] = []
    for loc, msg in check_references(site):
        if any(f"'{x}'" in msg for x in dropped_ids):
            continue
        section = str(loc[0])
        if section in index_maps and len(loc) > 1 and isinstance(loc[1], int):
            loc = (section, index_maps[section][loc[1]], *loc[2:])
        out.append((loc, msg))
    return out


Problem = tuple[tuple[str | int, ...], str]


def _unique(items: list[Any], attr: str, section: str) -> list[Problem]:
    seen: set[str] = set()
    out: list[Problem] = []
    for i, item in enumerate(items):
        value = getattr(item, attr)
        if value in seen:
            out.append(((section, i, attr), f"duplicate {attr} {value!r}"))
        seen.add(value)
    return out


@dataclass(frozen=True)
class ThroughWay:
    """Edge ``edge`` (index in site.edges) joins ``cabin`` to a second landing ``other``."""

    edge: int
    elevator: str
    cabin: str
    landing: str
    other: str


def cabin_through_ways(site: Site) -> list[ThroughWay]:
    """Edges that would let a path cross an elevator's cabin node without riding.

    A cabin node has ONE landing on its floor (the first edge that joins it to a node that is
    not a stop of its elevator); every further edge to another node makes the cabin a shortcut
    between two landings. The site check refuses these edges and the planner never uses them.
    """
    cabin_of = {stop.node: el.id for el in site.elevators for stop in el.stops}
    landing: dict[str, str] = {}
    out: list[ThroughWay] = []
    for i, e in enumerate(site.edges):
        for cabin, other in ((e.a, e.b), (e.b, e.a)):
            elevator = cabin_of.get(cabin)
            if elevator is None or cabin_of.get(other) == elevator:
                continue
            first = landing.setdefault(cabin, other)
            if first != other:
                out.append(ThroughWay(i, elevator, cabin, first, other))
    return out


def check_references(site: Site) -> list[Problem]:
    """Every cross reference of the site; returns (loc, message) pairs, empty when sound."""
    p: list[Problem] = []
    for section, attr in (
        ("floors", "id"),
        ("nodes", "id"),
        ("pois", "id"),
        ("tours", "id"),
        ("charging_stations", "id"),
        ("wait_points", "id"),
        ("areas", "id"),
        ("doors", "id"),
        ("elevators", "id"),
        ("modules", "id"),
        ("buttons", "id"),
        ("robots", "name"),
    ):
        p += _unique(getattr(site, section), attr, section)
    floors = {f.id for f in site.floors}
    nodes = {n.id: n for n in site.nodes}
    pois = {poi.id for poi in site.pois}

    def node_ref(loc: tuple[str | int, ...], node: str | None) -> None:
        if node is not None and node not in nodes:
            p.append((loc, f"unknown node {node!r}"))

    for i, n in enumerate(site.nodes):
        if n.floor not in floors:
            p.append((("nodes", i, "floor"), f"unknown floor {n.floor!r}"))
    seen_edges: set[tuple[str, str]] = set()
    for i, e in enumerate(site.edges):
        node_ref(("edges", i, "a"), e.a)
        node_ref(("edges", i, "b"), e.b)
        if e.a == e.b:
            p.append((("edges", i), "an edge must join two different nodes"))
        elif e.a in nodes and e.b in nodes:
            if nodes[e.a].floor != nodes[e.b].floor:
                p.append((("edges", i), "an edge joins nodes of one floor; use an elevator"))
            key = (min(e.a, e.b), max(e.a, e.b))
            if key in seen_edges:
                p.append((("edges", i), f"duplicate edge {e.a}-{e.b}"))
            seen_edges.add(key)
    for i, poi in enumerate(site.pois):
        node_ref(("pois", i, "node"), poi.node)
    for i, t in enumerate(site.tours):
        for j, point in enumerate(t.points):
            if point not in pois:
                p.append((("tours", i, "points", j), f"unknown point of interest {point!r}"))
    for section in ("charging_stations", "wait_points"):
        for i, item in enumerate(getattr(site, section)):
            node_ref((section, i, "node"), item.node)
    in_area: dict[str, str] = {}
    for i, a in enumerate(site.areas):
        for j, node in enumerate(a.nodes):
            node_ref(("areas", i, "nodes", j), node)
            if node in in_area and in_area[node] != a.id:
                p.append(
                    (("areas", i, "nodes", j), f"node {node!r} is already in area {in_area[node]}")
                )
            in_area[node] = a.id
        node_ref(("areas", i, "passing_place"), a.passing_place)
        if a.passing_place is not None and a.passing_place in a.nodes:
            p.append((("areas", i, "passing_place"), "a passing place must lie outside its area"))

    points = {(m.id, pt.name): pt.kind for m in site.modules for pt in m.points}

    def io_ref(loc: tuple[str | int, ...], ref: IORef | None, role: Role) -> None:
        if ref is None:
            return
        kind = points.get((ref.module, ref.point))
        if kind is None:
            p.append((loc, f"unknown building point {ref.module!r}/{ref.point!r}"))
            return
        problem = kind_problem(role, kind, f"{ref.module}/{ref.point}")
        if problem is not None:
            p.append((loc, problem))

    for i, m in enumerate(site.modules):
        p += [(("modules", i, *loc), msg) for loc, msg in _unique(m.points, "name", "points")]
        seen_addr: set[tuple[PointKind, int]] = set()
        for j, pt in enumerate(m.points):
            node_ref(("modules", i, "points", j, "node"), pt.node)
            if (pt.kind, pt.address) in seen_addr:
                p.append(
                    (
                        ("modules", i, "points", j, "address"),
                        f"address {pt.address} used twice for {pt.kind}",
                    )
                )
            seen_addr.add((pt.kind, pt.address))
        ports = [(mm.host, mm.port) for mm in site.modules[:i] if mm.port != 0]
        if m.port != 0 and (m.host, m.port) in ports:
            p.append((("modules", i, "port"), f"{m.host}:{m.port} used by another module"))
    for i, d in enumerate(site.doors):
        node_ref(("doors", i, "node"), d.node)
        io_ref(("doors", i, "open"), d.open, Role.door_open)
        io_ref(("doors", i, "is_open"), d.is_open, Role.door_is_open)
    for i, el in enumerate(site.elevators):
        seen_floors: set[str] = set()
        for j, stop in enumerate(el.stops):
            if stop.floor not in floors:
                p.append((("elevators", i, "stops", j, "floor"), f"unknown floor {stop.floor!r}"))
            if stop.floor in seen_floors:
                p.append((("elevators", i, "stops", j, "floor"), "two stops on one floor"))
            seen_floors.add(stop.floor)
            node_ref(("elevators", i, "stops", j, "node"), stop.node)
            if stop.node in nodes and nodes[stop.node].floor != stop.floor:
                loc = ("elevators", i, "stops", j, "node")
                p.append((loc, f"node {stop.node!r} is on another floor"))
            io_ref(("elevators", i, "stops", j, "call"), stop.call, Role.elevator_call)
            io_ref(
                ("elevators", i, "stops", j, "in_position"),
                stop.in_position,
                Role.elevator_in_position,
            )
    for way in cabin_through_ways(site):
        p.append(
            (
                ("edges", way.edge),
                f"makes cabin node {way.cabin!r} of elevator {way.elevator} a through-way:"
                f" a cabin has one landing ({way.landing!r}); join {way.other!r} to"
                f" {way.landing!r} instead",
            )
        )
    for i, b in enumerate(site.buttons):
        node_ref(("buttons", i, "node"), b.node)
        io_ref(("buttons", i, "input"), b.input, Role.button_input)
        io_ref(("buttons", i, "led"), b.led, Role.button_led)
        # the checks a request of this kind meets at the Task Manager (guidebot.task_kinds)
        where = ("buttons", i, "task", "params")
        try:
            params = check_params(b.task.kind, b.task.params)
            KINDS[b.task.kind].target(site, params, nodes)
        except BadParams as exc:
            p.append((where, str(exc)))
        except UnknownTarget as exc:
            p.append(((*where, exc.param), str(exc)))
    for i, r in enumerate(site.robots):
        node_ref(("robots", i, "start_node"), r.start_node)
        if r.battery_panic > r.battery_low:
            p.append((("robots", i, "battery_panic"), "must not exceed battery_low"))
        if r.interface == "vda5050":
            for field, value in (
                ("manufacturer", r.manufacturer),
                ("serial_number", r.serial_number),
            ):
                if value is None:
                    p.append((("robots", i, field), "a VDA 5050 robot needs it (its MQTT topics)"))
        for floor in r.map_ids:
            if floor not in floors:
                p.append((("robots", i, "map_ids", floor), f"unknown floor {floor!r}"))
    p += emergency_problems(site, {key: kind.value for key, kind in points.items()})
    return p
