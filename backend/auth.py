"""Bearer tokens and roles: who may connect to the hub and call the REST API.

A token maps to a ``Principal`` (a name and a role). The name is what the hub stamps as
``source`` on everything the client publishes, so a robot can only ever speak as itself.

Tokens are kept as SHA-256 digests only (``sha256:<hex>``): the server never holds a token it
could leak (docs/security.md). Tokens are long random secrets, not passwords, so one fast hash
is enough; a presented token is hashed and looked up by digest, then the digests are compared
in constant time. Failed sign-ins are limited per network address (``Authenticator``).
"""

from __future__ import annotations

import contextlib
import enum
import hashlib
import re
import secrets
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import Protocol, cast

from fastapi import HTTPException, Request, status

from backend.ratelimit import RateLimited, RateLimiter
from backend.state import app_state

__all__ = [
    "PERSON_ROLES",
    "Authenticator",
    "Principal",
    "Role",
    "RoleCheck",
    "SessionGate",
    "SignInRefused",
    "TokenStore",
    "bearer_token",
    "client_address",
    "is_digest",
    "require_roles",
    "token_digest",
]

DIGEST_PREFIX = "sha256:"
_DIGEST = re.compile(r"^sha256:[0-9a-f]{64}$")


class Role(enum.StrEnum):
    ADMIN = "admin"
    OPERATOR = "operator"
    PANEL = "panel"
    GUI = "gui"
    MODULE = "module"
    ROBOT = "robot"
    # People with accounts (backend/accounts): the site editor, the net editor, read-only staff
    INSTALLER = "installer"
    AUTHOR = "author"
    VIEWER = "viewer"


PERSON_ROLES = frozenset({Role.ADMIN, Role.OPERATOR, Role.INSTALLER, Role.AUTHOR, Role.VIEWER})
"""The roles an account (a person) may have; tokens may have any role."""


@dataclass(frozen=True, slots=True)
class Principal:
    name: str
    role: Role


def is_digest(value: str) -> bool:
    """True for a stored token digest ``sha256:<64 hex>`` (as opposed to a token)."""
    return bool(_DIGEST.match(value))


def token_digest(token: str) -> str:
    """The stored form of a token; a digest is returned unchanged."""
    if is_digest(token):
        return token
    return DIGEST_PREFIX + hashlib.sha256(token.encode()).hexdigest()


class TokenStore:
    """Token digests known to the server; looked up on every connection and REST call."""

    def __init__(self) -> None:
        self._tokens: dict[str, Principal] = {}

    def add(self, token: str, name: str, role: Role | str) -> Principal:
        """Register a token, or the digest of one (``sha256:<hex>``)."""
        if not token:
            raise ValueError("a token may not be empty")
        principal = Principal(name=name, role=Role(role))
        self._tokens[token_digest(token)] = principal
        return principal

    def remove(self, token: str) -> None:
        self._tokens.pop(token_digest(token), None)

    def lookup(self, token: str | None) -> Principal | None:
        if not token or is_digest(token):
            return None  # a digest is what we store, never a credential
        digest = token_digest(token)
        principal = self._tokens.get(digest)
        # The dict finds the digest by its hash; compare the full digest in constant time so
        # nothing depends on how much of it matched.
        stored = digest if principal is not None else DIGEST_PREFIX + "0" * 64
        if not secrets.compare_digest(stored, digest) or principal is None:
            return None
        return principal

    def __contains__(self, token: str) -> bool:
        return token_digest(token) in self._tokens

    def __len__(self) -> int:
        return len(self._tokens)


class SignInRefused(Exception):
    """Authentication failed: ``status`` 401 (unknown token) or 429 (too many failures)."""

    def __init__(self, status_code: int, reason: str, retry_after: int | None = None) -> None:
        super().__init__(reason)
        self.status_code = status_code
        self.reason = reason
        self.retry_after = retry_after


