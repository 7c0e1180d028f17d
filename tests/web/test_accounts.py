"""People's accounts in a real browser (issue 40): a password sign-in on the console, the
admins' Accounts view, a disabled account thrown out of an open console, sign-out and an
expired session; axe-core on the sign-in form and the view."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from backend.auth import Role

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PASSWORD = "Tall-ships sail at dawn 7"


async def make(fleet: Any, name: str, role: Role, display_name: str = "") -> None:
    accounts = fleet.server.app.state.accounts
    await accounts.create(name, role.value, PASSWORD, display_name, by="test", address="test")


async def password_sign_in(watch: Any, name: str, password: str = PASSWORD) -> None:
    page = watch.page
    await page.get_by_label("Account name").fill(name)
    await page.get_by_label("Password").fill(password)
    await page.get_by_role("button", name="Sign in").click()


async def test_a_person_signs_in_with_a_password_and_signs_out(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "ada", Role.OPERATOR, "Ada Lovelace")
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()
        await web.axe_check(page)
        await web.screenshot(page, "sign-in")
        watch.expect_error(r"status of 401")
        await password_sign_in(watch, "ada", "not the password at all")
        await expect(page.get_by_role("alert")).to_contain_text("Wrong account name or password")
        await password_sign_in(watch, "ada")
        await page.get_by_label("Floor", exact=True).wait_for()
        await expect(page.locator("#who")).to_contain_text("Ada Lovelace")
        cookies = await page.context.cookies()
        session = next(c for c in cookies if c["name"] == "guidebot_session")
        assert session["httpOnly"] and session["sameSite"] == "Strict"
        assert await page.evaluate("document.cookie") == ""  # the page cannot read it
        assert await page.evaluate("sessionStorage.getItem('guidebot.token')") is None
        # A change made over REST from the page carries the CSRF token.
        await web.open_view(page, "Fleet")
        await page.get_by_role("button", name="Pause the fleet").click()
        await expect(page.get_by_text("Pause the fleet: done.")).to_be_visible()
        events = await fleet.server.app.state.store.events(source="ada", limit=100)
        assert [e["kind"] for e in events] == ["sign_in_failed", "signed_in", "staff_action"]
        await page.get_by_role("button", name="Sign out", exact=True).click()
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()
        await page.reload()
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()


async def test_an_expired_session_is_back_at_the_sign_in(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "ada", Role.OPERATOR)
        watch = await open_page(fleet.admin_url)
        watch.expect_error(r"status of 401")
        await password_sign_in(watch, "ada")
        await watch.page.get_by_label("Floor", exact=True).wait_for()
        accounts = fleet.server.app.state.accounts
        store = accounts.store
        (digest,) = [row.digest for row in await _sessions(store) if row.account == "ada"]
        await store.change_session(digest, seen_at=0.0)  # idle since 1970
        await watch.page.reload()
        await expect(watch.page.get_by_role("heading", name="Sign in")).to_be_visible()


async def _sessions(store: Any) -> list[Any]:
    from sqlalchemy import select

    from backend.db.models import AccountSessionRow

    async with store.sessionmaker() as db:
        return list((await db.execute(select(AccountSessionRow))).scalars())


async def test_an_admin_manages_accounts_and_a_disabled_one_is_thrown_out(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "root", Role.ADMIN, "Head of operations")
        await make(fleet, "ada", Role.OPERATOR, "Ada Lovelace")
        operator = await open_page(fleet.admin_url)
        operator.expect_error(r"status of 401")
        await password_sign_in(operator, "ada")
        await operator.page.get_by_label("Floor", exact=True).wait_for()

        admin = await open_page(fleet.admin_url)
        page = admin.page
        await password_sign_in(admin, "root")
        await page.get_by_label("Floor", exact=True).wait_for()
        await web.open_view(page, "Accounts")
        table = page.get_by_role("table", name="Accounts")
        await expect(table.get_by_role("row")).to_have_count(3)
        await expect(table).to_contain_text("Ada Lovelace")
        await page.get_by_role("textbox", name="Account name").fill("vic")
        await page.get_by_role("textbox", name="Display name").fill("Victoria, front desk")
        await page.get_by_role("combobox", name="Role", exact=True).select_option("viewer")
        await page.get_by_label("First password").fill("Morning light in hall B")
        await page.get_by_role("button", name="Create account").click()
        await expect(table.get_by_role("row")).to_have_count(4)
        await expect(page.get_by_role("combobox", name="Role of vic")).to_have_value("viewer")
        await web.axe_check(page)
        await web.screenshot(page, "accounts")

        await page.get_by_role("button", name="Disable ada").click()
        await expect(page.get_by_role("button", name="Enable ada")).to_be_visible()
        # The operator's open console is thrown out at once: its hub link is closed.
        await expect(operator.page.get_by_role("heading", name="Sign in")).to_be_visible()
        await expect(operator.page.get_by_role("alert")).to_contain_text("session ended")
        await password_sign_in(operator, "ada")
        await expect(operator.page.get_by_role("alert")).to_contain_text("disabled")


async def test_an_installer_signs_in_on_the_site_editor_and_a_viewer_is_told_why_not(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The same sign-in form on the site editor: an installer edits the site (rule
    ``administer``), a viewer is refused with the reason."""
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "ines", Role.INSTALLER)
        await make(fleet, "vic", Role.VIEWER)
        watch = await open_page(f"{fleet.server.url}/config/")
        page = watch.page
        await password_sign_in(watch, "vic")
        await expect(page.get_by_role("alert")).to_contain_text(
            "the site editor is for installers and administrators"
        )
        await password_sign_in(watch, "ines")
        await page.get_by_label("Floor", exact=True).wait_for()
        await web.axe_check(page)
        await page.reload()  # the session, not the tab, keeps the installer signed in
        await page.get_by_label("Floor", exact=True).wait_for()


