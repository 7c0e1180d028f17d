"""A fault-free demo raises no alert (a false alarm is worse than none), and its clean stop
leaves none for the next start (docs/console.md, "Alerts").

`guidebot demo` as a user runs it, in real time (time scale 1: the building's 12 s lift with
its door open 8 s at each floor, the rides of about 20 s that made false "not confirmed within
17 s" alarms), with busy visitors, watched over the hub as an admin until the lift has carried
robots several times and tasks have ended."""

from __future__ import annotations

import asyncio
import signal
import sys
import time
from pathlib import Path

import httpx
import pytest
from netports import free_block, free_ports

from guidebot.client import HubClient
from guidebot.messages import Message
from guidebot.testing import wait_on

pytestmark = pytest.mark.timeout(420)

ADMIN_TOKEN = "dev-admin-token"
ADMIN = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
LIFT_ARRIVALS = 4
"""Arrivals of the lift's cabin (door open) to watch: the false alarms came within two."""


async def start_demo(tmp_path: Path, port: int, gui: int) -> asyncio.subprocess.Process:
    command = [sys.executable, "-m", "guidebot.cli", "demo", "--no-can", "--robots", "3"]
    command += ["--port", str(port), "--gui-port", str(gui), "--sim-control-port", "0"]
    command += ["--visitor-every", "1", "--db", f"sqlite+aiosqlite:///{tmp_path}/demo.db"]
    return await asyncio.create_subprocess_exec(
        *command, stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE
    )


async def healthy(url: str, process: asyncio.subprocess.Process) -> None:
    """Until the server answers (a subprocess announces nothing on the hub before it)."""
    async with httpx.AsyncClient(timeout=5) as http:
        while process.returncode is None:
            try:
                if (await http.get(f"{url}/api/health")).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            await asyncio.sleep(0.2)
    raise AssertionError(f"demo exited with {process.returncode}")


async def stop(process: asyncio.subprocess.Process) -> None:
    process.send_signal(signal.SIGTERM)
    _, err = await asyncio.wait_for(process.communicate(), 60)
    assert process.returncode == 0, err.decode()[-2000:]


async def test_a_fault_free_demo_raises_no_alert_and_its_stop_leaves_none(tmp_path: Path) -> None:
    (port,) = free_ports(1)
    gui = free_block(3)  # robot i's touch screen takes gui + i
    url = f"http://127.0.0.1:{port}"
    process = await start_demo(tmp_path, port, gui)
    try:
        await asyncio.wait_for(healthy(url, process), 90)
        seen: list[Message] = []
        changed = asyncio.Event()

        def record(message: Message) -> None:
            seen.append(message)
            changed.set()

        async with HubClient(f"ws://127.0.0.1:{port}/ws", ADMIN_TOKEN) as hub:
            for type_ in ("alert_raised", "elevator_in_position", "task_event"):
                hub.subscribe(type_, record)
            await hub.sync()
            async with httpx.AsyncClient(base_url=url, headers=ADMIN, timeout=10) as http:
                before = (await http.get("/api/alerts?include_acked=true")).json()

            def arrivals() -> int:
                return sum(
                    1
                    for m in seen
                    if m.type == "elevator_in_position" and m.payload.get("door_open")
                )

            def ended() -> int:
                return sum(
                    1 for m in seen if m.type == "task_event" and m.payload["state"] == "done"
                )

            try:
                await wait_on(changed, lambda: arrivals() >= LIFT_ARRIVALS and ended(), 300)
            except TimeoutError:
                raise AssertionError(
                    f"{arrivals()} lift arrivals, {ended()} tasks done in 300 s"
                ) from None
            alerts = [m.payload for m in seen if m.type == "alert_raised"]
            assert not alerts and not before, [*before, *alerts]
    finally:
        if process.returncode is None:
            await stop(process)

    # The next start on the same database shows nothing stale: no robot was lost (each said
    # it was leaving), and no open alert was last seen by the last server life.
    restarted = time.time()
    process = await start_demo(tmp_path, port, gui)
    try:
        await asyncio.wait_for(healthy(url, process), 90)
        async with httpx.AsyncClient(base_url=url, headers=ADMIN, timeout=10) as http:
            kept = (await http.get("/api/alerts?include_acked=true")).json()
        assert not [a for a in kept if a["kind"] == "robot_lost"], kept
        stale = [a for a in kept if a["resolved_at"] is None and a["last_seen"] < restarted]
        assert not stale, stale
    finally:
        await stop(process)