class Authenticator:
    """Tokens plus a limit on failed attempts per network address.

    An address over its budget of failures is refused with 429 for every attempt, right token
    or not, until its bucket refills: otherwise guessing would go on, only answered differently.
    """

    def __init__(self, tokens: TokenStore, failures: RateLimiter) -> None:
        self.tokens = tokens
        self.failures = failures

    def authenticate(self, token: str | None, address: str) -> Principal:
        wait = self.failures.wait_time(address)
        if wait > 0:
            retry = max(1, int(wait + 0.999))
            raise SignInRefused(
                status.HTTP_429_TOO_MANY_REQUESTS,
                f"too many failed sign-in attempts from this address; try again in {retry} s",
                retry,
            )
        if not token:
            # No credential at all: nothing was guessed, so nothing is counted. A page whose
            # session ended (expired, signed out) sends its requests in flight without one,
            # each refused: counted, they spent the address's budget and its person's next
            # sign-in met 429 (docs/security.md, "Rate limits").
            raise SignInRefused(status.HTTP_401_UNAUTHORIZED, "missing or unknown bearer token")
        principal = self.tokens.lookup(token)
        if principal is None:
            # Counted even when this failure empties the bucket: the next attempt gets 429.
            with contextlib.suppress(RateLimited):
                self.failures.spend(address, "failed sign-ins")
            raise SignInRefused(status.HTTP_401_UNAUTHORIZED, "missing or unknown bearer token")
        return principal


def bearer_token(authorization: str | None, query_token: str | None = None) -> str | None:
    """The token of a request: ``Authorization: Bearer <t>`` first, else ``?token=<t>``."""
    if authorization:
        scheme, _, value = authorization.partition(" ")
        if scheme.lower() == "bearer" and value.strip():
            return value.strip()
    return query_token or None


def client_address(request_client: object) -> str:
    """The peer address of a request or WebSocket (``unknown`` behind odd transports)."""
    host = getattr(request_client, "host", None)
    return str(host) if host else "unknown"


class SessionGate(Protocol):
    """A person's session cookie as a principal (backend/accounts, on ``app.state.sessions``):
    None without a live session; HTTPException 403 for a state-changing request without the
    session's CSRF token."""

    async def __call__(self, request: Request) -> Principal | None: ...


class RoleCheck(Protocol):
    """A route's token check; ``roles`` and ``action`` say what it lets through (the docs'
    tables are tested against them)."""

    roles: frozenset[Role]
    action: str | None

    def __call__(self, request: Request) -> Awaitable[Principal]: ...


def require_roles(*roles: Role, action: str | None = None) -> RoleCheck:
    """FastAPI dependency: 401 without a known token or live session, 429 after too many
    failed attempts, 403 for another role; admin passes all. A request without a token is
    checked for a person's session cookie (``SessionGate``). ``action``: the rule these roles
    come from. The principal is kept on ``request.state.principal`` (the audit trail)."""
    allowed = frozenset(roles) | {Role.ADMIN}

    async def dependency(request: Request) -> Principal:
        auth: Authenticator = request.app.state.auth
        headers, query = request.headers, request.query_params
        token = bearer_token(headers.get("authorization"), query.get("token"))
        sessions: SessionGate | None = app_state(request.app).sessions
        principal = await sessions(request) if token is None and sessions is not None else None
        try:
            if principal is None:
                principal = auth.authenticate(token, client_address(request.client))
        except SignInRefused as exc:
            extra = {"WWW-Authenticate": "Bearer"}
            if exc.retry_after is not None:
                extra["Retry-After"] = str(exc.retry_after)
            raise HTTPException(exc.status_code, exc.reason, headers=extra) from None
        request.state.principal = principal
        if principal.role is not Role.ADMIN and principal.role not in allowed:
            raise HTTPException(
                status.HTTP_403_FORBIDDEN,
                f"role {principal.role.value!r} may not do this "
                f"(needs one of {sorted(r.value for r in allowed)})",
            )
        return principal

    check = cast(RoleCheck, dependency)
    check.roles = allowed
    check.action = action
    return check