async def virtual_authenticator(page: Any) -> Any:
    """Chromium's virtual authenticator (DevTools protocol, WebAuthn domain) on this page: a
    platform authenticator that keeps passkeys and verifies its user without asking."""
    cdp = await page.context.new_cdp_session(page)
    await cdp.send("WebAuthn.enable")
    await cdp.send(
        "WebAuthn.addVirtualAuthenticator",
        {
            "options": {
                "protocol": "ctap2",
                "transport": "internal",
                "hasResidentKey": True,
                "hasUserVerification": True,
                "isUserVerified": True,
                "automaticPresenceSimulation": True,
            }
        },
    )
    return cdp


async def test_a_passkey_is_added_and_then_signs_in_without_a_password(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """Passkeys need a secure context and a host name (not an IP address) for their relying
    party: the page is opened as http://localhost."""
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "ada", Role.OPERATOR, "Ada Lovelace")
        watch = await open_page("")
        page = watch.page
        await virtual_authenticator(page)
        await page.goto(fleet.admin_url.replace("127.0.0.1", "localhost"))
        await password_sign_in(watch, "ada")
        await page.get_by_label("Floor", exact=True).wait_for()
        await web.open_view(page, "Robots")
        await page.get_by_role("button", name="Add a passkey").click()
        await expect(page.get_by_text("Add a passkey: done.")).to_be_visible()
        await page.get_by_role("button", name="Sign out", exact=True).click()
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()
        await web.axe_check(page)
        await page.get_by_role("button", name="Use a passkey").click()
        await expect(page.locator("#who")).to_contain_text("Ada Lovelace")  # no name typed
        await expect(page.get_by_role("heading", name="Robots")).to_be_visible()
        events = await fleet.server.app.state.store.events(source="ada", limit=100)
        signed_in = [e["data"]["with"] for e in events if e["kind"] == "signed_in"]
        assert signed_in == ["password", "passkey"]
        changes = [e["data"]["change"] for e in events if e["kind"] == "account_changed"]
        assert changes == ["passkey_added"]


