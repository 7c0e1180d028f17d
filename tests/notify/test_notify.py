"""Staff told where they are (issue 44): an alert raised on a real server reaches a real SMTP
server and a real webhook receiver (signature checked the way docs/server.md tells a venue);
quiet hours suppress, a repeat is sent until the alert is acknowledged, a receiver that is down
is retried, given up and shown while the server keeps answering; bad settings are refused."""

from __future__ import annotations

import asyncio
import datetime as dt
import hashlib
import hmac
import logging
from typing import Any

import httpx
import orjson
import pytest

from backend.notify.service import FAILED_KIND, Delivery, Notifier
from backend.testing import RunningServer
from guidebot.messages import Message
from tests.promtool import promtool_accepts

from .conftest import OPERATOR_TOKEN, VIEWER_TOKEN
from .receivers import Hooks, Inbox, closed_port, smtp_server

SECRET = "a-shared-secret-of-the-venue"


def email_channel(to: str = "duty@museum.example", **rules: Any) -> dict[str, Any]:
    return {"kind": "email", "name": "Duty phone", "to": to, **rules}


def webhook_channel(url: str, **rules: Any) -> dict[str, Any]:
    return {"kind": "webhook", "name": "Chat room", "url": url, "secret": SECRET, **rules}


async def set_smtp(admin: httpx.AsyncClient, port: int, **more: Any) -> None:
    body = {"host": "127.0.0.1", "port": port, "security": "none", "sender": "bot@museum.example"}
    answer = await admin.put("/api/notifications/smtp", json={**body, **more})
    assert answer.status_code == 200, answer.text


async def add(admin: httpx.AsyncClient, channel: dict[str, Any]) -> dict[str, Any]:
    answer = await admin.post("/api/notifications/channels", json=channel)
    assert answer.status_code == 201, answer.text
    return dict(answer.json())


def verify(post: Any, secret: str) -> dict[str, Any]:
    """What a venue's receiver does (docs/server.md, "Webhook signature")."""
    timestamp = post.headers["x-guidebot-timestamp"]
    expected = hmac.new(secret.encode(), f"{timestamp}.".encode() + post.body, hashlib.sha256)
    assert hmac.compare_digest(
        post.headers["x-guidebot-signature"], f"sha256={expected.hexdigest()}"
    )
    return dict(orjson.loads(post.body))


async def settled(notifier: Notifier, alert_id: str) -> dict[str, Any]:
    """The delivery of this alert once it is sent, given up or dropped (waits on the
    notifier)."""
    done = asyncio.get_running_loop().create_future()

    def check(delivery: Delivery) -> None:
        if delivery.alert_id == alert_id and delivery.status in ("sent", "failed", "dropped"):
            if not done.done():
                done.set_result(delivery.view())

    notifier.listeners.append(check)
    try:
        for delivery in notifier.log:
            check(delivery)
        return dict(await done)
    finally:
        notifier.listeners.remove(check)


def counted(scrape: str, series: str) -> float:
    (line,) = [line for line in scrape.splitlines() if line.startswith(series + " ")]
    return float(line.split()[-1])


def raise_alert(server: RunningServer, subject: str = "R1", severity: str = "error") -> str:
    alerts = server.app.state.alerts
    return str(
        alerts.raise_("robot_lost", subject, f"robot {subject} lost its connection", severity).id
    )  # type: ignore[arg-type]


async def test_a_raised_alert_reaches_the_smtp_server(
    server: RunningServer, admin: httpx.AsyncClient, inbox: Inbox
) -> None:
    await set_smtp(admin, inbox.port)
    await add(admin, email_channel())
    alert_id = raise_alert(server)
    (mail,) = await inbox.wait_for(1)
    assert mail["To"] == "duty@museum.example"
    assert mail["From"] == "bot@museum.example"
    assert mail["Subject"] == "[GuideBot error] robot R1 lost its connection"
    assert "Alert: robot_lost R1" in mail.get_content()
    delivery = await settled(server.app.state.notify, alert_id)
    assert delivery["status"] == "sent" and delivery["attempts"] == 1, delivery
    assert delivery["result"].startswith("accepted: "), delivery
    logged = (await admin.get("/api/notifications/deliveries")).json()
    assert delivery in logged


