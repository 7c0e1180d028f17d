"""PNML (ISO/IEC 15909-2, place/transition nets) reader.

Plain PNML from other tools is read as is (names, graphics, nested pages or none, reference
nodes, arc weights, ProM's final markings, PIPE's ``<value>`` labels); what PNML cannot say
lives in ``<toolspecific tool="guidebot" version="1">`` (see docs/petri-nets.md). Every element
read is kept on the model so ``write_pnml`` gives the file back with nothing lost. Reading never
raises on content problems: it returns the net and the list of problems found.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from petri_nets.model import (
    REQUIRED,
    ActionSpec,
    ArcSpec,
    ConditionSpec,
    FinalMarking,
    MatchSpec,
    NetDoc,
    PageSpec,
    ParamSpec,
    PlaceSpec,
    Problem,
    TransitionSpec,
)
from petri_nets.pnml_dialects import (
    PNML_NS,
    PTNET_TYPE,
    TOOL,
    TOOL_VERSION,
    is_pt_type,
    label_value,
    parse_count,
    text_of,
)
from petri_nets.pnml_writer import write_pnml
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

_NODES = ("place", "transition", "arc", "referencePlace", "referenceTransition")


class _Reader:
    def __init__(self, file: str) -> None:
        self.file = file
        self.problems: list[Problem] = []
        self.task = False

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
        net = self.read_net(nets[0])
        net.root = root
        net.task = self.task
        return net

    def read_net(self, node: Node) -> NetDoc:
        net = NetDoc(id=node.attrib.get("id", ""), file=self.file, line=node.line, element=node)
        if not net.id:
            self.problem(node.line, "<net> has no id")
        net.type = node.attrib.get("type", "")
        if not is_pt_type(net.type):
            self.problem(node.line, f"net type {net.type!r} is not a place/transition net")
        net.name = label_value(node, "name")
        for tool in node.findall("toolspecific"):
            if self.ours(tool):
                self.read_net_tool(net, tool)
            else:
                net.foreign.append(tool)
        for marks in node.findall("finalmarkings"):
            self.read_final_markings(net, marks)
        refs: dict[str, tuple[str, int]] = {}
        pages = node.findall("page")
        if any(child.tag in _NODES for child in node.children):
            # older PNML (WoPeD, PIPE): nodes straight under <net>, no page
            implicit = PageSpec("", None, node.line, element=node, implicit=True)
            self.read_page_content(net, implicit, node, refs)
        elif not pages:
            self.problem(node.line, "<net> has no <page>")
        for page in pages:
            self.read_page(net, page, None, refs)
        self.resolve_references(net, refs)
        return net

    def ours(self, tool: Node) -> bool:
        if tool.attrib.get("tool") != TOOL:
            return False
        self.task = True
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

    def read_final_markings(self, net: NetDoc, node: Node) -> None:
        """ProM's ``<finalmarkings><marking><place idref><text>n``: the markings it ends in."""
        for marking in node.findall("marking"):
            counts: dict[str, int] = {}
            lines: dict[str, int] = {}
            for place in marking.findall("place"):
                ref = place.attrib.get("idref", "")
                count = parse_count(text_of(place))
                if not ref or count is None:
                    self.problem(
                        place.line, "a final marking's <place> needs idref and a natural number"
                    )
                    continue
                counts[ref] = counts.get(ref, 0) + count
                lines.setdefault(ref, place.line)
            net.final_markings.append(FinalMarking(counts, marking.line, lines))

    def read_page(
        self, net: NetDoc, node: Node, parent: str | None, refs: dict[str, tuple[str, int]]
    ) -> None:
        page = PageSpec(
            node.attrib.get("id", f"page{len(net.pages) + 1}"),
            parent,
            node.line,
            node.find("graphics"),
            element=node,
        )
        self.read_page_content(net, page, node, refs)

    def read_page_content(
        self, net: NetDoc, page: PageSpec, node: Node, refs: dict[str, tuple[str, int]]
    ) -> None:
        net.pages.append(page)
        for child in node.children:
            if child.tag == "place":
                net.places.append(self.read_place(child, page.id))
            elif child.tag == "transition":
                net.transitions.append(self.read_transition(child, page.id))
            elif child.tag == "arc":
                net.arcs.append(self.read_arc(child, page.id))
            elif child.tag == "page" and not page.implicit:
                self.read_page(net, child, page.id, refs)
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

    def count(self, node: Node, tag: str, what: str, minimum: int) -> int | None:
        """A marking or weight label, checked; None when absent or bad (a problem is said)."""
        value = label_value(node, tag)
        if value is None:
            return None
        count = parse_count(value)
        if count is None or count < minimum:
            holder = node.find(tag)
            line = holder.line if holder is not None else node.line
            kind = "a natural number" if minimum == 0 else "a positive integer"
            self.problem(line, f"{what}: {tag} {value!r} is not {kind}")
            return None
        return count

    def node_fields(self, node: Node, page: str) -> dict[str, Any]:
        """What a place and a transition read alike: id, line, page, name and graphics."""
        return {
            "id": self.node_id(node),
            "line": node.line,
            "page": page,
            "name": label_value(node, "name"),
            "graphics": node.find("graphics"),
            "name_graphics": self.name_graphics(node),
            "element": node,
        }

    def read_place(self, node: Node, page: str) -> PlaceSpec:
        place = PlaceSpec(**self.node_fields(node, page))
        place.initial = self.count(node, "initialMarking", f"place {place.id}", 0) or 0
        capacity = label_value(node, "capacity")  # PIPE: 0 = unbounded
        if capacity not in (None, "", "0"):
            self.problem(
                node.find("capacity").line,  # type: ignore[union-attr]
                f"place {place.id}: capacity {capacity!r} is not supported "
                "(place/transition nets here are unbounded; set it to 0)",
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
        trans = TransitionSpec(**self.node_fields(node, page))
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
            element=node,
        )
        arc.weight = self.count(node, "inscription", f"arc {arc.id}", 1) or 1
        # PIPE and TINA: <type value="inhibitor"/>; ProM: <arctype><text>reset</text></arctype>
        kind_node = node.find("type") or node.find("arctype")
        kind = "normal"
        if kind_node is not None:
            kind = kind_node.attrib.get("value") or label_value(node, kind_node.tag) or kind
        if kind_node is not None and kind.strip().lower() not in ("normal", "regular", ""):
            self.problem(
                kind_node.line,
                f"arc {arc.id}: {kind} arcs are not supported (only normal arcs of "
                "place/transition nets)",
            )
        arc.foreign = node.findall("toolspecific")
        for tool in arc.foreign:
            self.ours(tool)  # kept as is, but it makes the net a task net
        return arc

    def resolve_references(self, net: NetDoc, refs: dict[str, tuple[str, int]]) -> None:
        """Arcs to a reference node go to the node it stands for (following chains); the ids
        the file wrote are kept for writing back."""
        for arc in net.arcs:
            ends = []
            for attr in ("source", "target"):
                seen: set[str] = set()
                target = getattr(arc, attr)
                while target in refs and target not in seen:
                    seen.add(target)
                    target = refs[target][0]
                if target in seen:
                    self.problem(arc.line, f"arc {arc.id}: reference cycle through {target!r}")
                ends.append(target)
            if (arc.source, arc.target) != tuple(ends):
                arc.written = (arc.source, arc.target)
                arc.source, arc.target = ends


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
