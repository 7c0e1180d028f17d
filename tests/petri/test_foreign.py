"""Nets from other Petri-net tools (tests/petri/foreign/, written the way ProM, WoPeD, PIPE, TINA
and the Model Checking Contest write them): checked, run as plain place/transition nets to
their final marking, and written back as the same file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from guidebot.cli import main
from petri_nets.builder import NetBuilder, net_ended, run
from petri_nets.cli import check_files, run_net
from petri_nets.describe import describe
from petri_nets.library import load_net
from petri_nets.pnml import read_pnml, read_pnml_file, write_pnml
from petri_nets.xmlsafe import Node, parse_xml

from .rig import make_rig

FOREIGN = Path(__file__).with_name("foreign")

# file -> (outcome, transitions fired in order, final marking)
EXPECTED: dict[str, tuple[str, list[str], dict[str, int]]] = {
    # ProM: ISO-8859-1, no namespace, core-model type, its final marking reached
    "prom_order.pnml": ("done", ["n5", "n6", "n8"], {"n2": 1}),
    # the same with an end transition that waits for the consumed source: not its final marking
    "prom_stuck.pnml": ("stuck", ["n5", "n6"], {"n4": 1}),
    # WoPeD: 2004 type URI, no page, AND split and join, its own toolspecific everywhere
    "woped_claim.pnml": ("done", ["t1", "t2_op_1", "t3", "t4", "t5_op_1"], {"p7": 1}),
    # PIPE: "P/T net", <value>Default,N</value> markings and weights 2 and 3, no page
    "pipe_producer.xml": ("done", ["T0", "T0", "T0", "T1", "T1"], {"P2": 2}),
    # TINA: the standard, generated ids, a weight of 3
    "tina_batch.pnml": (
        "done",
        ["t-2C3C-7F100-6", "t-2C3C-7F103-7"] * 2,
        {"p-2C3C-7F0F5-3": 1, "p-2C3C-7F0FC-5": 2},
    ),
    # MCC style: nested pages, reference places both ways across them, weight 4
    "mcc_assembly.pnml": ("done", ["assemble", "ship"] * 2, {"shipped": 2}),
}


def shape(node: Node) -> tuple[Any, ...]:
    """A document's structure: tags, attributes, stripped text, children in order."""
    return (
        node.tag,
        tuple(sorted(node.attrib.items())),
        node.text.strip(),
        tuple(shape(child) for child in node.children),
    )


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_foreign_net_checks_and_runs_to_its_final_marking(name: str) -> None:
    path = FOREIGN / name
    assert check_files([path]) == []
    doc, _ = read_pnml_file(path)
    assert doc is not None and not doc.task  # no guidebot parts: a plain net
    outcome, fired, final = EXPECTED[name]
    result = run_net(path, {}, {})
    assert (result["outcome"], result["fired"], result["final_marking"]) == (outcome, fired, final)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_foreign_net_written_back_is_the_same_file(name: str, tmp_path: Path) -> None:
    original = (FOREIGN / name).read_bytes()
    doc, problems = read_pnml(original, name)
    assert doc is not None and problems == []
    written = write_pnml(doc)
    # structurally the file the tool wrote: every element, attribute and text in order (names,
    # graphics, its toolspecific data, PIPE's arc paths, ProM's final markings, reference
    # places), in the same namespace or none, and nothing of ours
    before, after = parse_xml(original), parse_xml(written)
    assert shape(after) == shape(before)
    assert after.ns == before.ns
    assert b"guidebot" not in written
    # and it still runs the same
    (tmp_path / name).write_bytes(written)
    assert run_net(tmp_path / name, {}, {})["final_marking"] == EXPECTED[name][2]


def test_latin1_names_and_other_tools_data_are_read() -> None:
    doc, _ = read_pnml_file(FOREIGN / "prom_order.pnml")
    assert doc is not None
    assert [t.name for t in doc.transitions][:2] == ["Bestellung erfassen", "Bonität prüfen"]
    assert doc.transitions[2].foreign[0].attrib["activity"] == "$invisible$"
    assert [m.counts for m in doc.final_markings] == [{"n1": 0, "n2": 1, "n3": 0, "n4": 0}]
    pipe, _ = read_pnml_file(FOREIGN / "pipe_producer.xml")
    assert pipe is not None
    assert [(p.name, p.initial) for p in pipe.places] == [
        ("Rohstoff", 3),
        ("Lager", 0),
        ("Geliefert", 0),
    ]
    assert [a.weight for a in pipe.arcs] == [1, 2, 3, 1]