async def test_the_smtp_user_and_password_sign_in_and_the_password_is_never_shown(
    server: RunningServer, admin: httpx.AsyncClient, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)  # (aiosqlite logs statements with their values at DEBUG)
    password = "correct horse battery"
    async with smtp_server({"bot": password}) as inbox:
        await set_smtp(admin, inbox.port, username="bot", password=password)
        channel = await add(admin, email_channel())
        # A change without the password keeps it.
        await set_smtp(admin, inbox.port, username="bot")
        answer = await admin.post(f"/api/notifications/channels/{channel['id']}/test")
        assert answer.json()["status"] == "sent", answer.text
        (mail,) = await inbox.wait_for(1)
        assert inbox.logins == ["bot"]
        assert "Test message" in mail["Subject"]
    shown = (await admin.get("/api/notifications")).json()
    assert shown["smtp"]["password_set"] is True and "password" not in shown["smtp"]
    assert password not in orjson.dumps(shown).decode()
    assert password not in caplog.text


async def test_a_webhook_is_signed_and_its_secret_never_shown(
    server: RunningServer,
    admin: httpx.AsyncClient,
    hooks: Hooks,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)  # (aiosqlite logs statements with their values at DEBUG)
    channel = await add(admin, webhook_channel(f"{hooks.url}/chat"))
    assert channel["secret_set"] is True and "secret" not in channel
    alert_id = raise_alert(server, severity="warning")
    (post,) = await hooks.wait_for("/chat", 1)
    payload = verify(post, SECRET)
    assert payload["event"] == "alert"
    assert payload["text"] == "GuideBot warning: robot R1 lost its connection"
    assert payload["alert"]["id"] == alert_id and payload["alert"]["kind"] == "robot_lost"
    assert post.headers["x-guidebot-delivery"] == payload["delivery"]
    # A change that leaves the secret out keeps it: the next message is signed alike.
    changed = {**webhook_channel(f"{hooks.url}/chat"), "name": "Front desk chat"}
    del changed["secret"]
    answer = await admin.put(f"/api/notifications/channels/{channel['id']}", json=changed)
    assert answer.status_code == 200 and answer.json()["secret_set"] is True
    tested = await admin.post(f"/api/notifications/channels/{channel['id']}/test")
    assert tested.json()["status"] == "sent"
    posts = await hooks.wait_for("/chat", 2)
    assert verify(posts[1], SECRET)["event"] == "test"
    listed = (await admin.get("/api/notifications")).text
    assert SECRET not in listed and SECRET not in caplog.text


async def test_quiet_hours_suppress(
    server: RunningServer, admin: httpx.AsyncClient, hooks: Hooks
) -> None:
    now = dt.datetime.now(dt.UTC)
    quiet = {
        "start": (now - dt.timedelta(hours=1)).strftime("%H:%M"),
        "end": (now + dt.timedelta(hours=1)).strftime("%H:%M"),
    }
    quiet_one = await add(admin, webhook_channel(f"{hooks.url}/quiet", quiet=quiet))
    await add(admin, webhook_channel(f"{hooks.url}/loud"))
    warnings = await add(admin, webhook_channel(f"{hooks.url}/warnings", severities=["warning"]))
    alert_id = raise_alert(server)
    await hooks.wait_for("/loud", 1)
    assert hooks.at("/quiet") == [] and hooks.at("/warnings") == []
    log = (await admin.get("/api/notifications/deliveries")).json()
    ours = [(d["channel"], d["status"]) for d in log if d["alert_id"] == alert_id]
    assert (quiet_one["id"], "suppressed") in ours
    muted = next(d for d in log if d["channel"] == quiet_one["id"])
    assert muted["error"].startswith("quiet hours"), muted
    assert not any(c == quiet_one["id"] and status != "suppressed" for c, status in ours)
    assert not any(d["channel"] == warnings["id"] for d in log)  # not its severity: no noise


