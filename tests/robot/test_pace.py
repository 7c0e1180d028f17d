"""A slower tour gives its visitor longer to answer "Shall we continue the tour?" (issue 41):
the tour net's answer times scaled like its speed and speech (guidebot/pace.py)."""

from __future__ import annotations

from typing import Any

import pytest

from guidebot.bus import Bus
from guidebot.pace import ANSWER_TIMEOUT_S, PACES, PATIENCE_S
from petri_nets.library import NetLibrary
from robot_agent.tasks import TaskRunner


def test_the_tour_net_s_answer_times_are_the_pace_s_usual_ones() -> None:
    give_tour = NetLibrary(watch=False).get("give_tour")
    assert give_tour.params["answer_timeout_s"] == ANSWER_TIMEOUT_S == 20.0
    assert give_tour.params["patience_s"] == PATIENCE_S > ANSWER_TIMEOUT_S


@pytest.mark.parametrize(
    ("params", "answer", "patience"),
    [
        ({"pace": "slow"}, 20.0 * PACES["slow"].answer, 30.0 * PACES["slow"].answer),
        ({}, None, None),  # the usual pace: the net's own defaults
        ({"pace": "slow", "answer_timeout_s": 60.0}, 60.0, 45.0),  # a task's own value wins
    ],
)
async def test_a_slower_tour_gives_longer_to_answer_continue(
    helpers: Any, params: dict[str, Any], answer: float | None, patience: float | None
) -> None:
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "run_petri_net")
    await runner.start()
    tour = {"tour": "ground", "points": [], **params}
    bus.endpoint("tm").publish(
        "task_assigned", {"task_id": "t1", "robot": "R1", "net": "give_tour", "params": tour}
    )
    run = seen.of("run_petri_net")[0].payload["params"]
    assert run.get("answer_timeout_s") == answer
    assert run.get("patience_s") == patience
    assert PACES["slow"].answer == 1.5
