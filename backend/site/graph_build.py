"""The route graph of a site, built while the server keeps serving.

The graph's structure is built in a thread (``off_loop``); its tables (hundreds of Dijkstra
searches, seconds of plain Python on a 10 000-node site) are computed in worker processes on
large sites (``in_processes``). In a thread they would share the GIL with the event loop for
all those seconds: every message to a robot or a GUI would wait for the hand-over (1 ms at a
time, longer when the machine is busy). The workers are started for one build and stopped
after it, so an idle server runs no extra process. Should a worker fail (killed, out of
memory), the tables are computed in a thread instead: slower for the loop, same graph.
"""

from __future__ import annotations

import logging
import os
from concurrent.futures.process import BrokenProcessPool

from backend.site.offloop import in_processes, off_loop
from guidebot.route_tables import TablePlan, Tables, compute_tables, merge, split
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site

__all__ = ["PROCESS_MIN_NODES", "build_site_graph", "compute_in_processes"]

log = logging.getLogger(__name__)

PROCESS_MIN_NODES = 2000
"""Sites with fewer nodes build their tables in the thread: starting a worker (about 0.2 s)
costs more than the searches."""


async def build_site_graph(
    site: Site, workers: int = 2, *, min_nodes: int = PROCESS_MIN_NODES
) -> SiteGraph:
    """The site's SiteGraph, tables included, built off the event loop (``workers``: worker
    processes for the tables of a site of ``min_nodes`` nodes or more, at most one per CPU;
    0 computes them in the thread)."""
    workers = min(workers, os.cpu_count() or 1)
    if workers < 1 or len(site.nodes) < min_nodes:
        return await off_loop(SiteGraph, site)
    graph, plan = await off_loop(_structure, site)
    try:
        tables = await compute_in_processes(plan, workers)
    except (BrokenProcessPool, OSError) as exc:
        log.warning("route tables: worker process failed (%s); computing in a thread", exc)
        tables = await off_loop(compute_tables, plan)
    graph.install(tables)
    return graph


def _structure(site: Site) -> tuple[SiteGraph, TablePlan]:
    graph = SiteGraph(site, tables=False)
    return graph, graph.plan()


async def compute_in_processes(plan: TablePlan, workers: int) -> Tables:
    """``compute_tables(plan)``, split over ``workers`` new processes."""
    return merge(await in_processes(compute_tables, split(plan, 2 * workers), workers))