async def test_a_repeat_is_sent_until_the_alert_is_acknowledged(
    server: RunningServer, admin: httpx.AsyncClient, hooks: Hooks
) -> None:
    notifier: Notifier = server.app.state.notify
    notifier.minute_s = 0.05  # a repeat "minute" of 50 ms
    await add(admin, webhook_channel(f"{hooks.url}/chat", repeat_minutes=1))
    alert_id = raise_alert(server)
    posts = await hooks.wait_for("/chat", 3)
    assert [verify(p, SECRET)["event"] for p in posts[:3]] == ["alert", "repeat", "repeat"]
    operator = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    answer = await admin.post(f"/api/alerts/{alert_id}/ack", headers=operator)
    assert answer.status_code == 200
    acked_at = notifier.clock()
    # Another alert's three messages: time enough for several more repeats of the first.
    other = raise_alert(server, "R2")
    await hooks.wait_for("/chat", len(hooks.at("/chat")) + 3)
    log = notifier.deliveries()
    assert [d for d in log if d["alert_id"] == alert_id and d["created_at"] > acked_at] == []
    assert sum(d["alert_id"] == other for d in log) >= 3


async def test_a_receiver_that_is_down_is_retried_and_shown_while_the_server_answers(
    server: RunningServer, admin: httpx.AsyncClient
) -> None:
    channel = await add(admin, webhook_channel(f"http://127.0.0.1:{closed_port()}/chat"))
    # The test button answers after the first attempt: retrying, saying why.
    tested = (await admin.post(f"/api/notifications/channels/{channel['id']}/test")).json()
    assert tested["status"] == "retrying" and tested["attempts"] == 1, tested
    assert "ConnectError" in tested["error"]
    given_up = asyncio.Event()
    watcher = server.app.state.hub.endpoint("test_watcher")

    def seen(message: Message) -> None:
        if message.payload["kind"] == FAILED_KIND:
            given_up.set()

    watcher.subscribe("alert_raised", seen)
    raise_alert(server)
    await given_up.wait()
    watcher.close()
    log = (await admin.get("/api/notifications/deliveries")).json()
    failed = next(d for d in log if d["reason"] == "alert" and d["alert"].endswith("robot_lost R1"))
    assert failed["status"] == "failed" and failed["attempts"] == 3, failed
    assert "ConnectError" in failed["error"]
    alerts = (await admin.get("/api/alerts")).json()
    shown = next(a for a in alerts if a["kind"] == FAILED_KIND)
    assert shown["subject"] == channel["id"] and "after 3 attempts" in shown["message"]
    # Staff read the log too (not the settings); the metrics count the failures.
    viewer = {"Authorization": f"Bearer {VIEWER_TOKEN}"}
    assert (await admin.get("/api/notifications/deliveries", headers=viewer)).status_code == 200
    assert (await admin.get("/api/notifications", headers=viewer)).status_code == 403
    scrape = (await admin.get("/metrics")).text
    assert counted(scrape, 'guidebot_notifications_given_up_total{kind="webhook"}') >= 1
    assert counted(scrape, 'guidebot_notifications_failed_attempts_total{kind="webhook"}') >= 3
    await promtool_accepts(scrape)


