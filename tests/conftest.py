"""Suite-wide checks (no test may leave threads behind) and the private Docker engine that the
`docker compose` tests share (tests/compose_engine.py)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest
from compose_engine import EngineUnavailable, missing, private_engine


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
