"""What /api/health reports: each server component and its state.

Components report themselves on ``app.state.health`` (a ``HealthBoard``) as they start, fail
or stop. A component that failed to start, or that runs degraded (a building module offline),
makes the whole server "degraded"; "disabled" components (turned off by settings, or with
nothing to do) do not.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

__all__ = ["COMPONENT_NAMES", "ComponentState", "HealthBoard"]

COMPONENT_NAMES = ("hub", "database", "task_manager", "traffic_manager", "building_interface")


class ComponentState(StrEnum):
    starting = "starting"
    ok = "ok"
    degraded = "degraded"
    failed = "failed"
    disabled = "disabled"
    stopped = "stopped"


@dataclass
class HealthBoard:
    states: dict[str, tuple[ComponentState, str]] = field(
        default_factory=lambda: {n: (ComponentState.starting, "") for n in COMPONENT_NAMES}
    )

    def set(self, name: str, state: ComponentState, detail: str = "") -> None:
        self.states[name] = (state, detail)

    def report(self) -> dict[str, Any]:
        """{"status": "ok" | "degraded", "components": {name: {"state", "detail"}}}."""
        good = (ComponentState.ok, ComponentState.disabled)
        status = "ok" if all(s in good for s, _ in self.states.values()) else "degraded"
        return {
            "status": status,
            "components": {
                name: {"state": state.value, "detail": detail}
                for name, (state, detail) in self.states.items()
            },
        }
