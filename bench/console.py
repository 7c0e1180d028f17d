"""Staff console benchmark: robot states to markers on the screen, in a real browser.

    guidebot bench console --robots 50 --rate 5 --seconds 20 --json

A server (separate process, the demo site with ``--robots`` robots, building off),
``--robots`` robot-state publishers over real WebSockets at ``--rate`` Hz each (moving along the
ground floor's corridors), and headless Chromium (/usr/bin/chromium) with /admin/ open on the
map. Last line: {"robots", "rate_hz", "state_to_screen_ms": {"p50", "p99"},
"dropped_frames_percent", "page_heap_mb", "page_heap_start_mb"}.

state_to_screen_ms: in the page, from a robot_state's timestamp (set by the publisher) to the
animation frame that moved its marker (web/lib/map.js). dropped_frames_percent: animation
frames missed against a 60 Hz display while the states stream. page_heap_mb: the JS heap after
a forced garbage collection at the end (page_heap_start_mb: the same after the warm-up), to
show whether the page leaks.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import click
import httpx
import orjson
import websockets
import yaml

from guidebot.benchutil import percentiles, print_result
from guidebot.processes import guidebot_command
from guidebot.site.yamlio import load_site_file

__all__ = ["CHROMIUM", "CHROMIUM_ARGS", "main"]

ROOT = Path(__file__).resolve().parent.parent
DEMO_SITE = ROOT / "sites" / "demo_museum.yaml"
CHROMIUM = os.environ.get("GUIDEBOT_CHROMIUM", "/usr/bin/chromium")
"""Debian's Chromium (scripts/system-deps.sh; Playwright cannot download a browser here), the
browser people use; ``GUIDEBOT_CHROMIUM`` names another (the tests set Debian's
chromium-headless-shell: tests/conftest.py)."""
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--headless",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
WARMUP_S = 2.0
FRAME_MONITOR = """
window.__frames = {count: 0, missed: 0, last: 0};
(function tick(now) {
  const f = window.__frames;
  if (f.last) {
    const gap = now - f.last;
    f.count += 1;
    if (gap > 25) f.missed += Math.round(gap / 16.667) - 1;
  }
  f.last = now;
  requestAnimationFrame(tick);
})(0);
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _write_site(folder: Path, robots: int) -> tuple[Path, list[tuple[str, str]]]:
    data = load_site_file(DEMO_SITE).model_dump(mode="json")
    data["robots"] = [
        {"name": f"R{i}", "token": f"bench-robot-token-{i:04d}", "start_node": "entrance"}
        for i in range(1, robots + 1)
    ]
    shutil.copytree(DEMO_SITE.parent / "demo_museum", folder / "demo_museum")
    site = folder / "site.yaml"
    site.write_text(yaml.safe_dump(data))
    return site, [(r["name"], r["token"]) for r in data["robots"]]


@contextlib.contextmanager
def _server(site: Path, db: Path, port: int) -> Any:
    env = {**os.environ, "GUIDEBOT_BUILDING_ENABLED": "false"}
    args = guidebot_command("server", "--port", str(port))
    args += ["--site", str(site), "--db", f"sqlite+aiosqlite:///{db}", "--log-level", "warning"]
    process = subprocess.Popen(args, env=env)
    try:
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 60
        with httpx.Client(timeout=1) as http:  # one client for every poll (each costs ~20 ms)
            while True:
                if process.poll() is not None:
                    raise click.ClickException(f"the server exited (code {process.returncode})")
                with contextlib.suppress(httpx.HTTPError):
                    if http.get(f"{url}/api/health").status_code == 200:
                        break
                if time.monotonic() > deadline:
                    raise click.ClickException("the server did not start within 60 s")
                time.sleep(0.2)
        yield url
    finally:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _loop_points() -> list[tuple[float, float]]:
    """A closed walk on the ground floor: entrance, hall, gallery A, corridor, gallery B."""
    return [(0, 0), (5, 0), (15, 0), (25, 0), (30, 0), (30, 8), (15, 8), (15, 0), (5, 0)]


def _pose(t: float, offset: float) -> tuple[float, float, float]:
    points = _loop_points()
    legs = list(zip(points, points[1:] + points[:1], strict=True))
    lengths = [math.dist(a, b) for a, b in legs]
    s = (t * 1.2 + offset) % sum(lengths)
    for (a, b), length in zip(legs, lengths, strict=True):
        if s <= length:
            k = s / length
            theta = math.atan2(b[1] - a[1], b[0] - a[0])
            return a[0] + (b[0] - a[0]) * k, a[1] + (b[1] - a[1]) * k, theta
        s -= length
    return points[0][0], points[0][1], 0.0


