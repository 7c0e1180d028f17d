"""The master's module table: the life-cycle states of a slave module and their legal
transitions (docs/robocan.md, section 4), the master's row per module, and the counters of
everything odd it saw on the bus. Data only; the master (master.py) drives them.
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from robot_agent.robocan import protocol as p

if TYPE_CHECKING:
    from robot_agent.robocan.drivers import Driver

__all__ = [
    "TRANSITIONS",
    "CommandFailed",
    "Counters",
    "IllegalTransition",
    "Module",
    "ModuleState",
    "module_kind_name",
]


class ModuleState(enum.Enum):
    QUERYING = "querying"
    CONFIGURING = "configuring"
    ONLINE = "online"
    DISABLED = "disabled"  # attached and powered, told by the master not to publish
    LOST = "lost"
    FAILED = "failed"


TRANSITIONS: dict[ModuleState, frozenset[ModuleState]] = {
    ModuleState.QUERYING: frozenset(
        {ModuleState.CONFIGURING, ModuleState.LOST, ModuleState.FAILED}
    ),
    ModuleState.CONFIGURING: frozenset(
        {ModuleState.ONLINE, ModuleState.LOST, ModuleState.FAILED, ModuleState.QUERYING}
    ),
    ModuleState.ONLINE: frozenset({ModuleState.LOST, ModuleState.QUERYING, ModuleState.DISABLED}),
    ModuleState.DISABLED: frozenset({ModuleState.ONLINE, ModuleState.LOST, ModuleState.QUERYING}),
    ModuleState.LOST: frozenset({ModuleState.QUERYING}),
    ModuleState.FAILED: frozenset({ModuleState.QUERYING, ModuleState.LOST}),
}


class IllegalTransition(RuntimeError):
    def __init__(self, module_id: int, current: ModuleState, target: ModuleState) -> None:
        allowed = ", ".join(sorted(s.value for s in TRANSITIONS[current]))
        super().__init__(
            f"module 0x{module_id:02X}: {current.value} -> {target.value} is illegal "
            f"(expected one of: {allowed})"
        )


class CommandFailed(RuntimeError):
    """A module did not acknowledge a command after all retries, or refused it."""


@dataclass(eq=False)
class Module:
    """The master's view of one slave module (an entry of the module table)."""

    module_id: int
    state: ModuleState = ModuleState.QUERYING
    description: p.Description | None = None
    last_seen: float = field(default_factory=time.monotonic)
    first_seen: float = field(default_factory=time.monotonic)
    online_since: float | None = None
    slave_state: p.SlaveState | None = None
    frames_rx: int = 0
    frames_tx: int = 0
    errors: int = 0  # bad frames from it, failed bring-ups
    faults: int = 0  # FAULT frames
    lost: int = 0  # times it was lost (time-out or reset)
    requeried: int = 0  # times it was queried again after its first bring-up
    drivers: list[Driver] = field(default_factory=list)
    element_drivers: dict[int, Driver] = field(default_factory=dict)  # element number -> driver
    watchdog_s: float = p.WATCHDOG_PERIOD_S
    retry_at: float = 0.0
    announced: bool = False
    disabling: bool = False  # the master disabled it: a DISABLED watchdog is no reset
    enabling: bool = False  # ENABLE on is on its way: its ACK makes the module ONLINE
    frame_time: float = 0.0
    """When the frame being handled reached the bus interface (python-can's receive timestamp,
    seconds): drivers that pair frames of several modules (the base's two wheels) pair them by
    it, since the master may handle them in another order (section 7, the queues per ID)."""

    @property
    def name(self) -> str:
        return self.description.name if self.description else f"module_{self.module_id:02x}"

    @property
    def critical(self) -> bool:
        return any(d.critical for d in self.drivers)

    @property
    def lost_timeout_s(self) -> float:
        return self.watchdog_s * p.LOST_TIMEOUT_FACTOR

    def to_dict(self) -> dict[str, Any]:
        """The public row of the module table (docs/robocan.md, section 8)."""
        d = self.description
        return {
            "module_id": self.module_id,
            "name": self.name,
            "kind": module_kind_name(d.kind) if d else None,
            "firmware": f"{d.firmware[0]}.{d.firmware[1]}" if d else None,
            "state": self.state.value,
            "critical": self.critical,
            "elements": [e.kind_name for e in d.elements] if d else [],
            "frames_rx": self.frames_rx,
            "frames_tx": self.frames_tx,
            "errors": self.errors,
            "faults": self.faults,
            "lost": self.lost,
            "requeried": self.requeried,
        }


def module_kind_name(kind: int) -> str:
    try:
        return p.ModuleKind(kind).name.lower()
    except ValueError:
        return f"kind_{kind}"


@dataclass
class Counters:
    """Everything odd the master saw on the bus; never a reason to stop."""

    frames_rx: int = 0
    frames_tx: int = 0
    unknown_id: int = 0
    bad_frame: int = 0
    overflow: int = 0
    block_errors: int = 0
    send_errors: int = 0
    driver_errors: int = 0
    record_errors: int = 0
    stalls: int = 0
    not_online: int = 0  # data frames from a module that is not online (dropped)
    modules_lost: int = 0
    modules_requeried: int = 0
