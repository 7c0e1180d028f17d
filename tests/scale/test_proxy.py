"""deploy/cluster/nginx.conf in front of two real servers (docs/scaling.md, "Behind a load
balancer"): REST reaches the leader whichever server nginx tries first, a POST is done once,
WebSockets pass, and after a fail-over REST reaches the new leader. Debian's nginx-light; the
test is skipped, saying why, without it."""

from __future__ import annotations

import re
import shutil
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from backend.accounts.cookies import CSRF_HEADER, SESSION_COOKIE
from bench.cluster_clients import WsClient
from bench.servers import ADMIN_TOKEN, GUI_TOKEN, ServerProcess, wait_until

from .test_accounts_across import PASSWORD, closed_with, hub_link, signed_in

CONF = Path(__file__).resolve().parents[2] / "deploy" / "cluster" / "nginx.conf"
AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _render(servers: list[ServerProcess], port: int, root: Path) -> str:
    """The shipped configuration with the test's addresses, paths under ``root``, no logs."""
    text = CONF.read_text()
    upstreams = "".join(f"        server 127.0.0.1:{s.port} max_fails=0;\n" for s in servers)
    text = re.sub(r"(?m)^\s*server server-\w+:\d+ max_fails=0;\n", "", text)
    text = text.replace("upstream guidebot {\n", "upstream guidebot {\n" + upstreams)
    text = text.replace("listen 8080;", f"listen 127.0.0.1:{port};")
    paths = "".join(
        f"    {name}_temp_path {root / name};\n"
        for name in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi")
    )
    return text.replace("http {\n", f"http {{\n    access_log off;\n{paths}", 1)


@pytest.fixture
def proxy(pair: list[ServerProcess], tmp_path: Path) -> Iterator[str]:
    nginx = shutil.which("nginx") or (
        "/usr/sbin/nginx" if Path("/usr/sbin/nginx").exists() else None
    )
    if nginx is None:
        pytest.skip("nginx is not installed: run `make system-deps` (Debian nginx-light)")
    port = _free_port()
    conf = tmp_path / "nginx.conf"
    conf.write_text(_render(pair, port, tmp_path))
    args = [nginx, "-p", str(tmp_path), "-c", str(conf)]
    args += ["-g", f"daemon off; pid {tmp_path / 'nginx.pid'}; error_log stderr;"]
    log = (tmp_path / "nginx.log").open("wb")
    process = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        process.terminate()
        process.wait(10)
        log.close()


async def test_rest_through_the_proxy_reaches_the_leader(
    pair: list[ServerProcess], proxy: str
) -> None:
    alpha, beta = pair
    await alpha.until(alpha.leads, "alpha to lead")

    async def proxied() -> bool:
        try:
            async with httpx.AsyncClient(headers=AUTH) as http:
                return (await http.get(f"{proxy}/api/tasks")).status_code == 200
        except httpx.HTTPError:
            return False

    await wait_until(proxied, 20, "nginx to answer")
    async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
        # Round robin: every other request lands on the follower first, which answers 503.
        answers = [await http.get(f"{proxy}/api/tasks") for _ in range(6)]
        assert [a.status_code for a in answers] == [200] * 6
        ids = []
        for _ in range(4):  # POST is retried on the leader too, and done exactly once
            created = await http.post(
                f"{proxy}/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            assert created.status_code in (200, 201), created.text
            ids.append(created.json()["id"])
        listed = await http.get(f"{alpha.url}/api/tasks", params={"limit": 1000})
        assert sorted(t["id"] for t in listed.json()["tasks"]) == sorted(ids)

        # WebSockets through the proxy reach a hub whichever server holds them.
        gui = await WsClient.connect(_Via(proxy), GUI_TOKEN)  # type: ignore[arg-type]
        robot = await WsClient.connect(beta, "robot-R1-demo-token")
        try:
            await gui.send("subscribe", {"patterns": ["say"]})
            await gui.send("ping", {}, id="subscribed")
            await wait_until(lambda: _true(gui.of_type("pong")), 20, "pong through nginx")
            await robot.send("say", {"text": "through the proxy"})
            await wait_until(lambda: _true(gui.of_type("say")), 20, "say through nginx")
        finally:
            await gui.close()
            await robot.close()

        alpha.kill()
        await beta.until(beta.leads, "beta to lead")
        after = await http.get(f"{proxy}/api/tasks", params={"limit": 1000})
        assert after.status_code == 200  # nginx skips the dead server and the 503s
        assert sorted(t["id"] for t in after.json()["tasks"]) == sorted(ids)


async def test_a_person_signed_in_by_cookie_uses_rest_and_the_hub_through_the_proxy(
    pair: list[ServerProcess], proxy: str
) -> None:
    """As a browser on the proxy's address: it sends its page's Origin on every POST and
    WebSocket, which the servers compare with the Host header nginx passes on (with its port:
    ``$http_host``, else every cookie request but a GET was refused). REST lands on the
    leader; hub links land on both servers in turn."""
    alpha, _ = pair
    await alpha.until(alpha.leads, "alpha to lead")
    await signed_in(alpha, "ada", "operator")
    browser = {"Origin": proxy}
    async with httpx.AsyncClient(base_url=proxy, timeout=30, headers=browser) as http:
        answer = await http.post("/api/session", json={"name": "ada", "password": PASSWORD})
        assert answer.status_code == 200, answer.text
        cookie, csrf = answer.cookies[SESSION_COOKIE], answer.json()["csrf"]
        mine = {"Cookie": f"{SESSION_COOKIE}={cookie}", CSRF_HEADER: csrf}
        for _ in range(4):  # round robin: each request lands on the follower first once
            assert (await http.get("/api/robots", headers=mine)).status_code == 200
            created = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}, headers=mine
            )
            assert created.status_code == 201, created.text
        links = [await hub_link(_Via(proxy), cookie) for _ in range(4)]  # type: ignore[arg-type]
        ended = await http.post("/api/session/everywhere", headers=mine)
        assert ended.json()["ended"] == 2  # signed_in's session and this one
        assert [await closed_with(ws) for ws in links] == [4001] * 4


class _Via:
    """Where WsClient connects: the proxy's port."""

    def __init__(self, url: str) -> None:
        self.port = int(url.rsplit(":", 1)[1])
        self.url = url


async def _true(value: object) -> object:
    return value
