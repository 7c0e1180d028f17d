"""Single sign-on with OpenID Connect (authorization code with PKCE: ``authlib``'s RFC 6749
and RFC 7636 requests, sent with httpx; the ID token checked with ``joserfc``): the venue's
identity provider says who the person is and which groups they are in;
``GUIDEBOT_OIDC_ROLES`` maps groups to roles. The account is made (or its role updated) at
each sign-in; a disabled account stays out.

Each sign-in's state, nonce and PKCE verifier are random, single-use and kept in memory for
``FLOW_TTL_S``: a callback with an unknown or used state, or an ID token with another nonce,
issuer or audience, signs nobody in (a failed sign-in of the address)."""

from __future__ import annotations

import hashlib
import secrets
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import httpx
from authlib.oauth2.rfc6749.parameters import prepare_grant_uri, prepare_token_request
from authlib.oauth2.rfc7636 import create_s256_code_challenge
from fastapi import status
from joserfc import jwt
from joserfc.jwk import KeySet

from backend.accounts.service import ACCOUNT_NAME, AccountService, Session
from backend.auth import Role, SignInRefused

__all__ = ["FLOW_TTL_S", "OidcConfig", "SingleSignOn", "SsoRefused"]

FLOW_TTL_S = 600.0
MAX_FLOWS = 10_000
SCOPES = "openid profile groups"
REFUSED = "single sign-on refused: start again from the sign-in page"
RANK = (Role.ADMIN, Role.OPERATOR, Role.INSTALLER, Role.AUTHOR, Role.VIEWER)
"""Several groups mapped: the first of these roles wins."""


@dataclass(frozen=True, slots=True)
class OidcConfig:
    issuer: str
    client_id: str
    client_secret: str | None
    name: str
    groups_claim: str
    roles: dict[str, Role]

    @classmethod
    def from_settings(cls, settings: Any) -> OidcConfig | None:
        """None when single sign-on is off (the settings checked every role is a person's)."""
        if not settings.oidc_issuer:
            return None
        roles = {group: Role(role) for group, role in settings.oidc_roles.items()}
        return cls(
            issuer=settings.oidc_issuer.rstrip("/"),
            client_id=settings.oidc_client_id,
            client_secret=settings.oidc_client_secret,
            name=settings.oidc_name,
            groups_claim=settings.oidc_groups_claim,
            roles=roles,
        )


class SsoRefused(SignInRefused):
    """A refused single sign-on, for the sign-in page to say why: ``code`` (``refused``: a
    wrong state, nonce or token, 401; ``provider``: the provider answered an error, 401;
    ``no_role``, ``disabled``: 403; ``locked``: 429; ``unreachable``: 502) and ``then``, the
    page the sign-in started from (the console's when the state is unknown)."""

    def __init__(self, refused: SignInRefused, code: str, then: str) -> None:
        super().__init__(refused.status_code, refused.reason, refused.retry_after)
        self.code, self.then = code, then


_CODES = {status.HTTP_401_UNAUTHORIZED: "refused", status.HTTP_429_TOO_MANY_REQUESTS: "locked"}


@dataclass(frozen=True, slots=True)
class _Flow:
    nonce: str
    verifier: str
    redirect_uri: str
    then: str
    expires: float


