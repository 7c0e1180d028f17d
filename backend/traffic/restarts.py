"""Restarted robot agents: the holds of a process that is gone (docs/server.md, "Lock policy").

Each agent process draws a random ``boot_id`` when it starts and sends it in every
``robot_state``. The same name with a new id means the old process is gone: whatever it held
(areas, the elevator's area, its place in a queue) was for a task and a plan nobody runs any
more, and the new process would otherwise queue behind its own former holds.

Safety: the new process reports where the robot stands. The area it is inside stays held, by
the new process (entered: released when it leaves, as usual); every other area is released at
once, since the robot is not in it and the new process was granted nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

from backend.traffic.locks import AreaLocks, Grant

__all__ = ["BootIds", "Handover", "release_former_holds"]


class BootIds:
    """The boot id each robot's agent process last announced."""

    def __init__(self) -> None:
        self._ids: dict[str, str] = {}

    def restarted(self, robot: str, boot_id: object) -> str | None:
        """The previous id when ``boot_id`` is a new one for a robot already heard from (its old
        process is gone); None on a robot's first word, from the same process, or from an agent
        that sends no id (an older agent: no restart is ever assumed for it)."""
        if not isinstance(boot_id, str) or not boot_id:
            return None
        previous = self._ids.get(robot)
        self._ids[robot] = boot_id
        return previous if previous is not None and previous != boot_id else None


@dataclass(frozen=True, slots=True)
class Handover:
    """What a restart did to the robot's former holds."""

    released: list[str]
    """Areas released at once (the robot is not inside): the next waiters are granted them."""
    kept: list[str]
    """Areas held on, now by the new process: the one it reports being inside."""
    grants: list[Grant]


def release_former_holds(locks: AreaLocks, robot: str, here: str | None) -> Handover:
    """Drop the old process's holds and waiting request, keeping only the area ``here`` the
    robot stands in (marked entered: it is released when the robot leaves it)."""
    held = locks.held_by(robot)
    kept = [a for a in held if a == here]
    grants = locks.release_all(robot, keep=set(kept))
    for area in kept:
        locks.mark_entered(robot, area)
    return Handover([a for a in held if a not in kept], kept, grants)
