"""Suite-wide checks (no test may leave threads behind) and the private Docker engine that the
`docker compose` tests share (tests/compose_engine.py)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest
from compose_engine import EngineUnavailable, missing, private_engine

from guidebot.heap import no_final_collection, quiet_imports

no_final_collection()  # each pytest process (xdist's workers too) exits without a last pass

HEADLESS_SHELL = "/usr/bin/chromium-headless-shell"
"""Debian's chromium-headless-shell (scripts/system-deps.sh): the same Blink and V8 as
/usr/bin/chromium without the browser's own user interface; the browser tests spent 36 % less
CPU with it (69 against 107 CPU-seconds for 34 of them, 28 Nov 2026). The tests and the
benchmarks they run use it unless ``GUIDEBOT_CHROMIUM`` names a browser."""
if os.path.exists(HEADLESS_SHELL):
    os.environ.setdefault("GUIDEBOT_CHROMIUM", HEADLESS_SHELL)


@pytest.hookimpl(wrapper=True)
def pytest_collection(session: pytest.Session) -> Iterator[None]:
    """Collect (import every test module and what it imports) with the collector off, and
    freeze what that made: it lives as long as the process (guidebot/heap.py)."""
    with quiet_imports():
        return (yield)


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which reads the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The docker tests first, in one pytest-xdist worker (`--dist loadgroup`, the Makefile):
    they share the session's private engine (`engine` below) and its image cache, and are the
    longest stretch of the suite, which then runs beside the rest instead of after it.

    The others keep their order. pytest-xdist hands them out a few at a time to each worker
    as it frees up, so the workers end within seconds of each other (7 s apart in a run of
    four). Starting the other long ones first (the cluster tests, the demos, the busy
    browser tests) was tried: five workers starting pairs of servers at once on a loaded
    machine timed out in set-up (28 Nov 2026)."""
    for item in items:
        if item.get_closest_marker("docker") is not None:
            item.add_marker(pytest.mark.xdist_group("docker"))

    items.sort(key=lambda item: item.get_closest_marker("docker") is None)  # stable


@pytest.hookimpl(trylast=True)  # after pytest-xdist's own, which names the groups
def pytest_collection_finish(session: pytest.Session) -> None:
    """Refuse to run the docker tests split over workers: pytest-xdist's loadgroup marks a
    grouped test by a suffix of its node id, which pytest 9.2 drops silently
    (pytest-dev/pytest-xdist#1386; pyproject.toml pins pytest below 9.2 meanwhile)."""
    if not session.config.getoption("loadgroup", False):
        return
    split = [i.nodeid for i in session.items if i.get_closest_marker("docker") is not None]
    split = [nodeid for nodeid in split if not nodeid.endswith("@docker")]
    if split:
        raise pytest.UsageError(
            f"pytest-xdist did not group {split[0]} with the other docker tests (pytest "
            "9.2 and pytest-xdist#1386): use pytest below 9.2, or run without -n"
        )


@pytest.fixture(autouse=True)
def no_thread_leaks() -> Iterator[None]:
    """Fail a test that leaves non-daemon threads running (they would outlive the process)."""
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + 2.0
    while True:
        leaked = [
            t for t in threading.enumerate() if t not in before and t.is_alive() and not t.daemon
        ]
        if not leaked or time.monotonic() > deadline:
            break
        time.sleep(0.02)
    assert not leaked, f"threads left running: {[t.name for t in leaked]}"


@pytest.fixture(scope="session")
def engine() -> Iterator[dict[str, str]]:
    """A private dockerd shared by the `docker compose` tests (the images built for one serve
    the next); yields the environment that talks to it. Skips where none can start."""
    reason = missing()
    if reason is not None:
        pytest.skip(f"no Docker engine can start here: {reason}")
    try:
        with private_engine() as env:
            yield env
    except EngineUnavailable as error:
        pytest.skip(f"no Docker engine can start here: {error}")