def test_an_edit_rewrites_only_what_changed() -> None:
    doc, _ = read_pnml_file(FOREIGN / "pipe_producer.xml")
    assert doc is not None
    doc.places[0].initial = 5
    doc.transitions[0].name = "produce"
    again, problems = read_pnml(write_pnml(doc))
    assert again is not None and problems == []
    assert again.places[0].initial == 5 and again.transitions[0].name == "produce"
    kept = [child.tag for child in again.places[0].element.children]  # type: ignore[union-attr]
    assert kept == ["graphics", "name", "initialMarking", "capacity"]
    assert [c.tag for c in again.arcs[0].element.children].count("arcpath") == 2  # type: ignore[union-attr]


def test_a_looping_foreign_net_is_stopped_by_the_firing_guard_with_outcome_running() -> None:
    result = run_net(FOREIGN / "mcc_tokenring.pnml", {}, {}, max_firings=500)
    assert result["outcome"] == "running" and result["firings"] == 500
    assert result["final_marking"] == {"s0_has": 2}  # after an even number of passes
    runner = CliRunner()
    out = runner.invoke(main, ["petri", "run", "--json", str(FOREIGN / "mcc_tokenring.pnml")])
    assert out.exit_code == 0, out.output
    assert '"outcome": "running"' in out.output.splitlines()[-1]
    assert '"firings": 10000' in out.output.splitlines()[-1]  # the default guard


def test_a_looping_foreign_net_yields_on_a_robot_and_stays_killable(tmp_path: Path) -> None:
    (tmp_path / "ring.pnml").write_bytes((FOREIGN / "mcc_tokenring.pnml").read_bytes())
    rig = make_rig(tmp_path)
    rig.dispatch.step_budget = 40
    iid = rig.dispatch.start("ring")
    assert len(rig.fired(iid)) == 40
    assert rig.clock.run_ready() == 1
    assert len(rig.fired(iid)) == 80
    assert rig.dispatch.kill(iid) and rig.ended(iid) == "killed"


def test_one_guidebot_toolspecific_makes_a_task_net_with_the_stricter_rule(tmp_path: Path) -> None:
    text = (FOREIGN / "mcc_tokenring.pnml").read_text()
    marked = text.replace(
        "<page id=", '<toolspecific tool="guidebot" version="1"/>\n    <page id=', 1
    )
    (tmp_path / "ring.pnml").write_text(marked)
    net, problems = load_net(tmp_path / "ring.pnml")
    assert net is None
    assert [p.message for p in problems] == [
        "no final place is reachable and no transition removes marks: the net can never end "
        "(declare a <final/> place, or <endless/> if it runs until killed)"
    ]


def with_arc_part(part: str) -> str:
    text = (FOREIGN / "pipe_producer.xml").read_bytes().decode("iso-8859-1")
    return text.replace('<type value="normal"/>', part, 1)


@pytest.mark.parametrize(
    ("document", "expected"),
    [
        (
            with_arc_part('<type value="inhibitor"/>'),
            ":130: arc P0 to T0: inhibitor arcs are not supported (only normal arcs of "
            "place/transition nets)",
        ),
        (
            with_arc_part("<arctype><text>reset</text></arctype>"),
            ":130: arc P0 to T0: reset arcs are not supported (only normal arcs of "
            "place/transition nets)",
        ),
        (
            with_arc_part("").replace(
                "<value>Default,3</value>", "<value>Default,1,red,2</value>", 1
            ),
            ":17: place P0: initialMarking 'Default,1,red,2' is not a natural number",
        ),
        (
            with_arc_part("").replace(
                "<value>0</value>\n</capacity>", "<value>4</value>\n</capacity>", 1
            ),
            ":23: place P0: capacity '4' is not supported (place/transition nets here are "
            "unbounded; set it to 0)",
        ),
        (
            with_arc_part("").replace(
                'type="P/T net"', 'type="http://www.pnml.org/version-2009/grammar/symmetricnet"'
            ),
            ":2: net type 'http://www.pnml.org/version-2009/grammar/symmetricnet' is not a "
            "place/transition net",
        ),
    ],
    ids=["inhibitor", "reset", "coloured", "capacity", "symmetric"],
)
def test_what_a_plain_net_cannot_say_is_refused_with_its_line(
    document: str, expected: str, tmp_path: Path
) -> None:
    path = tmp_path / "net.xml"
    path.write_bytes(document.encode("iso-8859-1"))
    assert [str(p).removeprefix(str(path)) for p in check_files([path])] == [expected]


