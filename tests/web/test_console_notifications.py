"""The console's Notifications view in a real browser (issue 44): an admin sets the SMTP server
and an e-mail channel, presses "Send test" and the test SMTP server receives it; a webhook that
is down shows its failure; a refused setting says why; axe-core on the view."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.notify.receivers import closed_port, smtp_server

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def sent_tests(log: Any) -> Any:
    """The delivery log's rows of test messages sent (its "Why" cell says "test")."""
    return log.locator("tr[data-status=sent]").filter(
        has=log.page.get_by_role("cell", name="test", exact=True)
    )


async def test_an_admin_sets_a_channel_tests_it_and_sees_a_failure(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with smtp_server() as inbox, fleet_factory(robots=0) as fleet:
        fleet.server.app.state.notify.retry_delays_s = (60.0,)
        watch = await open_page(fleet.admin_url)
        await web.sign_in(watch, fleet.server.admin_token)
        page = watch.page
        await web.open_view(page, "Notifications")
        smtp = page.get_by_role("form", name="SMTP server")
        await smtp.get_by_label("Host").fill("127.0.0.1")
        await smtp.get_by_label("Port").fill(str(inbox.port))
        await smtp.get_by_label("Security").select_option("none")
        await smtp.get_by_label("From address").fill("guidebot@museum.example")
        await smtp.get_by_role("button", name="Save SMTP server").click()
        await expect(page.get_by_text("Save the SMTP server: done.")).to_be_visible()

        await page.get_by_role("button", name="Add a channel").click()
        form = page.get_by_role("form", name="New channel")
        await form.get_by_label("Name").fill("Duty phone")
        await form.get_by_label("E-mail address").fill("duty@museum.example")
        await form.get_by_label("Time zone").fill("Europe/Paris")
        await form.get_by_role("button", name="Save channel").click()
        channels = page.get_by_role("table", name="Channels")
        await expect(channels.get_by_role("row")).to_have_count(2)
        await expect(channels).to_contain_text("duty@museum.example")
        await web.axe_check(page)

        await page.get_by_role("button", name="Send test to Duty phone").click()
        await expect(page.get_by_text("Send test to Duty phone: done.")).to_be_visible()
        (mail,) = await inbox.wait_for(1)
        assert mail["To"] == "duty@museum.example" and "Test message" in mail["Subject"]
        # An alert meanwhile goes out too (a loaded machine's slow Modbus poll raised this one
        # in a run): the log has its row beside the test's.
        fleet.server.app.state.alerts.raise_("module_offline", "otb_ground", "no answer")
        await inbox.wait_for(2)
        log = page.get_by_role("table", name="Delivery log")
        await page.get_by_role("button", name="Refresh the log").click()
        await expect(log.locator("tr[data-status=sent]")).to_have_count(2)
        await expect(sent_tests(log)).to_have_count(1)

        # A webhook that is down: the test says so, the log shows the error and the retry.
        await page.get_by_role("button", name="Add a channel").click()
        form = page.get_by_role("form", name="New channel")
        await form.get_by_label("Kind").select_option("webhook")
        await form.get_by_label("Name").fill("Front desk chat")
        await form.get_by_label("Webhook URL").fill(f"http://127.0.0.1:{closed_port()}/hook")
        await form.get_by_label("Shared secret").fill("the front desk's shared secret")
        await form.get_by_label("Quiet hours on").check()
        await form.get_by_role("button", name="Save channel").click()
        await expect(channels.get_by_role("row")).to_have_count(3)
        await page.get_by_role("button", name="Send test to Front desk chat").click()
        refused = page.get_by_role("alert").filter(has_text="Front desk chat")  # not the bar's
        await expect(refused).to_contain_text("Front desk chat: not delivered (retrying)")
        await expect(refused).to_contain_text("ConnectError")
        failing = log.locator("tr[data-status=retrying]")
        await expect(failing).to_contain_text("Front desk chat")
        await expect(failing).to_contain_text("ConnectError")
        await web.axe_check(page)
        await web.screenshot(page, "notifications")

        # A setting the server refuses: the field and the reason are shown.
        watch.expect_error(r"status of 422")
        await page.get_by_role("button", name="Edit Front desk chat").click()
        form = page.get_by_role("form", name="Channel Front desk chat")
        await form.get_by_label("Webhook URL").fill("http://chat.museum.example/hook")
        await form.get_by_role("button", name="Save channel").click()
        says = "url: Value error, a webhook URL must use https://"
        await expect(page.get_by_role("alert").filter(has_text="url:")).to_contain_text(says)
        assert "the front desk's shared secret" not in await page.content()

        # An operator reads the log, and sets nothing.
        operator = await open_page(fleet.admin_url)
        await web.sign_in(operator, web.operator_token)
        await web.open_view(operator.page, "Notifications")
        their_log = operator.page.get_by_role("table", name="Delivery log")
        await expect(sent_tests(their_log)).to_have_count(1)
        await expect(operator.page.get_by_role("button", name="Add a channel")).to_have_count(0)
        await web.axe_check(operator.page)
