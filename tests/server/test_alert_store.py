"""The alert store (backend/alerts.py): one alert per cause, counted; acknowledged it stays so
while its cause persists; it resolves itself when its cause is gone; a restart resolves what
the last server life left active."""

from __future__ import annotations

from backend.alerts import AlertNotFound, AlertStore
from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from guidebot.bus import Bus
from guidebot.messages import Message


def store_on(bus: Bus) -> tuple[AlertStore, list[Message]]:
    endpoint = bus.endpoint("alerts")
    seen: list[Message] = []
    bus.endpoint("console").subscribe("alert_*", seen.append)
    return AlertStore(endpoint.publish), seen


async def test_one_alert_per_cause_counted_and_resolved_when_the_cause_is_gone() -> None:
    alerts, seen = store_on(Bus())
    first = alerts.raise_("robot_lost", "R2", "robot R2 lost its connection")
    again = alerts.raise_("robot_lost", "R2", "robot R2 lost its connection")
    other = alerts.raise_("robot_lost", "R3", "robot R3 lost its connection")
    assert again is first and first.count == 2 and other is not first
    assert first.last_seen >= first.raised_at
    assert [a["subject"] for a in alerts.listing()] == ["R3", "R2"]
    assert alerts.resolve("robot_lost", "R2", "robot R2 is back online") is first
    assert alerts.resolve("robot_lost", "R2", "twice") is None  # already resolved: no message
    assert not first.active and first.resolution == "robot R2 is back online"
    assert [a["subject"] for a in alerts.listing()] == ["R3"]
    assert [m.type for m in seen] == ["alert_raised"] * 3 + ["alert_resolved"]
    assert seen[-1].payload["id"] == first.id and seen[-1].payload["resolved_at"]
    # The same cause later: the same alert opens again, to acknowledge again.
    back = alerts.raise_("robot_lost", "R2", "robot R2 lost its connection")
    assert back is first and back.open and back.count == 3


async def test_an_acknowledged_alert_stays_acknowledged_while_its_cause_persists() -> None:
    alerts, seen = store_on(Bus())
    alert = alerts.raise_("module_offline", "otb_ground", "Modbus module otb_ground: timeout")
    alerts.acknowledge(alert.id, "desk")
    alerts.raise_("module_offline", "otb_ground", "Modbus module otb_ground: timeout")
    assert alert.acked_by == "desk" and alert.count == 2 and alert.active and not alert.open
    assert alerts.listing() == []  # nothing in the red bar
    assert seen[-1].type == "alert_raised" and seen[-1].payload["acked_by"] == "desk"
    alerts.acknowledge(alert.id, "admin")  # idempotent: the first acknowledgement stands
    assert alert.acked_by == "desk"
    alerts.resolve("module_offline", "otb_ground", "Modbus module otb_ground is online")
    [kept] = alerts.listing(include_acked=True)
    assert kept["resolved_at"] and kept["acked_by"] == "desk"


async def test_acknowledge_all_and_event_alerts_resolved_by_acknowledging() -> None:
    alerts, _ = store_on(Bus())
    lost = alerts.raise_("robot_lost", "R1", "robot R1 lost its connection")
    failed = alerts.raise_("task_failed", "t1", "task t1 failed (R1)", "warning", lasting=False)
    done = alerts.acknowledge_all("desk")
    assert {a.id for a in done} == {lost.id, failed.id}
    assert alerts.acknowledge_all("desk") == []
    assert lost.active and lost.acked_by == "desk"  # its cause is still there
    assert not failed.active and failed.resolution == "acknowledged by desk"
    try:
        alerts.acknowledge("nope", "desk")
    except AlertNotFound:
        pass
    else:
        raise AssertionError("an unknown alert was acknowledged")


async def test_a_restart_resolves_the_alerts_the_last_server_life_left(db_url: str) -> None:
    engine = make_engine(db_url)
    try:
        await migrate(engine)
        db = DbStore(make_sessionmaker(engine))
        await db.start()
        bus = Bus()
        alerts = AlertStore(bus.endpoint("alerts").publish, db.record_event)
        lost = alerts.raise_("robot_lost", "R1", "robot R1 lost its connection")
        alerts.acknowledge(lost.id, "desk")
        alerts.raise_("module_offline", "otb_first", "Modbus module otb_first: refused")
        gone = alerts.raise_("robot_lost", "R2", "robot R2 lost its connection")
        alerts.resolve("robot_lost", "R2", "robot R2 is back online")
        await db.stop()

        later, seen = store_on(Bus())
        later.record = db.record_event
        stale = await later.restore(db.events)
        assert {(a.kind, a.subject) for a in stale} == {
            ("robot_lost", "R1"),
            ("module_offline", "otb_first"),
        }
        assert later.listing() == [] and not later.active()
        kept = {a["id"]: a for a in later.listing(include_acked=True)}
        assert (
            kept[lost.id]["acked_by"] == "desk"
            and "server restarted" in kept[lost.id]["resolution"]
        )
        assert kept[gone.id]["resolution"] == "robot R2 is back online"
        assert [m.type for m in seen] == ["alert_resolved", "alert_resolved"]
        # Seen again after the restart: the same alert, open again.
        assert later.raise_("module_offline", "otb_first", "refused").open
    finally:
        await engine.dispose()


async def test_a_long_report_is_cut_to_the_payloads_bounds_not_refused() -> None:
    """A robot's fault detail can be long: the alert is still raised (and published)."""
    alerts, seen = store_on(Bus())
    alert = alerts.raise_("robot_fault", "R1/" + "x" * 300, "R1: motor_lost " + "y" * 2000)
    assert len(alert.message) == 500 and len(alert.subject) == 200
    assert seen[-1].payload["message"] == alert.message
    assert alerts.resolve("robot_fault", "R1/" + "x" * 300, "back") is alert
