"""REST of people's accounts: signing in and out (``/api/session``) and the admins' accounts
API (``/api/accounts``, rule ``manage_accounts``), the event log's export for the venue's
records (``/api/audit/export``)."""

from __future__ import annotations

import csv
import io
import time
from typing import Annotated, Any

import httpx
import orjson
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Request, Response, status
from fastapi.responses import RedirectResponse
from pydantic import BaseModel, ConfigDict, Field

from backend.accounts.cookies import CookieGate, clear_cookie, set_cookie
from backend.accounts.oidc import SingleSignOn, SsoRefused
from backend.accounts.passkeys import PasskeyService, RelyingParty
from backend.accounts.passwords import verify_password
from backend.accounts.service import AccountError, AccountService, Session
from backend.actions import require_action
from backend.auth import Principal, SignInRefused, client_address
from backend.rest.deps import Store, app_service, error_response
from backend.rest.query import OPEN_QUERY
from backend.state import app_state

__all__ = ["SIGN_IN", "router"]

router = APIRouter(tags=["accounts"])

SIGN_IN = {"x-sign-in": True}
"""OpenAPI mark of the routes that take credentials themselves: public, yet they answer 401,
403 and 429 (backend/api/openapi.py keeps those statuses for them)."""

Manager = Annotated[Principal, Depends(require_action("manage_accounts"))]
Reader = Annotated[Principal, Depends(require_action("read"))]

_SIGN_IN_ERRORS: dict[int | str, dict[str, Any]] = {
    401: error_response("wrong account name or password"),
    403: error_response("the account is disabled, or a sign-out without its CSRF token"),
    429: error_response("too many failed sign-ins from this address or for this account"),
}


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class SignIn(_Body):
    name: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


class NewAccount(_Body):
    name: str = Field(min_length=1, max_length=64)
    role: str = Field(min_length=1, max_length=16)
    password: str = Field(min_length=1, max_length=1024)
    display_name: str = Field(default="", max_length=128)


class AccountChange(_Body):
    role: str | None = Field(default=None, max_length=16)
    display_name: str | None = Field(default=None, max_length=128)
    disabled: bool | None = None


class NewPassword(_Body):
    password: str = Field(min_length=1, max_length=1024)


class PasskeyAnswer(_Body):
    challenge_id: str = Field(min_length=1, max_length=64)
    credential: dict[str, Any]
    """The browser's PublicKeyCredential as JSON (``credential.toJSON()``)."""


class NewPasskey(PasskeyAnswer):
    label: str = Field(default="", max_length=64)


class OwnPassword(_Body):
    current: str = Field(min_length=1, max_length=1024)
    password: str = Field(min_length=1, max_length=1024)


def accounts(request: Request) -> AccountService:
    return app_service(request, "accounts", AccountService)


def passkeys(request: Request) -> PasskeyService:
    return app_service(request, "passkeys", PasskeyService)


Accounts = Annotated[AccountService, Depends(accounts)]
Passkeys = Annotated[PasskeyService, Depends(passkeys)]


def relying_party(request: Request) -> RelyingParty:
    """The passkeys' host name and origin: the settings', else the page's own (the Host
    header the browser sent; its origin is checked against it)."""
    settings = request.app.state.settings
    host = request.headers.get("host", "")
    rp_id = settings.passkey_rp_id or (request.url.hostname or "")
    origin = settings.passkey_origin or f"{request.url.scheme}://{host}"
    return RelyingParty(rp_id=rp_id, origin=origin)


def _view(session: Session) -> dict[str, Any]:
    return {
        "name": session.principal.name,
        "display_name": session.display_name,
        "role": session.principal.role.value,
        "csrf": session.csrf,
        "expires_at": session.expires_at,
    }


def _secure(request: Request) -> bool:
    return not request.app.state.settings.development


def _refused(exc: SignInRefused | AccountError) -> HTTPException:
    headers = {}
    if isinstance(exc, SignInRefused) and exc.retry_after is not None:
        headers["Retry-After"] = str(exc.retry_after)
    return HTTPException(exc.status_code, exc.reason, headers=headers or None)


@router.post("/api/session", responses=_SIGN_IN_ERRORS, openapi_extra=SIGN_IN)
async def sign_in(request: Request, body: SignIn, service: Accounts) -> Response:
    """Sign a person in with their account name and password: the session cookie (HttpOnly,
    SameSite=Strict, Secure outside development) and ``csrf``, the token to send as
    ``X-CSRF-Token`` on every state-changing request. 401 for a wrong name or password
    alike; 429 after too many failures (per address, as the token sign-in, and per account)."""
    try:
        cookie, session = await service.sign_in(
            body.name, body.password, client_address(request.client)
        )
    except SignInRefused as exc:
        raise _refused(exc) from None
    return _with_cookie(request, service, cookie, session)


