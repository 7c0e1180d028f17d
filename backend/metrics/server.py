"""The central server's Prometheus metrics (docs/metrics.md), one registry per app.

Two kinds: histograms and counters fed by a tap on the hub (every message passes it once), and
values read only when Prometheus scrapes (queue sizes, clients, Modbus pollers), so nothing is
kept up to date that nobody reads.
"""

from __future__ import annotations

import statistics
import time
from collections import Counter as Tally
from collections import OrderedDict
from collections.abc import Callable, Iterable
from typing import Any

from prometheus_client import CollectorRegistry, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from backend.auth import Role
from backend.metrics.reaction import STEPS, ReactionJoin, steps_ms
from backend.state import AppState
from guidebot.messages import Message
from guidebot.payloads.tasks import ReactionMeasured
from guidebot.service import Service

__all__ = ["ServerMetrics"]

FAST = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)
STEP = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.2, 0.25, 0.3, 0.4, 0.5, 1.0, 2.5)
SLOW = (0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0)
FINAL = frozenset({"done", "failed", "cancelled"})
MAX_TRACKED = 5000  # open requests remembered for wait histograms; oldest forgotten first


def _bounded_put(table: OrderedDict[str, Any], key: str, value: Any) -> None:
    table[key] = value
    while len(table) > MAX_TRACKED:
        table.popitem(last=False)


