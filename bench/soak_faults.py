"""The soak's faults: a schedule drawn from the seed, and how each kind is injected from
outside the processes (docs/robot.md "Soak benchmark" lists them).

| kind | injected with | undone after ``hold_s`` by |
|---|---|---|
| robot_kill | SIGKILL of the robot agent | starting it again (same name, same screen port) |
| link_cut | the robot's TCP relay drops its connection and refuses new ones | accepting again |
| server_kill | SIGKILL of the server | starting it again on the same port and database |
| modbus_offline | building simulator `POST /modules/{id}/fault {"kind": "offline"}` | kind none |
| elevator_stuck | building simulator `POST /elevators/{id}/stuck` | `{"stuck": false}` |
| door_jam | building simulator `POST /doors/{id}/jam` | `{"jammed": false}` |
| can_unplug | robot `POST /sim/module_plug {"plugged": false}` | `{"plugged": true}` |
| battery_panic | robot `POST /sim/battery {"level": 0.05}` | nothing: the robot goes to charge |
| fire_alarm | simulator `POST /points/{module}/{point}` {alarm value} | normal value, resume |

The fire alarm (a site's alarm input, ``emergency.alarms``) lasts 20-60 *site* seconds (divided
by the time scale: wall seconds); undone, the input reads normal and a person's ``POST
/api/emergency/resume`` follows, tried again while refused. It joins the deck only with
``--fire-alarm``, so that the default mix, and the figures measured with it, stay as they were.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

__all__ = ["ALL_KINDS", "KINDS", "Fault", "schedule"]

KINDS = (
    "robot_kill",
    "link_cut",
    "server_kill",
    "modbus_offline",
    "elevator_stuck",
    "door_jam",
    "can_unplug",
    "battery_panic",
)
"""The default deck."""
ALL_KINDS = (*KINDS, "fire_alarm")

HOLD_S: dict[str, tuple[float, float]] = {
    "robot_kill": (1.0, 4.0),
    "link_cut": (3.0, 15.0),
    "server_kill": (1.0, 3.0),
    "modbus_offline": (3.0, 10.0),
    "elevator_stuck": (5.0, 20.0),
    "door_jam": (5.0, 20.0),
    "can_unplug": (2.0, 8.0),
    "battery_panic": (0.0, 0.0),
    "fire_alarm": (20.0, 60.0),
}
"""Wall seconds a fault lasts (drawn uniformly); site seconds for the kinds in SITE_SECONDS."""
SITE_SECONDS = frozenset({"fire_alarm"})

CAN_MODULES = (0x02, 0x04, 0x08, 0x10, 0x20, 0x40)


@dataclass(frozen=True)
class Fault:
    at_s: float
    """Seconds after the start of the soak."""
    kind: str
    target: str
    """A robot name, module id, elevator, door or alarm id (for can_unplug: ``R1:0x10``)."""
    hold_s: float

    def __str__(self) -> str:
        return f"t={self.at_s:6.1f}s {self.kind} {self.target} for {self.hold_s:.1f}s"


def schedule(
    seed: int,
    duration_s: float,
    every_s: float,
    robots: list[str],
    modules: list[str],
    elevators: list[str],
    doors: list[str],
    *,
    alarms: list[str] | None = None,
    kinds: tuple[str, ...] = KINDS,
    time_scale: float = 1.0,
) -> list[Fault]:
    """Faults at random times (exponential gaps of mean ``every_s``), kinds dealt from a
    shuffled deck so that every kind comes once before any comes twice. ``alarms``: the site's
    alarm ids (a ``fire_alarm`` in ``kinds`` needs one); ``time_scale`` turns site seconds into
    wall seconds."""
    unknown = set(kinds) - set(ALL_KINDS)
    if unknown:
        raise ValueError(f"unknown fault kind(s) {sorted(unknown)} (known: {', '.join(ALL_KINDS)})")
    if "fire_alarm" in kinds and not alarms:
        raise ValueError("a fire_alarm fault needs an alarm input in the site's emergency part")
    rng = random.Random(seed)
    targets = {
        "robot_kill": robots,
        "link_cut": robots,
        "battery_panic": robots,
        "server_kill": ["server"],
        "modbus_offline": modules,
        "elevator_stuck": elevators,
        "door_jam": doors,
        "fire_alarm": alarms or [],
    }
    faults: list[Fault] = []
    deck: list[str] = []
    t = min(5.0, duration_s / 10)
    while True:
        t += rng.expovariate(1.0 / every_s)
        if t >= duration_s:
            return faults
        if not deck:
            deck = list(kinds)
            rng.shuffle(deck)
        kind = deck.pop()
        if kind == "can_unplug":
            target = f"{rng.choice(robots)}:{rng.choice(CAN_MODULES):#04x}"
        else:
            target = rng.choice(targets[kind])
        low, high = HOLD_S[kind]
        hold = rng.uniform(low, high) / (time_scale if kind in SITE_SECONDS else 1.0)
        faults.append(Fault(round(t, 2), kind, target, round(hold, 2)))
