"""`guidebot demo` as a user runs it: the URL block, busy visitors, a robot crash survived, two
fleets side by side, a taken control port refused, nothing left running after SIGTERM, and a
second demo in the same folder as good as the first (modules online, plans and pictures, no
access log under the block)."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import psutil
import yaml
from netports import free_block, free_ports

from guidebot.demo_site import mismatched_modules, site_with_ports

ADMIN = {"Authorization": "Bearer dev-admin-token"}
ROOT = Path(__file__).resolve().parents[1]
PYTHONPATH = os.environ.get("PYTHONPATH", "")
BLOCK_TITLE = "GuideBot demo is running"
ACCESS_LOG = re.compile(r'"(GET|POST|PUT|DELETE|HEAD) /\S* HTTP/1\.[01]" \d{3}')


@dataclass
class Demo:
    process: asyncio.subprocess.Process
    url: str
    out: list[str] = field(default_factory=list)
    err: list[str] = field(default_factory=list)
    control: str = ""

    def descendants(self) -> list[psutil.Process]:
        return psutil.Process(self.process.pid).children(recursive=True)

    async def wait_line(
        self, pattern: str, stream: list[str], timeout: float = 60, times: int = 1
    ) -> str:
        """The ``times``-th line of ``stream`` matching ``pattern``, once it came."""
        async with asyncio.timeout(timeout):
            while True:
                found = [line for line in stream if re.search(pattern, line)]
                if len(found) >= times:
                    return found[times - 1]
                if self.process.returncode is not None:
                    raise AssertionError(f"demo exited: {self.err[-5:]}")
                await asyncio.sleep(0.1)


async def _pump(stream: asyncio.StreamReader | None, into: list[str]) -> None:
    assert stream is not None
    while line := await stream.readline():
        into.append(line.decode(errors="replace").rstrip())


@asynccontextmanager
async def demo(
    tmp_path: Path, *args: str, own_db: bool = False, cwd: Path | None = None
) -> AsyncIterator[Demo]:
    """``guidebot demo ARGS`` on free ports, on a database in ``tmp_path`` (``own_db``: the
    demo's default, as ``make demo`` runs it) in the folder ``cwd``."""
    (port,) = free_ports(1)
    gui = free_block(2)  # robot i's touch screen takes gui + i (two robots at most here)
    command = [sys.executable, "-m", "guidebot.cli", "demo", "--no-can", "--time-scale", "5"]
    command += ["--port", str(port), "--gui-port", str(gui), "--sim-control-port", "0"]
    if not own_db:
        command += ["--db", f"sqlite+aiosqlite:///{tmp_path}/demo-{port}.db"]
    command += args
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), PYTHONPATH]))}
    process = await asyncio.create_subprocess_exec(
        *command,
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=cwd,
        env=env,
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
        assert "operator token dev-operator-token" in text
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


async def _modules_online(http: httpx.AsyncClient) -> list[dict[str, object]]:
    """The building's modules once every one answers (the demo's simulator is up)."""
    for _ in range(600):
        modules: list[dict[str, object]] = (await http.get("/api/building")).json()["modules"]
        if modules and all(m["online"] for m in modules):
            return modules
        await asyncio.sleep(0.1)
    raise AssertionError(f"modules offline: {modules}")


async def test_a_second_demo_in_the_same_folder_is_as_good_as_the_first(tmp_path: Path) -> None:
    """``make demo`` twice in one checkout: the second starts from the shipped site with its own
    simulator's ports (a database of its own), says what became of the first one's site edit,
    shows every plan and picture and keeps the URL block readable (no access log)."""
    (tmp_path / "guidebot-demo.db").write_bytes(b"")  # an older demo's, in the checkout
    async with demo(
        tmp_path, "--robots", "1", "--scenario", "quiet", own_db=True, cwd=tmp_path
    ) as first:
        await first.wait_line(r"building sim\s+http", first.out)
        assert any("guidebot-demo.db, the database of a demo before" in x for x in first.out)
        async with httpx.AsyncClient(base_url=first.url, headers=ADMIN, timeout=10) as http:
            await _modules_online(http)
            live = (await http.get("/api/site")).json()
            edited = live["site"]
            shipped_name = edited["pois"][0]["name"]
            edited["pois"][0]["name"] = "Edited in the first demo"
            assert (await http.put("/api/site", json=edited)).status_code == 200
    assert any("the site was edited in this demo" in line for line in first.out), first.out

    async with demo(
        tmp_path, "--robots", "1", "--scenario", "quiet", own_db=True, cwd=tmp_path
    ) as second:
        await second.wait_line(r"building sim\s+http", second.out)
        assert any("starting from" in line and "demo_museum.yaml" in line for line in second.out)
        text = "\n".join(second.out)
        assert "operator token dev-operator-token" in text
        # The robots' start-up lines come first: the block is the last thing printed.
        ready = next(i for i, line in enumerate(second.out) if line.startswith("robot R1 ready"))
        title = next(i for i, line in enumerate(second.out) if line.startswith(BLOCK_TITLE))
        assert ready < title
        async with httpx.AsyncClient(base_url=second.url, headers=ADMIN, timeout=10) as http:
            await _modules_online(http)
            live = (await http.get("/api/site")).json()
            assert live["version"] == 1
            assert live["site"]["pois"][0]["name"] == shipped_name
            assert (await http.get("/api/alerts")).json() == []
            for floor in live["site"]["floors"]:
                plan = await http.get(f"/api/site/plans/{floor['id']}")
                assert plan.status_code == 200, floor
            pictures = [m for p in live["site"]["pois"] for m in p["media"] if m.endswith(".svg")]
            assert pictures
            screen = re.search(r"robot R1\s+(http://127\.0\.0\.1:\d+)", text)
            assert screen is not None, text
            for name in pictures:
                assert (await http.get(f"/media/{name}")).status_code == 200, name
                on_robot = await http.get(f"{screen[1]}/media/{name}")  # its touch screen
                assert on_robot.status_code == 200, name
            operator = {"Authorization": "Bearer dev-operator-token"}
            me = await http.get("/api/me", headers=operator)
            assert me.json() == {"name": "operator", "role": "operator"}
            # Enter shows the block again, once the robots' log has scrolled it away.
            assert second.process.stdin is not None
            second.process.stdin.write(b"\n")
            await second.process.stdin.drain()
            await second.wait_line(BLOCK_TITLE, second.out, times=2)
    logged = [line for line in second.out + second.err if ACCESS_LOG.search(line)]
    assert not logged, logged


async def test_a_demo_on_a_database_that_holds_an_older_site_says_its_modules_stay_offline(
    tmp_path: Path,
) -> None:
    """``--db`` names a database: it is the user's, kept over the site file; the demo warns."""
    db = f"sqlite+aiosqlite:///{tmp_path}/kept.db"
    for run in (1, 2):
        async with demo(
            tmp_path, "--robots", "0", "--scenario", "quiet", "--db", db, own_db=True
        ) as d:
            await d.wait_line(r"building sim\s+http", d.out)
            if run == 2:
                warning = await d.wait_line(r"WARNING: the database already held a site", d.err)
                assert "otb_ground" in warning and "stay offline" in warning


def test_the_served_site_copy_takes_the_files_it_names_and_nothing_else(tmp_path: Path) -> None:
    source = tmp_path / "src"
    (source / "pics" / "es").mkdir(parents=True)
    for name in ("plan.svg", "pics/a.svg", "pics/es/b.svg", "unnamed.svg"):
        (source / name).write_text("<svg/>")
    (tmp_path / "outside.svg").write_text("<svg/>")
    site = source / "site.yaml"
    doc = {
        "floors": [{"id": "F0", "plan_image": "plan.svg"}],
        "pois": [
            {"id": "a", "media": ["pics/a.svg", "../outside.svg", "missing.svg"]},
            {"id": "b", "translations": {"es": {"media": ["pics/es/b.svg"]}}},
        ],
        "modules": [{"id": "m1", "port": 502}, {"id": "m2", "port": 503}],
    }
    site.write_text(yaml.safe_dump(doc))
    served = tmp_path / "served"
    served.mkdir()
    copy = site_with_ports(site, {"m1": 40001}, served)
    files = sorted(str(p.relative_to(served)) for p in served.rglob("*") if p.is_file())
    assert files == ["pics/a.svg", "pics/es/b.svg", "plan.svg", "site.yaml"]
    modules = yaml.safe_load(copy.read_text())["modules"]
    assert [m["port"] for m in modules] == [40001, 503]
    assert mismatched_modules({"modules": modules}, {"m1": 40001, "m2": 40002}) == ["m2 (port 503)"]
