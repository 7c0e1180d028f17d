"""Synthetic sites of any size, for benchmarks and load tests: floors of corridor grids joined
by elevators, points of interest, tours, stations, single-node restricted areas and robots."""

from __future__ import annotations

import math
import random
from typing import Any

from guidebot.site.schema import Site
from guidebot.site.validate import validate_site

__all__ = ["synthetic_site"]


def synthetic_site(
    *,
    nodes: int = 10_000,
    robots: int = 100,
    areas: int = 100,
    pois: int = 100,
    floors: int | None = None,
    spacing_m: float = 2.0,
    seed: int = 1,
) -> Site:
    """A valid site with about ``nodes`` nodes (rounded to full grids)."""
    rng = random.Random(seed)
    floors = floors or max(1, round(nodes / 2500))
    side = max(2, math.ceil(math.sqrt(nodes / floors)))
    node_ids: list[str] = []
    doc_nodes: list[dict[str, Any]] = []
    edges: list[dict[str, Any]] = []
    for f in range(floors):
        for i in range(side):
            for j in range(side):
                nid = f"n{f}_{i}_{j}"
                node_ids.append(nid)
                doc_nodes.append(
                    {
                        "id": nid,
                        "floor": f"F{f}",
                        "x": i * spacing_m,
                        "y": j * spacing_m,
                        "passing_place": (i + j) % 7 == 0,
                    }
                )
                length = spacing_m * (1.0 + rng.random() * 0.5)
                if i + 1 < side:
                    edges.append({"a": nid, "b": f"n{f}_{i + 1}_{j}", "length_m": length})
                if j + 1 < side:
                    edges.append({"a": nid, "b": f"n{f}_{i}_{j + 1}", "length_m": length})
    modules: list[dict[str, Any]] = []
    elevators: list[dict[str, Any]] = []
    if floors > 1:
        for e, (i, j) in enumerate([(0, 0), (side - 1, side - 1), (side // 2, side // 2)]):
            points: list[dict[str, Any]] = []
            module = {"id": f"m{e}", "port": 0, "points": points}
            stops = []
            for f in range(floors):
                # The cabin is its own node with one landing (a cabin is never a through-way).
                cabin = f"lift{e}_{f}"
                doc_nodes.append(
                    {"id": cabin, "floor": f"F{f}", "x": i * spacing_m + 1.0, "y": j * spacing_m}
                )
                edges.append({"a": f"n{f}_{i}_{j}", "b": cabin, "length_m": 1.0})
                points += [
                    {"name": f"call{f}", "address": f + 1, "kind": "coil"},
                    {"name": f"here{f}", "address": f + 1, "kind": "discrete_input"},
                ]
                stops.append(
                    {
                        "floor": f"F{f}",
                        "node": cabin,
                        "call": {"module": f"m{e}", "point": f"call{f}"},
                        "in_position": {"module": f"m{e}", "point": f"here{f}"},
                    }
                )
            modules.append(module)
            elevators.append({"id": f"lift{e}", "stops": stops, "travel_time_s": 10})
    lift_nodes = {s["node"] for el in elevators for s in el["stops"]}
    free = [n for n in node_ids if n not in lift_nodes]
    rng.shuffle(free)
    area_nodes, free = free[:areas], free[areas:]
    poi_nodes, free = free[:pois], free[pois:]
    n_stations = max(1, robots // 10)
    station_nodes, free = free[:n_stations], free[n_stations:]
    poi_list = [{"id": f"p{k}", "node": n, "text": f"Point {k}"} for k, n in enumerate(poi_nodes)]
    tours = (
        [
            {
                "id": f"t{k}",
                "points": [p["id"] for p in rng.sample(poi_list, min(5, len(poi_list)))],
            }
            for k in range(max(1, pois // 5))
        ]
        if poi_list
        else []
    )
    doc = {
        "name": f"synthetic {len(node_ids)} nodes",
        "floors": [{"id": f"F{f}", "level": f} for f in range(floors)],
        "nodes": doc_nodes,
        "edges": edges,
        "pois": poi_list,
        "tours": tours,
        "charging_stations": [{"id": f"s{k}", "node": n} for k, n in enumerate(station_nodes)],
        "wait_points": [{"id": "wait", "node": free[0]}],
        "areas": [{"id": f"a{k}", "nodes": [n]} for k, n in enumerate(area_nodes)],
        "elevators": elevators,
        "modules": modules,
        "robots": [
            {"name": f"R{k}", "token": f"robot-R{k}-token", "start_node": rng.choice(free)}
            for k in range(robots)
        ],
    }
    return validate_site(doc)
