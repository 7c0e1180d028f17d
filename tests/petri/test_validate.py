"""Every validation error names the file, the line and what is wrong."""

from __future__ import annotations

from pathlib import Path

import pytest

from petri_nets.library import NetLibrary, load_net

HEAD = (
    '<pnml xmlns="http://www.pnml.org/version-2009/grammar/pnml">\n'
    '<net id="n" type="http://www.pnml.org/version-2009/grammar/ptnet">\n'
)
TOOL = '<toolspecific tool="guidebot" version="1">'


def problems_of(tmp_path: Path, body: str, net_tool: str = "") -> list[str]:
    """Validate a net whose page body starts on line 5 (line 3 is the net's toolspecific)."""
    text = HEAD + (f"{TOOL}{net_tool}</toolspecific>\n" if net_tool else "\n")
    text += '<page id="pg">\n' + body + "\n</page></net></pnml>\n"
    path = tmp_path / "n.pnml"
    path.write_text(text)
    net, problems = load_net(path)
    assert (net is None) == bool(problems)
    return [str(p).removeprefix(f"{path}:") for p in problems]


OK_END = '<place id="end"><toolspecific tool="guidebot" version="1"><final/></toolspecific></place>'


def test_a_good_net_has_no_problems(tmp_path: Path) -> None:
    body = (
        '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
        '<transition id="t"/>\n'
        f"{OK_END}\n"
        '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="end"/>'
    )
    assert problems_of(tmp_path, body) == []


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
            '<transition id="t"/>\n'
            f"{OK_END}\n"
            '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="nowhere"/>',
            "8: arc a2: dangling target 'nowhere' (no such place or transition)",
        ),
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking>\n'
            f'{TOOL}<action kind="dance"/></toolspecific></place>\n'
            '<transition id="t"/>\n'
            f"{OK_END}\n"
            '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="end"/>',
            "6: place s: unknown action kind 'dance' (expected one of publish, timer, run, "
            "kill, next)",
        ),
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
            f'<transition id="t">{TOOL}\n<condition kind="telepathy"/></toolspecific>'
            "</transition>\n"
            f"{OK_END}\n"
            '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="end"/>',
            "7: transition t: unknown condition kind 'telepathy' (expected one of message, "
            "timer, net_ended, guard)",
        ),
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking>\n'
            f'{TOOL}<action kind="publish" type="say">{{"text": "${{speech}}"}}</action>'
            "</toolspecific></place>\n"
            '<transition id="t"/>\n'
            f"{OK_END}\n"
            '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="end"/>',
            "6: place s: parameter 'speech' is used but not declared",
        ),
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
            '<place id="orphan"/>\n'
            '<transition id="t"/>\n'
            '<transition id="dead"/>\n'
            f"{OK_END}\n"
            '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="end"/>\n'
            '<arc id="a3" source="orphan" target="dead"/><arc id="a4" source="dead" '
            'target="end"/>',
            "8: transition dead can never be enabled: input place(s) orphan can never be marked",
        ),
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
            '<transition id="t"/>\n'
            '<place id="busy"/>\n'
            '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="busy"/>\n'
            f"{OK_END}",
            "2: no final place is reachable: the net can never end (mark it <endless/> if it "
            "runs until killed)",
        ),
        (
            '<place id="s"><initialMarking><text>one</text></initialMarking></place>',
            "5: place s: initialMarking 'one' is not a natural number",
        ),
        (
            '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
            '<transition id="t"/>\n'
            f"{OK_END}\n"
            '<arc id="a1" source="s" target="t"><inscription><text>0</text></inscription></arc>'
            '<arc id="a2" source="t" target="end"/>',
            "8: arc a1: inscription '0' is not a positive integer",
        ),
    ],
    ids=[
        "dangling-arc",
        "unknown-action",
        "unknown-condition",
        "undeclared-parameter",
        "never-enabled",
        "no-final-reachable",
        "bad-marking",
        "bad-weight",
    ],
)
def test_each_error_is_reported_with_its_line(tmp_path: Path, body: str, expected: str) -> None:
    assert expected in problems_of(tmp_path, body)


def test_a_timer_condition_without_a_timer_place_can_never_fire(tmp_path: Path) -> None:
    body = (
        '<place id="s"><initialMarking><text>1</text></initialMarking></place>\n'
        f'<transition id="t">{TOOL}<condition kind="timer"/></toolspecific></transition>\n'
        f"{OK_END}\n"
        '<arc id="a1" source="s" target="t"/><arc id="a2" source="t" target="end"/>'
    )
    assert (
        "6: transition t can never be enabled: a timer condition needs an input place with a "
        "timer action"
    ) in problems_of(tmp_path, body)


def test_missing_and_unknown_sub_net_parameters_are_library_errors(tmp_path: Path) -> None:
    library_dir = tmp_path / "lib"
    library_dir.mkdir()
    for name in ("navigate_to_point",):
        (library_dir / f"{name}.pnml").write_bytes(
            Path(f"petri_nets/library/{name}.pnml").read_bytes()
        )
    (library_dir / "trip.pnml").write_text(
        HEAD + "\n" + '<page id="pg">\n'
        '<place id="go"><initialMarking><text>1</text></initialMarking>'
        f'{TOOL}<action kind="run" net="navigate_to_point">{{"where": "n1"}}</action>'
        "</toolspecific></place>\n"
        '<place id="fly">'
        f'{TOOL}<action kind="run" net="teleport"/></toolspecific></place>\n'
        f'<transition id="t">{TOOL}<condition kind="net_ended" net="navigate_to_point"/>'
        "</toolspecific></transition>\n"
        f"{OK_END}\n"
        '<arc id="a1" source="go" target="t"/><arc id="a2" source="t" target="end"/>\n'
        "</page></net></pnml>\n"
    )
    messages = [str(p).split(":", 1)[1] for p in NetLibrary(library_dir).problems()]
    assert messages == [
        "5: place go: missing parameter 'node' of net navigate_to_point",
        "5: place go: parameter 'where' is not declared by net navigate_to_point",
        "6: place fly: net 'teleport' is not in the library",
    ]
