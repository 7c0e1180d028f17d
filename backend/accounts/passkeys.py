"""Passkeys (WebAuthn, the ``webauthn`` package): a signed-in person adds one; anyone signs in
with one, without typing a name (discoverable credentials: the authenticator says whose it
is). Challenges are random, single-use, kept in memory for ``CHALLENGE_TTL_S``; the server
stores public keys only. The relying party is this server's host name (or
``GUIDEBOT_PASSKEY_RP_ID``) and the page's origin must be this server (docs/security.md)."""

from __future__ import annotations

import secrets
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import orjson
from sqlalchemy import delete, func, select, update
from webauthn import (
    base64url_to_bytes,
    generate_authentication_options,
    generate_registration_options,
    options_to_json,
    verify_authentication_response,
    verify_registration_response,
)
from webauthn.helpers import bytes_to_base64url
from webauthn.helpers.exceptions import WebAuthnException
from webauthn.helpers.structs import (
    AuthenticatorSelectionCriteria,
    PublicKeyCredentialDescriptor,
    ResidentKeyRequirement,
    UserVerificationRequirement,
)

from backend.accounts.service import AccountError, AccountService, Session
from backend.auth import SignInRefused
from backend.db.models import PasskeyRow

__all__ = ["CHALLENGE_TTL_S", "PasskeyService", "RelyingParty"]

CHALLENGE_TTL_S = 120.0
MAX_CHALLENGES = 10_000
RP_NAME = "GuideBot"


NOT_ACCEPTED = "this passkey was not accepted (unknown here, removed, or a bad answer)"
"""A refused passkey's 401 (the page says "This passkey was not accepted.")."""


@dataclass(frozen=True, slots=True)
class RelyingParty:
    """Who the passkeys are for: the host name (RP ID) and the page's origin."""

    rp_id: str
    origin: str


@dataclass(frozen=True, slots=True)
class _Challenge:
    value: bytes
    account: str | None
    """Registration: the signed-in account; sign-in: None."""
    expires: float


