"""The notifier: every staff alert that opens (``alert_raised`` on the hub, backend/alerts.py)
is offered to each channel; a channel whose rules take it (severity, days, hours, quiet hours)
gets a delivery on its own bounded queue, sent by its own worker (a silent receiver delays
only its channel). A failed attempt is tried again
after a growing delay (``RETRY_DELAYS_S``), then given up: the delivery log shows it and a
``notification_failed`` alert (warning) is raised for the channel, resolved by its next
success. With ``repeat_minutes`` a channel is told again while the alert stays open (neither
acknowledged nor resolved).

Nothing here waits on a mail server or a webhook on the event loop's behalf: attempts run in
the workers, each bounded by its time-out; a full queue drops (and counts) instead of growing.
Only a process that may decide sends (the leader, backend/leadership.py): on a clustered server
the component runs on the leader only and every attempt asks ``may_send`` first.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import logging
import time
import uuid
from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import httpx
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric

from backend.alerts import AlertStore
from backend.notify.model import Channel, EmailChannel, Smtp, WebhookChannel
from backend.notify.senders import SendFailed, send_email, send_webhook
from backend.notify.store import NotifyStore
from guidebot.messages import Message
from guidebot.payloads.alerts import AlertPayload
from guidebot.service import Service, cancel_and_wait

__all__ = ["Delivery", "Notifier"]

log = logging.getLogger(__name__)

QUEUE_SIZE = 200
"""Deliveries waiting for a channel's worker; beyond it a new one is dropped (and counted)."""
RETRY_DELAYS_S = (10.0, 60.0, 300.0, 900.0)
"""After the first failed attempt, wait 10 s, then 1, 5 and 15 minutes: 5 attempts in all."""
ATTEMPT_LIMIT_S = 60.0
"""No attempt lasts longer, whatever the server's time-out says."""
LOG_SIZE = 500
"""Deliveries kept for the console's log (newest); older ones are forgotten."""
FAILED_KIND = "notification_failed"
"""The alert raised when a channel's delivery is given up (its subject: the channel id)."""

Reason = Literal["alert", "repeat", "test"]
KINDS = ("email", "webhook")


