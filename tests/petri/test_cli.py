"""``guidebot petri check | run | export`` as a user runs them."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from guidebot.cli import main
from petri_nets.pnml import read_pnml
from petri_nets.trace import read_trace, replay

from .test_pnml import PLAIN

LIBRARY = Path("petri_nets/library")
POINTS = json.dumps(
    [{"node": "n1", "poi": "p1", "text": "one"}, {"node": "n2", "poi": "p2", "text": "two"}]
)


def invoke(*args: str) -> tuple[int, list[str]]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.output.splitlines()


def test_check_passes_the_library_and_fails_a_broken_file(tmp_path: Path) -> None:
    code, _ = invoke("petri", "check", *map(str, sorted(LIBRARY.glob("*.pnml"))))
    assert code == 0
    broken = tmp_path / "broken.pnml"
    broken.write_text(PLAIN.replace('target="consume"', 'target="ghost"'))
    code, lines = invoke("petri", "check", str(broken))
    assert code == 1
    assert f"{broken}:26: arc a3: dangling target 'ghost' (no such place or transition)" in lines


def test_run_prints_the_trace_and_a_json_result_last() -> None:
    code, lines = invoke(
        "petri",
        "run",
        str(LIBRARY / "give_tour.pnml"),
        "--param",
        "tour=t1",
        "--param",
        f"points={POINTS}",
        "--reply",
        'ask_continue={"type": "continue_answer", "payload": {"answer": "no"}}',
        "--json",
    )
    assert code == 0, lines
    result = json.loads(lines[-1])
    assert set(result) == {"net", "outcome", "fired", "firings", "published", "final_marking"}
    assert result["net"] == "give_tour" and result["outcome"] == "done"
    assert result["fired"] == [
        "has_first",
        "arrived",
        "shown",
        "explained",
        "reported",
        "more_points",
        "answer_no",
    ]
    assert result["published"][:3] == ["navigate_to", "show_point", "face_people"]
    assert result["published"][-1] == "ask_continue"
    assert result["final_marking"] == {"visitor_left": 1}
    assert any("fired has_first" in line for line in lines[:-1])


def test_run_with_silence_lets_the_virtual_timer_fire() -> None:
    code, lines = invoke(
        "petri", "run", str(LIBRARY / "wink_one_eye.pnml"), "--param", "eye=eyelid_left", "--json"
    )
    assert code == 0
    assert json.loads(lines[-1])["published"] == ["move_servos"] * 3
    code, lines = invoke(
        "petri",
        "run",
        str(LIBRARY / "navigate_to_point.pnml"),
        "--param",
        "node=n9",
        "--reply",
        "navigate_to=[]",
        "--json",
    )
    assert json.loads(lines[-1])["outcome"] == "stuck"


def test_run_refuses_bad_parameters_and_replies() -> None:
    code, lines = invoke("petri", "run", str(LIBRARY / "navigate_to_point.pnml"), "--json")
    assert code == 1 and "missing parameter(s) node" in "\n".join(lines)
    code, lines = invoke(
        "petri",
        "run",
        str(LIBRARY / "navigate_to_point.pnml"),
        "--param",
        "node=n1",
        "--reply",
        "navigate_to={oops",
        "--json",
    )
    assert code == 2 and "invalid JSON" in "\n".join(lines)


def test_export_writes_pnml_another_tool_reads_back(tmp_path: Path) -> None:
    plain = tmp_path / "producer.pnml"
    plain.write_text(PLAIN)
    out = tmp_path / "out.pnml"
    code, _ = invoke("petri", "export", str(plain), "-o", str(out))
    assert code == 0
    doc, problems = read_pnml(out.read_bytes())
    assert problems == [] and doc is not None
    assert [p.id for p in doc.places] == ["ready", "buffer"]


def test_a_recorded_trace_replays_to_the_final_marking(tmp_path: Path) -> None:
    trace = tmp_path / "tour.jsonl"
    code, lines = invoke(
        "petri",
        "run",
        str(LIBRARY / "give_tour.pnml"),
        "--param",
        "tour=t1",
        "--param",
        f"points={POINTS}",
        "--trace",
        str(trace),
        "--json",
    )
    assert code == 0
    result = json.loads(lines[-1])
    messages = list(read_trace(trace))
    assert [
        m["type"]
        for m in messages
        if m["source"] == "dispatch" and m["type"] not in ("petri_net_event", "petri_net_ended")
    ] == result["published"]
    markings = replay(messages)
    assert markings["give_tour#run"] == result["final_marking"] == {"tour_done": 1}
    asked_at = next(
        m["payload"]["time"]
        for m in messages
        if m["type"] == "petri_net_event" and m["payload"]["transition"] == "more_points"
    )
    midway = replay(messages, until=asked_at)
    assert midway["give_tour#run"] == {"ask_continue": 1, "answer_wait": 1}
