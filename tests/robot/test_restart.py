"""A robot agent killed right after its corridor grant and started again (issue 36): the new
process never waits on its old holds, the other robots go on, and an offline holder past the
grace period raises an alert and is released safely.

Real server (Task and Traffic Managers, BuildingInterface over Modbus/TCP), robot agents on real
WebSocket links. R1's first process reaches the server through a LinkCutter: cutting it and
stopping that agent is the kill (its socket dies without a word, as under ``kill -9``); its new
process (a new agent, same name, same place) connects directly.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
import pytest

from guidebot.invariants import InvariantChecker
from robot_agent.agent import RobotAgent
from tests.robot.safety_rig import Fleet, fleet

pytestmark = pytest.mark.timeout(120)

KILLED_AT = "west"
"""R1 starts here, asks for the corridors (corr_a, then corr_b back to back) and is killed
once granted: at the edge of corr_a, outside it."""


async def post_go(f: Fleet, robot: str, node: str) -> str:
    async with httpx.AsyncClient(base_url=f.server.url) as http:
        r = await http.post(
            "/api/tasks",
            json={"kind": "go_to", "params": {"node": node}, "robot": robot},
            headers={"Authorization": f"Bearer {f.server.admin_token}"},
        )
    assert r.status_code == 201, r.text
    return str(r.json()["id"])


def done(f: Fleet, task_id: str) -> bool:
    ended = f.of("task_ended", task_id=task_id)
    if ended:
        assert ended[0].payload["outcome"] == "done", ended[0].payload
    return bool(ended)


async def kill_after_grant(
    f: Fleet, helpers: SimpleNamespace, *, when: tuple[str, str] | None = None
) -> tuple[str, Any]:
    """R1 (through a cutter) is given a go_to across the corridors and killed right after the
    corridor grant (or once it reported ``when``: a message type and node); R2 and R3 then
    queue for the corridor behind the dead process."""
    cutter = helpers.LinkCutter(f.server.port)
    await cutter.start()
    old = f.new_agent("R1", url=f"http://127.0.0.1:{cutter.port}", start_node=KILLED_AT)
    await old.start()
    hub = f.server.app.state.hub
    await f.wait_for(lambda: "R1" in hub.clients and f.states.get("R1", {}).get("boot_id"))
    r1_task = await post_go(f, "R1", "east")
    await f.wait_for(lambda: f.of("area_granted", robot="R1", area="corr_a"))
    if when is not None:
        await f.wait_for(lambda: f.of(when[0], robot="R1", node=when[1]))
    await cutter.cut()  # the kill: its socket dies, and the process never comes back
    await f.wait_for(lambda: not old.hub.connected.is_set())
    await old.stop()
    await cutter.stop()
    await f.wait_for(lambda: f.of("robot_disconnected", robot="R1"))
    traffic = f.server.app.state.traffic
    assert traffic.locks.holder("corr_a") == "R1"
    others = [await post_go(f, r, "east") for r in ("R2", "R3")]
    await f.wait_for(lambda: f.of("request_area", robot="R2", area="corr_a"))
    assert traffic.locks.holder("corr_a") == "R1"  # R2 waits behind the dead process
    return r1_task, others


async def restart_r1(f: Fleet, at: str = KILLED_AT) -> RobotAgent:
    """R1's new process, where the old one stopped (a real robot localises itself there)."""
    new = f.new_agent("R1", start_node=at)
    await new.start()
    return new


async def events(f: Fleet, kind: str) -> list[dict[str, Any]]:
    return await f.server.app.state.store.events(kind=kind)


async def assert_safe(f: Fleet) -> None:
    """The safety invariants, replayed from the event log: it has the server's own releases
    (a restart's), which the live monitor on the hub never sees."""
    replay = InvariantChecker.from_site(f.server.app.state.sites.site)
    replay.feed_events(await f.server.app.state.store.events(limit=100_000))
    assert not replay.violations, [str(v) for v in replay.violations]
    assert replay.counts["area"] > 0, replay.counts


async def test_restarted_robot_frees_its_corridor_at_once_and_all_three_go_on(
    tmp_path: Path, helpers: SimpleNamespace
) -> None:
    async with fleet(tmp_path, ["R1", "R2", "R3"], external=frozenset({"R1"})) as f:
        r1_task, others = await kill_after_grant(f, helpers)
        traffic = f.server.app.state.traffic
        new = await restart_r1(f)
        try:
            # Handed over at once (the grace period is 30 s: no offline rule at work here).
            await f.wait_for(lambda: traffic.locks.holder("corr_a") in ("R2", "R3"), timeout=15)
            assert not f.of("alert_raised", kind="lock_released_offline")
            [restarted] = await events(f, "robot_restarted")
            assert restarted["data"]["robot"] == "R1" and restarted["data"]["node"] == KILLED_AT
            assert set(restarted["data"]["released"]) == {"corr_a", "corr_b"}
            assert restarted["data"]["kept"] == []
            released = [
                e["data"]
                for e in await events(f, "area_released")
                if e["data"].get("robot") == "R1"
            ]
            assert {r["area"] for r in released} == {"corr_a", "corr_b"}
            assert all("agent restarted" in r["reason"] for r in released)
            # The other two go through, and the restarted R1 (its task back to it) too: it never
            # waits on its own former hold.
            await f.wait_for(lambda: all(done(f, t) for t in others), timeout=60)
            await f.wait_for(lambda: done(f, r1_task), timeout=60)
            await assert_safe(f)
        finally:
            await new.stop()


