"""Hub payloads are closed objects of strict values, as REST bodies are (tests/server/
test_contract.py): walking docs/protocol.md's publish table, every type a role may publish,
sent by that role with one wrong-typed value or one unknown key, is refused ``invalid_payload``
with a reason naming the field (``{"priority": true}`` used to pass as priority 1)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterator
from typing import Any

import orjson
from websockets.asyncio.client import ClientConnection

from backend.auth import Role
from backend.hub.permissions import ALWAYS
from backend.testing import RunningServer
from guidebot.messages import known_types, payload_model
from tests.server.test_permissions import hub_table

from .test_security import WAIT, authenticated

Schema = dict[str, Any]
Place = tuple[str | int, ...]

BAD_VALUES: dict[str, list[Any]] = {
    "integer": [True, "2", 2.5],
    "boolean": [1, "true"],
    "number": [True, "2.5"],
    "string": [1, True],
}
"""Wrong values per JSON type: a lax model took the first of each (true as 1, "2" as 2)."""

SENDERS = {Role.ROBOT: "R1", Role.OPERATOR: "op", Role.PANEL: "panel", Role.MODULE: "tm"}
"""A token of each role the table lets publish (tests/hub/conftest.py); admin shares module's
row."""


class Walk:
    """Valid examples and one-mistake variants of a payload model's JSON schema."""

    def __init__(self, schema: Schema) -> None:
        self.defs: dict[str, Schema] = schema.get("$defs", {})

    def resolve(self, schema: Schema) -> Schema:
        while "$ref" in schema:
            schema = self.defs[schema["$ref"].rsplit("/", 1)[1]]
        choices = [s for s in schema.get("anyOf", []) if s.get("type") != "null"]
        return self.resolve(choices[0]) if len(choices) == 1 else schema

    def example(self, schema: Schema, name: str = "") -> Any:
        """A valid value: required properties only, the robot field naming the sender R1."""
        schema = self.resolve(schema)
        if "enum" in schema or "const" in schema:
            return schema.get("enum", [schema.get("const")])[0]
        kind = schema.get("type")
        if "anyOf" in schema:  # int | bool
            return self.example(schema["anyOf"][0], name)
        if kind == "object":
            return {
                key: self.example(prop, key)
                for key, prop in schema.get("properties", {}).items()
                if key in schema.get("required", ())
            }
        if kind == "array":
            return [self.example(schema["items"])] * schema.get("minItems", 0)
        if kind == "string":
            return "R1" if name == "robot" else "x" * max(1, schema.get("minLength", 1))
        if kind == "integer":
            return schema.get("minimum", 1)
        if kind == "number":
            return schema.get("minimum", 0.5)
        if kind == "boolean":
            return False
        return {}  # Any

    def cases(self, schema: Schema, depth: int = 0) -> Iterator[tuple[Any, Place, str]]:
        """(a value of ``schema`` with one mistake, its place, what is wrong)."""
        schema = self.resolve(schema)
        if depth > 3:
            return
        kind = schema.get("type")
        if kind == "object" and "properties" in schema:
            base = self.example(schema)
            yield {**base, "zz_unknown": 1}, ("zz_unknown",), "an unknown key"
            for key, prop in schema["properties"].items():
                for bad, place, what in self.cases(prop, depth + 1):
                    yield {**base, key: bad}, (key, *place), what
        elif kind == "object" and isinstance(schema.get("additionalProperties"), dict):
            for bad, place, what in self.cases(schema["additionalProperties"], depth + 1):
                yield {"k": bad}, ("k", *place), what
        elif kind == "array" and "items" in schema:
            for bad, place, what in self.cases(schema["items"], depth + 1):
                yield [bad], (0, *place), what
        elif "enum" not in schema and "const" not in schema:
            for bad in BAD_VALUES.get(kind or "", []):
                yield bad, (), f"{kind} given {bad!r}"


async def until_pong(ws: ClientConnection, ping_id: str) -> AsyncIterator[dict[str, Any]]:
    """Every message the hub sends (in frames of one or a batch) until the pong of ``ping_id``."""
    while True:
        frame = orjson.loads(await asyncio.wait_for(ws.recv(), WAIT))
        for message in frame if isinstance(frame, list) else [frame]:
            if message.get("correlation_id") == ping_id and message["type"] == "pong":
                return
            yield message


def publishable() -> Iterator[tuple[Role, str]]:
    """(role, type) for every row of the publish table, and the control types for a GUI."""
    for role, types in hub_table().items():
        if role in SENDERS:
            for type_ in sorted(known_types() if types is None else types):
                yield role, type_
    for type_ in sorted(ALWAYS):
        yield Role.GUI, type_


async def test_every_published_payload_is_a_closed_object_of_strict_values(
    server: RunningServer,
) -> None:
    lax: list[str] = []
    checked: set[str] = set()
    senders = {**SENDERS, Role.GUI: "gui"}
    for role in dict.fromkeys(role for role, _ in publishable()):
        sent: dict[str, tuple[str, Place, str]] = {}
        async for ws in authenticated(server, senders[role]):
            for type_ in [t for r, t in publishable() if r is role]:
                model = payload_model(type_)
                walk = Walk(model.model_json_schema())
                model.model_validate(walk.example(model.model_json_schema()))  # the base is valid
                for payload, place, what in walk.cases(model.model_json_schema()):
                    id_ = f"c{len(sent)}"
                    sent[id_] = (type_, place, what)
                    frame = {"type": type_, "id": id_, "payload": payload}
                    await ws.send(orjson.dumps(frame).decode())
                checked.add(type_)
            await ws.send(orjson.dumps({"type": "ping", "id": "done"}).decode())
            answers: dict[str, dict[str, Any]] = {}
            async for message in until_pong(ws, "done"):
                if message["type"] == "error":
                    answers[message["correlation_id"]] = message["payload"]
        for id_, (type_, place, what) in sent.items():
            error = answers.get(id_)
            field = ".".join(str(p) for p in ("payload", *place))
            if error is None or error["code"] != "invalid_payload":
                lax.append(f"{role.value} {type_} {field} ({what}): {error}")
            elif f"{field}: " not in error["reason"]:
                lax.append(f"{role.value} {type_} {field} ({what}): reason {error['reason']!r}")
    assert lax == []
    assert checked == known_types()  # every registered type was walked