async def test_a_person_removes_a_passkey_and_an_admin_removes_a_lost_phone_s(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """ "Your passkeys" lists a person's passkeys (name, added, last used); one removed signs
    nobody in any more. An admin removes all of a person's passkeys from the Accounts view (a
    lost phone): the person's open console is signed out, and the passkey refused."""
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "ada", Role.OPERATOR, "Ada Lovelace")
        await make(fleet, "root", Role.ADMIN)
        watch = await open_page("")
        page = watch.page
        watch.expect_error(r"status of 401")  # the removed passkey, refused
        await virtual_authenticator(page)
        await page.goto(fleet.admin_url.replace("127.0.0.1", "localhost"))
        await password_sign_in(watch, "ada")
        await page.get_by_label("Floor", exact=True).wait_for()
        await web.open_view(page, "Robots")  # where the page shows the outcome of an action
        await page.get_by_role("button", name="Add a passkey").click()
        await expect(page.get_by_text("Add a passkey: done.")).to_be_visible()
        await page.get_by_role("button", name="Sign out", exact=True).click()
        await page.get_by_role("button", name="Use a passkey").click()
        await expect(page.locator("#who")).to_contain_text("Ada Lovelace")

        await page.get_by_role("button", name="Your passkeys").click()
        table = page.get_by_role("table", name="Your passkeys")
        await expect(table.get_by_role("row")).to_have_count(2)
        cells = table.get_by_role("row").nth(1).get_by_role("cell")
        await expect(cells.nth(2)).not_to_have_text("never")  # last used: the sign-in above
        await web.axe_check(page)
        await web.screenshot(page, "passkeys")
        await table.get_by_role("button", name="Remove").click()
        await expect(table).to_contain_text("No passkey yet.")
        await page.get_by_role("button", name="Sign out", exact=True).click()
        await page.get_by_role("button", name="Use a passkey").click()
        await expect(page.get_by_role("alert")).to_contain_text("This passkey was not accepted.")

        # A passkey again, then the phone is lost: the admin removes it.
        await password_sign_in(watch, "ada")
        await expect(table).to_contain_text("No passkey yet.")  # back on the view it showed
        await page.get_by_role("button", name="Add a passkey").click()
        await expect(page.get_by_text("Add a passkey: done.")).to_be_visible()
        await expect(table.get_by_role("row")).to_have_count(2)  # listed again at once
        admin = await open_page(fleet.admin_url)
        await password_sign_in(admin, "root")
        await admin.page.get_by_label("Floor", exact=True).wait_for()
        await web.open_view(admin.page, "Accounts")
        accounts = admin.page.get_by_role("table", name="Accounts")
        await expect(accounts.get_by_role("row", name="ada")).to_contain_text("1")
        await admin.page.get_by_role("button", name="Remove passkeys of ada").click()
        await admin.page.get_by_role("dialog").get_by_role("button", name="Remove passkeys").click()
        await expect(admin.page.get_by_text("Remove passkeys of ada: done.")).to_be_visible()
        await expect(admin.page.get_by_role("button", name="Remove passkeys of ada")).to_have_count(
            0
        )
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()  # thrown out
        await page.get_by_role("button", name="Use a passkey").click()
        await expect(page.get_by_role("alert")).to_contain_text("This passkey was not accepted.")

        events = await fleet.server.app.state.store.events(kind="account_changed", limit=100)
        removed = [
            (e["source"], e["data"]["target"], e["data"]["passkeys"])
            for e in events
            if e["data"]["change"] == "passkey_removed"
        ]
        assert removed == [("ada", "ada", 1), ("root", "ada", 1)]


async def test_the_accounts_view_says_so_when_there_is_no_account(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """Before the first account (the admin signed in with the admin token), the Accounts
    table has a "none" row, as the other views' empty tables do."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await page.get_by_label("Staff token").fill(fleet.server.admin_token)
        await page.get_by_role("button", name="Sign in").click()
        await page.get_by_label("Floor", exact=True).wait_for()
        await web.open_view(page, "Accounts")
        table = page.get_by_role("table", name="Accounts")
        await expect(table.get_by_role("row")).to_have_count(2)
        await expect(table).to_contain_text("No account yet: create the first below.")
        await web.axe_check(page)