class ServerMetrics(Service):
    """Everything ``GET /metrics`` shows; ``app_state`` is the FastAPI app's state."""

    def __init__(self, app_state: AppState, endpoint: Any = None) -> None:
        """``endpoint``: the hub endpoint tapped while started (and reaction_measured's
        sender); without one, feed ``observe`` by hand."""
        super().__init__()
        self.state = app_state
        self.endpoint = endpoint
        self.registry = CollectorRegistry(auto_describe=False)
        r = self.registry
        self.delivery = Histogram(
            "guidebot_hub_delivery_latency_seconds",
            "Message timestamp (sender) to the hub routing it, for WebSocket clients' messages",
            buckets=FAST,
            registry=r,
        )
        self.task_wait = Histogram(
            "guidebot_task_wait_seconds",
            "Task requested (created) to assigned to a robot",
            buckets=SLOW,
            registry=r,
        )
        self.task_assignment = Histogram(
            "guidebot_task_assignment_seconds",
            "task_assigned sent to the robot's task_started back",
            buckets=FAST,
            registry=r,
        )
        self.lock_wait = Histogram(
            "guidebot_lock_wait_seconds",
            "request_area to area_granted, per area",
            ["area"],
            buckets=(0.005, 0.05, *SLOW),
            registry=r,
        )
        self.reaction_step = Histogram(
            "guidebot_reaction_step_seconds",
            "Steps of the reaction chain (docs/reaction.md), from live events",
            ["step"],
            buckets=STEP,
            registry=r,
        )
        self.reaction_chain = Histogram(
            "guidebot_reaction_seconds",
            "Building button: first changed sample to the robot's first moving CAN frame",
            buckets=STEP,
            registry=r,
        )
        self.messages_in: Tally[str] = Tally()
        self.messages_out: Tally[str] = Tally()
        self.tasks_ended: Tally[str] = Tally()
        self._created: OrderedDict[str, float] = OrderedDict()
        self._assigned: OrderedDict[str, float] = OrderedDict()
        self._area_requests: OrderedDict[str, tuple[str, float]] = OrderedDict()
        self.join = ReactionJoin(self._requester_of, self._button_input, self._measured)
        self._publish: Callable[[ReactionMeasured], object] | None = None
        r.register(_ScrapeCollector(self))

    # -- feeding -----------------------------------------------------------------------------

    async def on_start(self) -> None:
        """Tap every hub message; reaction_measured goes out on the same endpoint."""
        if self.endpoint is not None:
            self.subscribe(self.endpoint, "*", self.observe, tap=True)
            self._publish = self.endpoint.publish
            self.on_cleanup(self._stop_publishing)

    def _stop_publishing(self) -> None:
        self._publish = None

    def observe(self, message: Message) -> None:
        """One hub message (a tap handler: cheap, never raises into the bus)."""
        type_ = message.type
        self.messages_in[type_] += 1
        hub = self.state.hub
        out = self._recipients(hub, message)
        if out:
            self.messages_out[type_] += out
        if message.source in hub.clients:
            self.delivery.observe(max(0.0, time.time() - message.timestamp))
        handler = _HANDLERS.get(type_)
        if handler is not None:
            handler(self, message)

    @staticmethod
    def _recipients(hub: Any, message: Message) -> int:
        """WebSocket clients this message is queued for, from the hub's subscription table."""
        if message.destination is not None:
            return 1 if message.destination in hub.clients else 0
        return int(hub.recipients(message.type))

    def _on_task_event(self, message: Message) -> None:
        p, now = message.payload, message.timestamp
        task_id, state = str(p.get("task_id")), p.get("state")
        if state == "queued":
            if task_id not in self._created:
                _bounded_put(self._created, task_id, now)
        elif state == "assigned":
            created = self._created.pop(task_id, None)
            if created is not None:
                self.task_wait.observe(max(0.0, now - created))
        elif state in FINAL:
            self.tasks_ended[str(state)] += 1
            self._created.pop(task_id, None)

    def _on_task_assigned(self, message: Message) -> None:
        _bounded_put(self._assigned, str(message.payload.get("task_id")), message.timestamp)
        self.join.on_assigned(message)

    def _on_task_started(self, message: Message) -> None:
        sent = self._assigned.pop(str(message.payload.get("task_id")), None)
        if sent is not None:
            self.task_assignment.observe(max(0.0, message.timestamp - sent))

    def _on_request_area(self, message: Message) -> None:
        area = str(message.payload.get("area"))
        _bounded_put(self._area_requests, message.id, (area, message.timestamp))

    def _on_area_granted(self, message: Message) -> None:
        if message.destination is None:
            return  # the broadcast copy; the reply carries the correlation id
        asked = self._area_requests.pop(message.correlation_id or "", None)
        if asked is not None:
            self.lock_wait.labels(asked[0]).observe(max(0.0, message.timestamp - asked[1]))

    # -- the reaction chain ------------------------------------------------------------------

    def _requester_of(self, task_id: str) -> str | None:
        tasks = self.state.task_manager
        task = tasks.tasks.get(task_id) if tasks is not None else None
        return None if task is None else str(task.requester)

    def _button_input(self, button_id: str) -> tuple[str, str] | None:
        sites = self.state.sites
        for button in sites.site.buttons if sites is not None else ():
            if button.id == button_id:
                return (button.input.module, button.input.point)
        return None

    def _measured(
        self, task_id: str, robot: str, button: str | None, stamps: dict[str, float]
    ) -> None:
        steps = steps_ms(stamps)
        for name, ms in steps.items():
            self.reaction_step.labels(name).observe(max(0.0, ms / 1000))
        if "sampled_at" in stamps:
            self.reaction_chain.observe(max(0.0, stamps["moving_at"] - stamps["sampled_at"]))
        if self._publish is not None:
            self._publish(
                ReactionMeasured(
                    task_id=task_id, robot=robot, button=button, stamps=stamps, steps_ms=steps
                )
            )

    def render(self) -> bytes:
        return generate_latest(self.registry)


_HANDLERS: dict[str, Callable[[ServerMetrics, Message], None]] = {
    "task_event": ServerMetrics._on_task_event,
    "task_assigned": ServerMetrics._on_task_assigned,
    "task_started": ServerMetrics._on_task_started,
    "request_area": ServerMetrics._on_request_area,
    "area_granted": ServerMetrics._on_area_granted,
    "building_input_changed": lambda m, msg: m.join.on_input(msg),
    "task_reaction": lambda m, msg: m.join.on_robot_report(msg),
}


