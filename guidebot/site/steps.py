"""One step of a planned path: the node with what lies on it (door, elevator, restricted area).

The one definition of ``PathStep``: the site graph builds it, the ``path`` payload carries it
(pydantic validates it as a dataclass field), and the robot's navigation follows it. A plain
frozen dataclass with slots, because the graph builds one per node of every path it returns.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

from pydantic import ConfigDict, Strict

__all__ = ["PathStep"]

_Strict = Strict()
"""Each field strict when pydantic validates a step of a ``path`` payload (as every payload
field is, guidebot/messages.py): annotations only, nothing runs when the graph builds one.
Strictness is per field because a strict dataclass would take only PathStep instances, not the
JSON objects a ``path`` message carries."""


@dataclass(frozen=True, slots=True)
class PathStep:
    __pydantic_config__: ClassVar[ConfigDict] = ConfigDict(extra="forbid")

    node: Annotated[str, _Strict]
    floor: Annotated[str, _Strict]
    x: Annotated[float, _Strict]
    y: Annotated[float, _Strict]
    door: Annotated[str | None, _Strict] = None
    elevator: Annotated[str | None, _Strict] = None
    area: Annotated[str | None, _Strict] = None

    def as_dict(self) -> dict[str, object]:
        return {
            "node": self.node,
            "floor": self.floor,
            "x": self.x,
            "y": self.y,
            "door": self.door,
            "elevator": self.elevator,
            "area": self.area,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PathStep:
        """A step from a ``path`` message; an empty door, elevator or area means none.
        Raises KeyError or ValueError for a step without node, floor or coordinates."""
        return cls(
            node=str(data["node"]),
            floor=str(data["floor"]),
            x=float(data["x"]),
            y=float(data["y"]),
            door=data.get("door") or None,
            elevator=data.get("elevator") or None,
            area=data.get("area") or None,
        )