async def test_offline_holder_past_the_grace_is_alerted_then_released_safely_on_restart(
    tmp_path: Path, helpers: SimpleNamespace
) -> None:
    """Killed at the edge of corr_a, R1 may have driven in: past the grace the lock is kept
    and staff alerted (corr_b, away from it, is released). Its new process reports it outside:
    the corridor goes at once, and the alert resolves saying why."""
    async with fleet(
        tmp_path, ["R1", "R2", "R3"], external=frozenset({"R1"}), lock_offline_grace_s=1.0
    ) as f:
        _, others = await kill_after_grant(f, helpers)
        traffic = f.server.app.state.traffic
        await f.wait_for(lambda: f.of("alert_raised", kind="lock_holder_offline", subject="corr_a"))
        # Past the grace: corr_b, away from R1, is released; corr_a, at its edge, is kept.
        await f.wait_for(lambda: f.of("alert_raised", kind="lock_released_offline"))
        assert traffic.locks.holder("corr_b") is None
        assert traffic.locks.holder("corr_a") == "R1"  # it may be inside: kept (safety)
        new = await restart_r1(f)
        try:
            await f.wait_for(lambda: traffic.locks.holder("corr_a") in ("R2", "R3"), timeout=15)
            # Raised when R1 dropped off, counted again past the grace: one alert, one id.
            alert = f.of("alert_raised", kind="lock_holder_offline", subject="corr_a")[0]
            await f.wait_for(lambda: f.of("alert_resolved", id=alert.payload["id"]))
            [resolved] = f.of("alert_resolved", id=alert.payload["id"])
            assert "agent restarted" in resolved.payload["resolution"]
            assert [a.kind for a in traffic.alerts.active() if a.subject == "corr_a"] == []
            await f.wait_for(lambda: all(done(f, t) for t in others), timeout=60)
            await assert_safe(f)
        finally:
            await new.stop()


async def test_robot_restarted_inside_the_corridor_keeps_it_and_does_not_wait_on_itself(
    tmp_path: Path, helpers: SimpleNamespace
) -> None:
    """Killed inside corr_a: the new process reports ca1, so corr_a stays held (by it) and only
    corr_b goes. R2 and R3 queued first for both; the restarted R1 needs corr_b to get out and
    gets it at once: the others' claim on it would have it wait on itself (a deadlock the
    wait-for graph does not show)."""
    async with fleet(tmp_path, ["R1", "R2", "R3"], external=frozenset({"R1"})) as f:
        traffic = f.server.app.state.traffic
        r1_task, others = await kill_after_grant(f, helpers, when=("node_reached", "ca1"))
        new = await restart_r1(f, at="ca1")
        try:
            await f.wait_for(lambda: done(f, r1_task), timeout=60)
            [restarted] = await events(f, "robot_restarted")
            assert restarted["data"]["kept"] == ["corr_a"]
            assert restarted["data"]["released"] == ["corr_b"]
            await f.wait_for(lambda: all(done(f, t) for t in others), timeout=60)
            assert traffic.locks.holder("corr_a") is None
            await assert_safe(f)
        finally:
            await new.stop()


async def test_restarted_robot_lets_go_of_the_door_its_old_process_held(
    tmp_path: Path, helpers: SimpleNamespace
) -> None:
    """R1 is killed just after D0 opened for it, before driving through; its new process,
    back in the hall, does not stand in the doorway: the door closes at once rather than
    standing open until the hold's time-out (max_hold_s, 120 s)."""
    async with fleet(tmp_path, ["R1", "R2"], external=frozenset({"R1"})) as f:
        cutter = helpers.LinkCutter(f.server.port)
        await cutter.start()
        old = f.new_agent("R1", url=f"http://127.0.0.1:{cutter.port}", start_node="hall")
        await old.start()
        hub = f.server.app.state.hub
        await f.wait_for(lambda: "R1" in hub.clients and f.states.get("R1", {}).get("boot_id"))
        task = await post_go(f, "R1", "west")

        def opened_for_r1() -> bool:
            return any(
                m.type == "door_opened" and m.destination == "R1" and m.payload["door"] == "D0"
                for m in f.seen
            )

        await f.wait_for(opened_for_r1)
        await cutter.cut()
        await f.wait_for(lambda: not old.hub.connected.is_set())
        await old.stop()
        await cutter.stop()
        await f.wait_for(lambda: f.of("robot_disconnected", robot="R1"))
        keeper = f.server.app.state.building.doors["D0"]
        assert "R1" in keeper.holders  # the dead process's hold
        async with httpx.AsyncClient(base_url=f.server.url) as http:
            r = await http.post(
                f"/api/tasks/{task}/cancel",
                headers={"Authorization": f"Bearer {f.server.admin_token}"},
            )
        assert r.status_code < 300, r.text  # so that the new process does not pass D0 again
        mark = len(f.seen)
        new = await restart_r1(f, at="hall")
        try:
            await f.wait_for(
                lambda: any(
                    m.type == "door_closed" and m.destination is None and m.payload["door"] == "D0"
                    for m in f.seen[mark:]
                ),
                timeout=15,
            )
            assert "R1" not in keeper.holders
        finally:
            await new.stop()
