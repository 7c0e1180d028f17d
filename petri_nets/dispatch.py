"""Dispatch (the paper's RoboGraph dispatch): runs net instances over a message bus.

It answers run_petri_net / kill_petri_net, publishes each net's actions, petri_net_ended and
petri_net_event (monitoring), and routes incoming messages to the instances waiting for them.
Sub-nets are started in-process (the same as a run_petri_net carrying the parent's id). Main
tasks run one at a time: the idle net ("waiting" by default) is killed when a main task starts
and started again when it ends.

A net and its sub-nets run on the library's published nets as they were when the net was
started (``NetLibrary.installed``, pinned per instance): publishing a new version changes the
next start, never a task already running.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Mapping
from typing import Any

from pydantic import ValidationError

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.petri import KillPetriNet, PetriNetDebug, RunPetriNet
from petri_nets.clock import Clock, TimerHandle
from petri_nets.compiled import CompiledNet, missing_params
from petri_nets.engine import STEP_BUDGET, Instance
from petri_nets.library import NetLibrary, UnknownNet

__all__ = ["Dispatch", "DispatchError", "MainTaskBusy"]

log = logging.getLogger(__name__)


class DispatchError(ValueError):
    """A start request that cannot be honoured (unknown net, bad parameters, duplicate id)."""


class MainTaskBusy(DispatchError):
    """A main task is already running on this robot."""


class Dispatch:
    """Runs nets from ``library`` on ``bus``; ``open()`` to listen, ``close()`` to stop all."""

    def __init__(
        self,
        bus: BusEndpoint,
        library: NetLibrary,
        clock: Clock,
        *,
        idle_net: str | None = "waiting",
        idle_params: dict[str, Any] | None = None,
        monitor: bool = True,
        max_instances: int = 100_000,
        step_budget: int = STEP_BUDGET,
    ) -> None:
        self.bus = bus
        self.library = library
        self.clock = clock
        self.idle_net = idle_net
        self.idle_params = idle_params or {}
        self.monitor = monitor
        self.max_instances = max_instances
        self.step_budget = step_budget
        self._instances: dict[str, Instance] = {}
        self._leases: dict[str, TimerHandle] = {}
        """Instance id -> when its breakpoints go (a debugger that stops renewing them)."""
        self._pins: dict[Instance, Mapping[str, CompiledNet]] = {}
        """The published nets each instance starts its sub-nets from."""
        self._waiting: dict[str, dict[Instance, None]] = {}
        self._unsubscribe: dict[str, Callable[[], None]] = {}
        self._own: list[Callable[[], None]] = []
        self._ids = itertools.count(1)
        self._main: Instance | None = None
        self._idle: Instance | None = None
        self._open = False

    # ---------------------------------------------------------------- life cycle

    def open(self) -> None:
        """Listen for run/kill requests and start the idle net."""
        if self._open:
            return
        self._open = True
        self._own = [
            self.bus.subscribe("run_petri_net", self._on_run),
            self.bus.subscribe("kill_petri_net", self._on_kill),
            self.bus.subscribe("petri_net_debug", self._on_debug),
        ]
        self._start_idle()

    def close(self) -> None:
        """Kill every instance and stop listening."""
        self._open = False
        for instance in [i for i in self._instances.values() if i.parent is None]:
            instance.kill()
        for unsubscribe in (*self._own, *self._unsubscribe.values()):
            unsubscribe()
        self._own = []
        self._unsubscribe.clear()
        self._waiting.clear()

    def __enter__(self) -> Dispatch:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------------- Python API

    def start(
        self,
        net: str,
        params: dict[str, Any] | None = None,
        main: bool = False,
        *,
        instance_id: str | None = None,
    ) -> str:
        """Start a net; returns its instance id. Raises DispatchError / MainTaskBusy."""
        if main and self._main is not None:
            raise MainTaskBusy(f"main task {self._main.net.name} ({self._main.id}) is running")
        instance = self._create(net, params or {}, None, instance_id, main)
        if main:
            self._main = instance
            if self._idle is not None:
                idle, self._idle = self._idle, None
                idle.kill()
        instance.begin()
        return instance.id

    def kill(self, instance_id: str) -> bool:
        """Kill an instance and its sub-nets; False when no such instance runs."""
        instance = self._instances.get(instance_id)
        if instance is None:
            return False
        instance.kill()
        return True

    def kill_net(self, net: str) -> int:
        """Kill every instance of a net (sub-nets of others included); returns how many."""
        victims = [i for i in self._instances.values() if i.net.name == net]
        for instance in victims:
            instance.kill()
        return len(victims)

    def running(self) -> list[dict[str, Any]]:
        """Every running instance: id, net, main, parent, marking (for GUIs and robot_state);
        ``paused_at`` and ``breakpoints`` while a debugger holds it."""
        out = []
        for i in self._instances.values():
            item: dict[str, Any] = {
                "instance_id": i.id,
                "net": i.net.name,
                "main": i.main,
                "parent": i.parent.id if i.parent else None,
                "marking": i.marking(),
            }
            if i.breakpoints is not None or i.paused_at is not None:
                ids = i.net.trans_ids
                item["paused_at"] = None if i.paused_at is None else ids[i.paused_at]
                item["breakpoints"] = (
                    sorted(ids[t] for t in i.breakpoints.at) if i.breakpoints else []
                )
            out.append(item)
        return out

    def awaited(self) -> list[dict[str, Any]]:
        """What every running instance waits for: instance_id, net, transition, type and the
        payload fields it matches (``Instance.awaited``)."""
        return [
            {"instance_id": i.id, "net": i.net.name, **waiting}
            for i in self._instances.values()
            for waiting in i.awaited()
        ]

    def debug(self, request: PetriNetDebug) -> bool:
        """Breakpoints, step or resume on one instance (False: no such instance, or a step or
        resume of one not paused). Breakpoints go after ``lease_s`` unless renewed."""
        instance = self._instances.get(request.instance_id)
        if instance is None:
            return False
        if request.command == "step":
            return instance.step()
        if request.command == "resume":
            return instance.resume()
        unknown = instance.set_breakpoints(request.breakpoints)
        if unknown:
            log.info("%s: no transition(s) %s to break at", instance.id, ", ".join(unknown))
        lease = self._leases.pop(instance.id, None)
        if lease is not None:
            lease.cancel()
        if request.breakpoints:
            self._leases[instance.id] = self.clock.call_later(
                request.lease_s, lambda: self._lease_over(instance.id)
            )
        return True

    def _lease_over(self, instance_id: str) -> None:
        self._leases.pop(instance_id, None)
        instance = self._instances.get(instance_id)
        if instance is not None:
            log.info("%s: breakpoints not renewed: cleared", instance_id)
            instance.set_breakpoints([])

    def _on_debug(self, message: Message) -> None:
        try:
            self.debug(message.payload_as(PetriNetDebug))
        except ValidationError as exc:
            log.warning("petri_net_debug refused: %s", exc)

    def get(self, instance_id: str) -> Instance | None:
        return self._instances.get(instance_id)

    @property
    def main_task(self) -> str | None:
        return self._main.id if self._main is not None else None

    # ---------------------------------------------------------------- bus requests

    def _on_run(self, message: Message) -> None:
        try:
            request: RunPetriNet = message.payload_as(RunPetriNet)
        except ValidationError as exc:
            reason = "; ".join(
                f"{'.'.join(map(str, e['loc'])) or 'payload'}: {e['msg']}" for e in exc.errors()
            )
            net = message.payload.get("net")
            instance_id = message.payload.get("instance_id")
            self._refuse(
                message,
                "bad_request",
                f"run_petri_net refused: {reason}",
                instance_id if isinstance(instance_id, str) else None,
                net if isinstance(net, str) else "",
            )
            return
        try:
            self.start(request.net, request.params, request.main, instance_id=request.instance_id)
        except DispatchError as exc:
            self._refuse(
                message,
                "busy" if isinstance(exc, MainTaskBusy) else "bad_request",
                str(exc),
                request.instance_id,
                request.net,
            )

    def _refuse(
        self, message: Message, code: str, reason: str, instance_id: str | None, net: str
    ) -> None:
        """Say why, to the requester, and end the request as failed so nobody waits forever."""
        log.warning("run_petri_net refused: %s", reason)
        self.bus.publish(
            "error",
            {"code": code, "reason": reason, "message_id": message.id},
            destination=message.source or None,
            correlation_id=message.id,
        )
        self.bus.publish(
            "petri_net_ended",
            {"net": net, "instance_id": instance_id or "", "outcome": "failed", "parent": None},
        )

    def _on_kill(self, message: Message) -> None:
        try:
            request: KillPetriNet = message.payload_as(KillPetriNet)
        except ValidationError as exc:
            log.warning("kill_petri_net refused: %s", exc)
            return
        if request.instance_id:
            self.kill(request.instance_id)
        elif request.net:
            self.kill_net(request.net)

    # ---------------------------------------------------------------- host of instances

    def _create(
        self,
        net_name: str,
        params: dict[str, Any],
        parent: Instance | None,
        instance_id: str | None,
        main: bool,
    ) -> Instance:
        pin = self.library.installed if parent is None else self._pins.get(parent)
        try:
            net = self.library.get(net_name, pin)
        except UnknownNet as exc:
            raise DispatchError(f"unknown net {exc.args[0]}") from None
        missing = missing_params(net, params)
        if missing:
            raise DispatchError(f"net {net_name}: missing parameter(s) {', '.join(missing)}")
        undeclared = [k for k in params if k not in net.params]
        if undeclared:  # kept (a sender may know more than the net needs), but said
            log.info("net %s: parameter(s) %s not declared", net_name, ", ".join(undeclared))
        if instance_id is None:
            instance_id = f"{net_name}#{next(self._ids)}"
        elif instance_id in self._instances:
            raise DispatchError(f"instance id {instance_id!r} is already running")
        if len(self._instances) >= self.max_instances:
            raise DispatchError(f"too many instances ({self.max_instances})")
        instance = Instance(self, net, instance_id, params, parent, main)
        self._instances[instance_id] = instance
        self._pins[instance] = self.library.installed if pin is None else pin
        for message_type in net.by_type:
            waiting = self._waiting.get(message_type)
            if waiting is None:
                waiting = self._waiting[message_type] = {}
                self._unsubscribe[message_type] = self.bus.subscribe(
                    message_type, self._deliver_to(waiting)
                )
            waiting[instance] = None
        return instance

    @staticmethod
    def _deliver_to(waiting: dict[Instance, None]) -> Callable[[Message], None]:
        def deliver(message: Message) -> None:
            for instance in list(waiting):
                instance.on_message(message)

        return deliver

    def start_child(self, parent: Instance, net: str, params: dict[str, Any]) -> Instance:
        child = self._create(net, params, parent, None, False)
        parent.children[child.id] = child
        child.begin()
        return child

    def publish_action(
        self, instance: Instance, type: str, payload: dict[str, Any], destination: str | None
    ) -> None:
        self.bus.publish(type, payload, destination=destination)

    def event(
        self,
        instance: Instance,
        kind: str,
        transitions: list[str] | None,
        marking: dict[str, int],
    ) -> None:
        """Monitoring: ``fired`` lists a step's firings in order (``transition`` is the last)."""
        if self.monitor:
            payload: dict[str, Any] = {
                "instance_id": instance.id,
                "net": instance.net.name,
                "kind": kind,
                "transition": transitions[-1] if transitions else None,
                "marking": marking,
                "time": self.clock.now(),
            }
            if transitions is not None:
                payload["transitions"] = transitions
            self.bus.publish("petri_net_event", payload)

    def ended(self, instance: Instance) -> None:
        self._instances.pop(instance.id, None)
        self._pins.pop(instance, None)
        lease = self._leases.pop(instance.id, None)
        if lease is not None:
            lease.cancel()
        for message_type in instance.net.by_type:
            waiting = self._waiting.get(message_type)
            if waiting is not None:
                waiting.pop(instance, None)
                if not waiting:
                    del self._waiting[message_type]
                    self._unsubscribe.pop(message_type)()
        self.bus.publish(
            "petri_net_ended",
            {
                "net": instance.net.name,
                "instance_id": instance.id,
                "outcome": instance.outcome,
                "parent": instance.parent.id if instance.parent else None,
            },
        )
        if instance is self._idle:
            self._idle = None
        if instance is self._main:
            self._main = None
            self._start_idle()

    def _start_idle(self) -> None:
        if not self._open or self.idle_net is None or self._main is not None:
            return
        if self._idle is not None and self._idle.running:
            return
        try:
            instance = self._create(self.idle_net, dict(self.idle_params), None, None, False)
        except DispatchError as exc:
            log.error("idle net %s not started: %s", self.idle_net, exc)
            return
        self._idle = instance
        instance.begin()
