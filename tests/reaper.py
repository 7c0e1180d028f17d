"""Servers a test run starts for itself (PostgreSQL, redis-server) are stopped however the run
ends: a fixture's ``finally`` runs on a normal end, not when Ctrl-C cuts an xdist run short
nor when a worker is killed, and the servers then ran on, unknown, after the run.

A reaper is a small shell process in a session of its own (a Ctrl-C does not reach it) that
reads a pipe from the test process. The fixture that stopped its server says so (``done()``)
and the reaper exits; if the pipe closes without that word (the test process ended, however:
exit, Ctrl-C, SIGKILL), the reaper runs the clean-up commands.
"""

from __future__ import annotations

import shlex
import subprocess

__all__ = ["Reaper"]

DONE = b"stopped\n"


class Reaper:
    """Runs ``cleanup`` (commands, in order) once this process is gone, unless ``done()``."""

    def __init__(self, cleanup: list[list[str]]) -> None:
        if not cleanup:
            raise ValueError("a reaper needs at least one clean-up command")
        script = 'IFS= read -r word; [ "$word" = stopped ] && exit 0; ' + "; ".join(
            shlex.join(command) for command in cleanup
        )
        self.process = subprocess.Popen(
            ["sh", "-c", script],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )

    def done(self) -> None:
        """The server was stopped by its owner: the reaper leaves without doing anything."""
        stdin = self.process.stdin
        if stdin is None or stdin.closed:
            return
        try:
            stdin.write(DONE)
            stdin.close()
        except BrokenPipeError:
            pass  # the reaper is gone already
        self.process.wait(10)
