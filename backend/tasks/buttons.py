"""Building buttons ("press to get a robot"): a press becomes a task request.

One live request per button: from the press until its task ends (done, failed or cancelled)
the button's LED is lit, and pressing again adds nothing (the LED is lit again, to show the
press was seen). After a server restart the live requests are found again from the tasks.
"""

from __future__ import annotations

import logging

from backend.tasks.manager import TaskManager
from backend.tasks.model import TaskError, TaskState
from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.building import BuildingInputChanged, SetOutput
from guidebot.payloads.tasks import TaskEvent
from guidebot.service import Service
from guidebot.site.building import Button
from guidebot.site.schema import Site

__all__ = ["ButtonWatcher"]

log = logging.getLogger(__name__)

REQUESTER_PREFIX = "button:"
FINAL = frozenset({TaskState.DONE.value, TaskState.FAILED.value, TaskState.CANCELLED.value})


class ButtonWatcher(Service):
    def __init__(self, endpoint: BusEndpoint, tasks: TaskManager, site: Site) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.tasks = tasks
        self._buttons: dict[tuple[str, str], Button] = {}
        self._by_id: dict[str, Button] = {}
        self._lit: dict[str, Button] = {}  # task id -> button whose LED is on
        self._waiting: dict[str, str] = {}  # button id -> its live task id
        self.presses_ignored = 0
        self.load_site(site)

    def load_site(self, site: Site) -> None:
        self._buttons = {(b.input.module, b.input.point): b for b in site.buttons}
        self._by_id = {b.id: b for b in site.buttons}

    async def on_start(self) -> None:
        self.on(self.endpoint, BuildingInputChanged, self._on_input)
        self.on(self.endpoint, TaskEvent, self._on_task_event)
        for task in self.tasks.tasks.values():  # live requests restored after a restart
            button = self._by_id.get(task.requester.removeprefix(REQUESTER_PREFIX))
            if task.requester.startswith(REQUESTER_PREFIX) and button and not task.final:
                self._track(button, task.id)

    def _on_input(self, _msg: Message, change: BuildingInputChanged) -> None:
        button = self._buttons.get((change.module, change.point))
        if button is None or not change.value:
            return
        waiting = self._waiting.get(button.id)
        if waiting is not None:
            # Pressed again while its request is queued or running: acknowledge, add nothing.
            self.presses_ignored += 1
            self._set_led(button, True)
            return
        try:
            task = self.tasks.request(
                button.task.kind,
                button.task.params,
                priority=button.task.priority,
                requester=f"{REQUESTER_PREFIX}{button.id}",
            )
        except TaskError as exc:
            log.warning("button %s: request refused: %s", button.id, exc)
            return
        if not task.final:
            self._track(button, task.id)

    def _track(self, button: Button, task_id: str) -> None:
        self._waiting[button.id] = task_id
        self._lit[task_id] = button
        self._set_led(button, True)

    def _on_task_event(self, _msg: Message, event: TaskEvent) -> None:
        button = self._lit.get(event.task_id)
        if button is None or event.state not in FINAL:
            return
        del self._lit[event.task_id]
        self._waiting.pop(button.id, None)
        self._set_led(button, False)

    def _set_led(self, button: Button, on: bool) -> None:
        if button.led is not None:
            self.endpoint.publish(
                SetOutput(module=button.led.module, point=button.led.point, value=int(on))
            )
