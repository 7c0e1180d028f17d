"""Simulated RoboCAN slave modules: they speak only the wire protocol, as the firmware would.

The BellBot set of the paper (motor controllers 0x02 and 0x04, sonar rings 0x10 and 0x20,
head and I/O 0x40) plus a battery monitor 0x08. Physics (distance, servo travel, battery
drain and charge) runs ``time_scale`` times faster than the wall clock; protocol timing
(watchdogs, publishing periods, time-outs) does not.

The modules of one simulated robot share a ``SimHost``: one connection to the virtual bus
(one reader thread, software filtering on *M* + 1 and the broadcast ID, as each module's own
filter would) and one scheduler task. The scheduler sleeps until the next frame some module
owes (watchdog, ENCODER, SONAR, BATTERY) and runs the 50 Hz physics step only while something
moves (a wheel, a servo); a received command wakes it at once. Periodic frames fall on a grid
of their own period (multiples of it on the monotonic clock), so modules with the same period
send in the same wake-up. The frames on the wire, their lengths and rates are those of
docs/robocan.md.

One module per kind of simulated module: ``host`` (bus connection and scheduler),
``module`` (firmware skeleton), ``motor``, ``sonar``, ``head``, ``battery`` and
``simulator`` (the robot's layout).
"""

from robot_agent.robocan.sim.battery import SimBattery
from robot_agent.robocan.sim.head import HeadIo
from robot_agent.robocan.sim.host import SimHost
from robot_agent.robocan.sim.module import FLAWS, SimModule
from robot_agent.robocan.sim.motor import MotorController
from robot_agent.robocan.sim.simulator import BELLBOT, Simulator
from robot_agent.robocan.sim.sonar import SonarRing

__all__ = [
    "BELLBOT",
    "FLAWS",
    "HeadIo",
    "MotorController",
    "SimBattery",
    "SimHost",
    "SimModule",
    "Simulator",
    "SonarRing",
]
