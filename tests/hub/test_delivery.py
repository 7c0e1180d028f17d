"""Acknowledged delivery over the real hub and real WebSockets (docs/protocol.md, "Delivery
guarantee"): a copy without an acknowledgement is sent again, one id is handled once, nothing is
sent after the ack, and a receiver that goes away stops the retries."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from backend.hub.core import CLOSE_OVERFLOW
from backend.robot_links import announce_robot_links
from backend.testing import RunningServer
from guidebot.bus import Bus
from guidebot.delivery import Courier, ack_for, courier_for, listen
from guidebot.messages import Message
from guidebot.testing import Recorder, wait_until
from robot_agent.link import Link

from .conftest import ClientFactory

FAST = {"initial_s": 0.05, "max_s": 0.2}


def server_courier(server: RunningServer, name: str = "task_manager") -> tuple[Courier, Recorder]:
    """A Courier on an in-process endpoint, as the Task Manager has, and the acks it gets."""
    endpoint = server.app.state.hub.endpoint(name)
    courier = courier_for(endpoint, **FAST)
    listen(endpoint, courier)
    return courier, Recorder(endpoint, "ack")


def assignment(task_id: str = "T1", robot: str = "R1") -> Message:
    return Message(
        type="task_assigned",
        source="task_manager",
        destination=robot,
        payload={"task_id": task_id, "robot": robot, "net": "give_tour", "params": {}},
    )


async def test_an_unacknowledged_task_assigned_is_sent_again_until_acked(
    server: RunningServer, connect: ClientFactory
) -> None:
    robot = await connect("R1")
    copies: list[Message] = []

    def on_assigned(message: Message) -> None:
        copies.append(message)
        if len(copies) == 3:  # the first two are "lost": nothing answers them
            robot.send(ack_for(message, "R1"))

    robot.subscribe("task_assigned", on_assigned)
    await robot.sync()
    courier, acks = server_courier(server)
    sent = courier.post(assignment())
    await acks.wait("ack", message_id=sent.id)
    await wait_until(lambda: courier.pending == 0)
    assert [m.id for m in copies] == [sent.id] * 3  # one message, three copies
    assert courier.retries == 2 and courier.acked == 1
    # No retry storm after the ack: five times the longest back-off, nothing more comes.
    await asyncio.sleep(5 * FAST["max_s"])
    await robot.sync()
    assert len(copies) == 3


async def test_a_repeated_task_assigned_is_handled_once_and_acked_each_time(
    server: RunningServer, connect: ClientFactory
) -> None:
    upstream = await connect("R1")
    onboard = Bus()
    link = Link(onboard.endpoint("link"), upstream, "R1")
    await link.start()
    seen_on_board = Recorder(onboard.endpoint("tasks"), "task_assigned")
    await upstream.sync()
    endpoint = server.app.state.hub.endpoint("task_manager")
    acks = Recorder(endpoint, "ack")
    message = assignment()
    endpoint.send(message)
    endpoint.send(message)  # a retry whose first ack was lost: the same id again
    await acks.wait_for(lambda: len(acks.of("ack", message_id=message.id)) == 2)
    await upstream.sync()
    assert [m.payload["task_id"] for m in seen_on_board.messages] == ["T1"]
    assert link.seen.duplicates == 1
    await link.stop()


async def test_a_robot_report_whose_ack_is_lost_is_resent_and_handled_once(
    server: RunningServer, connect: ClientFactory
) -> None:
    hub = server.app.state.hub
    upstream = await connect("R1", backoff_initial=0.05)
    onboard = Bus()
    link = Link(onboard.endpoint("link"), upstream, "R1", retry_initial_s=0.05, retry_max_s=0.2)
    await link.start()
    await upstream.sync()
    handled: list[Message] = []

    def traffic_manager(message: Message) -> None:
        handled.append(message)
        if len(handled) == 1:
            # Handled, then the link dies before the ack leaves: the robot cannot know.
            hub.clients["R1"].request_close(CLOSE_OVERFLOW, "test: link cut before the ack")

    hub.endpoint("traffic_manager").subscribe("release_area", traffic_manager)
    onboard.endpoint("navigation").publish("release_area", {"robot": "R1", "area": "A1"})
    await wait_until(lambda: link.courier.pending == 0 and link.connections >= 1)
    assert len(handled) == 1  # the copy sent after the reconnect was acknowledged, not re-run
    assert link.resent >= 1
    assert hub.acks.duplicates >= 1
    await link.stop()


async def test_retries_stop_when_the_robot_goes_away(
    server: RunningServer, connect: ClientFactory
) -> None:
    hub = server.app.state.hub
    sites = SimpleNamespace(site=SimpleNamespace(robot=lambda name: name))
    stop_announcing = announce_robot_links(hub, sites)  # the server's robot_disconnected
    robot = await connect("R1")
    copies: list[Message] = []
    robot.subscribe("task_assigned", copies.append)  # never acknowledges
    await robot.sync()
    courier, _ = server_courier(server)
    courier.post(assignment())
    await wait_until(lambda: len(copies) >= 3)
    await robot.close()
    await wait_until(lambda: courier.pending == 0)
    retries = courier.retries
    await asyncio.sleep(5 * FAST["max_s"])
    assert courier.retries == retries  # nothing sent to a robot that is gone
    stop_announcing()


async def test_an_ack_from_another_client_does_not_stop_the_retries(
    server: RunningServer, connect: ClientFactory
) -> None:
    robot = await connect("R1")
    other = await connect("R2")
    copies: list[Message] = []
    robot.subscribe("task_assigned", copies.append)
    await robot.sync()
    courier, acks = server_courier(server)
    sent = courier.post(assignment())
    other.send(ack_for(sent.model_copy(update={"source": "task_manager"}), "R2"))
    await acks.wait("ack", message_id=sent.id)
    await wait_until(lambda: len(copies) >= 2)  # still sent: R2 may not ack R1's messages
    assert courier.pending == 1
    robot.send(ack_for(copies[-1], "R1"))
    await wait_until(lambda: courier.pending == 0)


async def test_a_message_for_an_in_process_module_is_not_kept(server: RunningServer) -> None:
    """The in-process bus delivers synchronously: nothing to lose, nothing to retry."""
    hub = server.app.state.hub
    courier, _ = server_courier(server)
    received = Recorder(hub.endpoint("R9"), "task_assigned")
    courier.post(assignment(robot="R9"))
    assert len(received.messages) == 1 and courier.pending == 0


async def test_a_request_gets_its_reply_not_the_ack(
    server: RunningServer, connect: ClientFactory
) -> None:
    """The hub acknowledges open_door at once; the answer comes when the door is open."""
    building = server.app.state.hub.endpoint("building")

    def open_later(message: Message) -> None:
        loop = asyncio.get_running_loop()
        loop.call_later(0.05, building.reply, message, "door_opened", {"door": "D1"})

    building.subscribe("open_door", open_later)
    robot = await connect("R1")
    reply = await robot.request("open_door", {"door": "D1"}, timeout=5)
    assert reply.type == "door_opened"


async def test_a_task_request_is_sent_again_until_answered(
    server: RunningServer, connect: ClientFactory
) -> None:
    """The hub does not ack it: the Task Manager answers and acks it once the task is written
    (and answers a repeated id with the same task, tests/server/test_tasks.py)."""
    upstream = await connect("R1")
    onboard = Bus()
    link = Link(onboard.endpoint("link"), upstream, "R1", retry_initial_s=0.05, retry_max_s=0.2)
    await link.start()
    await upstream.sync()
    task_manager = server.app.state.hub.endpoint("task_manager")
    copies: list[Message] = []

    def answer_the_second(message: Message) -> None:
        copies.append(message)
        if len(copies) == 2:  # as the Task Manager does: the answer, then the ack
            task_manager.reply(message, "task_event", {"task_id": "T7", "state": "queued"})
            task_manager.send(ack_for(message, "task_manager"))

    task_manager.subscribe("task_request", answer_the_second)
    onboard.endpoint("gui").publish("task_request", {"kind": "tour"})
    await wait_until(lambda: link.courier.pending == 0)
    assert len(copies) >= 2 and {m.id for m in copies} == {copies[0].id}
    sent = len(copies)
    await asyncio.sleep(5 * FAST["max_s"])
    assert len(copies) == sent  # answered: no more copies
    await link.stop()


def test_keyed_messages_are_replaced_and_withdrawn_one_by_one() -> None:
    """The key index stays true through replacement, acks, withdrawal and overflow drops."""
    sent: list[Message] = []
    courier = Courier(sent.append, name="task_manager", max_pending=3)
    first = courier.post(assignment("T1", "R1"), key=("task", "T1", "R1"))
    courier.post(assignment("T2", "R2"), key=("task", "T2", "R2"))
    newer = courier.post(assignment("T1", "R1"), key=("task", "T1", "R1"))  # replaces the first
    assert courier.pending_ids() == [sent[1].id, newer.id]
    assert first.id not in courier.pending_ids()
    # An ack of the replaced copy changes nothing; the ack of the kept one frees its key.
    assert not courier.on_ack(ack_for(first, "R1"))
    assert courier.on_ack(ack_for(newer, "R1"))
    courier.withdraw(("task", "T1", "R1"))  # nothing under that key any more
    assert courier.pending_ids() == [sent[1].id]
    # Overflow drops the oldest (T2's): its key goes with it, and a later T2 is kept anew.
    for n in range(3, 6):
        courier.post(assignment(f"T{n}", "R3"), key=("task", f"T{n}", "R3"))
    assert courier.dropped == 1 and sent[1].id not in courier.pending_ids()
    again = courier.post(assignment("T2", "R2"), key=("task", "T2", "R2"))
    assert again.id in courier.pending_ids() and courier.pending == 3
    courier.withdraw(("task", "T4", "R3"))
    courier.withdraw(("task", "T2", "R2"))
    assert [m.payload["task_id"] for m in sent if m.id in courier.pending_ids()] == ["T5"]
