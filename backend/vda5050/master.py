"""The master control: one MQTT session for every VDA 5050 robot of the site, each message
checked against the official schema of its topic before it reaches its robot (backend/vda5050/
vehicle.py); what the schema refuses is logged, counted and raised as an alert, never handled."""

from __future__ import annotations

import asyncio
import json
import logging
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from prometheus_client.core import CounterMetricFamily, Metric

from backend.vda5050.pauses import PauseOwner
from backend.vda5050.vehicle import Gate, Holder, Record, Send, VdaRobot, vehicle_of
from guidebot.bus import BusEndpoint
from guidebot.service import Service
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site
from guidebot.vda5050.mqtt import MqttSession
from guidebot.vda5050.schemas import SchemaViolation, check
from guidebot.vda5050.topics import BrokerAddress

__all__ = ["MasterControl"]

log = logging.getLogger(__name__)

INCOMING = frozenset({"state", "connection", "factsheet"})

Alert = Callable[[str, str, str, bool], None]
"""raise (kind, subject, message, lasting) an alert for staff."""
Resolve = Callable[[str, str, str], None]
TaskLookup = Callable[[str, str], tuple[str, dict[str, Any]] | None]
"""(robot, task id) -> the net and parameters of that robot's task, if the Task Manager has it
on that task (not ended): what a new master resumes a vehicle's running order with."""


