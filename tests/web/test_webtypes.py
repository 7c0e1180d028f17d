"""The web pages' message types (web/lib/messages.d.ts) come from the payload models: the
committed file is what ``guidebot webtypes`` writes now, and each schema form has its
TypeScript form (what ``tsc --checkJs`` in ``make lint`` checks the pages against)."""

from __future__ import annotations

import json
import re
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any, Literal

import pytest
from click.testing import CliRunner
from pydantic import BaseModel, Field

from guidebot.messages import PayloadModel, WireEnum, known_types
from guidebot.paths import ROOT
from guidebot.webtypes import OUTPUT, SchemaError, render, webtypes


def test_committed_types_are_up_to_date() -> None:
    """Fails after a payload model changed and the file was not written again."""
    assert OUTPUT.read_text(encoding="utf-8") == render(), (
        f"{OUTPUT} is stale: run `guidebot webtypes` and commit it"
    )


def test_every_message_type_has_its_payload_type() -> None:
    text = OUTPUT.read_text(encoding="utf-8")
    block = text.split("export interface Payloads {\n", 1)[1].split("\n}", 1)[0]
    mapped = dict(re.findall(r"^  (\w+): (\w+);$", block, re.MULTILINE))
    assert set(mapped) == set(known_types())
    assert mapped["robot_state"] == "RobotState"
    assert mapped["battery_low"] == mapped["battery_panic"] == "BatteryAlarm"
    for name in set(mapped.values()):
        assert re.search(rf"^export (interface|type) {name}\b", text, re.MULTILINE), name


def test_the_envelope_has_every_field_a_page_receives() -> None:
    """The hub writes every envelope field (guidebot/wire.py): none is optional to a page."""
    text = render({})
    block = text.split("export interface Envelope {\n", 1)[1].split("\n}", 1)[0]
    fields = dict(re.findall(r"^  (\w+\??): (.+);$", block, re.MULTILINE))
    assert fields == {
        "type": "string",
        "id": "string",
        "timestamp": "number",
        "source": "string",
        "destination": "string | null",
        "correlation_id": "string | null",
        "version": "number",
        "payload": "{ [key: string]: any }",
    }


class Mood(StrEnum):
    CALM = "calm"
    BUSY = "busy"


class Inner(PayloadModel):
    """A nested model, declared once."""

    n: int


class Sample(PayloadModel):
    """Every form a payload uses.

    Second line of the docstring."""

    name: str
    count: int = 0
    ratio: float | None = None
    mood: Annotated[Mood, WireEnum] = Mood.CALM
    kind: Literal["a", "b"]
    tags: list[str] = Field(default_factory=list)
    scores: dict[str, float] = Field(default_factory=dict)
    where: tuple[float, float] | None = None
    inner: Inner
    inners: list[Inner | None] = Field(default_factory=list)
    extra: dict[str, Any] = Field(default_factory=dict)
    anything: Any = None
    odd: int = Field(default=0, alias="odd-name", description="A field with a */ in it.")


def test_each_schema_form_has_its_typescript_form() -> None:
    text = render({"sample": Sample})
    assert (
        "/**\n * Every form a payload uses.\n *\n * Second line of the docstring.\n */\n"
        "export interface Sample {\n"
        "  name: string;\n"
        "  count?: number;\n"
        "  ratio?: number | null;\n"
        "  mood?: Mood;\n"
        '  kind: "a" | "b";\n'
        "  tags?: string[];\n"
        "  scores?: { [key: string]: number };\n"
        "  where?: [number, number] | null;\n"
        "  inner: Inner;\n"
        "  inners?: (Inner | null)[];\n"
        "  extra?: { [key: string]: any };\n"
        "  anything?: any;\n"
        "  /** A field with a *\\/ in it. */\n"
        '  "odd-name"?: number;\n'
        "}\n"
    ) in text
    assert 'export type Mood = "calm" | "busy";' in text
    inner = "/** A nested model, declared once. */\nexport interface Inner {\n  n: number;\n}"
    assert inner in text
    assert "export interface Payloads {\n  sample: Sample;\n}" in text
    assert text.count("export interface Inner ") == 1


def test_two_models_of_one_name_are_refused() -> None:
    first = type("Twin", (PayloadModel,), {"__annotations__": {"a": int}})
    second = type("Twin", (PayloadModel,), {"__annotations__": {"b": str}})
    with pytest.raises(SchemaError, match="two payload schemas are named Twin"):
        render({"one": first, "two": second})


def test_a_schema_without_a_typescript_form_is_refused() -> None:
    """A model that writes its own schema: the file does not silently say something else."""

    class Odd(BaseModel):
        blob: str = Field(json_schema_extra={"type": "blob"})

    with pytest.raises(SchemaError, match="JSON schema type 'blob' has no TypeScript form"):
        render({"odd": Odd})


def test_check_says_stale_and_writing_makes_it_current(tmp_path: Path) -> None:
    target = tmp_path / "messages.d.ts"
    target.write_text("// old\n", encoding="utf-8")
    runner = CliRunner()
    stale = runner.invoke(webtypes, ["--check", "--output", str(target)])
    assert stale.exit_code == 1
    assert "is stale: run `guidebot webtypes`" in stale.output
    wrote = runner.invoke(webtypes, ["--output", str(target)])
    assert wrote.exit_code == 0, wrote.output
    assert target.read_text(encoding="utf-8") == render()
    current = runner.invoke(webtypes, ["--check", "--output", str(target)])
    assert current.exit_code == 0
    assert "is up to date" in current.output


def test_the_checker_types_the_vendored_library_versions() -> None:
    """tools/typecheck installs the libraries' types: the versions web/vendor/ holds."""
    vendored = json.loads((ROOT / "package.json").read_text(encoding="utf-8"))["dependencies"]
    checker = json.loads((ROOT / "tools" / "typecheck" / "package.json").read_text())
    tools = checker["devDependencies"]
    assert tools["lit-html"] == vendored["lit-html"]
    assert tools["uplot"] == vendored["uplot"]
    assert tools["@types/leaflet"].split(".")[:2] == vendored["leaflet"].split(".")[:2]
    assert re.fullmatch(r"\d+\.\d+\.\d+", tools["typescript"]), "pin TypeScript exactly"
