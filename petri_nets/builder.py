"""Build nets in Python (library sources, tests, benchmarks) and get the same NetDoc a PNML
file gives; ``write_pnml`` turns it into a file. Places and transitions get a layered drawing
(petri_nets.layout) so graphical editors and the console's monitor show a net one can follow.
"""

from __future__ import annotations

import json
from typing import Any

from petri_nets.layout import layered
from petri_nets.model import (
    REQUIRED,
    ActionSpec,
    ArcSpec,
    ConditionSpec,
    MatchSpec,
    NetDoc,
    PageSpec,
    ParamSpec,
    PlaceSpec,
    TransitionSpec,
)
from petri_nets.xmlsafe import Node

__all__ = [
    "NetBuilder",
    "guard",
    "kill",
    "message",
    "net_ended",
    "next_item",
    "publish",
    "run",
    "timer",
    "timer_elapsed",
]


def _body(data: dict[str, Any] | None) -> str:
    return json.dumps(data or {})


def publish(type: str, payload: dict[str, Any] | None = None) -> ActionSpec:
    return ActionSpec("publish", 0, type=type, body=_body(payload))


def timer(seconds: float | str) -> ActionSpec:
    return ActionSpec("timer", 0, seconds=str(seconds))


def run(net: str, params: dict[str, Any] | None = None, var: str | None = None) -> ActionSpec:
    return ActionSpec("run", 0, net=net, body=_body(params), var=var)


def kill(net: str) -> ActionSpec:
    return ActionSpec("kill", 0, net=net)


def next_item(list: str, var: str, order: str | None = None) -> ActionSpec:
    return ActionSpec("next", 0, list=list, var=var, order=order)


def message(type: str, binds: dict[str, str] | None = None, **matches: Any) -> ConditionSpec:
    return ConditionSpec(
        "message",
        0,
        type=type,
        matches=[
            MatchSpec(k, v if isinstance(v, str) else json.dumps(v), 0) for k, v in matches.items()
        ],
        binds=list((binds or {}).items()),
    )


def timer_elapsed() -> ConditionSpec:
    return ConditionSpec("timer", 0)


def net_ended(net: str, outcome: str | None = None) -> ConditionSpec:
    return ConditionSpec("net_ended", 0, net=net, outcome=outcome)


def guard(var: str, test: str, value: str | None = None) -> ConditionSpec:
    return ConditionSpec("guard", 0, var=var, test=test, value=value)


def _graphics(x: float, y: float) -> Node:
    position = Node("position", {"x": str(round(x)), "y": str(round(y))}, 0)
    return Node("graphics", {}, 0, [position])


class NetBuilder:
    """``NetBuilder("blink").place("p0", initial=1).transition("t0", ["p0"], [])``."""

    def __init__(
        self,
        net_id: str,
        description: str = "",
        *,
        endless: bool = False,
        params: dict[str, Any] | None = None,
        required: tuple[str, ...] = (),
    ) -> None:
        self.doc = NetDoc(
            id=net_id,
            file=f"{net_id}.pnml",
            line=0,
            name=net_id,
            description=description,
            endless=endless,
            pages=[PageSpec("page1", None, 0)],
        )
        for name in required:
            self.doc.params.append(ParamSpec(name, REQUIRED, 0))
        for name, default in (params or {}).items():
            self.doc.params.append(ParamSpec(name, default, 0))

    def place(
        self,
        place_id: str,
        *,
        initial: int = 0,
        action: ActionSpec | None = None,
        final: bool = False,
        outcome: str = "done",
        name: str | None = None,
    ) -> NetBuilder:
        self.doc.places.append(
            PlaceSpec(
                place_id,
                0,
                "page1",
                name=(name or place_id.replace("_", " ")).strip(),
                initial=initial,
                action=action,
                final=final,
                outcome=outcome,
            )
        )
        return self

    def transition(
        self,
        trans_id: str,
        inputs: list[str] | dict[str, int],
        outputs: list[str] | dict[str, int],
        condition: ConditionSpec | None = None,
        *,
        priority: int = 0,
        name: str | None = None,
    ) -> NetBuilder:
        self.doc.transitions.append(
            TransitionSpec(
                trans_id,
                0,
                "page1",
                name=(name or trans_id.replace("_", " ")).strip(),
                condition=condition,
                priority=priority,
            )
        )
        ins = inputs if isinstance(inputs, dict) else dict.fromkeys(inputs, 1)
        outs = outputs if isinstance(outputs, dict) else dict.fromkeys(outputs, 1)
        for place, weight in ins.items():
            self._arc(place, trans_id, weight)
        for place, weight in outs.items():
            self._arc(trans_id, place, weight)
        return self

    def _arc(self, source: str, target: str, weight: int) -> None:
        self.doc.arcs.append(
            ArcSpec(f"a{len(self.doc.arcs) + 1}", source, target, 0, "page1", weight=weight)
        )

    def build(self) -> NetDoc:
        """The net, drawn: every place and transition gets a layered position."""
        doc = self.doc
        nodes = [(p.id, p.name or p.id) for p in doc.places]
        nodes += [(t.id, t.name or t.id) for t in doc.transitions]
        starts = [p.id for p in doc.places if p.initial > 0]
        at = layered(nodes, [(a.source, a.target) for a in doc.arcs], starts)
        for place in doc.places:
            place.graphics = _graphics(*at[place.id])
        for transition in doc.transitions:
            transition.graphics = _graphics(*at[transition.id])
        return doc
