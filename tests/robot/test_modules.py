"""Speech, battery logic, the task runner, the head watchdog and the link, each on a real Bus."""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import pytest

from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.payloads.robot import RobotState
from robot_agent.battery import BatteryMonitor
from robot_agent.clock import Clock
from robot_agent.head import HeadWatchdog
from robot_agent.link import Link
from robot_agent.speech import Speech, simulated_duration
from robot_agent.state import StateReporter
from robot_agent.tasks import IllegalTransition, MainTask, TaskPhase, TaskRunner


async def test_speech_simulated_is_scaled_by_the_clock(helpers: Any) -> None:
    bus = Bus()
    speech = Speech(bus.endpoint("speech"), Clock(50.0), engine=None)
    await speech.start()
    seen = helpers.Recorder(bus.endpoint("t"), "speech_*")
    text = "Welcome to the museum, please follow me to the first room."
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    bus.endpoint("net").publish("say", {"text": text})
    await seen.wait_for(lambda: seen.of("speech_ended"))
    took = loop.time() - t0
    assert [m.type for m in seen.messages] == ["speech_started", "speech_ended"]
    assert seen.of("speech_ended")[0].payload["text"] == text
    # Robot time is 50x wall time: a ~5 s sentence takes well under its real duration.
    assert took < simulated_duration(text)
    await speech.stop()


async def test_speech_with_espeak_ng(helpers: Any) -> None:
    import shutil

    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng not installed (make system-deps)")
    bus = Bus()
    speech = Speech(bus.endpoint("speech"), Clock(100.0))
    assert speech.engine is not None
    await speech.start()
    seen = helpers.Recorder(bus.endpoint("t"), "speech_*")
    bus.endpoint("net").publish("say", {"text": "Hello visitors.", "lang": "en"})
    await seen.wait_for(lambda: seen.of("speech_ended"))
    assert seen.of("speech_ended")[0].payload["outcome"] == "done"
    await speech.stop()


async def test_a_new_say_interrupts_the_current_one(helpers: Any) -> None:
    bus = Bus()
    speech = Speech(bus.endpoint("speech"), Clock(1.0), engine=None)
    await speech.start()
    seen = helpers.Recorder(bus.endpoint("t"), "speech_*")
    net = bus.endpoint("net")
    net.publish("say", {"text": "a long story " * 50})
    await seen.wait_for(lambda: seen.of("speech_started"))
    net.publish("say", {"text": "Short."})
    await seen.wait_for(lambda: len(seen.of("speech_ended")) == 2)
    first, second = seen.of("speech_ended")
    assert first.payload["outcome"] == "interrupted"
    assert second.payload == {"text": "Short.", "lang": "en", "voice": None, "outcome": "done"}
    await speech.stop()


async def test_battery_thresholds_fire_once_per_discharge(helpers: Any) -> None:
    bus = Bus()
    battery = BatteryMonitor(bus.endpoint("battery"), "R1", low=0.3, panic=0.1)
    await battery.start()
    seen = helpers.Recorder(bus.endpoint("t"), "battery_low", "battery_panic", "charged")
    entity = bus.endpoint("entity")
    for level in (0.5, 0.31, 0.29, 0.25, 0.2, 0.09, 0.05):
        entity.publish("battery_level", {"level": level, "charging": False})
    assert [(m.type, m.payload["level"]) for m in seen.messages] == [
        ("battery_low", 0.29),
        ("battery_panic", 0.09),
    ]
    # Docked and charging: "charged" ends the docking when full, and the alarms re-arm.
    bus.endpoint("nav").publish("docked", {"station": "station_a", "node": "charge_a"})
    for level in (0.5, 0.9, 0.96):
        entity.publish("battery_level", {"level": level, "charging": True})
    assert seen.of("charged")[0].payload["station"] == "station_a"
    entity.publish("battery_level", {"level": 0.28, "charging": False})
    assert len(seen.of("battery_low")) == 2


def test_battery_refuses_inconsistent_thresholds() -> None:
    with pytest.raises(ValueError, match="panic < low"):
        BatteryMonitor(Bus().endpoint("b"), "R1", low=0.1, panic=0.2)


def test_task_phase_transitions_are_checked() -> None:
    task = MainTask("t1", "give_tour", {}, "i1")
    task.move(TaskPhase.RUNNING)
    task.move(TaskPhase.ENDED)
    with pytest.raises(IllegalTransition, match="ended -> running"):
        task.move(TaskPhase.RUNNING)


