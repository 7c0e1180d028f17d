"""The audit trail: every state-changing REST request a person makes (a principal of a
person's role, by account or by a staff token) becomes a ``staff_action`` event with the
account, role, client address, method, path and answer. Never a body, query or header: no
password, cookie or token can reach the log this way. Signing in and out and account
changes are recorded by backend/accounts/service.py with more detail."""

from __future__ import annotations

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.accounts.cookies import SAFE_METHODS
from backend.auth import PERSON_ROLES, Principal
from backend.state import app_state

__all__ = ["AUDIT_KINDS", "SELF_AUDITED", "AuditTrail"]

AUDIT_KINDS = (
    "staff_action",
    "signed_in",
    "sign_in_failed",
    "signed_out",
    "signed_out_everywhere",
    "account_changed",
)
"""The audit trail's event kinds: kept ``GUIDEBOT_AUDIT_RETENTION_DAYS``, not the event log's
``GUIDEBOT_EVENT_RETENTION_DAYS`` (docs/security.md, "Audit")."""

SELF_AUDITED = ("/api/session", "/api/accounts")
"""Paths whose routes record their own, more detailed events."""


class AuditTrail:
    """ASGI middleware (installed by backend/app.py) recording people's actions."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in SAFE_METHODS:
            await self.app(scope, receive, send)
            return
        answer = 500

        async def sending(message: Message) -> None:
            nonlocal answer
            if message["type"] == "http.response.start":
                answer = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, sending)
        finally:
            self._record(scope, answer)

    @staticmethod
    def _record(scope: Scope, answer: int) -> None:
        principal = scope.get("state", {}).get("principal")
        path: str = scope.get("path", "")
        if not isinstance(principal, Principal) or principal.role not in PERSON_ROLES:
            return
        if path.startswith(SELF_AUDITED):
            return
        store = app_state(scope["app"]).store
        if store is None:
            return
        client = scope.get("client")
        address = str(client[0]) if client else "unknown"
        store.record_event(
            "staff_action",
            principal.name,
            {
                "account": principal.name,
                "role": principal.role.value,
                "address": address,
                "method": scope["method"],
                "path": path[:256],
                "status": answer,
            },
        )