def test_a_final_marking_of_an_unknown_place_is_reported(tmp_path: Path) -> None:
    text = (FOREIGN / "prom_order.pnml").read_bytes().replace(b'idref="n4"', b'idref="n44"')
    path = tmp_path / "order.pnml"
    path.write_bytes(text)
    assert [str(p).removeprefix(str(path)) for p in check_files([path])] == [
        ":179: final marking: no place 'n44'"
    ]


def test_a_transition_without_input_place_is_always_enabled(tmp_path: Path) -> None:
    # PIPE models arrivals this way: the net never ends, the guard stops the dry run
    text = (FOREIGN / "pipe_producer.xml").read_bytes().decode("iso-8859-1")
    arrivals = text.replace(
        '<arc id="P0 to T0" source="P0" target="T0">', '<arc id="x" source="P2" target="T1">'
    )
    path = tmp_path / "arrivals.xml"
    path.write_bytes(arrivals.encode("iso-8859-1"))
    assert check_files([path]) == []
    result = run_net(path, {}, {}, max_firings=30)
    assert result["outcome"] == "running" and result["firings"] == 30
    assert result["fired"][:2] == ["T0", "T0"]


def test_a_monitor_is_told_a_foreign_net_is_plain_and_where_it_should_end() -> None:
    net, problems = load_net(FOREIGN / "prom_order.pnml")
    assert net is not None and problems == []
    described = describe(net)
    assert described["plain"] is True
    assert described["final_markings"] == [{"n1": 0, "n2": 1, "n3": 0, "n4": 0}]
    assert [t["name"] for t in described["transitions"]][1] == "Bonität prüfen"
    assert described["places"][0]["position"] == {"x": 11.25, "y": 11.25}


def test_a_file_in_its_own_namespace_goes_back_in_it() -> None:
    text = (
        (FOREIGN / "woped_claim.pnml")
        .read_text()
        .replace("<pnml>", '<pnml xmlns="pnml.woped.org">')
    )
    doc, problems = read_pnml(text, "claim.pnml")
    assert doc is not None and problems == []
    written = write_pnml(doc)
    assert b'<pnml xmlns="pnml.woped.org">' in written
    assert shape(parse_xml(written)) == shape(parse_xml(text))
    assert parse_xml(written).children[0].ns == "pnml.woped.org"


def test_a_long_step_is_reported_in_parts_and_every_firing_is_told(tmp_path: Path) -> None:
    (tmp_path / "ring.pnml").write_bytes((FOREIGN / "mcc_tokenring.pnml").read_bytes())
    rig = make_rig(tmp_path)
    rig.dispatch.step_budget = 2500
    iid = rig.dispatch.start("ring")
    sizes = [
        len(m.payload["transitions"])
        for m in rig.log
        if m.type == "petri_net_event" and m.payload["kind"] == "fired"
    ]
    assert sizes == [1000, 1000, 500]
    assert rig.fired(iid)[:3] == ["pass0", "pass1", "pass0"]
    rig.dispatch.kill(iid)


def test_a_task_net_runs_a_foreign_net_and_hears_how_it_ended(tmp_path: Path) -> None:
    (tmp_path / "order.pnml").write_bytes((FOREIGN / "prom_stuck.pnml").read_bytes())
    b = NetBuilder("supervise")
    b.place("go", initial=1, action=run("order")).place("ok", final=True)
    b.place("escalate", final=True, outcome="failed")
    b.transition("order_done", ["go"], ["ok"], net_ended("order", "done"))
    b.transition("order_stuck", ["go"], ["escalate"], net_ended("order", "stuck"))
    (tmp_path / "supervise.pnml").write_bytes(write_pnml(b.build()))
    rig = make_rig(tmp_path)
    assert rig.dispatch.library.problems() == []
    iid = rig.dispatch.start("supervise")
    assert rig.fired(iid) == ["order_stuck"] and rig.ended(iid) == "failed"