async def test_task_runner_reports_start_end_cancel_and_refuses_a_second_task(helpers: Any) -> None:
    bus = Bus()
    cancelled: list[bool] = []
    runner = TaskRunner(bus.endpoint("tasks"), "R1", on_cancel=lambda: cancelled.append(True))
    seen = helpers.Recorder(bus.endpoint("t"), "task_*", "run_petri_net", "kill_petri_net")
    await runner.start()
    tm = bus.endpoint("task_manager")
    dispatch = bus.endpoint("dispatch")
    # Idle: the waiting net runs.
    assert seen.of("run_petri_net")[0].payload["net"] == "waiting"
    tm.publish("task_assigned", {"task_id": "t1", "robot": "R1", "net": "give_tour", "params": {}})
    assert seen.of("kill_petri_net")[0].payload["instance_id"].startswith("R1-waiting")
    run = seen.of("run_petri_net")[1].payload
    assert run["net"] == "give_tour" and run["main"] is True
    assert seen.of("task_started")[0].payload == {"task_id": "t1", "robot": "R1"}
    # A second main task while busy is refused (the server requeues it), the first untouched.
    tm.publish("task_assigned", {"task_id": "t2", "robot": "R1", "net": "give_tour"})
    refusal = seen.of("task_ended")[0].payload
    assert refusal["outcome"] == "refused" and refusal["reason"] == "robot busy with task t1"
    assert runner.task_id == "t1"
    # Cancel: the net is killed, navigation stopped, the end reported as cancelled.
    tm.publish("task_cancel", {"task_id": "t1", "reason": "battery panic"})
    assert cancelled == [True]
    dispatch.publish(
        "petri_net_ended",
        {"net": "give_tour", "instance_id": run["instance_id"], "outcome": "killed"},
    )
    ended = seen.of("task_ended")[-1].payload
    assert ended == {
        "task_id": "t1",
        "robot": "R1",
        "outcome": "cancelled",
        "reason": "battery panic",
        "trouble": False,
    }
    assert runner.current is None
    assert seen.of("run_petri_net")[-1].payload["net"] == "waiting"


async def test_a_net_refused_by_rg_ends_the_task_as_failed_with_rg_reason(helpers: Any) -> None:
    """RG refuses an unknown net at once, inside the publish: the task must end as failed
    with RG's reason and the robot go back to waiting, not raise ended -> running."""
    from petri_nets.clock import AsyncioClock
    from petri_nets.dispatch import Dispatch
    from petri_nets.library import NetLibrary

    bus = Bus()
    dispatch = Dispatch(
        bus.endpoint("dispatch"), NetLibrary(watch=False), AsyncioClock(), idle_net=None
    )
    dispatch.open()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "task_*")
    await runner.start()
    bus.endpoint("tm").publish(
        "task_assigned", {"task_id": "t1", "robot": "R1", "net": "no_such_net"}
    )
    ended = seen.of("task_ended")
    assert [m.payload["outcome"] for m in ended] == ["failed"]
    assert "unknown net" in ended[0].payload["reason"]
    assert runner.current is None and runner.finished[0].phase is TaskPhase.ENDED
    dispatch.close()


async def test_a_failed_task_says_why_from_what_went_wrong_while_it_ran(helpers: Any) -> None:
    """A net that fails says nothing itself: the reason is the last navigation failure or
    robot fault seen during the task, else a plain sentence, never empty (found under load
    in tests/robot/test_e2e.py and by the soak)."""
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "task_ended", "run_petri_net")
    await runner.start()
    tm, dispatch, nav = bus.endpoint("tm"), bus.endpoint("dispatch"), bus.endpoint("navigation")

    def run_and_fail(task_id: str, *problems: tuple[str, dict[str, Any]]) -> dict[str, Any]:
        tm.publish("task_assigned", {"task_id": task_id, "robot": "R1", "net": "go_to_poi"})
        instance = seen.of("run_petri_net")[-1].payload["instance_id"]
        for type_, payload in problems:
            nav.publish(type_, payload)
        dispatch.publish(
            "petri_net_ended", {"net": "go_to_poi", "instance_id": instance, "outcome": "failed"}
        )
        return dict(seen.of("task_ended")[-1].payload)

    ended = run_and_fail(
        "t1",
        ("robot_fault", {"robot": "R1", "kind": "motor_lost", "detail": "module 0x02 lost"}),
        ("navigation_failed", {"node": "gb1", "reason": "base fault: module 0x02 lost"}),
    )
    assert ended["outcome"] == "failed"
    assert ended["reason"] == "navigation to gb1 failed: base fault: module 0x02 lost"
    assert ended["trouble"] is False
    ended = run_and_fail("t2")  # nothing seen: still a sentence, and not the last task's
    assert ended["reason"] == "the go_to_poi task net failed (no step said why)"


