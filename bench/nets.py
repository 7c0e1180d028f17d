"""RoboGraph editor benchmark: a large net opened, drawn and re-checked in a real browser.

    guidebot bench nets --places 200 --rounds 20 --json

A server in this process (no site, no robots: the editor needs neither) and headless Chromium
(/usr/bin/chromium) with /nets/ open. A chain of ``--places`` places (and as many transitions
less one, drawn by the layered layout) is opened from its PNML text ``--rounds`` times, and
one edit (a place's marking) re-checked after each, then published to ``--robots`` robots.
Last line: {"places", "rounds", "robots", "open_ms": {"p50", "p99"}, "check_ms": {"p50",
"p99"}, "publish_ms": {"p50", "p99"}}.

open_ms: in the page, from handing the file's text to the editor to the net drawn and checked
by the server (POST /api/net-editor/import, the drawing, POST /api/net-editor/check, the
redraw, the next animation frame). check_ms: from one edit to its problems drawn (the check's
round trip and the redraw). publish_ms: from the page's POST /api/net-editor/publish (checked,
stored, installed in the server's dispatch, sent as nets_changed) to the server hearing the
last robot's nets_loaded for that version. The robots are hub clients in this process that
decode each nets_changed and answer at once (reading the nets is a robot's own work, off its
loop: robot_agent/net_sync.py).
"""

from __future__ import annotations

import asyncio
import tempfile
import time
from pathlib import Path
from typing import Any

import click

from backend.settings import Settings
from backend.testing import running_server
from bench.console import CHROMIUM, CHROMIUM_ARGS
from guidebot.benchutil import percentiles, print_result
from guidebot.client import HubClient
from guidebot.messages import Message
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


PUBLISH = """async ([token]) => {
  const reply = await fetch("/api/net-editor/publish", {method: "POST",
    headers: {Authorization: `Bearer ${token}`, "Content-Type": "application/json"},
    body: JSON.stringify({net: guidebotNets.model.doc, note: "bench"})});
  if (!reply.ok) throw new Error(`publish: ${reply.status} ${await reply.text()}`);
  guidebotNets.model.published(guidebotNets.model.doc);  // as the page's Publish: nothing unsaved
  return (await reply.json()).seq;
}"""


def chain_pnml(places: int) -> str:
    """A net of ``places`` places in a row, laid out in layers, as PNML text."""
    builder = NetBuilder("bench_chain").place("p0", initial=1)
    for i in range(1, places):
        builder.place(f"p{i}", final=i == places - 1)
        builder.transition(f"t{i}", [f"p{i - 1}"], [f"p{i}"])
    return write_pnml(builder.build()).decode()


async def followers(url: str, token: str, robots: int) -> list[HubClient]:
    """``robots`` hub clients that answer every nets_changed with nets_loaded, as robots."""
    clients = [HubClient(url, token, name=f"bench-robot-{i:02d}") for i in range(robots)]
    for client in clients:

        def answer(message: Message, client: HubClient = client) -> None:
            client.publish("nets_loaded", {"version": int(message.payload["version"])})

        client.subscribe("nets_changed", answer)
        await client.start()
    for client in clients:
        await asyncio.wait_for(client.connected.wait(), 60)
    return clients


async def run(places: int, rounds: int, robots: int = 20) -> dict[str, Any]:
    from playwright.async_api import async_playwright

    text = chain_pnml(places)
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-nets-") as tmp:
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{Path(tmp) / 'bench.db'}",
            admin_token="bench-nets-admin-token",
        )
        async with running_server(settings) as server, async_playwright() as p:
            browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            fleet = await followers(server.ws_url, server.admin_token, robots)
            loaded: dict[int, set[str]] = {}
            arrived = asyncio.Event()

            def on_loaded(message: Message) -> None:
                loaded.setdefault(int(message.payload["version"]), set()).add(message.source)
                arrived.set()

            server.app.state.hub.endpoint("bench-nets").subscribe("nets_loaded", on_loaded)
            publishes: list[float] = []
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
                    t0 = time.perf_counter()
                    version = int(await page.evaluate(PUBLISH, [server.admin_token]))
                    while len(loaded.get(version, ())) < robots:
                        arrived.clear()
                        await asyncio.wait_for(arrived.wait(), 60)
                    publishes.append((time.perf_counter() - t0) * 1000)
            finally:
                for client in fleet:
                    await client.close()
                await browser.close()
    return {
        "places": places,
        "rounds": rounds,
        "open_ms": percentiles(opens, 1),
        "check_ms": percentiles(checks, 1),
        "robots": robots,
        "publish_ms": percentiles(publishes, 1),
    }


@click.command()
@click.option("--places", default=200, show_default=True, type=click.IntRange(2, 2000))
@click.option("--rounds", default=20, show_default=True, type=click.IntRange(1, 1000))
@click.option("--robots", default=20, show_default=True, type=click.IntRange(1, 500))
@click.option("--json", "as_json", is_flag=True, help="Only the JSON result line.")
def main(places: int, rounds: int, robots: int, as_json: bool) -> None:
    """Open, draw, re-check and publish a large net in the RoboGraph editor, in a real
    browser, to ``--robots`` robots."""
    result = asyncio.run(run(places, rounds, robots))
    if not as_json:
        click.echo(
            f"{places} places: open {result['open_ms']['p50']} ms (p99 "
            f"{result['open_ms']['p99']}), check {result['check_ms']['p50']} ms (p99 "
            f"{result['check_ms']['p99']}), publish to {robots} robots "
            f"{result['publish_ms']['p50']} ms (p99 {result['publish_ms']['p99']})"
        )
    print_result(result)
