"""The tests' own PostgreSQL and redis-server do not outlive a test process that is killed (an
xdist worker killed, a run cut short by Ctrl-C): tests/reaper.py."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import psutil
import pytest

from tests.reaper import Reaper

ROOT = Path(__file__).resolve().parents[1]
OWNER = """
import sys, time
sys.path.insert(0, {root!r})
{body}
sys.stdout.flush()
time.sleep(600)
"""
REDIS = """
from tests.scale.redis import redis_server
running = redis_server()  # kept: a context manager collected would stop it
server = running.__enter__()
print(server.process.pid, server.reaper.process.pid, server.root)
"""
POSTGRES = """
from tests.server.postgres import postgres_server
running = postgres_server()  # kept: a context manager collected would stop it
server = running.__enter__()
pid = (server.root / "data" / "postmaster.pid").read_text().split()[0]
print(pid, server.reaper.process.pid, server.root)
"""


def killed_owner(body: str) -> tuple[int, int, Path]:
    """Run ``body`` (it prints a server's pid, its reaper's pid and its folder) in a Python
    process, SIGKILL that process once it printed; the three it printed."""
    code = OWNER.format(root=str(ROOT), body=body)
    owner = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert owner.stdout is not None
    with owner.stdout:
        try:
            line = owner.stdout.readline()
        finally:
            owner.kill()
            owner.wait()
    assert line, f"the owner exited with {owner.returncode} before it started its server"
    server, reaper, folder = line.split()
    return int(server), int(reaper), Path(folder)


def gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def wait_reaped(reaper: int) -> None:
    """Until the reaper has run its clean-up and exited (pytest-timeout guards a hang)."""
    try:
        psutil.Process(reaper).wait()
    except psutil.NoSuchProcess:
        pass


def test_redis_server_is_killed_when_its_test_process_is() -> None:
    if not os.path.exists("/usr/bin/redis-server"):
        pytest.skip("redis-server is not installed: run `make system-deps`")
    server, reaper, folder = killed_owner(REDIS)
    wait_reaped(reaper)
    assert gone(server), psutil.Process(server).cmdline()
    assert not folder.exists()


def test_postgresql_is_stopped_when_its_test_process_is_killed() -> None:
    server, reaper, folder = killed_owner(POSTGRES)
    wait_reaped(reaper)
    assert gone(server), psutil.Process(server).cmdline()
    assert not folder.exists()


def test_a_server_stopped_by_its_owner_is_not_touched_again() -> None:
    sleeper = subprocess.Popen(["sleep", "60"], start_new_session=True)
    try:
        reaper = Reaper([["kill", "-s", "KILL", str(sleeper.pid)]])
        reaper.done()
        assert reaper.process.returncode == 0
        assert sleeper.poll() is None  # done(): the reaper left without its clean-up
    finally:
        sleeper.kill()
        sleeper.wait()
