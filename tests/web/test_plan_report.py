"""``guidebot plan --html``: the report page opens from the file alone (uPlot inlined), draws the
wait against fleet size, lists every run and, for live runs, the heat map of the time lost
waiting for areas and elevators; no console error, axe-core clean (docs/planning.md)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from click.testing import CliRunner
from playwright.async_api import expect

from backend.planning.sim import Outcome
from guidebot.cli import main
from guidebot.paths import WEB_DIR

pytestmark = [pytest.mark.browser, pytest.mark.timeout(150)]

ROOT = Path(__file__).resolve().parents[2]
AXE = WEB_DIR / "vendor" / "axe-core" / "axe.min.js"


def _live_row(robots: int, corridor_s: float) -> dict[str, Any]:
    """A live run's row as ``run_live`` gives it (its measuring is tests/planning/test_live.py)."""
    outcome = Outcome(robots=robots, policy="nearest", requests=120, day_s=36000.0)
    outcome.waits_s = [30.0 * robots] * 120
    outcome.busy_s = 9000.0
    outcome.extra = {
        "mode": "live",
        "time_scale": 10.0,
        "lock_wait": {"corridor": {"count": 40, "total_s": corridor_s}},
        "lock_wait_s": corridor_s,
        "elevator_wait": {"lift": {"count": 12, "total_s": 300.0}},
        "elevator_wait_s": 300.0,
        "charging_s": 1800.0,
    }
    return {"mode": "live", **outcome.summary(10.0)}


async def test_the_plan_report_draws_the_waits_and_the_lock_wait_heat_map(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    report = tmp_path / "plan.html"
    result = CliRunner().invoke(
        main,
        [
            *("plan", "--site", str(ROOT / "sites" / "demo_museum.yaml")),
            *("--visitors", str(ROOT / "sites" / "profiles" / "demo_museum_300.yaml")),
            *("--robots", "1..3", "--html", str(report), "--json"),
        ],
    )
    assert result.exit_code == 0, result.output
    plan = json.loads(result.output.strip().splitlines()[-1])
    watch = await open_page(report.as_uri())
    page = watch.page
    await expect(page.locator("body")).to_have_attribute("data-drawn", "2")  # p50 and p95
    await expect(page.locator("#waits canvas")).to_be_visible()
    await expect(page.locator("#rows tbody tr")).to_have_count(3)
    await expect(page.get_by_text("Run with --live to measure it.")).to_be_visible()
    await expect(page.get_by_role("listitem")).to_have_text(
        ["model (nearest): 1 robot serves 95 % of the requests within 10 min."]
    )
    await page.add_script_tag(path=str(AXE))
    await web.axe_check(page)

    # With live runs: both drawn, and the heat map of the waits per area and fleet size.
    plan["fleets"] += [_live_row(2, 600.0), _live_row(3, 120.0)]
    from backend.planning.html import write_report

    write_report(plan, report)
    await page.reload()
    await expect(page.locator("body")).to_have_attribute("data-drawn", "4")
    await expect(page.locator("#rows tbody tr")).to_have_count(5)
    heat = page.locator("table.heatmap").first
    await expect(heat.locator("th[scope=row]")).to_have_text(["corridor"])
    times = "\u00d7"  # the count of waits: "(40x)" with a multiplication sign
    await expect(heat.locator("td.heat")).to_have_text(
        [f"10.0 min (40{times})", f"2.0 min (40{times})"]
    )
    assert await heat.locator("td.heat").first.get_attribute("style") == "--heat: 1.000"
    await page.add_script_tag(path=str(AXE))
    await web.axe_check(page)
