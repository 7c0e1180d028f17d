"""A Traffic Manager path as a VDA 5050 ``order``: pure functions, no bus, no broker.

Step ``i`` of the path is node sequence id ``2 i``, the edge from it to step ``i + 1`` is
``2 i + 1``, so an order update reuses the ids of the order it extends. The base (released)
runs up to ``released_to``; the rest of the path is horizon. An update starts at the last
node of the previous base (the spec's stitching node)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from guidebot.vda5050.topics import Vehicle

__all__ = ["build_order", "init_position", "instant_actions", "node_seq", "step_of_seq"]


def node_seq(index: int) -> int:
    return 2 * index


def step_of_seq(sequence_id: int) -> int:
    """The path step of a node sequence id (edges round down to the node before them)."""
    return sequence_id // 2


def build_order(
    vehicle: Vehicle,
    header_id: int,
    order_id: str,
    update_id: int,
    steps: Sequence[Mapping[str, Any]],
    *,
    start: int,
    released_to: int,
    map_ids: Mapping[str, str],
    actions: Mapping[int, list[dict[str, Any]]] | None = None,
) -> dict[str, Any]:
    """The order (or its update ``update_id`` > 0) for ``steps[start:]``; ``steps`` are the
    path's steps ({node, floor, x, y, ...}); ``map_ids`` floor -> mapId (default the floor
    id); ``actions`` step index -> the node actions there."""
    if not 0 <= start <= released_to < len(steps):
        raise ValueError(f"bad order window: start {start}, released to {released_to}")
    actions = actions or {}
    v3 = vehicle.version.startswith("3.")  # 3.0.0 edges name no start and end node
    nodes = []
    edges = []
    for i in range(start, len(steps)):
        step = steps[i]
        floor = str(step.get("floor") or "")
        nodes.append(
            {
                "nodeId": str(step["node"]),
                "sequenceId": node_seq(i),
                "released": i <= released_to,
                "nodePosition": {
                    "x": float(step["x"]),
                    "y": float(step["y"]),
                    "mapId": map_ids.get(floor, floor),
                },
                "actions": list(actions.get(i, [])),
            }
        )
        if i + 1 < len(steps):
            nxt = steps[i + 1]
            edge: dict[str, Any] = {
                "edgeId": f"{step['node']}->{nxt['node']}",
                "sequenceId": node_seq(i) + 1,
                "released": i + 1 <= released_to,
            }
            if not v3:
                edge |= {"startNodeId": str(step["node"]), "endNodeId": str(nxt["node"])}
            edges.append(edge | {"actions": []})
    return {
        **vehicle.header(header_id),
        "orderId": order_id,
        "orderUpdateId": update_id,
        "nodes": nodes,
        "edges": edges,
    }


def instant_actions(
    vehicle: Vehicle,
    header_id: int,
    actions: Sequence[tuple[str, str]],
    parameters: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """``instantActions`` of (actionId, actionType) pairs, each with ``parameters`` (key ->
    value) when given; blocking HARD (2.x), NONE (3.x: the only value its schema allows)."""
    params = [{"key": k, "value": v} for k, v in (parameters or {}).items()]
    blocking = "NONE" if vehicle.version.startswith("3.") else "HARD"
    return {
        **vehicle.header(header_id),
        "actions": [
            {"actionId": action_id, "actionType": kind, "blockingType": blocking}
            | ({"actionParameters": params} if params else {})
            for action_id, kind in actions
        ],
    }


def init_position(step: Mapping[str, Any], map_id: str) -> dict[str, Any]:
    """The parameters of ``initPosition`` that put the vehicle on ``step``'s node (after an
    elevator ride: the exit cabin node, on the target floor's map)."""
    return {
        "x": float(step["x"]),
        "y": float(step["y"]),
        "theta": 0.0,
        "mapId": map_id,
        "lastNodeId": str(step["node"]),
    }