async def test_a_task_failed_by_trouble_alone_says_so_typed(helpers: Any) -> None:
    """The Task Manager read trouble from the failure's words ("out of order"): the robot's
    navigation_failed ``trouble`` flag goes into its task_ended and its state's ``ended``
    list, and only for the failure that ended the task (a later robot fault wins)."""
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "task_ended", "run_petri_net")
    await runner.start()
    tm, dispatch, nav = bus.endpoint("tm"), bus.endpoint("dispatch"), bus.endpoint("navigation")
    cut = {"node": "gb1", "reason": "door door_gallery out of order", "closed": True}

    def run_and_fail(task_id: str, *problems: tuple[str, dict[str, Any]]) -> dict[str, Any]:
        tm.publish("task_assigned", {"task_id": task_id, "robot": "R1", "net": "go_to_poi"})
        instance = seen.of("run_petri_net")[-1].payload["instance_id"]
        for type_, payload in problems:
            nav.publish(type_, payload)
        dispatch.publish(
            "petri_net_ended", {"net": "go_to_poi", "instance_id": instance, "outcome": "failed"}
        )
        return dict(seen.of("task_ended")[-1].payload)

    ended = run_and_fail("t1", ("navigation_failed", cut | {"trouble": True}))
    assert ended["reason"] == "navigation to gb1 failed: door door_gallery out of order"
    assert ended["trouble"] is True
    assert run_and_fail("t2", ("navigation_failed", cut))["trouble"] is False  # staff's words
    fault = {"robot": "R1", "kind": "motor_lost", "detail": "module 0x02 lost"}
    later = run_and_fail(
        "t3", ("navigation_failed", cut | {"trouble": True}), ("robot_fault", fault)
    )
    assert later["trouble"] is False
    reporter = StateReporter(bus.endpoint("state"), "R1", None, None, runner)  # type: ignore[arg-type]
    state = RobotState(robot="R1", ended=reporter.ended())  # what the hub checks
    assert [(e.task_id, e.trouble) for e in state.ended] == [
        ("t3", False),
        ("t2", False),
        ("t1", True),
    ]


async def test_the_robot_state_names_the_last_tasks_that_ended(helpers: Any) -> None:
    """robot_state ``ended``: the newest three, as their task_ended said, so a restarted server
    that never heard a task_ended (lost in a long freeze) ends the task instead of giving it
    out again (docs/server.md, "After a restart")."""
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "run_petri_net")
    await runner.start()
    tm, dispatch = bus.endpoint("tm"), bus.endpoint("dispatch")
    for task_id, outcome in (("t1", "done"), ("t2", "failed"), ("t3", "killed"), ("t4", "done")):
        tm.publish("task_assigned", {"task_id": task_id, "robot": "R1", "net": "go_to_poi"})
        instance = seen.of("run_petri_net")[-1].payload["instance_id"]
        dispatch.publish(
            "petri_net_ended", {"net": "go_to_poi", "instance_id": instance, "outcome": outcome}
        )
    reporter = StateReporter(bus.endpoint("state"), "R1", None, None, runner)  # type: ignore[arg-type]
    ended = reporter.ended()
    assert [(e["task_id"], e["outcome"]) for e in ended] == [
        ("t4", "done"),
        ("t3", "cancelled"),
        ("t2", "failed"),
    ]
    assert ended[2]["reason"] == "the go_to_poi task net failed (no step said why)"
    state = RobotState(robot="R1", ended=ended)  # what the hub checks
    assert [e.task_id for e in state.ended] == ["t4", "t3", "t2"]


