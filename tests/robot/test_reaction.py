"""The robot's reaction stamps (robot_agent/reaction.py) against a real CAN listener."""

from __future__ import annotations

import threading
import uuid

import can

from backend.metrics.reaction import STAMPS
from guidebot.messages import Message
from robot_agent.agent import AgentConfig, RobotAgent
from robot_agent.robocan import protocol as p

from .conftest import Recorder

PATH = {
    "nodes": ["hall", "entrance"],
    "length_m": 5.0,
    "steps": [
        {"node": "hall", "floor": "F0", "x": 5.0, "y": 0.0},
        {"node": "entrance", "floor": "F0", "x": 0.0, "y": 0.0},
    ],
}


class FirstMovingFrame(can.Listener):
    def __init__(self) -> None:
        self.at: float | None = None
        self.seen = threading.Event()

    def on_message_received(self, msg: can.Message) -> None:
        if self.at is None and msg.data and msg.data[0] == p.Op.SET_VELOCITY:
            if int.from_bytes(msg.data[2:6], "little", signed=True) != 0:
                self.at = msg.timestamp
                self.seen.set()


def assigned(task_id: str) -> Message:
    payload = {"task_id": task_id, "robot": "R1", "net": "navigate_to_point"}
    return Message(
        type="task_assigned", source="link", payload={**payload, "params": {"node": "entrance"}}
    )


async def test_stamps_in_chain_order_and_t14_is_the_can_frame() -> None:
    channel = f"reaction-{uuid.uuid4().hex[:8]}"
    tap = FirstMovingFrame()
    tap_bus = can.Bus(interface="virtual", channel=channel)
    notifier = can.Notifier(tap_bus, [tap], timeout=0.05)
    config = AgentConfig(name="R1", can=f"virtual:{channel}", start_node="hall", speech_engine=None)
    try:
        async with RobotAgent(config) as agent:
            await agent.hardware.stack.wait_online(timeout=30)  # type: ignore[union-attr]
            traffic = agent.bus.endpoint("traffic_stand_in")
            traffic.subscribe("get_path", lambda m: traffic.reply(m, "path", PATH))
            seen = Recorder(agent.bus.endpoint("test"), "task_reaction")
            commands = Recorder(agent.bus.endpoint("test-commands"), "set_velocity", tap=True)

            # A task cancelled before the robot moves reports nothing.
            agent.bus.publish(
                Message(type="task_cancel", source="link", payload={"task_id": "nope"})
            )
            agent.bus.publish(assigned("t1"))
            await seen.wait_for(lambda: bool(seen.of("task_reaction")))
            report = seen.of("task_reaction")[0].payload
            assert report["task_id"] == "t1" and report["robot"] == "R1"
            order = [name for name in STAMPS if name in report]
            assert order == list(STAMPS[STAMPS.index("received_at") :])
            stamps = [report[name] for name in order]
            assert stamps == sorted(stamps), report
            assert tap.seen.wait(5.0)
            assert tap.at is not None

            def moving() -> list[Message]:
                sent = commands.of("set_velocity")
                return [m for m in sent if m.payload.get("v") or m.payload.get("w")]

            await commands.wait_for(lambda: len(moving()) >= 2)
            # T14 is stamped after the frame left the master, and for this command: before the
            # next velocity command (8 Hz) was made. (Usually well under 1 ms after the frame;
            # how long after is the machine's load, not checked.)
            after = moving()[1].timestamp
            assert tap.at <= report["moving_at"] < after, (tap.at, report["moving_at"], after)
            # Once per task: later velocity commands of the same task send nothing more.
            assert len(seen.of("task_reaction")) == 1
            assert agent.reaction is not None and agent.reaction.sent == 1
    finally:
        notifier.stop(1.0)
        tap_bus.shutdown()
