"""The reachability analysis of the RoboGraph editor: bound, unbounded places, dead
transitions, dead ends, and an exploration that gives up says so."""

from __future__ import annotations

from petri_nets.builder import NetBuilder
from petri_nets.library import NetLibrary
from petri_nets.reachability import analyse


def test_every_library_net_is_safe_and_has_no_dead_transition() -> None:
    library = NetLibrary()
    for name in library.names():
        result = analyse(library.get(name).doc)
        assert result.complete and result.bounded and result.bound == 1, name
        assert result.dead_transitions == [] and result.dead_ends == 0, name


def test_a_transition_that_makes_tokens_from_nothing_is_unbounded() -> None:
    net = (
        NetBuilder("pump")
        .place("p", initial=1)
        .place("q")
        .transition("more", ["p"], ["p", "q"])
        .build()
    )
    result = analyse(net)
    assert result.bounded is False and result.unbounded_places == ["q"]
    assert not result.complete


def test_a_transition_no_marking_enables_is_dead_and_a_dead_end_is_counted() -> None:
    net = (
        NetBuilder("dead")
        .place("start", initial=1)
        .place("middle")
        .place("never")
        .place("end", final=True)
        .transition("go", ["start"], ["middle"])
        .transition("stuck", ["middle", "never"], ["end"])
        .build()
    )
    result = analyse(net)
    assert result.complete and result.bounded is True and result.bound == 1
    assert result.dead_transitions == ["stuck"]
    assert result.dead_ends == 1  # middle marked, nothing enabled, end not reached


def test_the_exploration_gives_up_at_its_limit_and_says_so() -> None:
    net = (
        NetBuilder("count")
        .place("a", initial=200)
        .place("b")
        .transition("move", ["a"], ["b"])
        .build()
    )
    assert analyse(net).complete and analyse(net).states == 201
    limited = analyse(net, max_states=50)
    assert limited.states == 50 and not limited.complete and limited.bounded is None
