"""``guidebot plan --live --virtual``: the real server, Task Manager, Traffic Manager, building
simulator and bare simulated robots in one process on a virtual clock that jumps to the next
timer whenever every task waits (docs/planning.md, "The virtual run")."""

from __future__ import annotations

import asyncio
import shutil
import sqlite3
import time
from pathlib import Path

import pytest

from backend.planning.live import LiveOptions
from backend.planning.measure import read_events
from backend.planning.profile import PlanError, Request
from backend.planning.recorded import learn_pace
from backend.planning.sim import simulate
from backend.planning.virtual import run_virtual
from backend.planning.vtime import install, installed, virtual_time
from bench.plan_virtual import EPOCH, _spoken_once, play
from guidebot.bus import Bus
from guidebot.site.graph import SiteGraph
from guidebot.site.yamlio import load_site_file
from robot_agent.clock import Clock
from robot_agent.speech import Speech
from tests.planning.test_sim import DEMO


def test_the_virtual_clock_jumps_to_the_next_timer_and_time_reads_it() -> None:
    async def main() -> tuple[float, float, float]:
        loop = asyncio.get_running_loop()
        start, epoch = loop.time(), time.time()
        await asyncio.sleep(3600.0)
        return loop.time() - start, time.time() - epoch, time.monotonic()

    wall = time.perf_counter()
    looped, epoch_s, mono = virtual_time(main(), epoch=EPOCH)
    assert looped == pytest.approx(3600.0) and epoch_s == pytest.approx(3600.0)
    assert mono == pytest.approx(3600.0)
    # An hour of sleeping is not waited for (the bound is generous: it is about a jump).
    assert time.perf_counter() - wall < 60.0
    assert abs(time.time() - EPOCH) > 1.0  # the real clock is back after the run


def test_a_clock_a_module_took_at_import_follows_the_virtual_clock(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The real clock is put back after the test (install() is for good in a run's process).
    monkeypatch.setattr(time, "time", time.time)
    monkeypatch.setattr(time, "monotonic", time.monotonic)
    install()
    # What a default argument (``clock=time.time``) or a dataclass's default_factory keeps.
    taken_time, taken_monotonic = time.time, time.monotonic

    async def main() -> tuple[float, float]:
        await asyncio.sleep(3600.0)
        return taken_time(), taken_monotonic()

    epoch_s, mono = virtual_time(main(), epoch=EPOCH)
    assert epoch_s == pytest.approx(EPOCH + 3600.0) and mono == pytest.approx(3600.0)
    assert installed() and abs(taken_time() - EPOCH) > 1.0  # the real clock outside a run


def test_a_virtual_run_refuses_a_process_whose_clock_was_not_switched_first() -> None:
    site = load_site_file(DEMO)
    with pytest.raises(PlanError, match="plan_virtual_run"):
        play(DEMO, site, [Request(0.0, "ground", 1)], robots=1, day_s=60.0)


def test_work_in_a_thread_takes_no_virtual_time() -> None:
    def slow() -> str:
        time_sleep = __import__("time").sleep
        time_sleep(0.2)  # real seconds in a thread
        return "done"

    async def main() -> tuple[str, float, bool]:
        loop = asyncio.get_running_loop()
        ticker = asyncio.create_task(asyncio.sleep(30.0))  # a timer that must not fire early
        start = loop.time()
        result = await asyncio.to_thread(slow)
        took = loop.time() - start
        done = ticker.done()
        await ticker
        return result, took, done

    result, took, ticker_done = virtual_time(main(), epoch=EPOCH)
    assert result == "done" and took == 0.0 and not ticker_done


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_virtual_day_is_repeatable_and_its_tours_last_as_the_model_says(
    tmp_path: Path,
) -> None:
    site = load_site_file(DEMO)
    # The whole ground tour, then one that leaves after the first point (the robot, called back
    # from its errand, drives from wherever it is).
    requests = [Request(0.0, "ground", 9), Request(400.0, "ground", 1)]

    def play(name: str) -> tuple[dict, list]:
        outcome = run_virtual(
            DEMO,
            site,
            requests,
            robots=1,
            day_s=900.0,
            options=LiveOptions(virtual=True, workdir=tmp_path / name),
        )
        events = asyncio.run(
            read_events(f"sqlite+aiosqlite:///{tmp_path / name}/virtual-1/plan.db")
        )
        summary = outcome.summary(10.0) | {"wait_of": outcome.wait_of, "end": outcome.last_end_s}
        # Times the product took with a clock it kept from its import (the tasks' created_at:
        # default_factory=time.time) are virtual too: a door's trouble closure kept that way
        # was held 120 real seconds, hours of a virtual day.
        with sqlite3.connect(tmp_path / name / "virtual-1" / "plan.db") as db:
            created = db.execute("SELECT min(created_at), max(created_at) FROM tasks").fetchone()
        assert EPOCH <= created[0] <= created[1] <= EPOCH + 900.0 + 3600.0, created
        return summary, events

    (first, log), (second, log_again) = play("a"), play("b")
    assert first["mode"] == "virtual" and first["served"] == 2 and first["failed"] == 0
    # Deterministic: the same requests give the same day, event for event, to the millisecond.
    for key in ("wait_of", "end", "utilisation", "robot_time_s", "elevator_wait_s"):
        assert first[key] == second[key], key
    assert [(round(at, 3), kind) for at, kind, _, _ in log] == [
        (round(at, 3), kind) for at, kind, _, _ in log_again
    ]
    # A tour's legs and explanations against the model's nominal seconds (the ETA model's): the
    # legs take 1.0 to 1.2 times nominal (doors, turns), the explanations 1.4 to 1.9 times
    # (the "continue?" question and the visitors' answer, 2.5 s). The busy demo fleet recorded
    # live: 1.17 and 1.65 (docs/planning.md, "The virtual run").
    pace = learn_pace([(at, kind, d) for at, kind, _, d in log], site)
    assert MOVE[0] <= pace.move <= MOVE[1] and TALK[0] <= pace.talk <= TALK[1], pace
    # The day ends when the model, at that pace, says (the drive to the first point included).
    model = simulate(site, SiteGraph(site), requests, robots=1, day_s=900.0, pace=pace)
    assert first["end"] == pytest.approx(model.last_end_s, rel=0.05)


MOVE = (1.0, 1.2)
TALK = (1.4, 1.9)


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed")
def test_speech_takes_its_audios_length_and_synthesis_takes_no_virtual_time() -> None:
    async def main() -> tuple[float, float, float, bool]:
        loop = asyncio.get_running_loop()
        speech = Speech(Bus().endpoint("speech"), Clock(), engine="auto")
        ticker = asyncio.create_task(asyncio.sleep(30.0))  # must not fire during synthesis
        with _spoken_once():
            start = loop.time()
            voice = await speech._voice("en")
            first = await speech._duration("Welcome to the museum. Follow me!", voice)
            second = await speech._duration("Welcome to the museum. Follow me!", voice)
            took = loop.time() - start
        done = ticker.done()
        ticker.cancel()
        return first, second, took, done

    first, second, took, ticker_done = virtual_time(main(), epoch=EPOCH)
    # espeak-ng's audio of that text lasts a couple of seconds; the same text, the same length.
    assert 1.0 < first < 5.0 and second == first
    assert took == 0.0 and not ticker_done