class PasskeyService:
    def __init__(self, accounts: AccountService) -> None:
        self.accounts = accounts
        self._challenges: OrderedDict[str, _Challenge] = OrderedDict()

    def _remember(self, value: bytes, account: str | None) -> str:
        now = time.monotonic()
        while self._challenges and (
            len(self._challenges) >= MAX_CHALLENGES
            or next(iter(self._challenges.values())).expires < now
        ):
            self._challenges.popitem(last=False)
        challenge_id = secrets.token_urlsafe(16)
        self._challenges[challenge_id] = _Challenge(value, account, now + CHALLENGE_TTL_S)
        return challenge_id

    def _take(self, challenge_id: str, account: str | None) -> bytes | None:
        """The challenge, once (None: unknown, used, expired or another account's)."""
        challenge = self._challenges.pop(challenge_id, None)
        if challenge is None or challenge.expires < time.monotonic():
            return None
        if challenge.account != account:
            return None
        return challenge.value

    async def _rows(self, account: str) -> list[PasskeyRow]:
        async with self.accounts.store.sessionmaker() as db:
            query = select(PasskeyRow).where(PasskeyRow.account == account)
            return list((await db.execute(query)).scalars())

    async def listed(self, account: str) -> list[dict[str, Any]]:
        return [
            {
                "id": row.credential_id[:16],
                "label": row.label,
                "created_at": row.created_at,
                "last_used": row.last_used,
            }
            for row in await self._rows(account)
        ]

    async def counts(self) -> dict[str, int]:
        """How many passkeys each account has (accounts without one are left out)."""
        async with self.accounts.store.sessionmaker() as db:
            query = select(PasskeyRow.account, func.count()).group_by(PasskeyRow.account)
            return {account: int(n) for account, n in await db.execute(query)}

    # --- removing ---------------------------------------------------------------------------
    async def remove(self, account: str, short_id: str, *, by: str, address: str) -> None:
        """Remove one of ``account``'s passkeys, named by the start of its id as ``listed``
        shows it (a person's own, or an admin's). 404 for none of the account's."""
        rows = [r for r in await self._rows(account) if r.credential_id.startswith(short_id)]
        if not short_id or len(rows) != 1:
            raise AccountError(404, f"{account!r} has no passkey {short_id!r}")
        await self._delete(account, [rows[0].credential_id])
        self._removed(by, address, account, 1, rows[0].label)

    async def remove_all(self, account: str, *, by: str, address: str) -> int:
        """An admin removes every passkey of ``account`` (a lost phone or laptop) and ends its
        sessions (the lost device may still hold one); how many there were. 404 for no such
        account."""
        if await self.accounts.store.get(account) is None:
            raise AccountError(404, f"no account named {account!r}")
        rows = await self._rows(account)
        await self._delete(account, [r.credential_id for r in rows])
        await self.accounts.end_all(account, "passkeys removed")
        self._removed(by, address, account, len(rows), "")
        return len(rows)

    async def _delete(self, account: str, ids: list[str]) -> None:
        async with self.accounts.store.sessionmaker() as db, db.begin():
            await db.execute(
                delete(PasskeyRow).where(
                    PasskeyRow.account == account, PasskeyRow.credential_id.in_(ids)
                )
            )

    def _removed(self, by: str, address: str, account: str, count: int, label: str) -> None:
        data: dict[str, Any] = {"account": by, "address": address, "target": account}
        data |= {"change": "passkey_removed", "passkeys": count}
        if label:
            data["label"] = label
        self.accounts.audit("account_changed", by, data)

    # --- adding one -------------------------------------------------------------------------
    async def registration_options(self, session: Session, rp: RelyingParty) -> dict[str, Any]:
        name = session.principal.name
        existing = [
            PublicKeyCredentialDescriptor(id=_bytes(row.credential_id))
            for row in await self._rows(name)
        ]
        options = generate_registration_options(
            rp_id=rp.rp_id,
            rp_name=RP_NAME,
            user_name=name,
            user_id=secrets.token_bytes(16),
            user_display_name=session.display_name or name,
            authenticator_selection=AuthenticatorSelectionCriteria(
                resident_key=ResidentKeyRequirement.REQUIRED,
                user_verification=UserVerificationRequirement.REQUIRED,
            ),
            exclude_credentials=existing,
        )
        challenge_id = self._remember(options.challenge, name)
        return {"challenge_id": challenge_id, "options": orjson.loads(options_to_json(options))}

    async def register(
        self,
        session: Session,
        rp: RelyingParty,
        challenge_id: str,
        credential: dict[str, Any],
        label: str,
        address: str,
    ) -> dict[str, Any]:
        name = session.principal.name
        challenge = self._take(challenge_id, name)
        if challenge is None:
            raise AccountError(409, "the passkey request expired or was used: start again")
        try:
            verified = verify_registration_response(
                credential=credential,
                expected_challenge=challenge,
                expected_rp_id=rp.rp_id,
                expected_origin=rp.origin,
                require_user_verification=True,
            )
        except (WebAuthnException, ValueError, KeyError, TypeError) as exc:
            raise AccountError(422, f"the passkey was not accepted: {exc}") from None
        row = PasskeyRow(
            credential_id=bytes_to_base64url(verified.credential_id),
            account=name,
            public_key=bytes_to_base64url(verified.credential_public_key),
            sign_count=verified.sign_count,
            label=label.strip()[:64],
            created_at=time.time(),
            last_used=None,
        )
        async with self.accounts.store.sessionmaker() as db, db.begin():
            db.add(row)
        self.accounts.audit(
            "account_changed",
            name,
            {"account": name, "address": address, "target": name, "change": "passkey_added"},
        )
        return {"id": row.credential_id[:16], "label": row.label}

    # --- signing in -------------------------------------------------------------------------
    def sign_in_options(self, rp: RelyingParty) -> dict[str, Any]:
        options = generate_authentication_options(
            rp_id=rp.rp_id, user_verification=UserVerificationRequirement.REQUIRED
        )
        challenge_id = self._remember(options.challenge, None)
        return {"challenge_id": challenge_id, "options": orjson.loads(options_to_json(options))}

    async def sign_in(
        self, rp: RelyingParty, challenge_id: str, credential: dict[str, Any], address: str
    ) -> tuple[str, Session]:
        """A session for the passkey's account, or SignInRefused (401 for any passkey that is
        not accepted, counted as a failed sign-in of the address; 403 disabled; 429)."""
        self.accounts.refuse_if_locked(address)
        challenge = self._take(challenge_id, None)
        raw_id = credential.get("id")
        row = None
        if isinstance(raw_id, str) and len(raw_id) <= 1400:
            async with self.accounts.store.sessionmaker() as db:
                row = await db.get(PasskeyRow, raw_id)
        account = await self.accounts.store.get(row.account) if row is not None else None
        if challenge is None or row is None or account is None:
            name = account.name if account else ""
            raise self.accounts.failed(name, address, "passkey", NOT_ACCEPTED)
        self.accounts.refuse_if_locked(address, account.name)
        try:
            verified = verify_authentication_response(
                credential=credential,
                expected_challenge=challenge,
                expected_rp_id=rp.rp_id,
                expected_origin=rp.origin,
                credential_public_key=_bytes(row.public_key),
                credential_current_sign_count=row.sign_count,
                require_user_verification=True,
            )
        except (WebAuthnException, ValueError, KeyError, TypeError):
            # Whatever is wrong with the answer (its shape too), it signs nobody in.
            raise self.accounts.failed(account.name, address, "passkey", NOT_ACCEPTED) from None
        if account.disabled:
            self.accounts.audit(
                "sign_in_failed",
                account.name,
                {"account": account.name, "address": address, "why": "disabled"},
            )
            raise SignInRefused(403, "this account is disabled")
        async with self.accounts.store.sessionmaker() as db, db.begin():
            await db.execute(
                update(PasskeyRow)
                .where(PasskeyRow.credential_id == row.credential_id)
                .values(sign_count=verified.new_sign_count, last_used=time.time())
            )
        return await self.accounts.open_session(account, address, "passkey")


def _bytes(value: str) -> bytes:
    return base64url_to_bytes(value)