async def test_an_assignment_resent_for_a_task_that_ended_is_answered_not_run(
    helpers: Any,
) -> None:
    """The link was down when the task ended (or the server restarted): the server resends
    task_assigned before the queued task_ended reaches it. The robot says again how the task
    ended instead of running it a second time (the soak saw the repeat refuse the next task
    as "robot busy")."""
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "task_ended", "run_petri_net")
    await runner.start()
    tm, dispatch = bus.endpoint("tm"), bus.endpoint("dispatch")
    assign = {"task_id": "t1", "robot": "R1", "net": "go_to_poi"}
    tm.publish("task_assigned", assign)
    instance = seen.of("run_petri_net")[-1].payload["instance_id"]
    dispatch.publish(
        "petri_net_ended", {"net": "go_to_poi", "instance_id": instance, "outcome": "done"}
    )
    tm.publish("task_assigned", assign)  # resent
    assert len(seen.of("run_petri_net")) == 1  # not run again
    ended = [m.payload for m in seen.of("task_ended")]
    once = {"task_id": "t1", "robot": "R1", "outcome": "done", "reason": "", "trouble": False}
    assert ended == [once] * 2
    assert runner.current is None
    # The next task runs as usual.
    tm.publish("task_assigned", {**assign, "task_id": "t2"})
    assert runner.current is not None and runner.current.task_id == "t2"


async def test_a_task_the_server_took_back_after_its_end_runs_again_when_given_again(
    helpers: Any,
) -> None:
    """A visit that failed only because a door was jammed goes back to the queue (the server
    cancels it on the robot after its task_ended) and may come back to the same robot once
    the door works: that is a new run, not a resend answered with the old failure (which
    failed the visit with a reason no longer true), and the robot's state no longer names
    it as ended."""
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "task_ended", "run_petri_net")
    await runner.start()
    tm, dispatch = bus.endpoint("tm"), bus.endpoint("dispatch")
    assign = {"task_id": "t1", "robot": "R1", "net": "go_to_poi"}
    tm.publish("task_assigned", assign)
    instance = seen.of("run_petri_net")[-1].payload["instance_id"]
    dispatch.publish(
        "petri_net_ended", {"net": "go_to_poi", "instance_id": instance, "outcome": "failed"}
    )
    tm.publish("task_cancel", {"task_id": "t1", "reason": "waiting for door D0 to work again"})
    assert not [t for t in runner.finished if t.task_id == "t1"]
    tm.publish("task_assigned", assign)  # given again
    assert len(seen.of("run_petri_net")) == 2
    assert runner.current is not None and runner.current.task_id == "t1"
    assert [m.payload["outcome"] for m in seen.of("task_ended")] == ["failed"]


async def test_tour_points_become_tour_progress_and_points_out_of_range_do_not(
    helpers: Any,
) -> None:
    """A point the tour reached or explained goes to the Task Manager as tour_progress (the
    wire of docs/messages.md); one the Task Manager would refuse (index 0) is not sent."""
    bus = Bus()
    runner = TaskRunner(bus.endpoint("tasks"), "R1", waiting_net=None)
    seen = helpers.Recorder(bus.endpoint("t"), "tour_progress")
    await runner.start()
    bus.endpoint("tm").publish(
        "task_assigned", {"task_id": "t1", "robot": "R1", "net": "give_tour"}
    )
    tour = bus.endpoint("give_tour")
    tour.publish("show_point", {"poi": "p1", "point": {"poi": "p1", "index": 1, "total": 2}})
    tour.publish("point_explained", {"point": {"poi": "p1", "index": 1, "total": 2}})
    tour.publish("show_point", {"poi": "p0", "point": {"poi": "p0", "index": 0, "total": 2}})
    why = "gallery g2 closed: cleaning"
    tour.publish("point_skipped", {"point": {"poi": "p2", "index": 2, "total": 2}, "reason": why})
    base = {"task_id": "t1", "robot": "R1", "total": 2}
    assert [m.payload for m in seen.of("tour_progress")] == [
        {**base, "index": 1, "poi": "p1", "stage": "arrived", "reason": ""},
        {**base, "index": 1, "poi": "p1", "stage": "explained", "reason": ""},
        {**base, "index": 2, "poi": "p2", "stage": "skipped", "reason": why},
    ]
    await runner.stop()


async def test_head_watchdog_confirms_servos_a_lost_head_never_does(helpers: Any) -> None:
    bus = Bus()
    head = HeadWatchdog(bus.endpoint("head_watchdog"), Clock(10.0), timeout_s=1.0, min_wall_s=0.05)
    await head.start()
    seen = helpers.Recorder(bus.endpoint("t"), "servo_in_position")
    net = bus.endpoint("net")
    net.publish("move_servos", {"servos": {"mouth": 0.5, "left_eye": 1.0}})
    # The real head answers for the mouth only.
    bus.endpoint("head").publish("servo_in_position", {"servo": "mouth", "position": 0.5})
    await seen.wait_for(lambda: len(seen.of("servo_in_position")) == 2)
    degraded = [m.payload for m in seen.messages if m.payload.get("degraded")]
    assert degraded == [{"servo": "left_eye", "position": 1.0, "degraded": True}]
    assert head.degraded == 1
    await head.stop()


