"""Single sign-on (OpenID Connect, authlib) against a real provider: node oidc-provider
(tests/oidc/provider.mjs, installed by scripts/system-deps.sh) started by the test, driven in
Chromium through its own login and consent pages. Hostile cases: a callback with a wrong
state, an ID token with a wrong nonce."""

from __future__ import annotations

import asyncio
import contextlib
import re
import shutil
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import expect

from backend.accounts.oidc import OidcConfig, SingleSignOn
from backend.auth import Role

OIDC = Path(__file__).resolve().parents[1] / "oidc"
NODE = shutil.which("node")

pytestmark = [
    pytest.mark.browser,
    pytest.mark.timeout(120),
    pytest.mark.skipif(
        NODE is None or not (OIDC / "node_modules" / "oidc-provider").is_dir(),
        reason="node and tests/oidc/node_modules (scripts/system-deps.sh) are needed",
    ),
]

ROLES = {"museum-operators": Role.OPERATOR, "museum-installers": Role.INSTALLER}
PROVIDER_ERRORS = r"ERR_NAME_NOT_RESOLVED|ERR_INTERNET_DISCONNECTED|ERR_CONNECTION|ERR_ADDRESS"
"""The provider's development pages load a web font from the internet: not this test's."""


@contextlib.asynccontextmanager
async def oidc_provider(redirect_uri: str) -> AsyncIterator[str]:
    """The provider running; its issuer URL."""
    assert NODE is not None
    process = await asyncio.create_subprocess_exec(
        NODE,
        str(OIDC / "provider.mjs"),
        redirect_uri,
        cwd=OIDC,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        while True:
            line = (await asyncio.wait_for(process.stdout.readline(), 30)).decode()
            assert line, "the OpenID provider ended before it was ready"
            if line.startswith("ready "):
                break
        yield line.split()[1]
    finally:
        process.terminate()
        await process.wait()


@contextlib.asynccontextmanager
async def sso_fleet(fleet_factory: Any) -> AsyncIterator[Any]:
    """A fleet whose server signs people in through the test's provider."""
    async with fleet_factory(robots=0) as fleet:
        callback = f"{fleet.server.url}/api/session/oidc/callback"
        async with oidc_provider(callback) as issuer:
            app = fleet.server.app
            config = OidcConfig(
                issuer=issuer,
                client_id="guidebot",
                client_secret="guidebot-test-secret",
                name="Museum login",
                groups_claim="groups",
                roles=ROLES,
            )
            app.state.sso = SingleSignOn(config, app.state.accounts)
            yield fleet


async def opened(open_page: Any, fleet: Any) -> Any:
    """The console, with the provider's development pages' noise kept out: their web font
    (from the internet) and their missing favicon (GuideBot's pages have theirs inline)."""
    watch = await open_page("")
    watch.expect_error(PROVIDER_ERRORS)
    await watch.page.route("**/favicon.ico", lambda route: route.fulfill(status=204))
    await watch.page.goto(fleet.admin_url)
    return watch


async def through_the_provider(page: Any, login: str) -> None:
    await page.get_by_role("button", name="Use Museum login").click()
    await page.locator("input[name=login]").fill(login)
    await page.locator("input[name=password]").fill("anything")
    await page.get_by_role("button", name="Sign-in").click()
    await page.get_by_role("button", name="Continue").click()


async def test_a_person_signs_in_through_the_venue_s_provider(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with sso_fleet(fleet_factory) as fleet:
        watch = await opened(open_page, fleet)
        page = watch.page
        await through_the_provider(page, "olga")
        await page.get_by_label("Floor", exact=True).wait_for()
        await expect(page.locator("#who")).to_contain_text("olga (from the provider)")
        await expect(page.locator("#who")).to_contain_text("operator")
        account = await fleet.server.app.state.accounts.store.get("olga")
        assert account is not None and account.role == "operator"
        assert account.password_hash == ""  # the provider's person has no password here
        events = await fleet.server.app.state.store.events(source="olga", limit=10)
        assert [(e["kind"], e["data"].get("with")) for e in events] == [("signed_in", "sso")]


async def refused_on_the_form(page: Any, fleet: Any, words: str) -> None:
    """Back on the console's sign-in form (not a JSON page), saying why in words, with the
    fragment taken off the address."""
    await expect(page.get_by_role("alert")).to_contain_text(words)
    await expect(page.get_by_role("button", name="Use Museum login")).to_be_visible()
    await expect(page.get_by_label("Account name")).to_be_visible()
    assert page.url == fleet.admin_url.split("#")[0], page.url


async def test_no_role_for_the_groups_and_a_wrong_nonce_or_state_sign_nobody_in(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with sso_fleet(fleet_factory) as fleet:
        sso: SingleSignOn = fleet.server.app.state.sso
        watch = await opened(open_page, fleet)
        page = watch.page
        await through_the_provider(page, "gus")  # a visitor: no group of GuideBot's
        await refused_on_the_form(
            page, fleet, "Museum login: none of your groups has a GuideBot role"
        )
        assert await fleet.server.app.state.accounts.store.get("gus") is None
        await web.axe_check(page)

        # The flow's nonce changed after the browser left: the ID token's is not the one sent
        # (a new browser, not signed in at the provider).
        watch = await opened(open_page, fleet)
        page = watch.page
        await page.get_by_role("button", name="Use Museum login").click()
        await page.locator("input[name=login]").wait_for()
        ((state, flow),) = list(sso._flows.items())
        sso._flows[state] = flow.__class__(
            "another-nonce", flow.verifier, flow.redirect_uri, flow.then, flow.expires
        )
        await page.locator("input[name=login]").fill("olga")
        await page.locator("input[name=password]").fill("anything")
        await page.get_by_role("button", name="Sign-in").click()
        await page.get_by_role("button", name="Continue").click()
        await refused_on_the_form(page, fleet, "Single sign-on refused")
        assert await fleet.server.app.state.accounts.store.get("olga") is None

        # The person cancels at the provider: it sends the browser back with an error.
        watch = await opened(open_page, fleet)
        page = watch.page
        await page.get_by_role("button", name="Use Museum login").click()
        await page.locator("input[name=login]").wait_for()
        ((state, _),) = list(sso._flows.items())
        await page.goto(
            f"{fleet.server.url}/api/session/oidc/callback?error=access_denied&state={state}"
        )
        await refused_on_the_form(page, fleet, "Museum login did not sign you in")
        events = await fleet.server.app.state.store.events(kind="sign_in_failed", limit=10)
        assert [e["data"]["why"] for e in events] == [
            "sso no role",
            "sso token (InvalidClaimError)",
            "sso provider error",
        ]


async def test_a_callback_with_a_state_the_server_did_not_send_is_refused(
    fleet_factory: Any,
) -> None:
    async with sso_fleet(fleet_factory) as fleet:
        async with httpx.AsyncClient(base_url=fleet.server.url, timeout=10) as http:
            forged = await http.get(
                "/api/session/oidc/callback", params={"state": "forged", "code": "stolen"}
            )
            started = await http.get("/api/session/oidc/start", params={"next": "/config/"})
        assert forged.status_code == 302 and "set-cookie" not in forged.headers
        assert forged.headers["location"] == "/admin/#sso_refused=refused"
        assert started.status_code == 302
        assert "code_challenge_method=S256" in started.headers["location"]
        events = await fleet.server.app.state.store.events(kind="sign_in_failed", limit=10)
        assert [e["data"]["why"] for e in events] == ["sso state"]


async def test_sso_refusals_go_back_to_the_sign_in_form_saying_why(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """An unreachable provider, and an address over its failure budget (the answer says when
    to try again), both end on the page's sign-in form; a code the page does not know says
    "refused", never words from the address."""
    async with fleet_factory(robots=0) as fleet:
        app = fleet.server.app
        config = OidcConfig(
            "http://127.0.0.1:9/idp", "guidebot", None, "Museum login", "groups", {}
        )
        app.state.sso = SingleSignOn(config, app.state.accounts)
        async with httpx.AsyncClient(base_url=fleet.server.url, timeout=10) as http:
            away = await http.get("/api/session/oidc/start", params={"next": "/config/"})
            assert away.status_code == 302
            assert away.headers["location"] == "/config/#sso_refused=unreachable"
            for _ in range(fleet.server.app.state.settings.sign_in_failure_burst):
                await http.get("/api/session/oidc/callback", params={"state": "x", "code": "y"})
            locked = await http.get("/api/session/oidc/callback", params={"state": "x"})
        assert locked.status_code == 302
        assert re.fullmatch(r"/admin/#sso_refused=locked&retry=\d+", locked.headers["location"])

        watch = await open_page("")
        page = watch.page
        await page.goto(f"{fleet.server.url}/config/#sso_refused=unreachable")
        await expect(page.get_by_role("alert")).to_contain_text(
            "Museum login cannot be reached: try again later"
        )
        await page.goto(f"{fleet.server.url}{locked.headers['location']}")
        await expect(page.get_by_role("alert")).to_contain_text(
            "Too many failed sign-ins: try again in"
        )
        await page.goto(f"{fleet.server.url}/nets/#sso_refused=Call+0800+for+help")
        await expect(page.get_by_role("alert")).to_contain_text("Single sign-on refused")
        await expect(page.locator("body")).not_to_contain_text("0800")