@router.get("/api/session", responses=_SIGN_IN_ERRORS, openapi_extra=SIGN_IN)
async def current_session(request: Request, service: Accounts) -> dict[str, Any]:
    """This browser's session, if its cookie has a live one: ``signed_in`` true with the
    name, display name, role, the CSRF token and when it expires; else ``signed_in`` false
    (never 401: a page asks before it knows; tokens ask ``GET /api/me``)."""
    session = await CookieGate(service).session(request)
    sso = app_state(request.app).sso
    if session is None:
        return {
            "signed_in": False,
            "sso": sso.config.name if isinstance(sso, SingleSignOn) else None,
            "name": None,
            "display_name": None,
            "role": None,
            "csrf": None,
            "expires_at": None,
        }
    return {"signed_in": True, "sso": None, **_view(session)}


@router.delete(
    "/api/session",
    status_code=status.HTTP_204_NO_CONTENT,
    responses=_SIGN_IN_ERRORS,
    openapi_extra=SIGN_IN,
)
async def sign_out(request: Request, service: Accounts) -> Response:
    """Sign this browser out: its session ends (on every page and hub link of it) and the
    cookie is cleared. Without a live session there is nothing to end (204 all the same);
    with one, the CSRF token is required (403 without)."""
    session = await CookieGate(service).session(request)
    if session is not None:
        await CookieGate(service)(request)  # the CSRF check
        await service.sign_out(session, client_address(request.client))
    response = Response(status_code=status.HTTP_204_NO_CONTENT)
    clear_cookie(response, secure=_secure(request))
    return response


def _own_session(request: Request) -> Session:
    session: Session | None = getattr(request.state, "session", None)
    if session is None:
        raise HTTPException(
            status.HTTP_409_CONFLICT, "signed in with a token, not an account: nothing to do"
        )
    return session


@router.post("/api/session/everywhere")
async def sign_out_everywhere(request: Request, _: Reader, service: Accounts) -> dict[str, Any]:
    """End every session of this account (other browsers, other devices, this one): for a
    person who left a console signed in somewhere. 409 for a token."""
    session = _own_session(request)
    address = client_address(request.client)
    ended = await service.end_all(session.principal.name, "signed out everywhere")
    service.audit(
        "signed_out_everywhere",
        session.principal.name,
        {"account": session.principal.name, "address": address, "sessions": ended},
    )
    return {"ended": ended}


@router.post("/api/session/password")
async def change_own_password(
    request: Request, _: Reader, body: OwnPassword, service: Accounts
) -> dict[str, Any]:
    """A person changes their own password (the current one first): every session of the
    account ends, this one too (sign in again). 401 for a wrong current password."""
    session = _own_session(request)
    name = session.principal.name
    account = await service.store.get(name)
    address = client_address(request.client)
    if account is None or not await verify_password(account.password_hash, body.current):
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, "the current password is wrong")
    try:
        await service.reset_password(name, body.password, by=name, address=address)
    except AccountError as exc:
        raise _refused(exc) from None
    return {"name": name}


def _with_cookie(
    request: Request, service: AccountService, cookie: str, session: Session
) -> Response:
    """The session's view, with its cookie set."""
    response = Response(orjson.dumps(_view(session)), media_type="application/json")
    set_cookie(response, cookie, max_age=int(service.max_s), secure=_secure(request))
    return response


@router.post("/api/session/passkey/options", responses=_SIGN_IN_ERRORS, openapi_extra=SIGN_IN)
async def passkey_sign_in_options(request: Request, keys: Passkeys) -> dict[str, Any]:
    """Start a passkey sign-in: ``options`` for ``navigator.credentials.get`` (no account
    named: the authenticator offers the person's passkeys) and the ``challenge_id`` to send
    back. 429 while the address is over its failure budget."""
    try:
        keys.accounts.refuse_if_locked(client_address(request.client))
    except SignInRefused as exc:
        raise _refused(exc) from None
    return keys.sign_in_options(relying_party(request))


@router.post("/api/session/passkey", responses=_SIGN_IN_ERRORS, openapi_extra=SIGN_IN)
async def passkey_sign_in(request: Request, body: PasskeyAnswer, keys: Passkeys) -> Response:
    """Sign in with the authenticator's answer: the session cookie as ``POST /api/session``.
    401 for a passkey not accepted (unknown, another challenge, a bad signature), counted
    as a failed sign-in; 403 for a disabled account."""
    try:
        cookie, session = await keys.sign_in(
            relying_party(request),
            body.challenge_id,
            body.credential,
            client_address(request.client),
        )
    except SignInRefused as exc:
        raise _refused(exc) from None
    return _with_cookie(request, keys.accounts, cookie, session)


