"""The route tables computed in worker processes: the same graph as one built in place, and a
worker that dies costs time, not the graph."""

from __future__ import annotations

import asyncio
import os
import random
import threading

import pytest

from backend.site.graph_build import build_site_graph, compute_in_processes
from backend.site.offloop import WORKER_NICE, in_processes
from guidebot.route_tables import compute_tables, split
from guidebot.site.graph import SiteGraph
from guidebot.site.synthetic import synthetic_site
from tests.server.workers import killing_new_workers, spawned_workers


def same_answers(ours: SiteGraph, reference: SiteGraph, pairs: int = 200) -> None:
    rng = random.Random(4)
    for _ in range(pairs):
        start, goal = rng.sample(reference.names, 2)
        assert ours.shortest_path(start, goal) == reference.shortest_path(start, goal)


def test_a_plan_split_over_worker_processes_gives_the_tables_computed_in_place() -> None:
    site = synthetic_site(nodes=600, robots=2, areas=2, pois=9, floors=3)
    plan = SiteGraph(site, tables=False).plan()
    assert len(split(plan, 4)) == 5  # the landmark chain, then stops and goals dealt out
    here = compute_tables(plan)
    there = asyncio.run(compute_in_processes(plan, 2))
    assert there.lm_from == here.lm_from and there.lm_to == here.lm_to
    assert there.transit == here.transit
    assert there.fields == here.fields and len(here.fields) == len(plan.goals) >= 9


@pytest.mark.skipif(not hasattr(os, "nice"), reason="POSIX priorities")
def test_workers_run_at_a_lower_priority_than_the_server() -> None:
    """A busy worker must not keep the server's loop waiting for a CPU."""
    (theirs,) = asyncio.run(in_processes(os.nice, [0], 1))  # os.nice(0): the current value
    assert theirs == min(os.nice(0) + WORKER_NICE, 19)


def test_a_site_graph_built_with_workers_answers_as_one_built_in_place() -> None:
    site = synthetic_site(nodes=600, robots=2, areas=2, pois=6, floors=3)
    built = asyncio.run(build_site_graph(site, 2, min_nodes=0))
    same_answers(built, SiteGraph(site))
    goal = site.pois[0].node
    assert (
        built.distances_to(goal)[site.nodes[0].id]
        == SiteGraph(site).distances_to(goal)[site.nodes[0].id]
    )


def test_a_killed_worker_falls_back_to_the_thread_and_the_graph_is_whole(
    caplog: pytest.LogCaptureFixture,
) -> None:
    site = synthetic_site(nodes=3000, robots=2, areas=2, pois=40, floors=3)

    built = asyncio.run(killing_new_workers(build_site_graph(site, 2, min_nodes=0)))
    assert "worker process failed" in caplog.text
    same_answers(built, SiteGraph(site), pairs=60)


def test_worker_processes_and_their_pools_thread_are_gone_when_the_call_returns() -> None:
    """in_processes waits for its pool to shut down: a worker still exiting (seconds on a loaded
    machine, being niced) kept the pool's thread alive after the call, past the suite's
    thread-leak check (tests/conftest.py)."""
    before = set(threading.enumerate())
    assert asyncio.run(in_processes(abs, [-1, -2], 2)) == [1, 2]
    assert spawned_workers() == set()
    assert [t.name for t in threading.enumerate() if t not in before and t.is_alive()] == []


def test_worker_processes_answer_in_the_order_asked_and_raise_what_the_work_raised() -> None:
    assert asyncio.run(in_processes(abs, [-1, -2, -3, -4, -5], 2)) == [1, 2, 3, 4, 5]
    assert asyncio.run(in_processes(abs, [], 2)) == []
    with pytest.raises(ValueError, match="invalid literal"):
        asyncio.run(in_processes(int, ["1", "x"], 2))
    assert spawned_workers() == set()