async def test_a_robot_without_a_head_skips_gestures_without_warning(
    helpers: Any, caplog: pytest.LogCaptureFixture
) -> None:
    """A bare base has no head: every gesture is confirmed degraded, as for a lost head, but
    that is how the robot is built, not a fault (the plan's virtual day logged ~3000 warnings)."""
    bus = Bus()
    head = HeadWatchdog(
        bus.endpoint("head_watchdog"), Clock(10.0), timeout_s=1.0, min_wall_s=0.05, fitted=False
    )
    with caplog.at_level(logging.INFO, logger="robot_agent.head"):
        await head.start()
        seen = helpers.Recorder(bus.endpoint("t"), "servo_in_position")
        bus.endpoint("net").publish("move_servos", {"servos": {"mouth": 0.5}})
        await seen.wait_for(lambda: seen.of("servo_in_position"))
        await head.stop()
    assert seen.of("servo_in_position")[0].payload["degraded"] is True
    assert [r.levelno for r in caplog.records] == [logging.INFO]
    assert "no head" in caplog.records[0].getMessage()


class _FakeUpstream:
    """Stands in for the hub client's surface only (the end-to-end tests use the real one)."""

    def __init__(self) -> None:
        self.name = "R1"
        self.connected = asyncio.Event()
        self.sent: list[Message] = []
        self.handlers: dict[str, Any] = {}
        self.on_connect_callbacks: list[Any] = []

    def send(self, message: Message) -> None:
        self.sent.append(message.model_copy(update={"source": self.name}))

    def subscribe(self, pattern: str, handler: Any) -> Any:
        self.handlers[pattern] = handler
        return lambda: self.handlers.pop(pattern, None)

    def on_connect(self, callback: Any) -> Any:
        self.on_connect_callbacks.append(callback)
        return lambda: None

    def deliver(self, message: Message) -> None:
        self.handlers[message.type](message)


async def test_link_takes_a_kill_only_when_addressed_and_forwards_net_events() -> None:
    """Staff kill one robot's net (addressed); a broadcast kill is for the server's RGM. The
    console's monitor follows petri_net_event on the hub."""
    bus = Bus()
    up = _FakeUpstream()
    up.connected.set()
    link = Link(bus.endpoint("link"), up, "R1")
    await link.start()
    kills: list[Message] = []
    dispatch = bus.endpoint("dispatch")
    dispatch.subscribe("kill_petri_net", kills.append)
    up.deliver(Message(type="kill_petri_net", source="gui", payload={"net": "give_tour"}))
    assert kills == []
    up.deliver(
        Message(
            type="kill_petri_net", source="console", destination="R1", payload={"instance_id": "i"}
        )
    )
    assert [m.payload for m in kills] == [{"instance_id": "i"}]
    event = {"instance_id": "i", "net": "waiting", "kind": "fired", "time": 1.0}
    dispatch.publish("petri_net_event", event)
    assert [m.type for m in up.sent] == ["petri_net_event"]
    await link.stop()


async def test_link_routes_replies_to_the_requester_and_never_echoes() -> None:
    bus = Bus()
    up = _FakeUpstream()
    up.connected.set()
    link = Link(bus.endpoint("link"), up, "R1")
    await link.start()
    nav = bus.endpoint("navigation")
    request = asyncio.ensure_future(nav.request("get_path", {"to_node": "hall"}, timeout=5))
    await asyncio.sleep(0)
    [sent] = up.sent
    assert sent.type == "get_path"
    up.deliver(
        Message(
            type="path",
            source="traffic",
            destination="R1",
            correlation_id=sent.id,
            payload={"steps": []},
        )
    )
    reply = await request
    assert reply.type == "path" and reply.correlation_id == sent.id
    # Hub messages published on board are not sent back up.
    up.deliver(Message(type="door_opened", source="building", payload={"door": "d1"}))
    assert [m.type for m in up.sent] == ["get_path"]
    # Messages for another robot are ignored.
    seen: list[Message] = []
    nav.subscribe("task_assigned", seen.append)
    up.deliver(
        Message(type="task_assigned", source="tm", destination="R2", payload={"task_id": "x"})
    )
    assert seen == []
    await link.stop()


