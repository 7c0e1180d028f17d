"""PNML writer: standard PNML, our data only inside guidebot toolspecific elements.

A net read from a file is written back from the elements it was read from, in their order:
whatever we do not own (other tools' toolspecific data, PIPE's arc paths and token classes,
ProM's final markings, reference nodes, labels we do not know) is copied as it came, in the
file's own namespace (or none, as ProM and PIPE write it), and a label is written anew only when
the model changed its value. So a foreign net read and written back is still the file its tool
wrote (UTF-8, comments dropped). A net built in Python is written in canonical form.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from typing import Any

from petri_nets.model import (
    REQUIRED,
    ActionSpec,
    ArcSpec,
    ConditionSpec,
    NetDoc,
    PageSpec,
    PlaceSpec,
    TransitionSpec,
)
from petri_nets.pnml_dialects import (
    PNML_NS,
    PTNET_TYPE,
    TOOL,
    TOOL_VERSION,
    parse_count,
    text_of,
)
from petri_nets.xmlsafe import Node

__all__ = ["write_pnml"]


def write_pnml(net: NetDoc) -> bytes:
    """The net as a PNML document (UTF-8)."""
    return _Writer(net).write()


def _ours(node: Node) -> bool:
    return node.tag == "toolspecific" and node.attrib.get("tool") == TOOL


class _Writer:
    def __init__(self, net: NetDoc) -> None:
        self.net = net
        self.ns = net.root.ns if net.root is not None else PNML_NS
        self.by_element: dict[int, PageSpec | PlaceSpec | TransitionSpec | ArcSpec] = {}
        for items in (net.pages, net.places, net.transitions, net.arcs):
            for item in items:
                if item.element is not None:
                    self.by_element[id(item.element)] = item
        self.done: set[int] = set()
        self.page_elements: dict[str, ET.Element] = {}

    # ---------------------------------------------------------------- helpers

    def sub(self, parent: ET.Element, tag: str, attrs: dict[str, str] | None = None) -> ET.Element:
        return ET.SubElement(parent, tag, attrs or {})

    def copy(self, node: Node, parent: ET.Element) -> None:
        """An element we keep but do not own, as it came (in the document's namespace)."""
        element = self.sub(parent, node.tag, dict(node.attrib))
        element.text = node.text.strip() or None
        for child in node.children:
            self.copy(child, element)

    def text_label(
        self, parent: ET.Element, tag: str, value: str, graphics: Node | None = None
    ) -> None:
        holder = self.sub(parent, tag)
        self.sub(holder, "text").text = value
        if graphics is not None:
            self.copy(graphics, holder)

    def label(
        self,
        parent: ET.Element,
        tag: str,
        value: str | None,
        original: Node | None,
        graphics: Node | None = None,
    ) -> None:
        """A text label: the original element when the value is unchanged, else anew."""
        if value is None:
            return
        if original is not None and text_of(original) == value:
            self.copy(original, parent)
        else:
            self.text_label(parent, tag, value, graphics)

    def count(
        self, parent: ET.Element, tag: str, value: int, original: Node | None, default: int
    ) -> None:
        """A marking or weight: the original element (``Default,2`` stays) when unchanged."""
        if original is not None and parse_count(text_of(original)) == value:
            self.copy(original, parent)
        elif value != default:
            self.text_label(parent, tag, str(value))

    def tool(self, parent: ET.Element) -> ET.Element:
        return self.sub(parent, "toolspecific", {"tool": TOOL, "version": TOOL_VERSION})

    # ---------------------------------------------------------------- document

    def write(self) -> bytes:
        net = self.net
        # every element in the document's one namespace: declared on the root by hand, as
        # ElementTree would otherwise invent prefixes (or need global registration)
        attrs = dict(net.root.attrib) if net.root is not None else {}
        if self.ns:
            attrs = {"xmlns": self.ns, **attrs}
        root = ET.Element("pnml", attrs)
        if net.root is not None and net.element is not None:
            for child in net.root.children:
                if child is net.element:
                    self.write_net(root)
                else:
                    self.copy(child, root)
        else:
            self.write_net(root)
        ET.indent(root)
        return ET.tostring(root, encoding="utf-8", xml_declaration=True)

    def write_net(self, parent: ET.Element) -> None:
        net = self.net
        source = net.element
        attrs = dict(source.attrib) if source is not None else {}
        attrs["id"] = net.id
        if net.type or source is None:
            attrs["type"] = net.type or PTNET_TYPE
        element = self.sub(parent, "net", attrs)
        kept = {id(child) for child in source.children} if source is not None else set()
        wrote: set[str] = set()
        if source is not None:
            for child in source.children:
                if child.tag == "name":
                    self.label(element, "name", net.name, child)
                    wrote.add("name")
                elif _ours(child):
                    if "tool" not in wrote:
                        self.net_tool(element)
                        wrote.add("tool")
                elif child.tag in ("page", "place", "transition", "arc"):
                    self.write_item(element, child)
                else:
                    if child.tag == "finalmarkings":
                        wrote.add("finalmarkings")
                    self.copy(child, element)
        if "name" not in wrote and net.name:
            self.text_label(element, "name", net.name)
        if "tool" not in wrote and (
            net.description or net.params or net.endless or (net.task and source is None)
        ):
            self.net_tool(element)
        for foreign in net.foreign:
            if id(foreign) not in kept:
                self.copy(foreign, element)
        for page in net.pages:
            if page.implicit:
                self.page_elements[page.id] = element
            elif page.parent is None and id(page) not in self.done:
                self.write_page(element, page)
        self.write_leftovers(element)
        if net.final_markings and "finalmarkings" not in wrote:
            self.write_final_markings(element)

    def net_tool(self, parent: ET.Element) -> None:
        net = self.net
        tool = self.tool(parent)
        if net.description:
            self.sub(tool, "description").text = net.description
        for param in net.params:
            attrs = {"name": param.name}
            if param.default is not REQUIRED:
                default = param.default
                attrs["default"] = default if isinstance(default, str) else json.dumps(default)
            self.sub(tool, "param", attrs)
        if net.endless:
            self.sub(tool, "endless")

    def write_final_markings(self, parent: ET.Element) -> None:
        holder = self.sub(parent, "finalmarkings")
        for marking in self.net.final_markings:
            element = self.sub(holder, "marking")
            for place, count in marking.counts.items():
                self.text_label(element, "place", str(count))
                element[-1].set("idref", place)

    # ---------------------------------------------------------------- pages and nodes

    def write_item(self, parent: ET.Element, node: Node) -> None:
        """The model object read from ``node``, if the model still has it."""
        item = self.by_element.get(id(node))
        if item is None or id(item) in self.done:
            return
        if isinstance(item, PageSpec):
            self.write_page(parent, item)
        elif isinstance(item, PlaceSpec):
            self.write_place(parent, item)
        elif isinstance(item, TransitionSpec):
            self.write_transition(parent, item)
        else:
            self.write_arc(parent, item)

    def write_page(self, parent: ET.Element, page: PageSpec) -> None:
        self.done.add(id(page))
        source = page.element
        attrs = dict(source.attrib) if source is not None else {}
        attrs["id"] = page.id
        element = self.sub(parent, "page", attrs)
        self.page_elements[page.id] = element
        wrote_graphics = False
        if source is not None:
            for child in source.children:
                if child.tag in ("page", "place", "transition", "arc"):
                    self.write_item(element, child)
                elif child.tag == "graphics":
                    if page.graphics is not None and not wrote_graphics:
                        self.copy(page.graphics, element)
                    wrote_graphics = True
                else:
                    self.copy(child, element)
        elif page.graphics is not None:
            self.copy(page.graphics, element)
        for sub in self.net.pages:
            if sub.parent == page.id and id(sub) not in self.done:
                self.write_page(element, sub)

    def write_leftovers(self, net_element: ET.Element) -> None:
        """Nodes not written with their element (built or added in Python): into their page."""
        items: list[PlaceSpec | TransitionSpec | ArcSpec] = [
            *self.net.places,
            *self.net.transitions,
            *self.net.arcs,
        ]
        for item in items:
            if id(item) in self.done:
                continue
            parent = self.page_elements.get(item.page)
            if parent is None:
                parent = next(iter(self.page_elements.values()), None)
            if parent is None:
                parent = self.page_elements["page1"] = self.sub(
                    net_element, "page", {"id": "page1"}
                )
            if isinstance(item, PlaceSpec):
                self.write_place(parent, item)
            elif isinstance(item, TransitionSpec):
                self.write_transition(parent, item)
            else:
                self.write_arc(parent, item)

    def node(
        self,
        parent: ET.Element,
        tag: str,
        item: PlaceSpec | TransitionSpec | ArcSpec,
        attrs: dict[str, str],
        labels: dict[str, Any],
    ) -> None:
        """Write a node's element from its source element; returns it and what was written.

        ``labels`` maps a label tag to a function(parent, original) writing it.
        """
        self.done.add(id(item))
        source = item.element
        element = self.sub(parent, tag, {**(source.attrib if source else {}), **attrs})
        wrote: set[str] = set()
        foreign = {id(f) for f in item.foreign}
        if source is not None:
            for child in source.children:
                if child.tag in labels:
                    if child.tag not in wrote:
                        labels[child.tag](element, child)
                    wrote.add(child.tag)
                elif _ours(child) and not isinstance(item, ArcSpec):
                    if "tool" not in wrote:
                        self.node_tool(element, item, force=True)
                    wrote.add("tool")
                elif child.tag == "toolspecific" and id(child) not in foreign:
                    continue  # removed from the model
                else:
                    wrote.add(f"#{id(child)}")
                    self.copy(child, element)
        for tag_name, write in labels.items():
            if tag_name not in wrote:
                write(element, None)
        if "tool" not in wrote:
            self.node_tool(element, item, force=False)
        for node in item.foreign:
            if f"#{id(node)}" not in wrote:
                self.copy(node, element)

    def node_tool(
        self, parent: ET.Element, item: PlaceSpec | TransitionSpec | ArcSpec, *, force: bool
    ) -> None:
        """Our toolspecific element: when there is something to say, or the file had one."""
        if isinstance(item, PlaceSpec):
            if item.action is not None or item.final or force:
                tool = self.tool(parent)
                if item.action is not None:
                    _write_action(self, tool, item.action)
                if item.final:
                    self.sub(tool, "final", {"outcome": item.outcome})
        elif isinstance(item, TransitionSpec):
            if item.condition is not None or item.priority or force:
                tool = self.tool(parent)
                if item.condition is not None:
                    _write_condition(self, tool, item.condition)
                if item.priority:
                    self.sub(tool, "priority", {"value": str(item.priority)})

    def graphics_writer(self, graphics: Node | None) -> Any:
        def write(parent: ET.Element, original: Node | None) -> None:
            if graphics is not None:
                self.copy(graphics, parent)

        return write

    def named(self, item: PlaceSpec | TransitionSpec) -> dict[str, Any]:
        """Label writers of a place or transition: name (with its graphics) and graphics."""
        return {
            "name": lambda el, orig: self.label(el, "name", item.name, orig, item.name_graphics),
            "graphics": self.graphics_writer(item.graphics),
        }

    def write_place(self, parent: ET.Element, place: PlaceSpec) -> None:
        labels = self.named(place)
        labels["initialMarking"] = lambda el, orig: self.count(
            el, "initialMarking", place.initial, orig, 0
        )
        self.node(parent, "place", place, {"id": place.id}, labels)

    def write_transition(self, parent: ET.Element, trans: TransitionSpec) -> None:
        self.node(parent, "transition", trans, {"id": trans.id}, self.named(trans))

    def write_arc(self, parent: ET.Element, arc: ArcSpec) -> None:
        source, target = arc.written or (arc.source, arc.target)
        self.node(
            parent,
            "arc",
            arc,
            {"id": arc.id, "source": source, "target": target},
            {
                "graphics": self.graphics_writer(arc.graphics),
                "inscription": lambda el, orig: self.count(el, "inscription", arc.weight, orig, 1),
            },
        )


def _write_action(writer: _Writer, parent: ET.Element, action: ActionSpec) -> None:
    attrs = {"kind": action.kind}
    for key in ("type", "destination", "net", "seconds", "list", "var", "order"):
        value = getattr(action, key)
        if value is not None:
            attrs[key] = value
    element = writer.sub(parent, "action", attrs)
    if action.body.strip():
        element.text = action.body.strip()


def _write_condition(writer: _Writer, parent: ET.Element, cond: ConditionSpec) -> None:
    attrs = {"kind": cond.kind}
    for key in ("type", "net", "outcome", "var", "test", "value"):
        value = getattr(cond, key)
        if value is not None:
            attrs[key] = value
    element = writer.sub(parent, "condition", attrs)
    for match in cond.matches:
        writer.sub(element, "match", {"field": match.field, "value": match.value})
    for var, field_name in cond.binds:
        writer.sub(element, "bind", {"var": var, "field": field_name})
