"""The reaction chain (GuideBot paper, section 7.1, Table 1): stamps, steps and their join.

A building input's press travels: BuildingInterface (first changed sample, filter, publish),
Task Manager (task_assigned), the robot's link, RG dispatch, navigation's get_path round trip,
the first velocity command and its CAN frame. The server sees the first half on the hub and the
robot reports the second half in ``task_reaction``; ``ReactionJoin`` puts them together per task
and hands each complete chain to ``on_measured`` (the metrics and ``reaction_measured``).

Stamps are time.time() of the process that took them: comparable when every process runs on
one machine (the benchmark, the demo), offset by the clocks' difference otherwise.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from guidebot.messages import Message

__all__ = ["STAMPS", "STEPS", "ReactionJoin", "Step", "steps_ms"]


@dataclass(frozen=True)
class Step:
    name: str
    start: str
    end: str
    paper: str
    """The paper's step(s) this one matches (Table 1)."""
    what: str


STAMPS: tuple[str, ...] = (
    "pressed_at",
    "sampled_at",
    "input_published_at",
    "assigned_at",
    "received_at",
    "net_started_at",
    "path_requested_at",
    "path_received_at",
    "commanded_at",
    "moving_at",
)
"""In chain order. ``pressed_at`` (T1) is known only to whoever pressed (the benchmark)."""

STEPS: tuple[Step, ...] = (
    Step("modbus_wait", "pressed_at", "sampled_at", "T1-T2 (Modbus)", "wait for the next poll"),
    Step(
        "filter",
        "sampled_at",
        "input_published_at",
        "in T4-T5 (Recv. PN)",
        "200 ms anti-spurious filter, then building_input_changed (T2)",
    ),
    Step(
        "task_manager",
        "input_published_at",
        "assigned_at",
        "T2-T8 (Traffic M., Task M., RG on the server)",
        "ButtonWatcher -> Task Manager picks a robot -> task_assigned",
    ),
    Step("link", "assigned_at", "received_at", "T8-T9 (Robot Wi-Fi Int.)", "hub -> robot link"),
    Step("rg_start", "received_at", "net_started_at", "T9-T10", "task runner -> run_petri_net"),
    Step(
        "req_path",
        "net_started_at",
        "path_requested_at",
        "T10",
        "net evolves to navigate_to -> get_path",
    ),
    Step(
        "get_path",
        "path_requested_at",
        "path_received_at",
        "T10-T11",
        "Traffic Manager over the hub",
    ),
    Step("command", "path_received_at", "commanded_at", "T11-T13", "first set_velocity"),
    Step("can", "commanded_at", "moving_at", "T13-T14", "base entity -> velocity frame on CAN"),
)

MAX_PENDING = 1000
"""Tasks assigned but not yet reported moving; beyond this the oldest are forgotten."""


def steps_ms(stamps: dict[str, float]) -> dict[str, float]:
    """Each step whose two stamps are known, in milliseconds."""
    return {
        s.name: round((stamps[s.end] - stamps[s.start]) * 1000, 3)
        for s in STEPS
        if s.start in stamps and s.end in stamps
    }


class ReactionJoin:
    """Joins building inputs, task assignments and robot reports into one chain per task.

    ``requester_of(task_id)`` names who asked for a task ("button:<id>" for a building button)
    and ``button_input(button_id)`` gives that button's (module, point).
    """

    def __init__(
        self,
        requester_of: Callable[[str], str | None],
        button_input: Callable[[str], tuple[str, str] | None],
        on_measured: Callable[[str, str, str | None, dict[str, float]], None],
    ) -> None:
        self.requester_of = requester_of
        self.button_input = button_input
        self.on_measured = on_measured
        self._inputs: dict[tuple[str, str], tuple[float, float]] = {}
        self._pending: OrderedDict[str, tuple[str, str | None, dict[str, float]]] = OrderedDict()
        # Input -> the task its press created, while that input's own message is still on its
        # way to us (the ButtonWatcher assigns inside the input's publish, before our tap).
        self._awaiting: dict[tuple[str, str], str] = {}

    def on_input(self, message: Message) -> None:
        p = message.payload
        if not p.get("value"):
            return
        sampled = p.get("sampled_at")
        key = (str(p.get("module")), str(p.get("point")))
        seen = (
            float(sampled) if isinstance(sampled, int | float) else message.timestamp,
            message.timestamp,
        )
        self._inputs[key] = seen
        entry = self._pending.get(self._awaiting.pop(key, ""))
        if entry is not None and entry[2]["assigned_at"] >= message.timestamp:
            entry[2]["sampled_at"], entry[2]["input_published_at"] = seen

    def on_assigned(self, message: Message) -> None:
        task_id, robot = message.payload.get("task_id"), message.payload.get("robot")
        if not isinstance(task_id, str) or not isinstance(robot, str):
            return
        stamps = {"assigned_at": message.timestamp}
        button = None
        requester = self.requester_of(task_id) or ""
        if requester.startswith("button:"):
            button = requester.removeprefix("button:")
            ref = self.button_input(button)
            if ref is not None:
                self._awaiting[ref] = task_id
                seen = self._inputs.get(ref)
                if seen is not None and seen[1] <= message.timestamp:
                    stamps["sampled_at"], stamps["input_published_at"] = seen
        self._pending[task_id] = (robot, button, stamps)
        self._pending.move_to_end(task_id)
        while len(self._pending) > MAX_PENDING:
            self._pending.popitem(last=False)

    def on_robot_report(self, message: Message) -> None:
        p = message.payload
        entry = self._pending.pop(str(p.get("task_id")), None)
        if entry is None:
            return
        robot, button, stamps = entry
        if p.get("robot") != robot:
            return
        for name in STAMPS:
            value: Any = p.get(name)
            if name not in stamps and isinstance(value, int | float):
                stamps[name] = float(value)
        self.on_measured(str(p["task_id"]), robot, button, stamps)