@dataclass
class Delivery:
    """One message to one channel, through its attempts."""

    id: str
    channel: str
    channel_name: str
    kind: str
    reason: Reason
    alert_id: str
    alert: str
    """The alert as one line: severity, kind, subject."""
    status: str = "queued"
    """queued, sending, retrying, sent, failed (given up), suppressed (the rules), dropped."""
    attempts: int = 0
    error: str = ""
    """The last failed attempt's reason (kept once sent: it was retried)."""
    result: str = ""
    created_at: float = 0.0
    updated_at: float = 0.0
    next_attempt_at: float | None = None

    def view(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class _Job:
    delivery: Delivery
    alert: dict[str, Any]
    first_done: asyncio.Future[None]


@dataclass
class _Open:
    """An open alert and, per channel that repeats, when it is told again."""

    alert: dict[str, Any]
    next_at: dict[str, float] = field(default_factory=dict)


class Notifier(Service):
    """Channels, the SMTP server, the queue and the delivery log (``app.state.notify``)."""

    def __init__(
        self,
        endpoint: Any,
        store: NotifyStore,
        *,
        alerts: AlertStore | None = None,
        may_send: Callable[[], bool] = lambda: True,
        clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.store = store
        self.alerts = alerts
        self.may_send = may_send
        self.clock = clock
        self.smtp: Smtp | None = None
        self.channels: dict[str, Channel] = {}
        self.retry_delays_s: tuple[float, ...] = RETRY_DELAYS_S
        self.minute_s = 60.0
        """Seconds in a repeat minute (tests shorten it)."""
        self.log: deque[Delivery] = deque(maxlen=LOG_SIZE)
        self.open: dict[str, _Open] = {}
        self.queues: dict[str, asyncio.Queue[_Job]] = {}
        """Per channel: its deliveries waiting for its worker (one attempt at a time)."""
        self._workers: dict[str, asyncio.Task[None]] = {}
        self.sent: Counter[str] = Counter()
        self.failed_attempts: Counter[str] = Counter()
        self.given_up: Counter[str] = Counter()
        self.dropped = 0
        self._wake = asyncio.Event()
        self._retries: set[asyncio.Task[None]] = set()
        self._http: httpx.AsyncClient | None = None
        self.listeners: list[Callable[[Delivery], None]] = []
        """Called with a delivery whenever it ends (sent, failed, dropped) or is retried."""

    # --- life cycle -----------------------------------------------------------------------
    async def on_start(self) -> None:
        self.smtp, self.channels = await self.store.load()
        self._http = httpx.AsyncClient(follow_redirects=False)
        self.on_cleanup(self._http.aclose)
        self.on_cleanup(self._cancel_retries)
        self.subscribe(self.endpoint, "alert_raised", self._raised)
        self.on(self.endpoint, AlertPayload, self._closed, types=["alert_acked", "alert_resolved"])
        self.on_cleanup(self._stop_workers)
        self.spawn(self._repeat(), name="notify-repeat")
        if self.alerts is not None:  # opened before this component started
            for alert in reversed(self.alerts.listing()):
                self.alert_opened(alert)

    async def _cancel_retries(self) -> None:
        for waiting in list(self._retries):
            await cancel_and_wait(waiting)

    # --- settings (the REST routes) -------------------------------------------------------
    async def set_smtp(self, smtp: Smtp) -> Smtp:
        """Store the SMTP server; a password left out keeps the stored one."""
        if smtp.password is None and self.smtp is not None and smtp.username == self.smtp.username:
            smtp = smtp.model_copy(update={"password": self.smtp.password})
        await self.store.save_smtp(smtp, self.clock())
        self.smtp = smtp
        return smtp

    async def put_channel(
        self, rules: EmailChannel | WebhookChannel, channel_id: str | None = None
    ) -> Channel:
        """Create (no id) or replace a channel; a webhook secret left out keeps the stored
        one. KeyError: no such channel."""
        if channel_id is None:
            channel_id = uuid.uuid4().hex[:12]
        else:
            old = self.channels[channel_id]
            if (
                isinstance(rules, WebhookChannel)
                and rules.secret is None
                and isinstance(old.rules, WebhookChannel)
            ):
                rules = rules.model_copy(update={"secret": old.rules.secret})
        channel = Channel(channel_id, rules)
        await self.store.save_channel(channel, self.clock())
        self.channels[channel_id] = channel
        self._wake.set()
        return channel

    async def delete_channel(self, channel_id: str) -> None:
        """KeyError: no such channel."""
        del self.channels[channel_id]
        await self.store.delete_channel(channel_id)
        worker, queue = self._workers.pop(channel_id, None), self.queues.pop(channel_id, None)
        await cancel_and_wait(worker)
        while queue is not None and not queue.empty():
            self._finish(queue.get_nowait(), "dropped", "the channel was deleted")
        if self.alerts is not None:
            self.alerts.resolve(FAILED_KIND, channel_id, "channel deleted")

    def deliveries(self, limit: int = LOG_SIZE) -> list[dict[str, Any]]:
        """The delivery log, newest first."""
        return [d.view() for d in list(self.log)[::-1][:limit]]

    async def test(self, channel_id: str, by: str, wait_s: float = 30.0) -> Delivery:
        """Send a test message to a channel (its rules aside) and wait for its first attempt
        (at most ``wait_s``): the delivery as it stands then. KeyError: no such channel."""
        channel = self.channels[channel_id]
        now = self.clock()
        alert = {
            "id": f"test-{uuid.uuid4().hex[:8]}",
            "kind": "notification_test",
            "subject": channel.rules.name,
            "message": f"Test message from the GuideBot console, sent by {by}",
            "severity": "warning",
            "raised_at": now,
            "last_seen": now,
            "count": 1,
        }
        job = self._enqueue(channel, alert, "test")
        if job is not None:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(job.first_done), wait_s)
            return job.delivery
        return self.log[-1]

    # --- alerts ---------------------------------------------------------------------------
    def _raised(self, message: Message) -> None:
        self.alert_opened(message.payload)

    def _closed(self, message: Message, alert: AlertPayload) -> None:
        self.open.pop(alert.id, None)

    def alert_opened(self, alert: dict[str, Any]) -> None:
        """An alert raised: new or opened again, every channel is offered it; raised again
        while open, it only counts (its latest text is what a repeat sends)."""
        alert_id = str(alert.get("id"))
        if alert.get("acked_at") is not None or alert.get("resolved_at") is not None:
            return
        known = self.open.get(alert_id)
        if known is not None:
            known.alert = dict(alert)
            return
        self.open[alert_id] = opened = _Open(dict(alert))
        for channel in list(self.channels.values()):
            self._offer(channel, opened, "alert")

    def _offer(self, channel: Channel, opened: _Open, reason: Reason) -> None:
        alert = opened.alert
        if alert.get("kind") == FAILED_KIND and alert.get("subject") == channel.id:
            return  # the channel's own failure is not sent to it
        rules, now = channel.rules, self.clock()
        if not rules.enabled or alert.get("severity") not in rules.severities:
            opened.next_at.pop(channel.id, None)  # never this channel's (until it is changed)
            return
        if rules.repeat_minutes is not None:
            opened.next_at[channel.id] = now + rules.repeat_minutes * self.minute_s
            self._wake.set()
        else:
            opened.next_at.pop(channel.id, None)
        why_not = rules.allows(str(alert.get("severity")), now)
        if why_not is None:
            self._enqueue(channel, alert, reason)
        elif reason == "alert":  # outside its days or hours, or in its quiet hours
            self._logged(channel, alert, reason, status="suppressed", error=why_not)

    async def _repeat(self) -> None:
        """Tell the repeating channels again when their time comes, while the alert is open."""
        while True:
            self._wake.clear()
            now, soonest = self.clock(), None
            for opened in list(self.open.values()):
                for channel_id, at in list(opened.next_at.items()):
                    channel = self.channels.get(channel_id)
                    if channel is None or channel.rules.repeat_minutes is None:
                        del opened.next_at[channel_id]
                        continue
                    if at <= now:
                        self._offer(channel, opened, "repeat")
                        at = opened.next_at.get(channel_id, at)
                    soonest = at if soonest is None else min(soonest, at)
            wait = None if soonest is None else max(0.0, soonest - self.clock())
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(wait):
                    await self._wake.wait()

    # --- the queue ------------------------------------------------------------------------
    def _logged(
        self, channel: Channel, alert: dict[str, Any], reason: Reason, **fields: Any
    ) -> Delivery:
        now = self.clock()
        delivery = Delivery(
            id=uuid.uuid4().hex[:16],
            channel=channel.id,
            channel_name=channel.rules.name,
            kind=channel.kind,
            reason=reason,
            alert_id=str(alert.get("id")),
            alert=f"{alert.get('severity')} {alert.get('kind')} {alert.get('subject')}",
            created_at=now,
            updated_at=now,
            **fields,
        )
        self.log.append(delivery)
        return delivery

    def _enqueue(self, channel: Channel, alert: dict[str, Any], reason: Reason) -> _Job | None:
        delivery = self._logged(channel, alert, reason)
        job = _Job(delivery, dict(alert), asyncio.get_running_loop().create_future())
        if not self._put(job):
            return None
        return job

    def _put(self, job: _Job) -> bool:
        if job.delivery.channel not in self.channels:
            self._finish(job, "dropped", "the channel was deleted")
            return False
        try:
            self._queue(job.delivery.channel).put_nowait(job)
        except asyncio.QueueFull:
            self.dropped += 1
            self._finish(job, "dropped", f"the channel's queue is full ({QUEUE_SIZE} waiting)")
            log.warning(
                "notify: %s to %s dropped: queue full",
                job.delivery.reason,
                job.delivery.channel_name,
            )
            return False
        return True

    def _finish(self, job: _Job, status: str, error: str = "") -> None:
        delivery = job.delivery
        delivery.status, delivery.updated_at, delivery.next_attempt_at = status, self.clock(), None
        if error:
            delivery.error = error
        if not job.first_done.done():
            job.first_done.set_result(None)
        self._changed(delivery)

    def _changed(self, delivery: Delivery) -> None:
        for listener in list(self.listeners):
            listener(delivery)

    def _queue(self, channel_id: str) -> asyncio.Queue[_Job]:
        """The channel's queue, its worker started with it."""
        queue = self.queues.get(channel_id)
        if queue is None:
            self.queues[channel_id] = queue = asyncio.Queue(QUEUE_SIZE)
            self._workers[channel_id] = asyncio.get_running_loop().create_task(
                self._work(queue), name=f"notify-{channel_id}"
            )
        return queue

    async def _stop_workers(self) -> None:
        for worker in list(self._workers.values()):
            await cancel_and_wait(worker)
        self._workers.clear()

    async def _work(self, queue: asyncio.Queue[_Job]) -> None:
        while True:
            job = await queue.get()
            try:
                await self._attempt(job)
            except asyncio.CancelledError:  # the channel deleted, the server stopping
                self._finish(job, "dropped", "stopped while sending")
                raise
            except Exception:  # a bug must not stop the worker
                log.exception("notify: delivery %s", job.delivery.id)
                self._finish(job, "failed", "internal error (see the server log)")

    async def _attempt(self, job: _Job) -> None:
        delivery = job.delivery
        channel = self.channels.get(delivery.channel)
        if channel is None:
            return self._finish(job, "dropped", "the channel was deleted")
        if not self.may_send():
            return self._finish(job, "dropped", "this process no longer leads the fleet")
        if delivery.attempts and delivery.reason != "test" and delivery.alert_id not in self.open:
            return self._finish(
                job, "dropped", "not retried: the alert was acknowledged or resolved"
            )
        delivery.attempts += 1
        delivery.status, delivery.updated_at = "sending", self.clock()
        try:
            result = await asyncio.wait_for(self._send(channel, job), ATTEMPT_LIMIT_S)
        except (SendFailed, TimeoutError) as exc:
            self._failed(channel, job, str(exc) or f"no answer within {ATTEMPT_LIMIT_S:.0f} s")
            return
        self.sent[channel.kind] += 1
        delivery.result = result
        self._finish(job, "sent")
        if self.alerts is not None:
            self.alerts.resolve(FAILED_KIND, channel.id, f"{channel.rules.name}: delivered again")

    def _failed(self, channel: Channel, job: _Job, error: str) -> None:
        delivery = job.delivery
        self.failed_attempts[channel.kind] += 1
        log.warning(
            "notify: %s %r attempt %d failed: %s",
            channel.kind,
            channel.rules.name,
            delivery.attempts,
            error,
        )
        if delivery.attempts <= len(self.retry_delays_s):
            delay = self.retry_delays_s[delivery.attempts - 1]
            delivery.error, delivery.status = error, "retrying"
            delivery.updated_at = self.clock()
            delivery.next_attempt_at = delivery.updated_at + delay
            if not job.first_done.done():
                job.first_done.set_result(None)
            self._changed(delivery)
            waiting = asyncio.get_running_loop().create_task(self._retry(job, delay))
            self._retries.add(waiting)
            waiting.add_done_callback(self._retries.discard)
            return
        self.given_up[channel.kind] += 1
        self._finish(job, "failed", error)
        if self.alerts is not None and delivery.reason != "test":
            self.alerts.raise_(
                FAILED_KIND,
                channel.id,
                f"Notifications: {channel.kind} {channel.rules.name!r} not delivered after "
                f"{delivery.attempts} attempts: {error}",
                "warning",
            )

    async def _retry(self, job: _Job, delay: float) -> None:
        await asyncio.sleep(delay)
        job.delivery.status = "queued"
        self._put(job)

    async def _send(self, channel: Channel, job: _Job) -> str:
        rules, alert, delivery = channel.rules, job.alert, job.delivery
        if isinstance(rules, EmailChannel):
            subject, text = email_text(alert, delivery.reason)
            return await send_email(self.smtp, rules, subject, text)
        assert self._http is not None
        now = self.clock()
        payload = webhook_payload(alert, delivery, now)
        return await send_webhook(self._http, rules, payload, int(now))

    # --- metrics (backend/metrics/server.py reads them when scraped) -----------------------
    def metrics(self) -> Iterable[Metric]:
        families = [
            ("sent", "Notifications delivered, by channel kind", self.sent),
            (
                "failed_attempts",
                "Notification attempts that failed (retried or given up)",
                self.failed_attempts,
            ),
            ("given_up", "Notifications not delivered after every attempt", self.given_up),
        ]
        for name, doc, values in families:
            family = CounterMetricFamily(f"guidebot_notifications_{name}", doc, labels=["kind"])
            for kind in KINDS:
                family.add_metric([kind], values[kind])
            yield family
        yield CounterMetricFamily(
            "guidebot_notifications_dropped",
            "Notifications dropped: their channel's queue was full",
            value=self.dropped,
        )
        yield GaugeMetricFamily(
            "guidebot_notifications_queued",
            "Notifications waiting for a worker",
            value=sum(q.qsize() for q in self.queues.values()),
        )


def _when(at: Any) -> str:
    try:
        return dt.datetime.fromtimestamp(float(at), dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    except (TypeError, ValueError, OverflowError):
        return "?"


def email_text(alert: dict[str, Any], reason: Reason) -> tuple[str, str]:
    """The subject and body of an alert's e-mail."""
    severity, message = alert.get("severity"), alert.get("message")
    again = " (still open)" if reason == "repeat" else ""
    subject = f"[GuideBot {severity}] {message}{again}"
    text = "\n".join(
        [
            str(message),
            "",
            f"Severity: {severity}",
            f"Alert: {alert.get('kind')} {alert.get('subject')}",
            f"Raised: {_when(alert.get('raised_at'))} (seen {alert.get('count', 1)} time(s))",
            "",
            "Acknowledge it in the GuideBot console (Alerts): repeats stop then.",
        ]
    )
    return " ".join(subject.split())[:250], text


def webhook_payload(alert: dict[str, Any], delivery: Delivery, now: float) -> dict[str, Any]:
    """The webhook's JSON body (docs/server.md, "Webhook payload")."""
    keys = ("id", "kind", "subject", "message", "severity", "raised_at", "last_seen", "count")
    again = " (still open)" if delivery.reason == "repeat" else ""
    return {
        "event": delivery.reason,
        "delivery": delivery.id,
        "sent_at": now,
        "text": f"GuideBot {alert.get('severity')}: {alert.get('message')}{again}",
        "alert": {key: alert.get(key) for key in keys},
    }