async def _publish(
    ws_url: str, robots: list[tuple[str, str]], rate: float, stop: asyncio.Event
) -> int:
    """Every robot publishes robot_state at ``rate`` Hz (staggered) until ``stop``."""
    async with contextlib.AsyncExitStack() as stack:
        links = [
            await stack.enter_async_context(websockets.connect(f"{ws_url}?token={token}"))
            for _, token in robots
        ]
        for link in links:
            await link.recv()  # welcome
        sent = 0
        step = 1.0 / rate / len(robots)
        start = time.monotonic()
        tick = 0
        while not stop.is_set():
            for i, ((name, _), link) in enumerate(zip(robots, links, strict=True)):
                # Open loop on a fixed schedule: slow sends never lower the rate.
                delay = start + sent * step - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
                x, y, theta = _pose(time.monotonic() - start, i * 3.7)
                message = {
                    "type": "robot_state",
                    "id": f"{name}-{tick}",
                    "timestamp": time.time(),
                    "payload": {
                        "robot": name, "x": x, "y": y, "theta": theta, "floor": "F0",
                        "node": None, "battery": 0.3 + (i % 7) / 10, "mode": "busy", "seq": tick,
                    },
                }  # fmt: skip
                await link.send(orjson.dumps(message).decode())
                sent += 1
            tick += 1
        return sent


async def _heap_mb(cdp: Any) -> float:
    await cdp.send("HeapProfiler.collectGarbage")
    usage = await cdp.send("Runtime.getHeapUsage")
    return round(usage["usedSize"] / 1e6, 2)


@contextlib.asynccontextmanager
async def _browser() -> AsyncIterator[Any]:
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            await browser.close()


async def run(robots: int, rate: float, seconds: float, folder: Path) -> dict[str, Any]:
    site, fleet = _write_site(folder, robots)
    port = _free_port()
    with _server(site, folder / "bench.db", port) as url:
        async with _browser() as browser:
            page = await browser.new_page(viewport={"width": 1280, "height": 800})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            await page.add_init_script(
                "sessionStorage.setItem('guidebot.token', 'dev-admin-token');"
                "sessionStorage.setItem('guidebot.view', 'map');"
            )
            await page.goto(f"{url}/admin/")
            await page.wait_for_function("() => window.guidebotProbe")
            cdp = await page.context.new_cdp_session(page)
            stop = asyncio.Event()
            publisher = asyncio.create_task(
                _publish(url.replace("http", "ws") + "/ws", fleet, rate, stop)
            )
            await asyncio.sleep(WARMUP_S)
            await page.evaluate("guidebotProbe.takeLatencies()")
            heap_start = await _heap_mb(cdp)
            await page.evaluate(FRAME_MONITOR)
            latencies: list[float] = []
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                await asyncio.sleep(1.0)
                latencies += await page.evaluate("guidebotProbe.takeLatencies()")
            frames = await page.evaluate("window.__frames")
            stop.set()
            sent = await publisher
            heap_end = await _heap_mb(cdp)
            if errors:
                raise click.ClickException(f"errors in the page: {errors[:3]}")
    expected = frames["count"] + frames["missed"]
    return {
        "robots": robots,
        "rate_hz": rate,
        "state_to_screen_ms": percentiles(latencies, 1),
        "dropped_frames_percent": round(100 * frames["missed"] / expected, 2) if expected else None,
        "page_heap_mb": heap_end,
        "page_heap_start_mb": heap_start,
        "states_drawn": len(latencies),
        "states_sent": sent,
    }


@click.command()
@click.option("--robots", type=click.IntRange(1, 500), default=50, show_default=True)
@click.option("--rate", type=click.FloatRange(0.1, 50), default=5.0, show_default=True)
@click.option("--seconds", type=click.FloatRange(1, 3600), default=20.0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print only the JSON result line.")
def main(robots: int, rate: float, seconds: float, as_json: bool) -> None:
    """Robot states to markers on the staff console's map, measured in the page."""
    if not Path(CHROMIUM).exists():
        raise click.ClickException(f"{CHROMIUM} not found: run scripts/system-deps.sh")
    with tempfile.TemporaryDirectory(prefix="guidebot-bench-console-") as tmp:
        result = asyncio.run(run(robots, rate, seconds, Path(tmp)))
    if not as_json:
        click.echo(f"{robots} robots at {rate:g} Hz for {seconds:g} s, measured in the page")
    print_result(result)
