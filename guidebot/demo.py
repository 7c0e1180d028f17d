"""``guidebot demo``: the whole fleet on one machine, as separate processes.

The building simulator (the site's Modbus modules on free ports of 127.0.0.1, its control API
on ``--sim-control-port``), the central server (SQLite, a copy of the site with the simulator's
ports and the plans and pictures it names, the hub's own listener on a free port, no access log)
and N robot agents with simulated RoboCAN hardware, connected to that listener. Every run starts
from the site file on a database of its own (in its temporary folder, gone after the run
unless ``--db`` names one): site edits last for that run, and the demo says so. It prints the
URLs and tokens of every page in one block, and no access log follows it. With ``--scenario
busy`` (the default) seeded simulated visitors press buttons, ask for tours at the visitor panel
and answer "continue the tour?" (demo_visitors.py).

A supervisor: a robot process that dies is reported and restarted (back-off 1, 2, 4 ... 30 s);
the server or the building simulator dying ends the demo. Ctrl-C or SIGTERM stops every process
in order (robots, server, building), each with SIGTERM first and SIGKILL only if it does not
exit within the grace period: no orphans. A stop asked for while a child is being started waits
until the child is recorded (else it would run on, never stopped), and a second Ctrl-C during
the stop does not cut it short.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import IO, Any

import click
import httpx

from guidebot.demo_site import mismatched_modules, site_with_ports
from guidebot.processes import spawn_guidebot, stop_process

__all__ = ["Fleet", "demo"]

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SITE = ROOT / "sites" / "demo_museum.yaml"
GRACE_S = 10.0
RESTART_MAX_S = 30.0
HEALTHY_RUN_S = 60.0  # a robot that ran this long before dying restarts at once again
DEFAULT_CONTROL_PORT = 15080
OLD_DEMO_DB = "guidebot-demo.db"  # every demo's database until each run got its own
ROBOTS_ONLINE_S = 30.0  # the URL block waits this long at most for the robots to connect


@dataclass
class Child:
    name: str
    args: list[str]
    process: subprocess.Popen[bytes] | None = None
    started: float = 0.0
    restarts: int = 0
    restart_at: float | None = None
    ready_line: str | None = None
    """The start of the line the child prints once it is up (``robot R1 ready``): its output
    is then relayed by the demo, which so knows when the line was printed (``ready``)."""
    ready: threading.Event | None = None
    relay: threading.Thread | None = None


def _relay(child: Child, stream: IO[bytes], ready: threading.Event) -> None:
    """Copy a child's output to the demo's, line by line, and set ``ready`` once its ready
    line went out: the URL block must come after it (the server could see a robot online
    before the robot's own line was printed, and the block was not the last thing shown)."""
    shown = True
    with stream:
        for line in iter(stream.readline, b""):
            if shown:
                try:
                    sys.stdout.buffer.write(line)
                    sys.stdout.buffer.flush()
                except (OSError, ValueError):  # nobody reads the demo's output any more
                    shown = False  # keep draining: a full pipe would block the robot
            if child.ready_line is not None and line.startswith(child.ready_line.encode()):
                ready.set()  # after the line went out: the URL block follows it


class Fleet:
    """Starts, watches, restarts and stops the demo's processes."""

    def __init__(self, env: dict[str, str] | None = None) -> None:
        self.children: list[Child] = []
        self.stopping = False
        self.env = env
        self._starting = False
        self._stop_asked = False

    def on_signal(self, _signum: int, _frame: FrameType | None) -> None:
        """SIGTERM and Ctrl-C: stop, raised as KeyboardInterrupt where the launcher is. Not
        inside a child's start: raised there, between the fork and the ``Popen``'s return, it
        left that child running and unknown, never stopped (holding the demo's output open:
        whoever waited for it to end waited for ever); the stop is raised once the child is
        recorded. Nor once the stop runs: it has its own grace period and SIGKILL."""
        if self.stopping:
            return
        if self._starting:
            self._stop_asked = True
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def _recording(self) -> Iterator[None]:
        """A child's start and its record, with a stop asked for meanwhile raised after."""
        self._starting = True
        try:
            yield
        finally:
            self._starting = False
            if self._stop_asked:
                self._stop_asked = False
                raise KeyboardInterrupt

    def spawn(
        self, name: str, *args: str, stdout: int | None = None, ready_line: str | None = None
    ) -> Child:
        child = Child(name, list(args), ready_line=ready_line)
        self.children.append(child)
        self._start(child, stdout)
        return child

    def adopt(self, name: str, start: Callable[[], subprocess.Popen[bytes]]) -> Child:
        """A child that is not ``guidebot`` (the MQTT broker): ``start()`` runs it, and the
        fleet stops it with the others."""
        child = Child(name, [])
        self.children.append(child)
        with self._recording():
            child.process = start()
            child.started = time.monotonic()
        return child

    def _start(self, child: Child, stdout: int | None = None) -> None:
        # A session of its own: Ctrl-C reaches only the launcher, which stops children in order.
        relayed = child.ready_line is not None
        env = self.env
        if relayed:  # unbuffered, so that its lines show as they come (a pipe is no terminal)
            env = {**(env if env is not None else os.environ), "PYTHONUNBUFFERED": "1"}
            stdout = subprocess.PIPE
        with self._recording():
            child.process = spawn_guidebot(child.args, stdout=stdout, env=env)
            child.started = time.monotonic()
        if not relayed:
            return
        ready = child.ready = threading.Event()
        assert child.process.stdout is not None
        child.relay = threading.Thread(
            target=_relay,
            args=(child, child.process.stdout, ready),
            name=f"demo-relay-{child.name}",
            daemon=True,
        )
        child.relay.start()

    def ready(self, name: str) -> bool:
        """Whether the child ``name`` printed its ready line (one without such a line: yes)."""
        return all(c.ready is None or c.ready.is_set() for c in self.children if c.name == name)

    def dead(self) -> list[Child]:
        return [c for c in self.children if c.process is not None and c.process.poll() is not None]

    def supervise(self, child: Child, now: float) -> str | None:
        """A dead robot: schedule its restart, or restart it when due; returns what to say."""
        process = child.process
        assert process is not None
        if child.restart_at is None:
            if now - child.started >= HEALTHY_RUN_S:
                child.restarts = 0
            delay = min(RESTART_MAX_S, 2.0**child.restarts)
            child.restarts += 1
            child.restart_at = now + delay
            return (
                f"demo: robot {child.name} exited (code {process.returncode}); "
                f"restarting it in {delay:g} s (restart {child.restarts})"
            )
        if now < child.restart_at:
            return None
        child.restart_at = None
        self._start(child)
        assert child.process is not None
        return f"demo: robot {child.name} restarted (pid {child.process.pid})"

    def stop_all(self) -> None:
        """Robots first (they report their last state), then the server, then the building."""
        self.stopping = True
        for child in reversed(self.children):
            if child.process is not None and stop_process(child.process, GRACE_S):
                click.echo(
                    f"demo: {child.name} ignored SIGTERM for {GRACE_S:g} s: killed", err=True
                )
            if child.relay is not None:
                child.relay.join(GRACE_S)  # its last lines, up to its output's end


class Keys:
    """The terminal the demo runs in: Enter shows the URL block again (the robots' log scrolls
    it away). A stream that ends (no terminal, </dev/null) is no longer watched."""

    def __init__(self, stream: IO[str] | None) -> None:
        self.stream = stream
        try:
            if stream is not None:
                stream.fileno()
        except (OSError, ValueError):
            self.stream = None

    def _foreground(self) -> bool:
        """Not a terminal, or one whose foreground we are (a read in the background of a
        terminal would stop the demo: SIGTTIN)."""
        assert self.stream is not None
        fd = self.stream.fileno()
        try:
            return not os.isatty(fd) or os.tcgetpgrp(fd) == os.getpgrp()
        except OSError:
            return False

    def enter_pressed(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for a line; True when one came."""
        if self.stream is None or not self._foreground():
            time.sleep(timeout_s)
            return False
        ready, _, _ = select.select([self.stream], [], [], timeout_s)
        if not ready:
            return False
        if not self.stream.readline():
            self.stream = None  # end of input
            return False
        return True


def _wait_healthy(url: str, fleet: Fleet, timeout_s: float = 60.0) -> dict[str, Any]:
    """The server's /api/health once it answers (one client for every poll: each new one
    loads the CA bundle, some 20 ms of CPU, and a start under load is polled many times)."""
    deadline = time.monotonic() + timeout_s
    with httpx.Client(timeout=1.0) as http:
        while time.monotonic() < deadline:
            if fleet.dead():
                raise click.ClickException(f"{fleet.dead()[0].name} exited during start-up")
            try:
                answer = http.get(f"{url}/api/health")
                if answer.status_code == 200:
                    health: dict[str, Any] = answer.json()
                    return health
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
    raise click.ClickException(f"the server at {url} did not answer within {timeout_s:g} s")


def _read_ready(child: Child, timeout_s: float = 60.0) -> dict[str, Any]:
    """The building simulator's first line: {"ready": true, "control": URL, "modules": {...}}."""
    assert child.process is not None and child.process.stdout is not None
    stream: IO[bytes] = child.process.stdout
    ready, _, _ = select.select([stream], [], [], timeout_s)
    line = stream.readline() if ready else b""
    try:
        info: dict[str, Any] = json.loads(line)
    except ValueError:
        code = child.process.poll()
        raise click.ClickException(
            f"the building simulator did not start (exit code {code}); is its control port "
            "taken? choose another with --sim-control-port (0: any free port)"
        ) from None
    return info


def _server_env(panel_token: str, operator_token: str, control: str) -> dict[str, str]:
    """The environment with the demo's visitor-panel and operator tokens added to
    GUIDEBOT_TOKENS, and the building simulator's control API for the console's "press a
    button"."""
    env = dict(os.environ)
    env.setdefault("GUIDEBOT_BUILDING_SIM_URL", control)
    tokens = json.loads(env.get("GUIDEBOT_TOKENS") or "[]")
    for token, name, role in (
        (panel_token, "visitor-panel", "panel"),
        (operator_token, "operator", "operator"),
    ):
        if not any(t.get("token") == token for t in tokens):
            tokens.append({"token": token, "name": name, "role": role})
    env["GUIDEBOT_TOKENS"] = json.dumps(tokens)
    return env


def _wait_robots_online(
    url: str, admin: str, names: list[str], fleet: Fleet, timeout_s: float = ROBOTS_ONLINE_S
) -> list[str]:
    """Wait until the robots are online and have printed their ready line (their start-up lines
    come before the URL block, which then stays the last thing printed); returns those still
    offline or not ready after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    offline = list(names)
    with httpx.Client(timeout=2.0, headers={"Authorization": f"Bearer {admin}"}) as http:
        while offline and time.monotonic() < deadline and not fleet.dead():
            try:
                robots = http.get(f"{url}/api/robots").json()
                online = {r["name"] for r in robots if r.get("online")}
                offline = [n for n in names if n not in online or not fleet.ready(n)]
            except (httpx.HTTPError, ValueError, TypeError, KeyError):
                pass
            if offline:
                time.sleep(0.2)
    return offline


def _live_site(url: str, admin: str) -> tuple[int, dict[str, Any]] | None:
    """The server's live site and its version; None when it cannot be read."""
    try:
        answer = httpx.get(
            f"{url}/api/site", headers={"Authorization": f"Bearer {admin}"}, timeout=10.0
        )
    except httpx.HTTPError:
        return None
    if answer.status_code != 200:
        return None
    live: dict[str, Any] = answer.json()
    return int(live["version"]), live["site"]


def _check_live_site(url: str, admin: str, ports: dict[str, int]) -> tuple[int | None, str]:
    """The live site's version, and a warning when it is not this run's (a ``--db`` that
    already held a site is kept over the site file): its modules would stay offline."""
    live = _live_site(url, admin)
    if live is None:
        return None, "demo: could not read the server's live site: its modules are not checked"
    version, site = live
    wrong = mismatched_modules(site, ports)
    if not wrong:
        return version, ""
    return version, (
        f"demo: WARNING: the database already held a site (version {version}), kept over the "
        f"site file; its modules {', '.join(wrong)} are not where this run's building simulator "
        "listens and stay offline. Start the demo without --db (a database of its own) or on an "
        "empty one."
    )


def _say_edits(url: str, admin: str, started: int | None, site: Path, own_db: bool) -> None:
    """At the end: whether the site was edited during the run, and what becomes of the edits."""
    live = _live_site(url, admin)
    if started is None or live is None or live[0] == started:
        return
    fate = (
        f"end with this demo: the next one starts from {site} again"
        if own_db
        else "stay in the database given with --db"
    )
    click.echo(
        f"demo: the site was edited in this demo (version {started} -> {live[0]}); edits {fate}"
    )


def url_block(
    url: str,
    admin: str,
    panel: str,
    screens: list[tuple[str, str, str]],
    control: str,
    scenario: str,
    seed: int,
    hub_url: str,
    operator: str = "",
    vda: str = "",
) -> str:
    """Every page's URL and token, in one short block."""
    lines = [
        "",
        "GuideBot demo is running (Ctrl-C stops everything; Enter shows this block again).",
        f"  staff console  {url}/admin/          admin token {admin}",
        *(
            [f"                 operator token {operator} (staff, no site edits)"]
            if operator
            else []
        ),
        f"  visitor panel  {url}/visitor/#token={panel}   (kiosk: add &kiosk=1)",
        f"  site editor    {url}/config/         admin token {admin}",
        *(f"  robot {n:<8} {s}   touch screen (robot token {t})" for n, t, s in screens),
        f"  API docs       {url}/docs   metrics {url}/metrics (admin token)",
        f"  hub            {hub_url}   the robots' link (pages: /ws on {url})",
        f"  building sim   {control}/state",
        *([f"  VDA 5050       {vda}"] if vda else []),
    ]
    if scenario == "busy":
        lines.append(
            f"  scenario busy (seed {seed}): visitors press buttons, ask for tours at the "
            "panel and answer 'continue the tour?'"
        )
    lines += [
        "  request a tour:",
        f"    curl -X POST {url}/api/tasks -H 'Authorization: Bearer {admin}' "
        "-H 'Content-Type: application/json' "
        '-d \'{"kind": "tour", "params": {"tour": "ground"}}\'',
        "",
    ]
    return "\n".join(lines)


@click.command()
@click.option("--robots", type=click.IntRange(0, 50), default=2, show_default=True)
@click.option(
    "--vda-robots",
    type=click.IntRange(0, 10),
    default=1,
    show_default=True,
    help="Simulated VDA 5050 vehicles (V1, ...) on a private Mosquitto (docs/vda5050.md).",
)
@click.option(
    "--vda-version",
    type=click.Choice(["2.1.0", "3.0.0"]),
    default="2.1.0",
    show_default=True,
    help="The VDA 5050 version the simulated vehicles speak (3.0.0: zones, hibernation).",
)
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
@click.option(
    "--sim-control-port",
    type=click.IntRange(0, 65535),
    default=DEFAULT_CONTROL_PORT,
    show_default=True,
    help="The building simulator's control API (0: any free port). Its Modbus modules always "
    "take free ports, so two demos can run on one machine.",
)
@click.option(
    "--db",
    default=None,
    help="Database URL (default: a SQLite file of this run, deleted at the end: every demo "
    "starts from the site file). A database that already holds a site keeps it, and the demo "
    "warns when its modules are not where this run's simulator listens.",
)
@click.option("--no-can", is_flag=True, help="Robots without CAN (a bare simulated base): light.")
@click.option(
    "--scenario",
    type=click.Choice(["busy", "quiet"]),
    default="busy",
    show_default=True,
    help="busy: simulated visitors press buttons, ask for tours and answer the robots; "
    "quiet: nothing happens until you ask.",
)
@click.option("--seed", type=int, default=1, show_default=True, help="The visitors' dice.")
@click.option(
    "--visitor-every",
    type=click.FloatRange(min=0.1),
    default=8.0,
    show_default=True,
    help="busy: mean wall seconds between two visitors' actions.",
)
@click.option(
    "--panel-token",
    default="dev-panel-token",
    show_default=True,
    envvar="GUIDEBOT_DEMO_PANEL_TOKEN",
    help="Token of the visitor panel (role panel) the demo adds to the server's tokens.",
)
@click.option(
    "--operator-token",
    default="dev-operator-token",
    show_default=True,
    envvar="GUIDEBOT_DEMO_OPERATOR_TOKEN",
    help="Token of a staff member in role operator the demo adds to the server's tokens.",
)
@click.option(
    "--visitors/--no-visitors",
    default=True,
    show_default=True,
    help="quiet: a simulated visitor on each robot answers yes to 'continue the tour?' (else "
    "tours stop at the first point unless someone answers on the touch screen).",
)
def demo(
    robots: int,
    vda_robots: int,
    vda_version: str,
    time_scale: float,
    site: Path,
    port: int,
    gui_port: int,
    sim_control_port: int,
    db: str | None,
    no_can: bool,
    scenario: str,
    seed: int,
    visitor_every: float,
    panel_token: str,
    operator_token: str,
    visitors: bool,
) -> None:
    """Run the building simulator, the server and N simulated robots until Ctrl-C."""
    from guidebot.demo_vda import (
        add_vda_robots,
        broker_command,
        launch_broker,
        mosquitto_binary,
        wait_broker,
    )
    from guidebot.demo_visitors import Visitors
    from guidebot.site.yamlio import load_site_file

    loaded = load_site_file(site)
    known = loaded.robots
    if robots > len(known):
        raise click.UsageError(f"{site} lists {len(known)} robots; --robots {robots} is too many")
    if len(panel_token) < 8:
        raise click.UsageError("--panel-token must be at least 8 characters")
    if len(operator_token) < 8:
        raise click.UsageError("--operator-token must be at least 8 characters")
    fleet = Fleet()
    signal.signal(signal.SIGTERM, fleet.on_signal)
    signal.signal(signal.SIGINT, fleet.on_signal)
    url = f"http://127.0.0.1:{port}"
    admin = os.environ.get("GUIDEBOT_ADMIN_TOKEN", "dev-admin-token")
    scale = f"{time_scale:g}"
    folder = Path(tempfile.mkdtemp(prefix="guidebot-demo-"))
    own_db = db is None
    db = db or f"sqlite+aiosqlite:///{folder / 'guidebot-demo.db'}"
    if own_db:
        click.echo(
            f"demo: starting from {site} on a database of this run: site edits made in the "
            "editor last until Ctrl-C (export the YAML from the editor to keep them)"
        )
        if Path(OLD_DEMO_DB).exists():
            click.echo(
                f"demo: ./{OLD_DEMO_DB}, the database of a demo before this version, is not "
                "used (nor changed): delete it when you no longer need it"
            )
    started_version: int | None = None
    try:
        building = fleet.spawn(
            "building-sim",
            "building-sim",
            "--site",
            str(site),
            "--time-scale",
            scale,
            "--control-port",
            str(sim_control_port),
            "--port-zero",
            stdout=subprocess.PIPE,
        )
        ready = _read_ready(building)
        control = str(ready["control"])
        ports = {str(k): int(v) for k, v in dict(ready["modules"]).items()}
        served = site_with_ports(site, ports, folder)
        mosquitto = mosquitto_binary() if vda_robots else None
        if vda_robots and mosquitto is None:
            click.echo("demo: mosquitto is not installed: no VDA 5050 robot", err=True)
        vda: list[str] = []
        if mosquitto is not None:
            command, mqtt_port = broker_command(mosquitto, folder)
            broker = fleet.adopt("mosquitto", lambda: launch_broker(command))
            assert broker.process is not None
            mqtt_url = wait_broker(broker.process, mqtt_port)
            taken = {r.start_node or "" for r in known[:robots]}
            vda = add_vda_robots(served, vda_robots, taken, vda_version)
        fleet.env = _server_env(panel_token, operator_token, control)
        # The robots connect to the hub's own listener (any free port; /api/health names it).
        server_args = ["--port", str(port), "--hub-ws-port", "0", "--site", str(served)]
        server_args += ["--mqtt", mqtt_url] if vda else []
        fleet.spawn("server", "server", *server_args, "--db", db, "--no-access-log")
        fleet.env = None
        hub_url = f"ws://127.0.0.1:{_wait_healthy(url, fleet)['hub_ws_port']}/ws"
        started_version, warning = _check_live_site(url, admin, ports)
        if warning:
            click.echo(warning, err=True)
        screens = []
        robot_children = set()
        for index, robot in enumerate(known[:robots]):
            args = ["robot", "--name", robot.name, "--server", hub_url, "--token", robot.token]
            args += ["--time-scale", scale, "--site", str(served)]
            args += ["--gui-port", str(gui_port + index)]
            args += ["--visitor", "yes"] if visitors and scenario == "quiet" else []
            args += ["--no-can"] if no_can else ["--simulate", "--can", f"virtual:{robot.name}"]
            robot_children.add(robot.name)
            fleet.spawn(robot.name, *args, ready_line=f"robot {robot.name} ready")
            screens.append((robot.name, robot.token, f"http://127.0.0.1:{gui_port + index}"))
        for name in vda:
            args = ["vda5050-sim", "--broker", mqtt_url, "--site", str(served), "--robot", name]
            robot_children.add(name)
            fleet.spawn(name, *args, "--time-scale", scale)
        late = _wait_robots_online(url, admin, sorted(robot_children), fleet)
        if late:
            click.echo(f"demo: not online yet: {', '.join(late)}", err=True)
        vda_line = f"{', '.join(vda)} (simulated vehicles) on {mqtt_url}" if vda else ""
        block = url_block(
            url,
            admin,
            panel_token,
            screens,
            control,
            scenario,
            seed,
            hub_url,
            operator_token,
            vda_line,
        )
        click.echo(block)
        keys = Keys(sys.stdin)
        crowd = None
        if scenario == "busy":
            crowd = Visitors(
                server=url,
                panel_token=panel_token,
                admin_token=admin,
                building=control,
                buttons=[b.id for b in loaded.buttons],
                tours=[t.id for t in loaded.tours],
                screens=[s for _, _, s in screens],
                seed=seed,
                every_s=visitor_every,
            )
        with httpx.Client(timeout=2.0) as http:
            while True:
                now = time.monotonic()
                for child in fleet.dead():
                    if child.name not in robot_children:
                        code = child.process.returncode if child.process else None
                        raise click.ClickException(f"{child.name} exited (code {code}): stopping")
                for child in fleet.children:
                    if child.name in robot_children and (
                        child.restart_at is not None or child in fleet.dead()
                    ):
                        said = fleet.supervise(child, now)
                        if said:
                            click.echo(said, err=True)
                if crowd is not None:
                    for action in crowd.tick(http, now):
                        click.echo(f"demo: {action}")
                if keys.enter_pressed(0.5):
                    click.echo(block)
    except KeyboardInterrupt:
        click.echo("\ndemo: stopping robots, server and building simulator ...")
        _say_edits(url, admin, started_version, site, own_db)
    finally:
        fleet.stop_all()
        shutil.rmtree(folder, ignore_errors=True)
        click.echo("demo: every process stopped")