class SingleSignOn:
    def __init__(self, config: OidcConfig, accounts: AccountService) -> None:
        self.config = config
        self.accounts = accounts
        self._flows: OrderedDict[str, _Flow] = OrderedDict()
        self._discovery: dict[str, Any] | None = None

    async def _provider(self) -> dict[str, Any]:
        """The provider's discovery document (read once)."""
        if self._discovery is None:
            url = f"{self.config.issuer}/.well-known/openid-configuration"
            async with httpx.AsyncClient(timeout=10) as http:
                answer = await http.get(url)
                answer.raise_for_status()
                self._discovery = answer.json()
        return self._discovery

    async def start(self, redirect_uri: str, then: str) -> str:
        """The provider's authorization URL to send the browser to."""
        provider = await self._provider()
        now = time.monotonic()
        while self._flows and (
            len(self._flows) >= MAX_FLOWS or next(iter(self._flows.values())).expires < now
        ):
            self._flows.popitem(last=False)
        state, nonce = secrets.token_urlsafe(24), secrets.token_urlsafe(24)
        verifier = secrets.token_urlsafe(48)
        self._flows[state] = _Flow(nonce, verifier, redirect_uri, then, now + FLOW_TTL_S)
        return str(
            prepare_grant_uri(
                provider["authorization_endpoint"],
                self.config.client_id,
                "code",
                redirect_uri=redirect_uri,
                scope=SCOPES,
                state=state,
                nonce=nonce,
                code_challenge=create_s256_code_challenge(verifier),
                code_challenge_method="S256",
            )
        )

    async def finish(
        self, state: str, code: str, address: str, *, error: str = "", then: str = "/admin/"
    ) -> tuple[str, Session, str]:
        """The provider sent the browser back: a session (cookie, session, the page to go
        to), or SsoRefused (401 a wrong state, nonce or token, or the provider's ``error``;
        403 no role or disabled; 429 too many failures). ``then``: the page to go back to
        when the state names no flow."""
        flow = self._flows.pop(state, None)
        if flow is not None:
            then = flow.then
        try:
            self.accounts.refuse_if_locked(address)
            if error or not code:
                why = "sso provider error" if error else "sso answer"
                raise self.accounts.failed("", address, why, REFUSED)
            return (*await self._finish(flow, code, address), then)
        except SsoRefused:
            raise
        except SignInRefused as exc:
            kind = "provider" if error and exc.status_code == 401 else None
            raise SsoRefused(exc, kind or _CODES.get(exc.status_code, "refused"), then) from None

    async def _finish(self, flow: _Flow | None, code: str, address: str) -> tuple[str, Session]:
        if flow is None or flow.expires < time.monotonic():
            raise self.accounts.failed("", address, "sso state", REFUSED)
        provider = await self._provider()
        try:
            body = prepare_token_request(
                "authorization_code",
                code=code,
                redirect_uri=flow.redirect_uri,
                code_verifier=flow.verifier,
                client_id=self.config.client_id,
            )
            secret = self.config.client_secret
            # client_secret_basic with a secret; a public client sends its id in the body.
            auth = httpx.BasicAuth(self.config.client_id, secret) if secret else None
            async with httpx.AsyncClient(timeout=10, auth=auth) as http:
                answer = await http.post(
                    provider["token_endpoint"],
                    content=body,
                    headers={"Content-Type": "application/x-www-form-urlencoded"},
                )
                answer.raise_for_status()
                token = answer.json()
                keys = KeySet.import_key_set((await http.get(provider["jwks_uri"])).json())
            claims = jwt.decode(token["id_token"], keys).claims
            jwt.JWTClaimsRegistry(
                iss={"essential": True, "value": self.config.issuer},
                aud={"essential": True, "value": self.config.client_id},
                nonce={"essential": True, "value": flow.nonce},
                exp={"essential": True},
                sub={"essential": True},
            ).validate(claims)
        except Exception as exc:  # any failure (JoseError, HTTP, a missing claim) signs nobody in
            name = type(exc).__name__
            raise self.accounts.failed("", address, f"sso token ({name})", REFUSED) from None
        return await self._account_session(claims, address, flow.then)

    def role_of(self, claims: dict[str, Any]) -> Role | None:
        groups = claims.get(self.config.groups_claim) or []
        roles = self.config.roles
        mapped = {roles[g] for g in groups if isinstance(g, str) and g in roles}
        return next((role for role in RANK if role in mapped), None)

    @staticmethod
    def account_name(claims: dict[str, Any]) -> str:
        """The account of a provider's person: its preferred_username when that is a valid
        account name, else ``sso-`` and a digest of the subject."""
        wanted = str(claims.get("preferred_username") or "").lower()
        if ACCOUNT_NAME.match(wanted):
            return wanted
        return "sso-" + hashlib.sha256(str(claims["sub"]).encode()).hexdigest()[:12]

    async def _account_session(
        self, claims: dict[str, Any], address: str, then: str
    ) -> tuple[str, Session]:
        name = self.account_name(claims)
        role = self.role_of(claims)
        if role is None:
            self.accounts.audit(
                "sign_in_failed", name, {"account": name, "address": address, "why": "sso no role"}
            )
            refused = SignInRefused(
                status.HTTP_403_FORBIDDEN,
                f"{self.config.name}: none of your groups has a GuideBot role: "
                "ask an administrator",
            )
            raise SsoRefused(refused, "no_role", then)
        display = str(claims.get("name") or "")[:128]
        account = await self.accounts.store.get(name)
        if account is None:
            account = await self.accounts.store.create(name, display, role.value, "")
            self.accounts.audit(
                "account_changed",
                "sso",
                {
                    "account": "sso",
                    "address": address,
                    "target": name,
                    "change": "created",
                    "role": role.value,
                },
            )
        elif account.role != role.value:
            changed = await self.accounts.store.change(name, role=role.value)
            assert changed is not None
            account = changed
            self.accounts.audit(
                "account_changed",
                "sso",
                {
                    "account": "sso",
                    "address": address,
                    "target": name,
                    "change": "changed",
                    "role": role.value,
                },
            )
        if account.disabled:
            self.accounts.audit(
                "sign_in_failed", name, {"account": name, "address": address, "why": "disabled"}
            )
            refused = SignInRefused(status.HTTP_403_FORBIDDEN, "this account is disabled")
            raise SsoRefused(refused, "disabled", then)
        return await self.accounts.open_session(account, address, "sso")