class MasterControl(Service):
    """The VDA 5050 robots of ``site`` on ``broker``; ``endpoint(name)`` gives hub endpoints."""

    def __init__(
        self,
        site: Site,
        broker: BrokerAddress,
        endpoint: Callable[[str], BusEndpoint],
        *,
        cafile: str | None = None,
        alert: Alert | None = None,
        resolve: Resolve | None = None,
        task_of: TaskLookup | None = None,
        holder: Holder | None = None,
        gate: Gate | None = None,
        record: Record | None = None,
        paused_by: Mapping[str, PauseOwner] | None = None,
    ) -> None:
        super().__init__()
        self.record = record
        """Writes the event log: the master's own pauses, read back by the next one."""
        self.paused_by = dict(paused_by or {})
        """Robot -> who held it paused when the last master control stopped (the event log)."""
        self.task_of = task_of
        self.holder = holder
        """The lock table's holder of an area: a zone grant it took back is REVOKED."""
        self.gate = gate
        self.site = site
        self.broker = broker
        self.endpoint = endpoint
        self.alert = alert
        self.resolve = resolve
        self.robots: dict[tuple[str, str, str], VdaRobot] = {}
        self.refused = 0
        """Messages from vehicles that were not JSON or that their schema refused."""
        self.refused_by: Counter[str] = Counter()
        """The same, by robot (the metric guidebot_vda5050_messages_refused_total)."""
        self.received = 0
        configs = [r for r in site.robots if r.interface == "vda5050"]
        subscriptions = [vehicle_of(r).topic(kind) for r in configs for kind in sorted(INCOMING)]
        self._configs = configs
        self.session = MqttSession(
            broker,
            client_id="guidebot-master",
            subscriptions=subscriptions,
            on_message=self._on_message,
            on_connect=self._on_connect,
            on_error=self._on_error,
            cafile=cafile,
        )

    async def on_start(self) -> None:
        announce = self.endpoint("vda5050")
        self.on_cleanup(announce.close)  # type: ignore[attr-defined]
        self._graph = SiteGraph(self.site, warm=False, tables=False)
        for config in self._configs:
            vehicle = vehicle_of(config)
            ep = self.endpoint(config.name)
            robot = VdaRobot(
                config,
                self.site,
                ep,
                announce,
                self._sender(vehicle.topic),
                task_of=self._task_lookup(config.name),
                step_of=lambda node: self._graph.step(node).as_dict(),
                holder=self.holder,
                gate=self.gate,
                record=self.record,
                paused_by=self.paused_by.get(config.name),
            )
            self.robots[(vehicle.interface, vehicle.manufacturer, vehicle.serial_number)] = robot
            self.on_cleanup(ep.close)  # type: ignore[attr-defined]
            self.on_cleanup(robot.close)
        await self.enter(self.session)
        self.spawn(self._watch_silence(), "vda5050 silence watch")
        log.info("VDA 5050: %d robot(s) on MQTT broker %s", len(self.robots), self.broker)

    @staticmethod
    def identities(site: Site) -> list[tuple[str, ...]]:
        """What of the site's VDA 5050 robots the MQTT session and the hub endpoints are made
        of: a change of these needs a new master control."""
        return sorted(
            (r.name, str(r.manufacturer), str(r.serial_number), r.mqtt_interface, r.vda_version)
            for r in site.robots
            if r.interface == "vda5050"
        )

    def use_site(self, site: Site) -> None:
        """A published site with the same VDA 5050 robots: maps, nodes, areas, zones and
        battery thresholds from now on (docs/vda5050.md, "Site edits")."""
        self.site = site
        self._graph = SiteGraph(site, warm=False, tables=False)
        configs = {r.name: r for r in site.robots if r.interface == "vda5050"}
        for robot in self.robots.values():
            robot.use_site(site, configs[robot.name])

    def _task_lookup(self, robot: str) -> Callable[[str], tuple[str, dict[str, Any]] | None]:
        lookup = self.task_of
        return lambda task_id: lookup(robot, task_id) if lookup is not None else None

    def _sender(self, topic: Callable[[str], str]) -> Send:
        async def send(name: str, message: dict[str, Any]) -> bool:
            check(name, message)  # ours: a refusal here is a bug of the master
            return await self.session.publish(topic(name), message)

        return send

    def _on_connect(self) -> None:
        if self.session.connections > 1:  # back after a loss: what did the vehicles do?
            for robot in self.robots.values():
                self.spawn(robot.instant("stateRequest"), f"stateRequest {robot.name}")
        if self.resolve is not None:
            self.resolve("vda5050_broker", str(self.broker), "connected")

    async def _watch_silence(self) -> None:
        """A vehicle that stops speaking without a last will (its software hangs, or it never
        came back after a broker outage) is disconnected after ``SILENCE_S``."""
        while True:
            await asyncio.sleep(1.0)
            for robot in self.robots.values():
                robot.check_silence()

    def _on_error(self, reason: str) -> None:
        for robot in self.robots.values():
            robot.broker_lost()
        log.error("VDA 5050: cannot reach the MQTT broker %s: %s", self.broker, reason)
        if self.alert is not None:
            self.alert(
                "vda5050_broker",
                str(self.broker),
                f"cannot reach the MQTT broker {self.broker}: {reason}; VDA 5050 robots are "
                "out of reach until it is back",
                True,
            )

    def _on_message(self, topic: str, payload: bytes) -> None:
        self.received += 1
        parts = topic.split("/")
        if len(parts) != 5 or parts[4] not in INCOMING:
            return
        robot = self.robots.get((parts[0], parts[2], parts[3]))
        if robot is None:
            return
        kind = parts[4]
        try:
            message = json.loads(payload)
            check(kind, message)
        except (ValueError, SchemaViolation) as exc:
            self._refuse(robot, topic, exc)
            return
        if kind == "state":
            robot.on_state(message)
        elif kind == "connection":
            robot.on_connection(message)
        else:
            robot.on_factsheet(message)

    def metrics(self) -> Iterable[Metric]:
        """Read at scrape time (backend/metrics/server.py; docs/metrics.md)."""
        received = CounterMetricFamily(
            "guidebot_vda5050_messages_received",
            "Messages from VDA 5050 vehicles on the MQTT broker",
        )
        received.add_metric([], self.received)
        refused = CounterMetricFamily(
            "guidebot_vda5050_messages_refused",
            "Messages from VDA 5050 vehicles ignored: not JSON, or refused by their schema",
            labels=["robot"],
        )
        for name in sorted(r.name for r in self.robots.values()):
            refused.add_metric([name], self.refused_by[name])
        yield from (received, refused)

    def _refuse(self, robot: VdaRobot, topic: str, exc: Exception) -> None:
        self.refused += 1
        self.refused_by[robot.name] += 1
        why = str(exc) if isinstance(exc, SchemaViolation) else f"not JSON: {exc}"
        log.warning("VDA 5050: %s: message on %s ignored: %s", robot.name, topic, why)
        if self.alert is not None:
            self.alert(
                "vda5050_message", robot.name, f"{robot.name} sent a bad message: {why}", False
            )
