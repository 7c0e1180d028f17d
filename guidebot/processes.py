"""Launching and stopping ``guidebot`` processes (server, building simulator, robot agents): the
one way the demo and the soak start a fleet of child processes and stop them.

A child gets a session of its own, so that Ctrl-C reaches only the launcher, which stops its
children in order; stopping is SIGTERM (the process reports its last state and exits), then
SIGKILL after a grace period.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Mapping
from typing import IO

__all__ = ["guidebot_command", "spawn_guidebot", "stop_process"]


def guidebot_command(*args: str) -> list[str]:
    """The command line of ``guidebot ARGS`` with this interpreter (no installed script needed)."""
    return [sys.executable, "-m", "guidebot.cli", *args]


def spawn_guidebot(
    args: list[str],
    *,
    stdout: int | IO[bytes] | None = None,
    stderr: int | IO[bytes] | None = None,
    env: Mapping[str, str] | None = None,
) -> subprocess.Popen[bytes]:
    """Start ``guidebot ARGS`` in a session of its own."""
    return subprocess.Popen(
        guidebot_command(*args), start_new_session=True, stdout=stdout, stderr=stderr, env=env
    )


def stop_process(process: subprocess.Popen[bytes], grace_s: float) -> bool:
    """SIGTERM, then SIGKILL if it has not exited after ``grace_s``; True when it had to be
    killed. A process that already exited is left alone."""
    if process.poll() is not None:
        return False
    process.terminate()
    try:
        process.wait(grace_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        return True
    return False
