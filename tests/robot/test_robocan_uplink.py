"""The link's rate for ``robocan_status`` (robot_agent.link.StatusThrottle): on board every
second, up to the server at most every few seconds, but at once when a module changes state."""

from __future__ import annotations

from typing import Any

from guidebot.messages import Message
from robot_agent.link import UP_TYPES, StatusThrottle


def status(state: str = "online", frames: int = 10) -> Message:
    counters: dict[str, Any] = dict.fromkeys(
        (
            "frames_rx frames_tx unknown_id bad_frame overflow block_errors send_errors "
            "driver_errors record_errors stalls not_online modules_lost modules_requeried"
        ).split(),
        0,
    )
    counters["frames_rx"] = frames
    module = {
        "module_id": 0x20,
        "name": "sonar_ring_20",
        "kind": "sonar_ring",
        "firmware": "1.0",
        "state": state,
        "critical": False,
        "elements": ["sonar"],
        "frames_rx": frames,
        "frames_tx": 1,
        "errors": 0,
        "faults": 0,
        "lost": 0,
        "requeried": 0,
    }
    payload = {
        "robot": "R1",
        "buses": [{"bus": "virtual:x", "counters": counters, "modules": [module]}],
    }
    return Message(type="robocan_status", payload=payload)


def test_counters_go_up_every_period_and_a_state_change_at_once() -> None:
    assert "robocan_status" in UP_TYPES
    throttle = StatusThrottle(5.0)
    assert throttle.allow(status(frames=1), 100.0)  # the first one at once
    assert not throttle.allow(status(frames=2), 101.0)  # only counters changed
    assert not throttle.allow(status(frames=3), 104.9)
    assert throttle.allow(status(frames=4), 105.0)  # a period later
    assert throttle.allow(status("lost", frames=5), 105.5)  # a module lost: at once
    assert not throttle.allow(status("lost", frames=6), 106.0)
    throttle.reset()  # the link came back
    assert throttle.allow(status("lost", frames=7), 106.5)
    assert throttle.held == 3


def test_a_status_that_is_not_one_is_not_sent() -> None:
    throttle = StatusThrottle(5.0)
    bad = Message(type="robocan_status", payload={"robot": "R1", "buses": [{"bus": 3}]})
    assert not throttle.allow(bad, 0.0)
