"""Suite-wide checks (no test may leave threads behind), the order tests start in, and the
private Docker engine that the `docker compose` tests share (tests/compose_engine.py)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from compose_engine import EngineUnavailable, missing, private_engine

ROOT = Path(__file__).resolve().parent.parent
LONGEST = frozenset(
    {
        "tests/building/test_bench_emergency.py",
        "tests/scale/test_acks_across.py",
        "tests/scale/test_areas_across.py",
        "tests/scale/test_benches.py",
        "tests/scale/test_broker_faults.py",
        "tests/scale/test_follower_site.py",
        "tests/scale/test_tour_across.py",
        "tests/server/test_bench_hub.py",
        "tests/test_alerts_fault_free.py",
        "tests/test_demo.py",
        "tests/test_soak.py",
        "tests/web/test_busy_truth.py",
        "tests/web/test_console_busy.py",
        "tests/web/test_console_cluster.py",
        "tests/web/test_console_truth.py",
        "tests/web/test_console_twice.py",
        "tests/web/test_visitor_a11y.py",
    }
)
"""Files with a test of a minute or more on a loaded machine (`--durations`, 28 Nov 2026): a
fleet, a cluster or a browser at work. They start first, after the docker tests."""


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which reads the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest tests first, so that the run ends on short ones: the docker tests, in one
    pytest-xdist worker (`--dist loadgroup`, the Makefile), as they share the session's private
    engine (`engine` below) and its image cache; then the tests of the files in `LONGEST` and
    those marked `slow`.

    pytest-xdist hands out tests in collection order, a few at a time to each worker as it
    frees up: a 100 s test that comes last keeps one worker busy 100 s after the others ended,
    and one that comes first runs beside the rest."""
    for item in items:
        if item.get_closest_marker("docker") is not None:
            item.add_marker(pytest.mark.xdist_group("docker"))

    def rank(item: pytest.Item) -> int:
        if item.get_closest_marker("docker") is not None:
            return 0
        slow = item.get_closest_marker("slow") is not None
        return 1 if slow or item.path.relative_to(ROOT).as_posix() in LONGEST else 2

    items.sort(key=rank)  # stable: collection order within each rank


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
