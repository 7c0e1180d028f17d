"""PNML in and out: plain nets from other tools, round trips, and a parser that refuses attacks."""

from __future__ import annotations

from pathlib import Path

import pytest

from petri_nets.library import load_net
from petri_nets.pnml import read_pnml, write_pnml
from petri_nets.validate import validate
from petri_nets.xmlsafe import MAX_BYTES, UnsafeXml, parse_xml

from .rig import make_rig

# What a generic editor writes: no guidebot parts, names, graphics, two pages with a reference
# place, arc weights, another tool's data.
PLAIN = """<?xml version="1.0" encoding="UTF-8"?>
<pnml xmlns="http://www.pnml.org/version-2009/grammar/pnml">
  <net id="producer" type="http://www.pnml.org/version-2009/grammar/ptnet">
    <name><text>Producer</text></name>
    <page id="main">
      <place id="ready">
        <name><text>ready</text><graphics><offset x="0" y="-10"/></graphics></name>
        <graphics><position x="10" y="20"/></graphics>
        <initialMarking><text>4</text></initialMarking>
        <toolspecific tool="otherTool" version="2.1"><colour>red</colour></toolspecific>
      </place>
      <transition id="produce">
        <name><text>produce</text></name>
        <graphics><position x="60" y="20"/></graphics>
      </transition>
      <arc id="a1" source="ready" target="produce">
        <inscription><text>2</text></inscription>
        <graphics><position x="30" y="25"/></graphics>
      </arc>
      <arc id="a2" source="produce" target="buffer_ref"/>
      <referencePlace id="buffer_ref" ref="buffer"/>
    </page>
    <page id="store">
      <place id="buffer"><name><text>buffer</text></name></place>
      <transition id="consume"/>
      <arc id="a3" source="buffer" target="consume"/>
    </page>
  </net>
</pnml>
"""


def test_a_plain_pnml_net_from_another_tool_is_read_and_runs(tmp_path: Path) -> None:
    doc, problems = read_pnml(PLAIN, "producer.pnml")
    assert problems == [] and doc is not None
    assert validate(doc) == []
    assert [p.id for p in doc.places] == ["ready", "buffer"]
    assert [(a.source, a.target, a.weight) for a in doc.arcs] == [
        ("ready", "produce", 2),
        ("produce", "buffer", 1),
        ("buffer", "consume", 1),
    ]
    (tmp_path / "producer.pnml").write_text(PLAIN)
    rig = make_rig(tmp_path)
    iid = rig.dispatch.start("producer")
    # 4 marks, weight 2: produce twice; each buffered mark is consumed; the net empties
    assert sorted(rig.fired(iid)) == ["consume", "consume", "produce", "produce"]
    assert rig.ended(iid) == "done"


def test_round_trip_read_write_read_keeps_the_net(tmp_path: Path) -> None:
    doc, _ = read_pnml(PLAIN, "producer.pnml")
    assert doc is not None
    written = write_pnml(doc)
    again, problems = read_pnml(written, "again.pnml")
    assert problems == [] and again is not None
    assert [(p.id, p.name, p.initial) for p in again.places] == [
        (p.id, p.name, p.initial) for p in doc.places
    ]
    assert [(p.id, p.page) for p in again.places] == [("ready", "main"), ("buffer", "store")]
    assert [(a.source, a.target, a.weight) for a in again.arcs] == [
        (a.source, a.target, a.weight) for a in doc.arcs
    ]
    assert again.places[0].graphics is not None
    position = again.places[0].graphics.find("position")
    assert position is not None and position.attrib == {"x": "10", "y": "20"}
    assert [t.attrib["tool"] for t in again.places[0].foreign] == ["otherTool"]
    assert write_pnml(again) == written  # a fixed point: nothing drifts on each save
    # a plain reader sees a standard document: the namespace and no guidebot parts
    assert b'xmlns="http://www.pnml.org/version-2009/grammar/pnml"' in written
    assert b"guidebot" not in written


def test_library_nets_round_trip_to_the_same_behaviour(tmp_path: Path) -> None:
    net, problems = load_net(Path("petri_nets/library/give_tour.pnml"))
    assert net is not None and problems == []
    copy = tmp_path / "give_tour.pnml"
    copy.write_bytes(write_pnml(net.doc))
    again, problems = load_net(copy)
    assert again is not None and problems == []
    assert again.version == net.version
    assert again.trans_ids == net.trans_ids and again.inputs == net.inputs


XXE = b"""<?xml version="1.0"?>
<!DOCTYPE pnml [<!ENTITY secret SYSTEM "file:///etc/passwd">]>
<pnml><net id="n"><page id="p"><place id="x"><name><text>&secret;</text></name></place>
</page></net></pnml>"""

BOMB = b"""<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
<!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">]>
<pnml><net id="n"><name><text>&lol3;</text></name></net></pnml>"""

PARAMETER_ENTITY = b"""<?xml version="1.0"?>
<!DOCTYPE pnml [<!ENTITY % remote SYSTEM "http://127.0.0.1:9/evil.dtd"> %remote;]>
<pnml/>"""


@pytest.mark.parametrize("document", [XXE, BOMB, PARAMETER_ENTITY], ids=["xxe", "bomb", "pe"])
def test_entities_and_dtds_are_refused_with_a_line(document: bytes) -> None:
    with pytest.raises(UnsafeXml, match="DTD") as raised:
        parse_xml(document)
    assert raised.value.line == 2
    _, problems = read_pnml(document, "evil.pnml")
    assert [str(p) for p in problems] == ["evil.pnml:2: a DTD (DOCTYPE) is not allowed"]


def test_oversized_and_too_deep_documents_are_refused() -> None:
    with pytest.raises(UnsafeXml, match="limit"):
        parse_xml(b"<pnml>" + b" " * MAX_BYTES + b"</pnml>")
    with pytest.raises(UnsafeXml, match="nesting deeper"):
        parse_xml(b"<a>" * 100 + b"</a>" * 100)


def test_malformed_xml_is_reported_at_its_line() -> None:
    _, problems = read_pnml(b"<pnml>\n<net id='n'>\n<page>\n</net>\n</pnml>", "bad.pnml")
    assert [str(p) for p in problems] == ["bad.pnml:4: mismatched tag"]
