"""The two ways out: an e-mail through the venue's SMTP server (aiosmtplib) and a signed JSON
POST (httpx). Each attempt is bounded by a time-out and raises ``SendFailed`` saying why; none
holds the event loop (both clients are asynchronous).

The webhook's signature (docs/server.md, "Webhook signature"): ``X-GuideBot-Signature:
sha256=<hex>``, the HMAC-SHA256 with the channel's secret of the ``X-GuideBot-Timestamp``
value (Unix seconds), a dot and the raw body."""

from __future__ import annotations

import hashlib
import hmac
from email.message import EmailMessage
from email.utils import formatdate, make_msgid
from typing import Any

import aiosmtplib
import httpx
import orjson

from backend.notify.model import EmailChannel, Smtp, WebhookChannel

__all__ = ["SendFailed", "send_email", "send_webhook", "sign"]

WEBHOOK_TIMEOUT_S = 10.0


class SendFailed(Exception):
    """One attempt failed; the text says why (never a secret)."""


def sign(secret: str, timestamp: str, body: bytes) -> str:
    """The signature header's value for ``body`` sent at ``timestamp``."""
    mac = hmac.new(secret.encode(), timestamp.encode() + b"." + body, hashlib.sha256)
    return "sha256=" + mac.hexdigest()


def email_message(smtp: Smtp, channel: EmailChannel, subject: str, text: str) -> EmailMessage:
    message = EmailMessage()
    message["From"] = smtp.sender
    message["To"] = channel.to
    message["Subject"] = subject
    message["Date"] = formatdate(localtime=False)
    message["Message-ID"] = make_msgid(domain=smtp.sender.rpartition("@")[2])
    message["Auto-Submitted"] = "auto-generated"
    message.set_content(text)
    return message


async def send_email(smtp: Smtp | None, channel: EmailChannel, subject: str, text: str) -> str:
    """Hand one message to the SMTP server; returns its answer."""
    if smtp is None:
        raise SendFailed("no SMTP server set (Notifications: SMTP server)")
    message = email_message(smtp, channel, subject, text)
    try:
        _errors, answer = await aiosmtplib.send(
            message,
            hostname=smtp.host,
            port=smtp.port,
            username=smtp.username,
            password=smtp.password,
            use_tls=smtp.security == "tls",
            start_tls=smtp.security == "starttls",
            timeout=smtp.timeout_s,
        )
    except aiosmtplib.SMTPException as exc:
        raise SendFailed(f"SMTP {smtp.host}:{smtp.port}: {_one_line(exc)}") from None
    except OSError as exc:  # refused, unreachable, name not found
        raise SendFailed(f"SMTP {smtp.host}:{smtp.port}: {_one_line(exc)}") from None
    return f"accepted: {_one_line(answer)}"


async def send_webhook(
    client: httpx.AsyncClient, channel: WebhookChannel, payload: dict[str, Any], timestamp: int
) -> str:
    """POST the signed payload; a 2xx answer is delivered, anything else raises."""
    body = orjson.dumps(payload)
    headers = {
        "Content-Type": "application/json",
        "User-Agent": "GuideBot-notify",
        "X-GuideBot-Timestamp": str(timestamp),
        "X-GuideBot-Delivery": str(payload.get("delivery", "")),
    }
    if channel.secret:
        headers["X-GuideBot-Signature"] = sign(channel.secret, str(timestamp), body)
    try:
        answer = await client.post(
            channel.url, content=body, headers=headers, timeout=WEBHOOK_TIMEOUT_S
        )
    except httpx.HTTPError as exc:
        raise SendFailed(f"webhook: {type(exc).__name__}: {_one_line(exc)}") from None
    if not answer.is_success:
        raise SendFailed(f"webhook answered {answer.status_code} {answer.reason_phrase}".strip())
    return f"answered {answer.status_code}"


def _one_line(value: object) -> str:
    text = " ".join(str(value).split())
    return text[:300] or type(value).__name__
