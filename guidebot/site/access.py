"""Step-free tours (docs/visitor.md, "A step-free tour"): which stops a tour over no edge with
steps (``Edge.steps``) cannot reach, for ``guidebot site check`` and the visitor panel.

The robot guiding a step-free tour goes from each stop to the next over step-free paths only
(the Traffic Manager's ``get_path`` with ``step_free``); a stop no such path leads to from the
stop before is skipped, and the tour goes on from where it is. The same rule is followed here.
"""

from __future__ import annotations

from collections.abc import Container

from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site, Tour
from guidebot.site.validate import SiteIssue

__all__ = ["step_free_skips", "step_free_warnings"]


def step_free_skips(
    site: Site, graph: SiteGraph, tour: Tour, closed: Container[str] = frozenset()
) -> list[str]:
    """The points of ``tour`` a step-free tour skips (none when the site marks no steps). The
    first stop is where the visitor meets the robot: it is never skipped here. ``closed``: the
    nodes closed now (building modes): a stop whose step-free ways all cross them is skipped
    too; a stop closures cut off for every tour (only closed nodes lead there) is not the
    steps' doing and is not listed, and the tour goes on from the stop before, as it will."""
    if not graph.step_edges:
        return []
    skipped: list[str] = []
    here: str | None = None
    for poi_id in tour.points:
        poi = site.poi(poi_id)
        if poi is None or poi.node not in graph:
            continue
        if (
            here is not None
            and here != poi.node
            and graph.step_free_path(here, poi.node, closed) is None
        ):
            if not closed or graph.search(here, poi.node, closed) is not None:
                skipped.append(poi.id)
            continue
        here = poi.node
    return skipped


def step_free_warnings(site: Site) -> list[SiteIssue]:
    """Warnings (not errors): each stop of a tour that only steps lead to from the stop before."""
    if not any(e.steps for e in site.edges):
        return []
    graph = SiteGraph(site, warm=False, tables=False)
    return [
        SiteIssue(
            f"tours[{i}].points",
            f"a step-free tour of {tour.id!r} skips {poi!r}: only steps lead there",
        )
        for i, tour in enumerate(site.tours)
        for poi in step_free_skips(site, graph, tour)
    ]