_SSO_ANSWERS: dict[int | str, dict[str, Any]] = {
    302: {
        "description": "to the identity provider; back to the page once signed in; or back to "
        "its sign-in form with `#sso_refused=<why>` (refused, provider, no_role, disabled, "
        "locked, unreachable; `&retry=<s>` when locked)"
    },
    404: error_response("single sign-on is not set up (GUIDEBOT_OIDC_ISSUER)"),
}
_NEXT = r"^/[A-Za-z0-9/_.-]{0,64}$"
"""Where a sign-in may send the browser back to: a path of this server, never a URL."""


def _sso(request: Request) -> SingleSignOn:
    sso = app_state(request.app).sso
    if not isinstance(sso, SingleSignOn):
        raise HTTPException(status.HTTP_404_NOT_FOUND, "single sign-on is not set up")
    return sso


def _callback_url(request: Request) -> str:
    configured = request.app.state.settings.oidc_redirect_uri
    host = request.headers.get("host", "")
    return configured or f"{request.url.scheme}://{host}/api/session/oidc/callback"


def _back_refused(then: str, code: str, retry_after: int | None = None) -> RedirectResponse:
    """Back to the page's sign-in form, which says why in words (the fragment carries a code,
    never text: a crafted link cannot put its own words on the form)."""
    retry = f"&retry={retry_after}" if retry_after is not None else ""
    return RedirectResponse(f"{then}#sso_refused={code}{retry}", status.HTTP_302_FOUND)


@router.get("/api/session/oidc/start", responses=_SSO_ANSWERS, openapi_extra=SIGN_IN)
async def sso_start(
    request: Request, then: Annotated[str, Query(alias="next", pattern=_NEXT)] = "/admin/"
) -> RedirectResponse:
    """Single sign-on: to the venue's identity provider (authorization code with PKCE), and
    back to ``next`` (a path of this server) once signed in; back to ``next``'s sign-in form
    with ``#sso_refused=unreachable`` when the provider cannot be reached."""
    sso = _sso(request)
    try:
        url = await sso.start(_callback_url(request), then)
    except httpx.HTTPError:
        return _back_refused(then, "unreachable")
    return RedirectResponse(url, status_code=status.HTTP_302_FOUND)


@router.get(
    "/api/session/oidc/callback",
    responses=_SSO_ANSWERS,
    openapi_extra={**SIGN_IN, OPEN_QUERY: True},  # the provider adds iss, session_state...
)
async def sso_callback(
    request: Request,
    state: Annotated[str, Query(max_length=128)] = "",
    code: Annotated[str, Query(max_length=2048)] = "",
    error: Annotated[str, Query(max_length=256)] = "",
) -> Response:
    """Where the identity provider sends the browser back: with the right state, a code for
    an ID token with the right nonce, and a group mapped to a role, the session cookie and
    302 to the page. Otherwise no cookie and 302 to the page's sign-in form with
    ``#sso_refused=`` and why: ``refused`` (a wrong or used state, a wrong nonce or token:
    a failed sign-in), ``provider`` (the provider's ``error``), ``no_role``, ``disabled``,
    ``locked`` (``&retry=`` seconds)."""
    sso = _sso(request)
    try:
        cookie, _, then = await sso.finish(state, code, client_address(request.client), error=error)
    except SsoRefused as exc:
        return _back_refused(exc.then, exc.code, exc.retry_after)
    response = RedirectResponse(then, status_code=status.HTTP_302_FOUND)
    set_cookie(response, cookie, max_age=int(sso.accounts.max_s), secure=_secure(request))
    return response


@router.get("/api/session/passkeys")
async def own_passkeys(request: Request, _: Reader, keys: Passkeys) -> dict[str, Any]:
    """This person's passkeys (the start of each id, label, added, last used). 409 for a
    token."""
    return {"passkeys": await keys.listed(_own_session(request).principal.name)}


@router.post("/api/session/passkeys/options")
async def passkey_options(request: Request, _: Reader, keys: Passkeys) -> dict[str, Any]:
    """Start adding a passkey to this person's account: ``options`` for
    ``navigator.credentials.create`` and the ``challenge_id``. 409 for a token."""
    return await keys.registration_options(_own_session(request), relying_party(request))


@router.post("/api/session/passkeys", status_code=status.HTTP_201_CREATED)
async def add_passkey(
    request: Request, _: Reader, body: NewPasskey, keys: Passkeys
) -> dict[str, Any]:
    """Keep the passkey the authenticator made (its public key only). 409: the challenge
    expired or was used; 422: the answer is not a valid passkey for this server."""
    try:
        return await keys.register(
            _own_session(request),
            relying_party(request),
            body.challenge_id,
            body.credential,
            body.label,
            client_address(request.client),
        )
    except AccountError as exc:
        raise _refused(exc) from None


