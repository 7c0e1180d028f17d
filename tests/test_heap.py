"""A ``guidebot`` process spares the collector's passes over what lives as long as it does
(guidebot/heap.py): its imports are frozen, and it exits without a last pass."""

from __future__ import annotations

import gc
import subprocess
import sys
from collections.abc import Iterator

import pytest

from guidebot.heap import quiet_imports


@pytest.fixture
def thawed() -> Iterator[None]:
    """The test starts with nothing frozen, and gives the collector back as it found it."""
    enabled = gc.isenabled()
    gc.unfreeze()
    yield
    gc.unfreeze()
    if enabled:
        gc.enable()
    else:
        gc.disable()


def test_what_an_import_made_is_frozen_and_no_pass_ran_meanwhile(thawed: None) -> None:
    passes = gc.get_stats()
    with quiet_imports():
        assert not gc.isenabled()
        made = [[i] for i in range(20_000)]  # more than enough to start a pass
        assert gc.get_stats() == passes
    assert gc.isenabled()
    assert gc.get_freeze_count() >= len(made)


def test_the_collector_stays_off_when_it_was_off(thawed: None) -> None:
    gc.disable()
    with quiet_imports():
        pass
    assert not gc.isenabled()


EXIT_CHECK = """
import atexit, gc, sys
from guidebot.cli import main
atexit.register(lambda: print("left to collect at exit:", len(gc.get_objects())))
sys.argv = ["guidebot", "webtypes", "--help"]
main()
"""


def test_a_guidebot_command_exits_with_its_heap_frozen() -> None:
    """Handlers run last-registered first: the one registered before the CLI ran looks at the
    heap after the CLI's own (which freezes it), as the interpreter's teardown then does."""
    run = subprocess.run(
        [sys.executable, "-c", EXIT_CHECK], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr
    left = int(run.stdout.rsplit("left to collect at exit:", 1)[1])
    assert left < 1000, f"{left} objects left for the interpreter's last collection"
