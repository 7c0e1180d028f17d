"""Where a task starts on the site and what its robot's net is given: pure functions of the
site, the graph and the task (no bus, no clock), shared by the Task Manager's checks, its
assignment and the visitor estimates (backend/tasks/eta.py)."""

from __future__ import annotations

from typing import Any

from backend.tasks.model import InvalidTask, Task
from guidebot.site.access import STEPS_REASON, first_stops_skipped, graph_of, steps_only_nodes
from guidebot.site.graph import SiteGraph
from guidebot.site.i18n import poi_texts, resolve_language
from guidebot.site.schema import Site
from guidebot.task_kinds import KINDS, UnknownTarget

__all__ = ["net_params", "target_node"]


def target_node(site: Site, graph: SiteGraph, kind: str, params: dict[str, Any]) -> str:
    """Where a ``kind`` task starts (for path cost); raises InvalidTask if ``params`` name
    what the site does not have."""
    spec = KINDS.get(kind)
    if spec is None:
        raise InvalidTask(f"unknown task kind {kind!r} (expected one of {sorted(KINDS)})")
    try:
        node = spec.target(site, params, graph)
    except UnknownTarget as exc:
        raise InvalidTask(str(exc)) from None
    return _step_free_target(site, graph, kind, params, node) if params.get("step_free") else node


def _step_free_target(
    site: Site, graph: SiteGraph, kind: str, params: dict[str, Any], node: str
) -> str:
    """A step-free visit starts where the visitor can come without steps (guidebot/site/
    access.py): a tour at its first such stop; a point only steps lead to is refused."""
    if kind == "go_to_poi" and node in steps_only_nodes(graph):
        raise InvalidTask(f"only steps lead to point {params['poi']!r}: no step-free visit")
    tour = site.tour(str(params.get("tour"))) if kind == "tour" else None
    if tour is None:
        return node
    skipped = len(first_stops_skipped(site, graph, tour))
    stops = [q for q in (site.poi(i) for i in tour.points[skipped:]) if q is not None]
    if not stops:
        raise InvalidTask(f"only steps lead to every stop of tour {tour.id!r}: no step-free tour")
    return stops[0].node


def net_params(site: Site, task: Task) -> dict[str, Any]:
    """Everything the robot's net needs (nodes, texts in the visitor's language), so it never
    asks back. The task's parameters were checked against this site (``target_node``)."""
    p = task.params
    lang = resolve_language(site, p.get("lang"))
    # The visitor's needs, which its robot follows from the first stop on: a slower tour
    # (guidebot/pace.py), a step-free one (robot_agent/visitor_needs.py).
    needs: dict[str, Any] = {"pace": p["pace"]} if p.get("pace") not in (None, "normal") else {}
    if task.kind in ("tour", "go_to_poi") and p.get("step_free"):
        needs["step_free"] = True
    if task.kind == "tour":
        tour = site.tour(p["tour"])
        assert tour is not None
        pois = [q for q in (site.poi(i) for i in tour.points) if q is not None]
        points = [
            {"poi": q.id, "node": q.node, "index": i, "total": len(pois)} | poi_texts(site, q, lang)
            for i, q in enumerate(pois, start=1)
        ]
        if needs.get("step_free"):  # its first stops only steps lead to: the visitor is told
            lead = len(first_stops_skipped(site, graph_of(site), tour))
            needs["skipped"] = [
                {"index": q["index"], "poi": q["poi"], "name": q["name"], "reason": STEPS_REASON}
                for q in points[:lead]
            ]
            points = points[lead:]
        return {"tour": tour.id, "points": points, "lang": lang} | needs
    if task.kind == "go_to_poi":
        poi = site.poi(p["poi"])
        assert poi is not None
        texts = poi_texts(site, poi, lang)
        return {
            "poi": poi.id,
            "node": poi.node,
            "text": texts["text"],
            "lang": texts["lang"],
        } | needs
    if task.kind == "charge":
        station = p.get("station") or site.charging_stations[0].id
        node = next(s.node for s in site.charging_stations if s.id == station)
        return {"station": station, "node": node}
    return {"node": p["node"]}