class _ScrapeCollector(Collector):
    """Values read at scrape time from the running services."""

    def __init__(self, metrics: ServerMetrics) -> None:
        self.m = metrics

    def collect(self) -> Iterable[Metric]:
        m, state = self.m, self.m.state
        yield _counter(
            "guidebot_hub_messages_in", "Messages published on the hub", "type", m.messages_in
        )
        yield _counter(
            "guidebot_hub_messages_out",
            "Messages queued for WebSocket clients (one per recipient)",
            "type",
            m.messages_out,
        )
        yield from self._hub(state.hub)
        yield from self._tasks(state.task_manager)
        yield _counter("guidebot_tasks_ended", "Tasks ended, by outcome", "outcome", m.tasks_ended)
        yield from self._modbus(state.building)
        master = state.vda5050  # the VDA 5050 master control, when it runs
        if master is not None:
            yield from master.metrics()
        notifier = state.notify  # the notifier, when it runs (the leader)
        if notifier is not None:
            yield from notifier.metrics()
        steps = GaugeMetricFamily(
            "guidebot_reaction_steps_info",
            "Reaction steps and the paper's step they match",
            labels=["step", "paper"],
        )
        for s in STEPS:
            steps.add_metric([s.name, s.paper], 1)
        yield steps

    @staticmethod
    def _hub(hub: Any) -> Iterable[Metric]:
        dropped = CounterMetricFamily(
            "guidebot_hub_messages_dropped",
            "Messages the hub did not route: refused (invalid, unknown type, impersonation), "
            "superseded in a slow client's queue (robot_state only; connected clients)",
            labels=["type", "reason"],
        )
        dropped.add_metric(["", "refused"], hub.refused)
        superseded = sum(c.outbox.superseded for c in hub.clients.values())
        dropped.add_metric(["robot_state", "superseded"], superseded)
        yield dropped
        yield CounterMetricFamily(
            "guidebot_hub_overflow_disconnects",
            "WebSocket clients closed for not reading (4008)",
            value=hub.overflow_disconnects,
        )
        clients = GaugeMetricFamily("guidebot_hub_clients", "Connected clients", labels=["role"])
        roles = Tally(c.role.value for c in hub.clients.values())
        for role in (r.value for r in Role):
            clients.add_metric([role], roles.get(role, 0))
        yield clients

    @staticmethod
    def _tasks(tasks: Any) -> Iterable[Metric]:
        if tasks is None:
            return
        gauge = GaugeMetricFamily(
            "guidebot_tasks", "Tasks not ended, by state (visitor tasks)", labels=["state"]
        )
        counts = Tally(
            t.state.value for t in tasks.tasks.values() if not t.final and not t.internal
        )
        for name in ("queued", "assigned", "running"):
            gauge.add_metric([name], counts.get(name, 0))
        yield gauge

    @staticmethod
    def _modbus(building: Any) -> Iterable[Metric]:
        period = GaugeMetricFamily(
            "guidebot_modbus_poll_period_seconds", "Configured poll period", labels=["module"]
        )
        jitter = GaugeMetricFamily(
            "guidebot_modbus_poll_jitter_seconds",
            "Poll start minus its slot on the schedule (recent polls), by percentile",
            # Not "quantile": Prometheus reserves it for summaries (promtool refuses it here).
            labels=["module", "percentile"],
        )
        rtt = GaugeMetricFamily(
            "guidebot_modbus_rtt_seconds", "Round trip of the last poll", labels=["module"]
        )
        online = GaugeMetricFamily(
            "guidebot_modbus_online", "1 while the module answers", labels=["module"]
        )
        polls = CounterMetricFamily("guidebot_modbus_polls", "Polls answered", labels=["module"])
        errors = CounterMetricFamily(
            "guidebot_modbus_errors", "Failed polls and commands", labels=["module"]
        )
        overruns = CounterMetricFamily(
            "guidebot_modbus_overruns", "Poll slots skipped (a slow answer)", labels=["module"]
        )
        for poller in building.pollers.values() if building is not None else ():
            name = [poller.module.id]
            period.add_metric(name, poller.period_s)
            samples = sorted(poller.jitter_s)
            if samples:
                jitter.add_metric([*name, "50"], statistics.median(samples))
                jitter.add_metric([*name, "99"], samples[int(0.99 * (len(samples) - 1))])
            health = poller.health
            if health.rtt_ms is not None:
                rtt.add_metric(name, health.rtt_ms / 1000)
            online.add_metric(name, 1 if health.online else 0)
            polls.add_metric(name, health.polls)
            errors.add_metric(name, health.errors)
            overruns.add_metric(name, health.overruns)
        yield from (period, jitter, rtt, online, polls, errors, overruns)


def _counter(name: str, doc: str, label: str, values: Tally[str]) -> CounterMetricFamily:
    family = CounterMetricFamily(name, doc, labels=[label])
    for key, value in sorted(values.items()):
        family.add_metric([key], value)
    return family
