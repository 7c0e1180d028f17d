"""RoboGraph editor benchmark: a large net opened, drawn and re-checked in a real browser.

    guidebot bench nets --places 200 --rounds 20 --json

A server in this process (no site, no robots: the editor needs neither) and headless Chromium
(/usr/bin/chromium) with /nets/ open. A chain of ``--places`` places (and as many transitions
less one, drawn by the layered layout) is opened from its PNML text ``--rounds`` times, and
one edit (a place's marking) re-checked after each. Last line: {"places", "rounds",
"open_ms": {"p50", "p99"}, "check_ms": {"p50", "p99"}, "publish_ms": null}.

open_ms: in the page, from handing the file's text to the editor to the net drawn and checked
by the server (POST /api/net-editor/import, the drawing, POST /api/net-editor/check, the
redraw, the next animation frame). check_ms: from one edit to its problems drawn (the check's
round trip and the redraw). publish_ms is null: the editor does not publish to the fleet yet
(docs/nets.md, "Not there yet").
"""

from __future__ import annotations

import asyncio
import tempfile
from pathlib import Path
from typing import Any

import click

from backend.settings import Settings
from backend.testing import running_server
from bench.console import CHROMIUM, CHROMIUM_ARGS
from guidebot.benchutil import percentiles, print_result
from petri_nets.builder import NetBuilder
from petri_nets.pnml_writer import write_pnml

__all__ = ["chain_pnml", "main", "run"]

OPEN = """async ([text]) => {
  const t0 = performance.now();
  await guidebotNets.openPnml(text, "bench.pnml");
  await new Promise((done) => requestAnimationFrame(() => done()));
  return performance.now() - t0;
}"""
CHECK = """async () => {
  const model = guidebotNets.model;
  const t0 = performance.now();
  model.edit("bench", (d) => { d.places[1].initial = d.places[1].initial ? 0 : 1; });
  await model.checked;
  await new Promise((done) => requestAnimationFrame(() => done()));
  return performance.now() - t0;
}"""


def chain_pnml(places: int) -> str:
    """A net of ``places`` places in a row, laid out in layers, as PNML text."""
    builder = NetBuilder("bench_chain").place("p0", initial=1)
    for i in range(1, places):
        builder.place(f"p{i}", final=i == places - 1)
        builder.transition(f"t{i}", [f"p{i - 1}"], [f"p{i}"])
    return write_pnml(builder.build()).decode()


async def run(places: int, rounds: int) -> dict[str, Any]:
    from playwright.async_api import async_playwright

    text = chain_pnml(places)
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-nets-") as tmp:
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{Path(tmp) / 'bench.db'}",
            admin_token="bench-nets-admin-token",
        )
        async with running_server(settings) as server, async_playwright() as p:
            browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = await browser.new_page(viewport={"width": 1280, "height": 800})
                await page.goto(f"{server.url}/nets/")
                await page.get_by_label("Staff token").fill(server.admin_token)
                await page.get_by_label("Staff token").press("Enter")
                await page.get_by_label("Library net").wait_for()
                opens: list[float] = []
                checks: list[float] = []
                for _ in range(rounds):
                    opens.append(await page.evaluate(OPEN, [text]))
                    drawn = await page.locator("#canvas g.net-node").count()
                    if drawn != 2 * places - 1:
                        raise RuntimeError(f"{drawn} nodes drawn, expected {2 * places - 1}")
                    checks.append(await page.evaluate(CHECK))
            finally:
                await browser.close()
    return {
        "places": places,
        "rounds": rounds,
        "open_ms": percentiles(opens, 1),
        "check_ms": percentiles(checks, 1),
        "publish_ms": None,
    }


@click.command()
@click.option("--places", default=200, show_default=True, type=click.IntRange(2, 2000))
@click.option("--rounds", default=20, show_default=True, type=click.IntRange(1, 1000))
@click.option("--json", "as_json", is_flag=True, help="Only the JSON result line.")
def main(places: int, rounds: int, as_json: bool) -> None:
    """Open, draw and re-check a large net in the RoboGraph editor, in a real browser."""
    result = asyncio.run(run(places, rounds))
    if not as_json:
        click.echo(
            f"{places} places: open {result['open_ms']['p50']} ms (p99 "
            f"{result['open_ms']['p99']}), check {result['check_ms']['p50']} ms (p99 "
            f"{result['check_ms']['p99']})"
        )
    print_result(result)
