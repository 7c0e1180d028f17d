"""Worker processes of site work (backend/site/offloop.py ``in_processes``), found and killed
for real: the server must fall back to a thread and lose nothing."""

from __future__ import annotations

import asyncio
import os
import signal
from collections.abc import Awaitable
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")


def spawned_workers() -> set[int]:
    """Process ids of this process's children started by multiprocessing's spawn (read from
    /proc; its resource tracker is not one of them)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parent = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            command = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if parent == os.getpid() and b"spawn_main" in command:
            found.add(int(stat.parent.name))
    return found


async def killing_new_workers(job: Awaitable[T]) -> T:
    """Run ``job``, SIGKILL the worker processes it starts as soon as they appear, and return
    what it returns. Processes that were already running are left alone."""
    earlier = spawned_workers()
    task = asyncio.ensure_future(job)
    for _ in range(1000):
        await asyncio.sleep(0.01)
        if workers := spawned_workers() - earlier:
            for pid in workers:
                os.kill(pid, signal.SIGKILL)
            break
    else:
        task.cancel()
        raise AssertionError("no worker process was started")
    return await task
