"""PNML (ISO/IEC 15909-2, place/transition nets) reader and writer.

Plain PNML from other tools is read as is (names, graphics, nested pages, reference nodes,
arc weights); what PNML cannot say lives in ``<toolspecific tool="guidebot" version="1">``
(see docs/petri-nets.md). Other tools' toolspecific data and graphics are kept and written back.
Reading never raises on content problems: it returns the net and the list of problems found.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

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
    Problem,
    TransitionSpec,
)
from petri_nets.templates import parse_literal
from petri_nets.xmlsafe import Node, XmlError, parse_xml

__all__ = [
    "PNML_NS",
    "PTNET_TYPE",
    "TOOL",
    "TOOL_VERSION",
    "read_pnml",
    "read_pnml_file",
    "write_pnml",
]

PNML_NS = "http://www.pnml.org/version-2009/grammar/pnml"
PTNET_TYPE = "http://www.pnml.org/version-2009/grammar/ptnet"
TOOL = "guidebot"
TOOL_VERSION = "1"


class _Reader:
    def __init__(self, file: str) -> None:
        self.file = file
        self.problems: list[Problem] = []

    def problem(self, line: int, message: str) -> None:
        self.problems.append(Problem(self.file, line, message))

    def read(self, data: bytes | str) -> NetDoc | None:
        try:
            root = parse_xml(data)
        except XmlError as exc:
            self.problem(exc.line, exc.message)
            return None
        if root.tag != "pnml":
            self.problem(root.line, f"root element is <{root.tag}>, expected <pnml>")
            return None
        nets = root.findall("net")
        if not nets:
            self.problem(root.line, "no <net> element")
            return None
        for extra in nets[1:]:
            self.problem(
                extra.line, "only one <net> per file is supported; move it to its own file"
            )
        return self.read_net(nets[0])

    def read_net(self, node: Node) -> NetDoc:
        net = NetDoc(id=node.attrib.get("id", ""), file=self.file, line=node.line)
        if not net.id:
            self.problem(node.line, "<net> has no id")
        net.type = node.attrib.get("type", "")
        if net.type and net.type != PTNET_TYPE:
            self.problem(node.line, f"net type {net.type!r} is not a place/transition net")
        net.name = node.text_of("name")
        for tool in node.findall("toolspecific"):
            if self.ours(tool):
                self.read_net_tool(net, tool)
            else:
                net.foreign.append(tool)
        pages = node.findall("page")
        if not pages:
            self.problem(node.line, "<net> has no <page>")
        refs: dict[str, tuple[str, int]] = {}
        for page in pages:
            self.read_page(net, page, None, refs)
        self.resolve_references(net, refs)
        return net

    def ours(self, tool: Node) -> bool:
        if tool.attrib.get("tool") != TOOL:
            return False
        if tool.attrib.get("version", TOOL_VERSION) != TOOL_VERSION:
            self.problem(
                tool.line,
                f"guidebot toolspecific version {tool.attrib.get('version')!r} "
                f"is not supported (expected {TOOL_VERSION})",
            )
        return True

    def read_net_tool(self, net: NetDoc, tool: Node) -> None:
        for child in tool.children:
            if child.tag == "description":
                net.description = child.text.strip()
            elif child.tag == "endless":
                net.endless = True
            elif child.tag == "param":
                name = child.attrib.get("name", "")
                if not name.isidentifier():
                    self.problem(child.line, f"parameter name {name!r} is not an identifier")
                    continue
                default = child.attrib.get("default")
                net.params.append(
                    ParamSpec(
                        name, REQUIRED if default is None else parse_literal(default), child.line
                    )
                )
            else:
                self.problem(child.line, f"unknown net setting <{child.tag}>")

    def read_page(
        self, net: NetDoc, node: Node, parent: str | None, refs: dict[str, tuple[str, int]]
    ) -> None:
        page_id = node.attrib.get("id", f"page{len(net.pages) + 1}")
        net.pages.append(PageSpec(page_id, parent, node.line, node.find("graphics")))
        for child in node.children:
            if child.tag == "place":
                net.places.append(self.read_place(child, page_id))
            elif child.tag == "transition":
                net.transitions.append(self.read_transition(child, page_id))
            elif child.tag == "arc":
                net.arcs.append(self.read_arc(child, page_id))
            elif child.tag == "page":
                self.read_page(net, child, page_id, refs)
            elif child.tag in ("referencePlace", "referenceTransition"):
                ref_id, target = child.attrib.get("id", ""), child.attrib.get("ref", "")
                if not ref_id or not target:
                    self.problem(child.line, f"<{child.tag}> needs id and ref")
                else:
                    refs[ref_id] = (target, child.line)

    def node_id(self, node: Node) -> str:
        node_id = node.attrib.get("id", "")
        if not node_id:
            self.problem(node.line, f"<{node.tag}> has no id")
        return node_id

    def name_graphics(self, node: Node) -> Node | None:
        name = node.find("name")
        return name.find("graphics") if name is not None else None

    def read_place(self, node: Node, page: str) -> PlaceSpec:
        place = PlaceSpec(
            self.node_id(node),
            node.line,
            page,
            name=node.text_of("name"),
            graphics=node.find("graphics"),
            name_graphics=self.name_graphics(node),
        )
        marking = node.text_of("initialMarking")
        if marking:
            if marking.isdigit():
                place.initial = int(marking)
            else:
                line = node.find("initialMarking").line  # type: ignore[union-attr]
                self.problem(
                    line, f"place {place.id}: initialMarking {marking!r} is not a natural number"
                )
        for tool in node.findall("toolspecific"):
            if not self.ours(tool):
                place.foreign.append(tool)
                continue
            for child in tool.children:
                if child.tag == "action":
                    if place.action is not None:
                        self.problem(child.line, f"place {place.id} has more than one action")
                    place.action = self.read_action(child)
                elif child.tag == "final":
                    place.final = True
                    place.outcome = child.attrib.get("outcome", "done")
                    if place.outcome not in ("done", "failed"):
                        self.problem(
                            child.line,
                            f"place {place.id}: final outcome "
                            f"{place.outcome!r} is not done or failed",
                        )
                else:
                    self.problem(child.line, f"unknown place setting <{child.tag}>")
        return place

    def read_action(self, node: Node) -> ActionSpec:
        a = node.attrib
        return ActionSpec(
            kind=a.get("kind", ""),
            line=node.line,
            type=a.get("type"),
            destination=a.get("destination"),
            body=node.text,
            net=a.get("net"),
            seconds=a.get("seconds"),
            list=a.get("list"),
            var=a.get("var"),
            order=a.get("order"),
        )

    def read_transition(self, node: Node, page: str) -> TransitionSpec:
        trans = TransitionSpec(
            self.node_id(node),
            node.line,
            page,
            name=node.text_of("name"),
            graphics=node.find("graphics"),
            name_graphics=self.name_graphics(node),
        )
        for tool in node.findall("toolspecific"):
            if not self.ours(tool):
                trans.foreign.append(tool)
                continue
            for child in tool.children:
                if child.tag == "condition":
                    if trans.condition is not None:
                        self.problem(
                            child.line, f"transition {trans.id} has more than one condition"
                        )
                    trans.condition = self.read_condition(child)
                elif child.tag == "priority":
                    value = child.attrib.get("value", child.text).strip()
                    try:
                        trans.priority = int(value)
                    except ValueError:
                        self.problem(
                            child.line,
                            f"transition {trans.id}: priority {value!r} is not an integer",
                        )
                else:
                    self.problem(child.line, f"unknown transition setting <{child.tag}>")
        return trans

    def read_condition(self, node: Node) -> ConditionSpec:
        a = node.attrib
        cond = ConditionSpec(
            kind=a.get("kind", ""),
            line=node.line,
            type=a.get("type"),
            net=a.get("net"),
            outcome=a.get("outcome"),
            var=a.get("var"),
            test=a.get("test"),
            value=a.get("value"),
        )
        for child in node.children:
            if child.tag == "match" and "field" in child.attrib and "value" in child.attrib:
                cond.matches.append(
                    MatchSpec(child.attrib["field"], child.attrib["value"], child.line)
                )
            elif child.tag == "bind" and "var" in child.attrib and "field" in child.attrib:
                cond.binds.append((child.attrib["var"], child.attrib["field"]))
            else:
                self.problem(
                    child.line,
                    f"<{child.tag}> in a condition: expected "
                    "<match field value/> or <bind var field/>",
                )
        return cond

    def read_arc(self, node: Node, page: str) -> ArcSpec:
        a = node.attrib
        arc = ArcSpec(
            self.node_id(node),
            a.get("source", ""),
            a.get("target", ""),
            node.line,
            page,
            graphics=node.find("graphics"),
        )
        weight = node.text_of("inscription")
        if weight is not None:
            if weight.isdigit() and int(weight) > 0:
                arc.weight = int(weight)
            else:
                self.problem(
                    node.line, f"arc {arc.id}: inscription {weight!r} is not a positive integer"
                )
        arc.foreign = node.findall("toolspecific")
        return arc

    def resolve_references(self, net: NetDoc, refs: dict[str, tuple[str, int]]) -> None:
        """Arcs to a reference node go to the node it stands for (following chains)."""
        for arc in net.arcs:
            for attr in ("source", "target"):
                seen: set[str] = set()
                target = getattr(arc, attr)
                while target in refs and target not in seen:
                    seen.add(target)
                    target = refs[target][0]
                if target in seen:
                    self.problem(arc.line, f"arc {arc.id}: reference cycle through {target!r}")
                setattr(arc, attr, target)


def read_pnml(data: bytes | str, file: str = "<string>") -> tuple[NetDoc | None, list[Problem]]:
    """Read one net; problems are reading errors (the validator adds semantic ones)."""
    reader = _Reader(file)
    net = reader.read(data)
    return net, reader.problems


def read_pnml_file(path: str | Path) -> tuple[NetDoc | None, list[Problem]]:
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        return None, [Problem(str(path), 0, f"cannot read: {exc.strerror}")]
    return read_pnml(data, str(path))


# ---------------------------------------------------------------- writer


def _q(tag: str) -> str:
    return f"{{{PNML_NS}}}{tag}"


def _copy(node: Node, parent: ET.Element) -> None:
    """Write a kept element (graphics, other tools' data) back, in the PNML namespace."""
    element = ET.SubElement(parent, _q(node.tag), node.attrib)
    element.text = node.text.strip() or None
    for child in node.children:
        _copy(child, element)


def _text(parent: ET.Element, tag: str, value: str, graphics: Node | None = None) -> None:
    holder = ET.SubElement(parent, _q(tag))
    ET.SubElement(holder, _q("text")).text = value
    if graphics is not None:
        _copy(graphics, holder)


def _tool(parent: ET.Element) -> ET.Element:
    return ET.SubElement(parent, _q("toolspecific"), {"tool": TOOL, "version": TOOL_VERSION})


def _write_action(parent: ET.Element, action: ActionSpec) -> None:
    attrs = {"kind": action.kind}
    for key in ("type", "destination", "net", "seconds", "list", "var", "order"):
        value = getattr(action, key)
        if value is not None:
            attrs[key] = value
    element = ET.SubElement(parent, _q("action"), attrs)
    if action.body.strip():
        element.text = action.body.strip()


def _write_condition(parent: ET.Element, cond: ConditionSpec) -> None:
    attrs = {"kind": cond.kind}
    for key in ("type", "net", "outcome", "var", "test", "value"):
        value = getattr(cond, key)
        if value is not None:
            attrs[key] = value
    element = ET.SubElement(parent, _q("condition"), attrs)
    for match in cond.matches:
        ET.SubElement(element, _q("match"), {"field": match.field, "value": match.value})
    for var, field_name in cond.binds:
        ET.SubElement(element, _q("bind"), {"var": var, "field": field_name})


def write_pnml(net: NetDoc) -> bytes:
    """Standard PNML: our data only inside guidebot toolspecific elements."""
    import json

    ET.register_namespace("", PNML_NS)
    root = ET.Element(_q("pnml"))
    net_el = ET.SubElement(root, _q("net"), {"id": net.id, "type": PTNET_TYPE})
    if net.name:
        _text(net_el, "name", net.name)
    if net.description or net.params or net.endless:
        tool = _tool(net_el)
        if net.description:
            ET.SubElement(tool, _q("description")).text = net.description
        for param in net.params:
            attrs = {"name": param.name}
            if param.default is not REQUIRED:
                default = param.default
                attrs["default"] = default if isinstance(default, str) else json.dumps(default)
            ET.SubElement(tool, _q("param"), attrs)
        if net.endless:
            ET.SubElement(tool, _q("endless"))
    for foreign in net.foreign:
        _copy(foreign, net_el)
    pages: dict[str, ET.Element] = {}
    for page in net.pages or [PageSpec("page1", None, 0)]:
        parent = pages.get(page.parent or "", net_el)
        pages[page.id] = ET.SubElement(parent, _q("page"), {"id": page.id})
        if page.graphics is not None:
            _copy(page.graphics, pages[page.id])
    first = next(iter(pages.values()))
    for place in net.places:
        el = ET.SubElement(pages.get(place.page, first), _q("place"), {"id": place.id})
        if place.name:
            _text(el, "name", place.name, place.name_graphics)
        if place.graphics is not None:
            _copy(place.graphics, el)
        if place.initial:
            _text(el, "initialMarking", str(place.initial))
        if place.action is not None or place.final:
            tool = _tool(el)
            if place.action is not None:
                _write_action(tool, place.action)
            if place.final:
                ET.SubElement(tool, _q("final"), {"outcome": place.outcome})
        for foreign in place.foreign:
            _copy(foreign, el)
    for trans in net.transitions:
        el = ET.SubElement(pages.get(trans.page, first), _q("transition"), {"id": trans.id})
        if trans.name:
            _text(el, "name", trans.name, trans.name_graphics)
        if trans.graphics is not None:
            _copy(trans.graphics, el)
        if trans.condition is not None or trans.priority:
            tool = _tool(el)
            if trans.condition is not None:
                _write_condition(tool, trans.condition)
            if trans.priority:
                ET.SubElement(tool, _q("priority"), {"value": str(trans.priority)})
        for foreign in trans.foreign:
            _copy(foreign, el)
    for arc in net.arcs:
        el = ET.SubElement(
            pages.get(arc.page, first),
            _q("arc"),
            {"id": arc.id, "source": arc.source, "target": arc.target},
        )
        if arc.graphics is not None:
            _copy(arc.graphics, el)
        if arc.weight != 1:
            _text(el, "inscription", str(arc.weight))
        for foreign in arc.foreign:
            _copy(foreign, el)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)