async def test_a_receiver_that_never_answers_costs_the_server_and_other_channels_nothing(
    server: RunningServer, admin: httpx.AsyncClient, hooks: Hooks
) -> None:
    hooks.hang = asyncio.Event()
    silent = await add(admin, webhook_channel(f"{hooks.url}/hang"))
    for robot in ("R1", "R2", "R3", "R4", "R5"):  # more deliveries than a few shared workers
        raise_alert(server, robot)
    await hooks.hanging.wait()  # the first attempt is stuck in the receiver
    pending = asyncio.create_task(admin.post(f"/api/notifications/channels/{silent['id']}/test"))
    for _ in range(3):
        answer = await admin.get("/api/health")
        assert answer.status_code == 200
    other = await add(admin, webhook_channel(f"{hooks.url}/chat"))
    tested = await admin.post(f"/api/notifications/channels/{other['id']}/test")
    assert tested.json()["status"] == "sent"  # not behind the silent channel's deliveries
    log = server.app.state.notify.deliveries()
    ours = [d for d in log if d["channel"] == silent["id"] and "robot_lost" in d["alert"]]
    stuck = [d["status"] for d in ours]
    assert stuck == ["queued"] * 4 + ["sending"]  # newest first: the first one still at it
    assert not pending.done()
    hooks.hang.set()
    assert (await pending).json()["status"] == "sent"


async def test_a_failed_delivery_is_not_retried_once_the_alert_is_acknowledged(
    server: RunningServer, admin: httpx.AsyncClient, hooks: Hooks
) -> None:
    hooks.hang, hooks.status["/hang"] = asyncio.Event(), 500
    await add(admin, webhook_channel(f"{hooks.url}/hang"))
    alert_id = raise_alert(server)
    await hooks.hanging.wait()  # the first attempt is at the receiver
    server.app.state.alerts.acknowledge(alert_id, "operator-1")
    hooks.hang.set()  # it answers 500
    delivery = await settled(server.app.state.notify, alert_id)
    assert delivery["status"] == "dropped" and delivery["attempts"] == 1, delivery
    assert delivery["error"] == "not retried: the alert was acknowledged or resolved"
    assert len(hooks.at("/hang")) == 1


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (email_channel(severities=["fatal"]), "severities"),
        (email_channel(to="duty at museum"), "is not an e-mail address"),
        (email_channel(to="a@b.example\nBcc: all@b.example"), "is not an e-mail address"),
        (webhook_channel("http://chat.museum.example/hook"), "must use https://"),
        (webhook_channel("ftp://chat.museum.example/hook"), "is not an http(s) URL"),
        ({**email_channel(), "colour": "red"}, "colour"),
        (email_channel(quiet={"start": "22:00", "end": "22:00"}), "is empty"),
        (email_channel(hours={"start": "7:00", "end": "19:00"}), "is not a time of day"),
        (email_channel(timezone="Mars/Olympus"), "is not an IANA time zone"),
        (email_channel(days=["mon", "mon"]), "lists a value twice"),
        (email_channel(repeat_minutes=0), "repeat_minutes"),
        (email_channel(repeat_minutes="5"), "repeat_minutes"),
        ({"kind": "pager", "name": "x"}, "kind"),
        ({**webhook_channel("https://chat.museum.example/hook"), "secret": "short"}, "secret"),
    ],
)
async def test_bad_settings_are_refused_saying_why(
    admin: httpx.AsyncClient, body: dict[str, Any], says: str
) -> None:
    answer = await admin.post("/api/notifications/channels", json=body)
    assert answer.status_code == 422, answer.text
    assert says in answer.text, answer.text
    assert (await admin.get("/api/notifications")).json()["channels"] == []


async def test_only_an_admin_changes_the_settings(
    server: RunningServer, admin: httpx.AsyncClient
) -> None:
    operator = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    body = webhook_channel("https://chat.museum.example/hook")
    answer = await admin.post("/api/notifications/channels", json=body, headers=operator)
    assert answer.status_code == 403
    bad_smtp = {"host": "127.0.0.1", "sender": "not an address", "port": 70000}
    answer = await admin.put("/api/notifications/smtp", json=bad_smtp)
    assert answer.status_code == 422 and "port" in answer.text and "sender" in answer.text
