"""The task book's rules (backend/tasks/book.py): what a robot holds, and the marks that go
with a task when it leaves its robot."""

from __future__ import annotations

import pytest

from backend.tasks import book as book_module
from backend.tasks.book import TaskBook
from backend.tasks.model import Task, TaskState
from backend.tasks.robots import RobotInfo
from guidebot.site.schema import RobotConfig


class Wall:
    """Unix seconds the test moves by hand (touring time)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def robot(name: str) -> RobotInfo:
    return RobotInfo(name, RobotConfig(name=name, token="t" * 16), online=True, node="hall")


def task(task_id: str, *, seq: int, priority: int = 5, internal: bool = False) -> Task:
    kind = "go_to" if internal else "tour"
    return Task(task_id, kind, {}, priority, "panel", seq, internal=internal)


def book_with(*names: str) -> tuple[TaskBook, Wall]:
    wall = Wall()
    book = TaskBook(wall=wall)
    for name in names:
        book.add_robot(robot(name))
    return book, wall


def given(book: TaskBook, t: Task, name: str, now: float = 0.0) -> Task:
    book.enqueue(t)
    t.move(TaskState.ASSIGNED)
    book.give(t, book.robots[name], now)
    return t


def test_a_task_given_to_a_robot_leaves_the_queue_and_the_robot_is_busy() -> None:
    book, _ = book_with("R1")
    t = given(book, task("t1", seq=1), "R1", now=5.0)
    assert t.id not in book.queue
    assert book.robots["R1"].current == "t1"
    assert book.current_of(book.robots["R1"]) is t
    assert "R1" not in book.idle
    assert book.marks("t1")["assigned_at"] == 5.0
    assert [(u.id, at) for u, at in book.unstarted()] == [("t1", 5.0)]


def test_a_robot_on_an_internal_task_stays_free_for_a_main_one() -> None:
    book, _ = book_with("R1")
    given(book, task("home", seq=1, internal=True), "R1")
    assert book.robots["R1"].current == "home"
    assert "R1" in book.idle
    assert book.marks("home")["touring"] is False  # going home is not touring


def test_requeue_clears_the_robots_task_and_every_mark_and_keeps_the_old_place() -> None:
    book, wall = book_with("R1")
    first = task("first", seq=1)
    book.enqueue(first)
    restored = task("t2", seq=2)
    book.add(restored)
    restored.robot = "R1"
    restored.state = TaskState.RUNNING
    book.restored(restored, book.robots["R1"], now=3.0)
    assert book.marks("t2")["unconfirmed"] is True
    later = task("later", seq=3)
    book.enqueue(later)

    book.requeue(restored, "the robot no longer runs it")

    r1 = book.robots["R1"]
    assert r1.current is None and "R1" in book.idle
    assert restored.robot is None and restored.state is TaskState.QUEUED
    assert restored.reason == "the robot no longer runs it"
    assert book.marks("t2")["unconfirmed"] is False
    assert book.marks("t2")["assigned_at"] is None
    assert book.unstarted() == []
    assert [t.id for t in book.queue.ordered()] == ["first", "t2", "later"]
    wall.now += 60  # no touring counted for a task restored without its start
    assert r1.touring_s == 0.0


def test_withdraw_counts_the_touring_time_once() -> None:
    book, wall = book_with("R1")
    t = given(book, task("t1", seq=1), "R1")
    wall.now += 90
    t.move(TaskState.RUNNING)
    t.move(TaskState.DONE)
    book.withdraw(t)
    book.withdraw(t)  # twice is the same as once
    r1 = book.robots["R1"]
    assert r1.touring_s == 90.0
    assert r1.current is None and "R1" in book.idle
    assert book.marks("t1")["touring"] is False


def test_withdraw_leaves_alone_the_robots_other_task() -> None:
    book, _ = book_with("R1")
    old = given(book, task("old", seq=1, internal=True), "R1")
    new = given(book, task("new", seq=2), "R1")
    old.move(TaskState.CANCELLED)
    book.withdraw(old)
    assert book.robots["R1"].current == "new"
    assert book.current_of(book.robots["R1"]) is new
    assert "R1" not in book.idle


def test_withdraw_takes_a_queued_task_out_of_the_queue() -> None:
    book, _ = book_with("R1")
    t = task("t1", seq=1)
    book.enqueue(t)
    book.withdraw(t)
    assert t.id not in book.queue
    assert len(book.queue) == 0


def test_an_unconfirmed_task_counts_from_the_first_report_without_it() -> None:
    book, _ = book_with("R1")
    t = task("t1", seq=1)
    book.add(t)
    t.robot, t.state = "R1", TaskState.RUNNING
    book.restored(t, book.robots["R1"], now=0.0)
    assert book.unconfirmed_for("t1", 10.0) == 0.0
    assert book.unconfirmed_for("t1", 14.5) == 4.5
    book.started("t1")
    assert book.unconfirmed_for("t1", 20.0) is None
    assert book.robots["R1"].current == "t1"  # confirmed: still its


def test_the_start_watchdog_forgets_tasks_that_moved_on() -> None:
    book, _ = book_with("R1", "R2")
    running = given(book, task("t1", seq=1), "R1", now=1.0)
    waiting = given(book, task("t2", seq=2), "R2", now=2.0)
    running.move(TaskState.RUNNING)
    assert [(t.id, at) for t, at in book.unstarted()] == [("t2", 2.0)]
    assert book.marks("t1")["assigned_at"] is None
    assert waiting.state is TaskState.ASSIGNED


def test_avoid_and_rather_not_end_with_the_task() -> None:
    book, _ = book_with("R1", "R2")
    t = task("t1", seq=1)
    book.enqueue(t)
    book.avoid("t1", "R1")
    book.avoid("t1", "R2")
    book.allow("t1", "R2")  # staff named R2
    book.rather_not("t1", "R2")
    assert set(book.avoided("t1")) == {"R1"}
    assert set(book.rather_not_robots("t1")) == {"R2"}
    book.changed(t)  # not final: kept
    assert set(book.avoided("t1")) == {"R1"}
    book.withdraw(t)
    t.move(TaskState.CANCELLED)
    book.changed(t)
    assert not book.avoided("t1") and not book.rather_not_robots("t1")


def test_only_the_last_finished_tasks_stay_in_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(book_module, "MAX_FINISHED_IN_MEMORY", 2)
    book, _ = book_with()
    for n in range(1, 4):
        t = task(f"t{n}", seq=n)
        book.enqueue(t)
        book.withdraw(t)
        t.move(TaskState.CANCELLED)
        book.changed(t)
    assert sorted(book.tasks) == ["t2", "t3"]


def test_a_robot_removed_from_the_site_is_no_longer_free() -> None:
    book, _ = book_with("R1", "R2")
    book.remove_robot("R2")
    assert set(book.robots) == {"R1"}
    assert set(book.idle) == {"R1"}
