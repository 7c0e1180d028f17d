"""RoboCAN: the on-board CAN master, its drivers and entities, simulated slave modules, and
the bandwidth study (docs/robocan.md). Start it with ``RoboCanStack`` / ``start_master``."""

from robot_agent.robocan.stack import RoboCanStack, start_master

__all__ = ["RoboCanStack", "start_master"]