@router.delete("/api/session/passkeys/{passkey_id}", status_code=status.HTTP_204_NO_CONTENT)
async def remove_own_passkey(
    request: Request,
    _: Reader,
    passkey_id: Annotated[str, Path(min_length=8, max_length=64, pattern=r"^[A-Za-z0-9_-]+$")],
    keys: Passkeys,
) -> Response:
    """Remove one of this person's passkeys (``id`` as ``GET /api/session/passkeys`` lists
    it): it signs nobody in from now on; sessions stay. 404 for none of theirs; 409 for a
    token."""
    name = _own_session(request).principal.name
    try:
        await keys.remove(name, passkey_id, by=name, address=client_address(request.client))
    except AccountError as exc:
        raise _refused(exc) from None
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/api/accounts")
async def list_accounts(_: Manager, service: Accounts, keys: Passkeys) -> dict[str, Any]:
    """Every account (never a password hash) with its last sign-in and how many passkeys."""
    counts = await keys.counts()
    return {
        "accounts": [
            {**a.public(), "passkeys": counts.get(a.name, 0)} for a in await service.store.all()
        ]
    }


@router.get("/api/accounts/{name}/passkeys")
async def account_passkeys(_: Manager, name: str, keys: Passkeys) -> dict[str, Any]:
    """A person's passkeys (the start of each id, label, added, last used)."""
    if await keys.accounts.store.get(name) is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no account named {name!r}")
    return {"passkeys": await keys.listed(name)}


@router.delete("/api/accounts/{name}/passkeys")
async def remove_account_passkeys(
    request: Request, who: Manager, name: str, keys: Passkeys
) -> dict[str, Any]:
    """Remove every passkey of a person (a lost phone or laptop) and end their sessions: they
    sign in with their password (or a new password an admin sets) and add a passkey again."""
    address = client_address(request.client)
    try:
        removed = await keys.remove_all(name, by=who.name, address=address)
    except AccountError as exc:
        raise _refused(exc) from None
    return {"removed": removed}


@router.post("/api/accounts", status_code=status.HTTP_201_CREATED)
async def create_account(
    request: Request, who: Manager, body: NewAccount, service: Accounts
) -> dict[str, Any]:
    """A new account with a first password the admin gives the person. 409 if the name is
    taken (by an account, a token or a robot), 422 for a bad name, role or password."""
    try:
        account = await service.create(
            body.name,
            body.role,
            body.password,
            body.display_name,
            by=who.name,
            address=client_address(request.client),
        )
    except AccountError as exc:
        raise _refused(exc) from None
    return account.public()


@router.put("/api/accounts/{name}")
async def change_account(
    request: Request, who: Manager, name: str, body: AccountChange, service: Accounts
) -> dict[str, Any]:
    """Change the role, display name or whether it is disabled; a new role or disabling ends
    the account's sessions at once. 409: the last enabled admin stays one."""
    try:
        account = await service.change(
            name,
            by=who.name,
            address=client_address(request.client),
            role=body.role,
            display_name=body.display_name,
            disabled=body.disabled,
        )
    except AccountError as exc:
        raise _refused(exc) from None
    return account.public()


@router.post("/api/accounts/{name}/password")
async def reset_password(
    request: Request, who: Manager, name: str, body: NewPassword, service: Accounts
) -> dict[str, Any]:
    """Set a new password (the person forgot theirs); ends the account's sessions."""
    try:
        account = await service.reset_password(
            name, body.password, by=who.name, address=client_address(request.client)
        )
    except AccountError as exc:
        raise _refused(exc) from None
    return account.public()


EXPORT_COLUMNS = ("id", "time", "kind", "source", "account", "address", "data")


@router.get(
    "/api/audit/export",
    response_class=Response,
    responses={200: {"content": {"text/csv": {}}, "description": "the events as CSV"}},
)
async def export_events(
    _: Manager,
    db: Store,
    person: Annotated[str | None, Query(pattern=r"^[A-Za-z0-9_.:-]{1,64}$")] = None,
    since: Annotated[float, Query(ge=0)] = 0.0,
    until: Annotated[float | None, Query(ge=0)] = None,
) -> Response:
    """The event log as CSV for the venue's records (oldest first): every event, or one
    person's (``person``: their account name), between ``since`` and ``until`` (Unix s)."""
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow(EXPORT_COLUMNS)
    after = 0
    while True:
        page = await db.events(after_id=after, limit=1000, source=person)
        for event in page:
            if event["at"] < since or (until is not None and event["at"] > until):
                continue
            data = event["data"] or {}
            writer.writerow(
                (
                    event["id"],
                    time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(event["at"])),
                    event["kind"],
                    event["source"],
                    data.get("account", ""),
                    data.get("address", ""),
                    orjson.dumps(data).decode(),
                )
            )
        if len(page) < 1000:
            break
        after = page[-1]["id"]
    name = f"guidebot-events-{person or 'all'}.csv"
    return Response(
        out.getvalue(),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )
