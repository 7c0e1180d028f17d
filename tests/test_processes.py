"""Launching and stopping guidebot child processes (the demo's and the soak's fleets)."""

from __future__ import annotations

import subprocess
import sys
import time

from guidebot.processes import spawn_guidebot, stop_process

IGNORES_SIGTERM = (
    "import signal, sys, time\n"
    "signal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
    "print('ready', flush=True)\n"
    "time.sleep(60)\n"
)


def test_a_child_that_ignores_sigterm_is_killed_after_the_grace() -> None:
    child = subprocess.Popen([sys.executable, "-c", IGNORES_SIGTERM], stdout=subprocess.PIPE)
    assert child.stdout is not None and child.stdout.readline() == b"ready\n"
    started = time.monotonic()
    assert stop_process(child, grace_s=0.5) is True
    assert child.returncode == -9 and time.monotonic() - started >= 0.5
    child.stdout.close()


def test_a_child_that_exits_on_sigterm_is_not_killed_and_a_dead_one_is_left_alone() -> None:
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    assert stop_process(child, grace_s=30) is False
    assert child.returncode == -15
    assert stop_process(child, grace_s=30) is False


def test_spawn_runs_this_interpreters_guidebot() -> None:
    child = spawn_guidebot(["--help"], stdout=subprocess.PIPE)
    out, _ = child.communicate(timeout=60)
    assert child.returncode == 0 and b"Usage" in out
