"""``guidebot demo``: the whole fleet on one machine, as separate processes.

The central server (SQLite, the demo site), the building simulator (the site's Modbus modules on
127.0.0.1) and N robot agents with simulated RoboCAN hardware. It prints the URLs and tokens to
use; Ctrl-C or SIGTERM stops every process in order (robots, building, server), each with
SIGTERM first and SIGKILL only if it does not exit within the grace period: no orphans.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from types import FrameType

import click
import httpx

__all__ = ["Fleet", "demo"]

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SITE = ROOT / "sites" / "demo_museum.yaml"
GRACE_S = 10.0


@dataclass
class Child:
    name: str
    args: list[str]
    process: subprocess.Popen[bytes] | None = None


class Fleet:
    """Starts, watches and stops the demo's processes."""

    def __init__(self) -> None:
        self.children: list[Child] = []
        self.stopping = False

    def spawn(self, name: str, *args: str) -> Child:
        child = Child(name, [sys.executable, "-m", "guidebot.cli", *args])
        # A session of its own: Ctrl-C reaches only the launcher, which stops children in order.
        child.process = subprocess.Popen(child.args, start_new_session=True)
        self.children.append(child)
        return child

    def dead(self) -> list[Child]:
        return [c for c in self.children if c.process is not None and c.process.poll() is not None]

    def stop_all(self) -> None:
        """Robots first (they report their last state), then the building, then the server."""
        self.stopping = True
        for child in reversed(self.children):
            process = child.process
            if process is None or process.poll() is not None:
                continue
            process.terminate()
            try:
                process.wait(GRACE_S)
            except subprocess.TimeoutExpired:
                click.echo(
                    f"demo: {child.name} ignored SIGTERM for {GRACE_S:g} s: killed", err=True
                )
                process.kill()
                process.wait()


def _panel_token() -> str:
    """The demo's visitor-panel token: GUIDEBOT_PANEL_TOKEN (default dev-panel-token), added
    to GUIDEBOT_TOKENS for the server process unless a panel token is already there."""
    token = os.environ.get("GUIDEBOT_PANEL_TOKEN", "dev-panel-token")
    tokens = json.loads(os.environ.get("GUIDEBOT_TOKENS") or "[]")
    panels = [t["token"] for t in tokens if t.get("role") == "panel"]
    if panels:
        return str(panels[0])
    tokens.append({"token": token, "name": "panel-entrance", "role": "panel"})
    os.environ["GUIDEBOT_TOKENS"] = json.dumps(tokens)
    return token


def _wait_healthy(url: str, fleet: Fleet, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if fleet.dead():
            raise click.ClickException(f"{fleet.dead()[0].name} exited during start-up")
        try:
            if httpx.get(f"{url}/api/health", timeout=1.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise click.ClickException(f"the server at {url} did not answer within {timeout_s:g} s")


@click.command()
@click.option("--robots", type=click.IntRange(0, 50), default=3, show_default=True)
@click.option("--time-scale", type=click.FloatRange(min=0.01), default=1.0, show_default=True)
@click.option(
    "--site",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=DEFAULT_SITE,
    show_default=True,
)
@click.option("--port", type=click.IntRange(1, 65535), default=8000, show_default=True)
@click.option(
    "--gui-port",
    type=click.IntRange(1, 65535),
    default=8101,
    show_default=True,
    help="Touch screen of the first robot; the next robots take the next ports.",
)
@click.option("--db", default="sqlite+aiosqlite:///./guidebot-demo.db", show_default=True)
@click.option("--no-can", is_flag=True, help="Robots without CAN (a bare simulated base): light.")
@click.option(
    "--visitors/--no-visitors",
    default=True,
    show_default=True,
    help="Simulated visitors answer yes to 'continue the tour?' (else tours stop at the "
    "first point unless someone answers on the touch screen).",
)
def demo(
    robots: int,
    time_scale: float,
    site: Path,
    port: int,
    gui_port: int,
    db: str,
    no_can: bool,
    visitors: bool,
) -> None:
    """Run the server, the building simulator and N simulated robots until Ctrl-C."""
    from guidebot.site.yamlio import load_site_file

    known = load_site_file(site).robots
    if robots > len(known):
        raise click.UsageError(f"{site} lists {len(known)} robots; --robots {robots} is too many")
    fleet = Fleet()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_signal)
    url = f"http://127.0.0.1:{port}"
    admin = os.environ.get("GUIDEBOT_ADMIN_TOKEN", "dev-admin-token")
    panel = _panel_token()
    scale = f"{time_scale:g}"
    try:
        fleet.spawn("server", "server", "--port", str(port), "--site", str(site), "--db", db)
        _wait_healthy(url, fleet)
        fleet.spawn("building-sim", "building-sim", "--site", str(site), "--time-scale", scale)
        screens = []
        for index, robot in enumerate(known[:robots]):
            args = ["robot", "--name", robot.name, "--server", url, "--token", robot.token]
            args += ["--time-scale", scale, "--site", str(site)]
            args += ["--gui-port", str(gui_port + index)]
            args += ["--visitor", "yes"] if visitors else []
            args += ["--no-can"] if no_can else ["--simulate", "--can", f"virtual:{robot.name}"]
            fleet.spawn(robot.name, *args)
            screens.append((robot.name, robot.token, f"http://127.0.0.1:{gui_port + index}"))
        click.echo(
            "\n".join(
                [
                    "",
                    "GuideBot demo is running (Ctrl-C stops everything).",
                    f"  server      {url}   (API docs {url}/docs)",
                    f"  admin token {admin}",
                    f"  visitor panel (phone) {url}/visitor/#token={panel}",
                    f"  visitor panel (kiosk) {url}/visitor/#token={panel}&kiosk=1",
                    *(f"  robot {n:<5} token {t}   touch screen {s}" for n, t, s in screens),
                    "  request a tour:",
                    f"    curl -X POST {url}/api/tasks -H 'Authorization: Bearer {admin}' "
                    "-H 'Content-Type: application/json' "
                    '-d \'{"kind": "tour", "params": {"tour": "ground"}}\'',
                    f"  follow it:  curl -H 'Authorization: Bearer {admin}' {url}/api/tasks",
                    "",
                ]
            )
        )
        while True:
            dead = fleet.dead()
            if dead:
                code = dead[0].process.returncode if dead[0].process else None
                raise click.ClickException(f"{dead[0].name} exited (code {code}): stopping")
            time.sleep(0.5)
    except KeyboardInterrupt:
        click.echo("\ndemo: stopping robots, building simulator and server ...")
    finally:
        fleet.stop_all()
        click.echo("demo: every process stopped")
