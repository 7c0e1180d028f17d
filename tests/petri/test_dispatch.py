"""The dispatch over the bus: run/kill messages, refusals, main tasks, hot reload, real time."""

from __future__ import annotations

import asyncio
import logging
import os
import time
from pathlib import Path

import pytest

from guidebot.bus import Bus
from guidebot.messages import Message
from petri_nets.builder import NetBuilder, message, publish
from petri_nets.clock import AsyncioClock
from petri_nets.dispatch import Dispatch, MainTaskBusy
from petri_nets.library import NetLibrary
from petri_nets.pnml import write_pnml

from .rig import Rig, make_rig


def test_run_and_kill_petri_net_messages(rig: Rig) -> None:
    rig.client.publish("run_petri_net", {"net": "head_talk", "instance_id": "talk-1"})
    assert [r["instance_id"] for r in rig.dispatch.running()] == ["talk-1"]
    rig.clock.advance(1.0)
    assert len(rig.published("move_servos")) >= 4
    rig.client.publish("kill_petri_net", {"instance_id": "talk-1"})
    assert rig.ended("talk-1") == "killed"
    events = [m.payload["kind"] for m in rig.log if m.type == "petri_net_event"]
    assert events[0] == "started" and events[-1] == "ended" and "fired" in events


@pytest.mark.parametrize(
    ("payload", "code", "reason"),
    [
        ({"net": "no_such_net"}, "bad_request", "unknown net no_such_net"),
        ({"net": "navigate_to_point", "params": {}}, "bad_request", "missing parameter(s) node"),
        ({"params": {}}, "bad_request", "net: Field required"),
    ],
    ids=["unknown-net", "missing-param", "no-net-field"],
)
def test_a_refused_run_request_gets_an_error_and_a_failed_end(
    rig: Rig, payload: dict[str, object], code: str, reason: str
) -> None:
    request = rig.client.publish("run_petri_net", {**payload, "instance_id": "x1"})
    errors = [m for m in rig.log if m.type == "error"]
    assert len(errors) == 1
    assert errors[0].destination == "client" and errors[0].correlation_id == request.id
    assert errors[0].payload["code"] == code and reason in errors[0].payload["reason"]
    assert rig.ended("x1") == "failed"
    assert rig.dispatch.running() == []


def test_only_one_main_task_at_a_time(rig: Rig) -> None:
    first = rig.dispatch.start("go_to_poi", {"node": "n1"}, main=True)
    with pytest.raises(MainTaskBusy, match="go_to_poi"):
        rig.dispatch.start("battery_charge", {"node": "dock"}, main=True)
    rig.client.publish(
        "run_petri_net", {"net": "battery_charge", "params": {"node": "d"}, "main": True}
    )
    assert [m.payload["code"] for m in rig.log if m.type == "error"] == ["busy"]
    rig.dispatch.start("blink")  # primitives still run next to the main task
    assert rig.dispatch.main_task == first
    rig.dispatch.kill(first)
    assert rig.dispatch.main_task is None
    rig.dispatch.start("battery_charge", {"node": "dock"}, main=True)


def one_shot(type: str) -> bytes:
    b = NetBuilder("shout")
    b.place("go", initial=1, action=publish(type)).place("end", final=True)
    b.transition("heard", ["go"], ["end"], message("heard"))
    return write_pnml(b.build())


def touch_later(path: Path, data: bytes) -> None:
    """Rewrite a file and move its mtime forward (coarse file-system clocks)."""
    before = path.stat().st_mtime_ns
    path.write_bytes(data)
    os.utime(path, ns=(before + 10**9, before + 10**9))


def test_an_edited_net_is_reloaded_and_a_broken_edit_keeps_the_old_one(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    net_file = tmp_path / "shout.pnml"
    net_file.write_bytes(one_shot("hello"))
    rig = make_rig(tmp_path)
    running = rig.dispatch.start("shout")
    touch_later(net_file, one_shot("goodbye"))
    rig.dispatch.start("shout")
    assert rig.action_types() == ["hello", "goodbye"]
    rig.say("heard")
    assert rig.ended(running) == "done"  # the old instance ran on with its own version
    touch_later(net_file, b"<pnml><net id='shout'>")
    with caplog.at_level(logging.ERROR):
        rig.dispatch.start("shout")
    assert rig.action_types() == ["hello", "goodbye", "goodbye"]
    assert "keeping the last good version" in caplog.text
    assert "shout.pnml:1: no element found" in caplog.text


async def test_real_time_with_a_time_scale() -> None:
    """wink_one_eye holds 30 s; at 1000x it takes 30 ms of real time (timers on the loop)."""
    bus = Bus()
    dispatch = Dispatch(
        bus.endpoint("dispatch"), NetLibrary(), AsyncioClock(scale=1000.0), idle_net=None
    )
    head = bus.endpoint("head")

    def servo_driver(msg: Message) -> None:
        for servo, position in msg.payload["servos"].items():
            head.publish("servo_in_position", {"servo": servo, "position": position})

    head.subscribe("move_servos", servo_driver)
    ended = asyncio.Event()
    outcomes: list[str] = []
    head.subscribe(
        "petri_net_ended", lambda m: (outcomes.append(m.payload["outcome"]), ended.set())
    )
    dispatch.open()
    try:
        started = time.monotonic()
        dispatch.start("wink_one_eye", {"hold_s": 30})
        await asyncio.wait_for(ended.wait(), timeout=20)
        assert outcomes == ["done"]
        assert time.monotonic() - started < 20
    finally:
        dispatch.close()


async def test_close_cancels_pending_timers() -> None:
    bus = Bus()
    dispatch = Dispatch(bus.endpoint("dispatch"), NetLibrary(), AsyncioClock(), idle_net="waiting")
    dispatch.open()
    assert [r["net"] for r in dispatch.running()] == ["waiting"]
    dispatch.close()
    assert dispatch.running() == []
    loop = asyncio.get_running_loop()
    assert not [h for h in getattr(loop, "_scheduled", []) if not h.cancelled()]