async def test_link_resends_reports_that_may_have_died_in_flight() -> None:
    bus = Bus()
    up = _FakeUpstream()
    up.connected.set()
    states: list[int] = []
    link = Link(bus.endpoint("link"), up, "R1", on_connect=lambda: states.append(1))
    await link.start()
    bus.endpoint("tasks").publish("task_ended", {"task_id": "t1", "robot": "R1"})
    await asyncio.sleep(0.15)  # the link's watcher is running
    up.connected.clear()  # the Wi-Fi drops
    await asyncio.sleep(0.3)  # the link notices within its 0.1 s poll
    up.connected.set()
    for callback in up.on_connect_callbacks:
        callback()
    ended = [m for m in up.sent if m.type == "task_ended"]
    assert len(ended) == 2 and ended[0].id == ended[1].id  # same id: receivers deduplicate
    assert states == [1]  # resynchronised (robot_state at once)
    await link.stop()


async def test_link_resends_a_node_reached_that_may_have_died_in_flight() -> None:
    """node_reached is must-arrive: one sent as the server died was lost, and the soak's
    checker then kept the robot in the lift cabin it had left (issue 36)."""
    bus = Bus()
    up = _FakeUpstream()
    up.connected.set()
    link = Link(bus.endpoint("link"), up, "R1")
    await link.start()
    reached = {"robot": "R1", "node": "landing", "floor": "F1", "at": 1.0}
    bus.endpoint("navigation").publish("node_reached", reached)
    await asyncio.sleep(0.15)  # the link's watcher is running
    up.connected.clear()  # the server dies
    await asyncio.sleep(0.3)  # the link notices within its 0.1 s poll
    up.connected.set()
    for callback in up.on_connect_callbacks:
        callback()
    sent = [m for m in up.sent if m.type == "node_reached"]
    assert len(sent) == 2 and sent[0].id == sent[1].id  # same id: receivers deduplicate
    await link.stop()


class _FakeUpstreamWithDisconnect(_FakeUpstream):
    """Like the hub client: says when an established connection is lost."""

    def __init__(self) -> None:
        super().__init__()
        self.on_disconnect_callbacks: list[Any] = []

    def on_disconnect(self, callback: Any) -> Any:
        self.on_disconnect_callbacks.append(callback)
        return lambda: self.on_disconnect_callbacks.remove(callback)

    def drop(self) -> None:
        self.connected.clear()
        for callback in list(self.on_disconnect_callbacks):
            callback()


async def test_link_told_of_a_drop_resends_without_polling() -> None:
    bus = Bus()
    up = _FakeUpstreamWithDisconnect()
    up.connected.set()
    drops: list[bool] = []
    link = Link(bus.endpoint("link"), up, "R1", on_disconnect=lambda: drops.append(True))
    await link.start()
    assert link._watch is None  # nothing polls the connection
    tasks = bus.endpoint("tasks")
    tasks.publish("task_ended", {"task_id": "t1", "robot": "R1"})
    up.drop()
    assert drops == [True]  # navigation forgets doors and cabins (it misses their news)
    tasks.publish("task_ended", {"task_id": "t2", "robot": "R1"})  # queued
    up.connected.set()
    for callback in up.on_connect_callbacks:
        callback()
    ended = [m.payload["task_id"] for m in up.sent if m.type == "task_ended"]
    assert ended == ["t1", "t2", "t1"]  # t1 may have died in flight: sent again
    await link.stop()
    assert up.on_disconnect_callbacks == []


async def test_link_resends_offline_reports_lost_in_a_second_drop() -> None:
    """A report queued while offline is flushed at the reconnect; if the link drops again at
    once, that flush may have died in flight too and the report goes again."""
    bus = Bus()
    up = _FakeUpstreamWithDisconnect()
    up.connected.set()
    link = Link(bus.endpoint("link"), up, "R1")
    await link.start()
    up.drop()
    bus.endpoint("tasks").publish("task_ended", {"task_id": "t1", "robot": "R1"})  # queued
    for _ in range(2):  # back, then gone again at once, then back
        up.connected.set()
        for callback in up.on_connect_callbacks:
            callback()
        up.drop()
    up.connected.set()
    for callback in up.on_connect_callbacks:
        callback()
    ended = [m.payload["task_id"] for m in up.sent if m.type == "task_ended"]
    assert ended == ["t1", "t1", "t1"]  # queued once, then sent again after each later drop
    await link.stop()
