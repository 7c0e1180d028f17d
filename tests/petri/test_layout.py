"""The layered drawing of a net (petri_nets.layout): the library's drawings and the monitor's
layout for a PNML file without graphics."""

from __future__ import annotations

import itertools

from petri_nets.layout import LABEL_CHAR_PX, layered, net_drawing
from petri_nets.library import NetLibrary


def test_layers_follow_the_flow_and_a_loop_does_not_lift_its_start() -> None:
    nodes = [("p0", "start"), ("t0", "go"), ("p1", "walking"), ("t1", "again"), ("t2", "stop")]
    nodes += [("p2", "done")]
    arcs = [("p0", "t0"), ("t0", "p1"), ("p1", "t1"), ("t1", "p1"), ("p1", "t2"), ("t2", "p2")]
    at = layered(nodes, arcs, starts=["p0"])
    assert at["p0"][1] < at["t0"][1] < at["p1"][1] < at["t2"][1] < at["p2"][1]
    assert at["t1"][1] == at["t2"][1]  # the loop's transition sits beside the way out
    assert at["t1"][0] != at["t2"][0]


def test_labels_written_to_the_right_fit_before_the_next_column() -> None:
    nodes = [("a", "a very long label indeed"), ("b", "x"), ("c", "y"), ("d", "z")]
    arcs = [("a", "b"), ("a", "c"), ("a", "d")]  # b, c and d share a layer
    at = layered(nodes, arcs, starts=["a"])
    row = sorted((at[n][0], n) for n in "bcd")
    for (x0, n), (x1, _) in itertools.pairwise(row):
        assert x1 - x0 >= LABEL_CHAR_PX * len(dict(nodes)[n])


def test_a_complete_pnml_drawing_is_kept_a_partial_one_is_replaced() -> None:
    places = [("p0", "start", (10.0, 20.0), 1), ("p1", "end", (10.0, 90.0), 0)]
    transitions = [("t0", "go", (10.0, 55.0))]
    arcs = [("p0", "t0"), ("t0", "p1")]
    own = net_drawing(places, transitions, arcs)
    assert own.source == "pnml" and own.positions["t0"] == (10.0, 55.0)
    partial = net_drawing(places, [("t0", "go", None)], arcs)
    assert partial.source == "layered"
    assert partial.positions["p0"][1] < partial.positions["t0"][1] < partial.positions["p1"][1]


def test_every_library_net_has_a_drawing_with_one_node_per_spot() -> None:
    library = NetLibrary(watch=False)
    for name in library.names():
        doc = library.get(name).doc
        spots = [
            (node.graphics.find("position").attrib["x"], node.graphics.find("position").attrib["y"])  # type: ignore[union-attr]
            for node in [*doc.places, *doc.transitions]
        ]
        assert len(set(spots)) == len(spots), name
