"""A compiled net's version: equal nets share it, and whatever changes what the net does or
what a monitor draws changes it (GUIs cache a net's structure by it)."""

from __future__ import annotations

from typing import Any

from petri_nets.builder import NetBuilder, publish
from petri_nets.compiled import compile_net
from petri_nets.model import NetDoc


def blink(*, weight: int = 1, default: Any = 5, body: dict[str, Any] | None = None) -> NetDoc:
    b = NetBuilder("blink", "two places", params={"times": default})
    b.place("on", initial=1, action=publish("led", body or {"on": True}))
    b.place("off", final=True)
    b.transition("switch", {"on": weight}, ["off"])
    return b.build()


def version(doc: NetDoc) -> str:
    return compile_net(doc).version


def test_equal_nets_have_one_version() -> None:
    assert version(blink()) == version(blink())
    assert len(version(blink())) == 16


def test_behaviour_and_drawing_change_the_version() -> None:
    base = version(blink())
    assert version(blink(weight=2)) != base
    assert version(blink(default=6)) != base
    assert version(blink(body={"on": False})) != base
    moved = blink()
    position = moved.places[0].graphics.find("position")  # type: ignore[union-attr]
    assert position is not None
    position.attrib["x"] = str(int(position.attrib["x"]) + 10)
    assert version(moved) != base


def test_values_json_cannot_carry_still_have_a_version() -> None:
    huge = version(blink(body={"n": 2**70}))
    assert huge == version(blink(body={"n": 2**70})) and huge != version(blink(body={"n": 2**69}))
    keyed = version(blink(body={1: "one"}))  # type: ignore[dict-item]
    assert keyed == version(blink(body={1: "one"})) and keyed != version(blink(body={2: "one"}))
