"""Building buttons ("press to get a robot"): a press becomes a task request; the button's
LED is lit while that task waits and goes off when a robot takes it."""

from __future__ import annotations

from collections.abc import Callable

from backend.site.building import Button
from backend.site.schema import Site
from backend.tasks.manager import TaskManager
from backend.tasks.model import TaskError, TaskState
from guidebot.bus import BusEndpoint
from guidebot.messages import Message

__all__ = ["ButtonWatcher"]


class ButtonWatcher:
    def __init__(self, endpoint: BusEndpoint, tasks: TaskManager, site: Site) -> None:
        self.endpoint = endpoint
        self.tasks = tasks
        self._buttons: dict[tuple[str, str], Button] = {}
        self._lit: dict[str, Button] = {}  # task id -> button whose LED is on
        self._waiting: dict[str, str] = {}  # button id -> task id, one live request per button
        self._unsubscribe: list[Callable[[], None]] = []
        self.load_site(site)

    def load_site(self, site: Site) -> None:
        self._buttons = {(b.input.module, b.input.point): b for b in site.buttons}

    def start(self) -> None:
        self._unsubscribe = [
            self.endpoint.subscribe("building_input_changed", self._on_input),
            self.endpoint.subscribe("task_event", self._on_task_event),
        ]

    def stop(self) -> None:
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe.clear()

    def _on_input(self, msg: Message) -> None:
        key = (str(msg.payload.get("module")), str(msg.payload.get("point")))
        button = self._buttons.get(key)
        if button is None or not msg.payload.get("value"):
            return
        waiting = self._waiting.get(button.id)
        if waiting is not None:
            return  # pressed again while its robot is still coming: one request per button
        try:
            task = self.tasks.request(
                button.task.kind,
                button.task.params,
                priority=button.task.priority,
                requester=f"button:{button.id}",
            )
        except TaskError:
            return
        if task.state is TaskState.QUEUED:
            self._waiting[button.id] = task.id
            self._set_led(button, True)
            self._lit[task.id] = button

    def _on_task_event(self, msg: Message) -> None:
        task_id = str(msg.payload.get("task_id"))
        button = self._lit.get(task_id)
        if button is None or msg.payload.get("state") == TaskState.QUEUED.value:
            return
        del self._lit[task_id]
        self._waiting.pop(button.id, None)
        self._set_led(button, False)

    def _set_led(self, button: Button, on: bool) -> None:
        if button.led is not None:
            self.endpoint.publish(
                "set_output",
                {"module": button.led.module, "point": button.led.point, "value": int(on)},
            )
