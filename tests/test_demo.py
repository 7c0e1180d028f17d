"""`guidebot demo` as a user runs it: the URL block, busy visitors, a robot crash survived, two
fleets side by side, a taken control port refused, and nothing left running after SIGTERM."""

from __future__ import annotations

import asyncio
import re
import signal
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import psutil
from netports import free_ports

ADMIN = {"Authorization": "Bearer dev-admin-token"}


@dataclass
class Demo:
    process: asyncio.subprocess.Process
    url: str
    out: list[str] = field(default_factory=list)
    err: list[str] = field(default_factory=list)
    control: str = ""

    def descendants(self) -> list[psutil.Process]:
        return psutil.Process(self.process.pid).children(recursive=True)

    async def wait_line(self, pattern: str, stream: list[str], timeout: float = 60) -> str:
        async with asyncio.timeout(timeout):
            while True:
                for line in stream:
                    if re.search(pattern, line):
                        return line
                if self.process.returncode is not None:
                    raise AssertionError(f"demo exited: {self.err[-5:]}")
                await asyncio.sleep(0.1)


async def _pump(stream: asyncio.StreamReader | None, into: list[str]) -> None:
    assert stream is not None
    while line := await stream.readline():
        into.append(line.decode(errors="replace").rstrip())


@asynccontextmanager
async def demo(tmp_path: Path, *args: str) -> AsyncIterator[Demo]:
    port, gui = free_ports(2)
    command = [sys.executable, "-m", "guidebot.cli", "demo", "--no-can", "--time-scale", "5"]
    command += ["--port", str(port), "--gui-port", str(gui), "--sim-control-port", "0"]
    command += ["--db", f"sqlite+aiosqlite:///{tmp_path}/demo-{port}.db", *args]
    process = await asyncio.create_subprocess_exec(
        *command, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    running = Demo(process, f"http://127.0.0.1:{port}")
    pumps = [
        asyncio.create_task(_pump(process.stdout, running.out)),
        asyncio.create_task(_pump(process.stderr, running.err)),
    ]
    seen: list[psutil.Process] = []
    try:
        yield running
        seen = running.descendants()
    finally:
        if process.returncode is None:
            seen = seen or running.descendants()
            process.send_signal(signal.SIGTERM)
            await asyncio.wait_for(process.wait(), 60)
        await asyncio.gather(*pumps)
    assert process.returncode == 0, running.err[-10:]
    assert "demo: every process stopped" in running.out
    alive = [p for p in seen if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    assert not alive, f"left running: {alive}"


async def test_busy_demo_survives_a_robot_crash_beside_a_second_fleet(tmp_path: Path) -> None:
    async with (
        demo(tmp_path, "--robots", "2", "--visitor-every", "0.3", "--seed", "3") as busy,
        demo(tmp_path, "--robots", "1", "--scenario", "quiet") as quiet,
    ):
        block = await busy.wait_line(r"building sim\s+http", busy.out)
        text = "\n".join(busy.out)
        assert f"{busy.url}/admin" in text and f"{busy.url}/config" in text
        assert f"{busy.url}/visitor/#token=dev-panel-token" in text
        assert re.search(r"robot R2\s+http://127\.0\.0\.1:\d+\s+touch screen", text)
        hub_line = re.search(r"hub\s+ws://127\.0\.0\.1:(\d+)/ws\s+the robots' link", text)
        assert hub_line is not None, text
        busy.control = block.split()[-1].removesuffix("/state")
        await quiet.wait_line(r"building sim\s+http", quiet.out)
        assert busy.control not in "\n".join(quiet.out)  # two simulators, two control ports

        # The visitors are busy: a button press and a panel request become tasks.
        async with httpx.AsyncClient(base_url=busy.url, headers=ADMIN, timeout=10) as http:
            for _ in range(600):
                tasks = (await http.get("/api/tasks")).json()["tasks"]
                requesters = {t["requester"] for t in tasks}
                if "visitor-panel" in requesters and any(
                    r.startswith("button:") for r in requesters
                ):
                    break
                await asyncio.sleep(0.1)
            else:
                raise AssertionError(f"no visitor tasks: {requesters}")

            # R1 crashes: the demo reports it and restarts it; the server never stopped.
            [r1] = [p for p in busy.descendants() if "R1" in p.cmdline()]
            r1.kill()
            await busy.wait_line(r"robot R1 exited \(code -9\); restarting it in 1 s", busy.err)
            await busy.wait_line(r"robot R1 restarted \(pid \d+\)", busy.err)
            for _ in range(600):
                robot = (await http.get("/api/robots/R1")).json()
                if robot["online"]:
                    break
                await asyncio.sleep(0.1)
            assert robot["online"]
            health = (await http.get("/api/health")).json()
            assert health["hub_ws_port"] == int(hub_line[1])  # the robots' listener, printed
        async with httpx.AsyncClient(timeout=10) as http:
            assert (await http.get(f"{quiet.url}/api/health")).status_code == 200

        # A third demo on the busy one's control port is refused with the reason.
        third = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "guidebot.cli",
            "demo",
            "--sim-control-port",
            busy.control.rsplit(":", 1)[1],
            "--port",
            str(free_ports(1)[0]),
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        _, err = await asyncio.wait_for(third.communicate(), 60)
        assert third.returncode == 1
        assert "--sim-control-port" in err.decode()
