"""Bearer tokens and roles: who may connect to the hub and call the REST API.

A token maps to a ``Principal`` (a name and a role). The name is what the hub stamps as
``source`` on everything the client publishes, so a robot can only ever speak as itself.
"""

from __future__ import annotations

import enum
import secrets
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from fastapi import HTTPException, Request, status

__all__ = ["Principal", "Role", "TokenStore", "bearer_token", "require_roles"]


class Role(enum.StrEnum):
    ADMIN = "admin"
    OPERATOR = "operator"
    PANEL = "panel"
    GUI = "gui"
    MODULE = "module"
    ROBOT = "robot"


@dataclass(frozen=True, slots=True)
class Principal:
    name: str
    role: Role


class TokenStore:
    """Tokens known to the server; looked up on every connection and REST call."""

    def __init__(self) -> None:
        self._tokens: dict[str, Principal] = {}

    def add(self, token: str, name: str, role: Role | str) -> Principal:
        if not token:
            raise ValueError("a token may not be empty")
        principal = Principal(name=name, role=Role(role))
        self._tokens[token] = principal
        return principal

    def remove(self, token: str) -> None:
        self._tokens.pop(token, None)

    def lookup(self, token: str | None) -> Principal | None:
        if not token:
            return None
        principal = self._tokens.get(token)
        if principal is not None:
            return principal
        # Constant-time comparison is what matters for secrets; dict lookup already found none,
        # compare once more against a dummy so timing does not depend on near-misses.
        secrets.compare_digest(token, "x" * len(token))
        return None

    def __len__(self) -> int:
        return len(self._tokens)


def bearer_token(authorization: str | None, query_token: str | None = None) -> str | None:
    """The token of a request: ``Authorization: Bearer <t>`` first, else ``?token=<t>``."""
    if authorization:
        scheme, _, value = authorization.partition(" ")
        if scheme.lower() == "bearer" and value.strip():
            return value.strip()
    return query_token or None


def require_roles(*roles: Role) -> Callable[[Request], Awaitable[Principal]]:
    """FastAPI dependency: 401 without a known token, 403 for another role; admin passes all."""
    allowed = frozenset(roles)

    async def dependency(request: Request) -> Principal:
        store: TokenStore = request.app.state.tokens
        headers, query = request.headers, request.query_params
        token = bearer_token(headers.get("authorization"), query.get("token"))
        principal = store.lookup(token)
        if principal is None:
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED,
                "missing or unknown bearer token",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if principal.role is not Role.ADMIN and principal.role not in allowed:
            raise HTTPException(
                status.HTTP_403_FORBIDDEN,
                f"role {principal.role.value!r} may not do this "
                f"(needs one of {sorted(r.value for r in allowed)})",
            )
        return principal

    return dependency
