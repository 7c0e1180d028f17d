"""A RoboGraph rig: a real in-process bus, a dispatch over a net library, a virtual clock and a
recorder of every message, optionally a scripted environment answering like the robot would."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from petri_nets.clock import VirtualClock
from petri_nets.dispatch import Dispatch
from petri_nets.library import DEFAULT_LIBRARY, NetLibrary
from petri_nets.scripted import ScriptedEnvironment


@dataclass
class Rig:
    bus: Bus
    clock: VirtualClock
    dispatch: Dispatch
    client: Endpoint
    log: list[Message] = field(default_factory=list)
    environment: ScriptedEnvironment | None = None

    def published(self, type: str) -> list[dict[str, Any]]:
        """Payloads of ``type`` messages the nets published."""
        return [m.payload for m in self.log if m.type == type and m.source == "dispatch"]

    def action_types(self) -> list[str]:
        quiet = {"petri_net_event", "petri_net_ended"}
        return [m.type for m in self.log if m.source == "dispatch" and m.type not in quiet]

    def ended(self, instance_id: str) -> str | None:
        for m in self.log:
            if m.type == "petri_net_ended" and m.payload["instance_id"] == instance_id:
                return str(m.payload["outcome"])
        return None

    def fired(self, instance_id: str) -> list[str]:
        return [
            transition
            for m in self.log
            if m.type == "petri_net_event"
            and m.payload["kind"] == "fired"
            and m.payload["instance_id"] == instance_id
            for transition in m.payload["transitions"]
        ]

    def say(self, type: str, **payload: Any) -> None:
        """Publish as the robot's other modules would."""
        self.client.publish(type, payload)

    def run(self, seconds: float = 3600.0) -> None:
        self.clock.advance(seconds)


def make_rig(
    folder: Path = DEFAULT_LIBRARY,
    *,
    replies: dict[str, Any] | None = None,
    idle_net: str | None = None,
) -> Rig:
    bus = Bus()
    clock = VirtualClock()
    dispatch = Dispatch(bus.endpoint("dispatch"), NetLibrary(folder), clock, idle_net=idle_net)
    rig = Rig(bus, clock, dispatch, bus.endpoint("client"))
    rig.client.subscribe("*", rig.log.append, tap=True)
    if replies is not None:
        rig.environment = ScriptedEnvironment(bus, clock, replies)
    dispatch.open()
    return rig


TOUR_POINTS = [
    {"node": "n1", "poi": "p1", "text": "The first point."},
    {"node": "n2", "poi": "p2", "text": "The second point."},
    {"node": "n3", "poi": "p3", "text": "The third point."},
]
