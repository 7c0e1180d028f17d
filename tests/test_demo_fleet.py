"""The demo's launcher (guidebot/demo.py ``Fleet``): a stop asked for at any moment, even while
a child is being started, leaves no child running.

The cause of `test_alerts_fault_free`'s second demo "not stopping within 60 s of SIGTERM": the
SIGTERM came as the demo started its robots; raised inside ``Popen`` (after the fork, before it
returned) it left that robot running and unrecorded. The demo stopped the others and exited,
but the robot ran on, holding the demo's stderr open: the test's ``communicate()`` never saw
its end."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator, Mapping
from typing import IO

import pytest

import guidebot.demo as demo
from guidebot.demo import Fleet

SLEEPER = [sys.executable, "-c", "import time; time.sleep(120)"]


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[subprocess.Popen[bytes]]]:
    """Every child the fleet starts (a sleeping Python, not guidebot), each start followed at
    once by a SIGTERM to this process: the signal comes while ``spawn_guidebot`` returns,
    where a real one can come (between the fork and ``Popen``'s return). Any left running
    is killed at the end."""
    children: list[subprocess.Popen[bytes]] = []

    def spawn_then_sigterm(
        args: list[str],
        *,
        stdout: int | IO[bytes] | None = None,
        stderr: int | IO[bytes] | None = None,
        env: Mapping[str, str] | None = None,
    ) -> subprocess.Popen[bytes]:
        child = subprocess.Popen(SLEEPER, start_new_session=True, stdout=stdout, stderr=stderr)
        children.append(child)
        os.kill(os.getpid(), signal.SIGTERM)
        return child

    monkeypatch.setattr(demo, "spawn_guidebot", spawn_then_sigterm)
    try:
        yield children
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
                child.wait()


@pytest.fixture
def fleet() -> Iterator[Fleet]:
    """A fleet whose handler takes SIGTERM and SIGINT, as the demo installs it."""
    fleet = Fleet()
    before = {s: signal.signal(s, fleet.on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield fleet
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def test_a_sigterm_while_a_child_starts_stops_that_child_too(
    fleet: Fleet, started: list[subprocess.Popen[bytes]]
) -> None:
    with pytest.raises(KeyboardInterrupt):
        fleet.spawn("R1", "robot", "--name", "R1")
    fleet.stop_all()
    assert len(started) == 1
    assert [c.process for c in fleet.children] == started  # recorded, so stopped
    assert started[0].returncode == -signal.SIGTERM


def test_a_sigterm_while_a_robot_restarts_stops_the_new_process(
    fleet: Fleet, started: list[subprocess.Popen[bytes]]
) -> None:
    with pytest.raises(KeyboardInterrupt):
        fleet.spawn("R1", "robot", "--name", "R1")
    [robot] = fleet.children
    assert robot.process is not None
    robot.process.kill()
    robot.process.wait()
    assert fleet.supervise(robot, 0.0) is not None  # the restart is scheduled
    with pytest.raises(KeyboardInterrupt):
        fleet.supervise(robot, 1e9)  # and is due: the new process starts, then SIGTERM
    fleet.stop_all()
    assert len(started) == 2 and robot.process is started[1]
    assert started[1].returncode == -signal.SIGTERM


def test_a_sigterm_during_the_stop_does_not_cut_it_short(
    fleet: Fleet, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A second Ctrl-C while the children stop: the stop goes on (it has its own grace period
    and SIGKILL); raised there, it left the children not yet stopped running."""
    child = fleet.adopt("sleeper", lambda: subprocess.Popen(SLEEPER, start_new_session=True))
    assert child.process is not None
    real = demo.stop_process

    def sigterm_then_stop(process: subprocess.Popen[bytes], grace_s: float) -> bool:
        os.kill(os.getpid(), signal.SIGTERM)
        return real(process, grace_s)

    monkeypatch.setattr(demo, "stop_process", sigterm_then_stop)
    try:
        fleet.stop_all()
    finally:
        if child.process.poll() is None:
            child.process.kill()
            child.process.wait()
    assert child.process.returncode == -signal.SIGTERM
