"""A light simulated robot for tests and tools: bare simulated base (no CAN), timed speech,
robot_state at 5 Hz, its touch screen on a free port, a simulated visitor who answers "continue
the tour?" (``visitor``; None: nobody does).

Usage (any team's tests)::

    from robot_agent.testing import light_robot

    async with light_robot(server.url, "R1", "robot-R1-token", site=site_file) as agent:
        agent.screen_server.url   # the touch screen
"""

from __future__ import annotations

from pathlib import Path

from robot_agent.agent import AgentConfig, RobotAgent
from robot_agent.gui import VisitorAnswer

__all__ = ["light_robot"]


def light_robot(
    server: str,
    name: str,
    token: str,
    *,
    site: Path | None = None,
    start_node: str | None = None,
    time_scale: float = 20.0,
    visitor: VisitorAnswer | None = "yes",
) -> RobotAgent:
    """A RobotAgent to use as ``async with``: starts on enter, stops on exit."""
    return RobotAgent(
        AgentConfig(
            name=name,
            server=server,
            token=token,
            can=None,
            time_scale=time_scale,
            start_node=start_node,
            speech_engine=None,
            state_period_s=0.2,
            site=site,
            auto_answer=visitor,
            gui_port=0,
        )
    )
