"""A hardened XML reader that keeps line numbers, for PNML files from anywhere.

Why not plain ElementTree: it keeps no line numbers (validation must say where an error is) and
it expands entities. This reader refuses any DTD (so no external entities and no entity bombs),
refuses documents over a size limit, and limits depth and element count.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

__all__ = ["MAX_BYTES", "MAX_DEPTH", "MAX_ELEMENTS", "Node", "UnsafeXml", "XmlError", "parse_xml"]

MAX_BYTES = 4 * 1024 * 1024
MAX_DEPTH = 64
MAX_ELEMENTS = 200_000


class XmlError(ValueError):
    """The document is not acceptable XML; ``line`` says where."""

    def __init__(self, message: str, line: int = 0) -> None:
        super().__init__(message)
        self.message = message
        self.line = line


class UnsafeXml(XmlError):
    """The document uses a feature we refuse (DTD, entities, external references, size)."""


@dataclass(eq=False)
class Node:
    """One element: local tag name, attributes (local names), text, children, line, and the
    namespace URI it was in ("" when none), so a writer can give a file back as it came."""

    tag: str
    attrib: dict[str, str]
    line: int
    children: list[Node] = field(default_factory=list)
    text: str = ""
    tail: str = ""
    ns: str = ""

    def find(self, tag: str) -> Node | None:
        for child in self.children:
            if child.tag == tag:
                return child
        return None

    def findall(self, tag: str) -> list[Node]:
        return [child for child in self.children if child.tag == tag]

    def text_of(self, tag: str) -> str | None:
        """The stripped text of ``<tag><text>..</text></tag>`` or ``<tag>..</tag>``."""
        child = self.find(tag)
        if child is None:
            return None
        inner = child.find("text")
        return (inner.text if inner is not None else child.text).strip()


def _local(name: str) -> str:
    return name.rsplit(" ", 1)[-1]


def _namespace(name: str) -> str:
    return name.rsplit(" ", 1)[0] if " " in name else ""


def parse_xml(data: bytes | str, *, max_bytes: int = MAX_BYTES) -> Node:
    """Parse a document into Nodes; raises XmlError / UnsafeXml with the line of the problem.

    Bytes are decoded by the XML declaration's encoding (UTF-8, UTF-16, ISO-8859-1, other
    single-byte code pages), as other Petri-net tools write them.
    """
    raw = data.encode("utf-8") if isinstance(data, str) else data
    if len(raw) > max_bytes:
        raise UnsafeXml(f"document is {len(raw)} bytes, the limit is {max_bytes}")
    parser = expat.ParserCreate(namespace_separator=" ")
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.buffer_text = True  # one text callback per run of text, not per line
    stack: list[Node] = []
    root: list[Node] = []
    count = 0
    names: dict[str, tuple[str, str]] = {}  # "uri local" -> (local, uri); tags repeat a lot

    def split(name: str) -> tuple[str, str]:
        parts = names.get(name)
        if parts is None:
            parts = names[name] = (_local(name), _namespace(name))
        return parts

    def refuse(what: str) -> None:
        raise UnsafeXml(f"{what} is not allowed", parser.CurrentLineNumber)

    def start(name: str, attrs: dict[str, str]) -> None:
        nonlocal count
        count += 1
        if count > MAX_ELEMENTS:
            refuse(f"more than {MAX_ELEMENTS} elements")
        if len(stack) >= MAX_DEPTH:
            refuse(f"nesting deeper than {MAX_DEPTH}")
        tag, ns = split(name)
        node = Node(
            tag,
            {split(k)[0]: v for k, v in attrs.items()} if attrs else {},
            parser.CurrentLineNumber,
            ns=ns,
        )
        if stack:
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)

    def end(name: str) -> None:
        stack.pop()

    def chars(text: str) -> None:
        if stack:
            node = stack[-1]
            if node.children:
                node.children[-1].tail += text
            else:
                node.text += text

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.StartDoctypeDeclHandler = lambda *a: refuse("a DTD (DOCTYPE)")
    parser.EntityDeclHandler = lambda *a: refuse("an entity declaration")
    parser.UnparsedEntityDeclHandler = lambda *a: refuse("an unparsed entity")
    parser.ExternalEntityRefHandler = lambda *a: refuse("an external entity reference")  # type: ignore[assignment,return-value]
    try:
        parser.Parse(raw, True)
    except expat.ExpatError as exc:
        raise XmlError(expat.errors.messages[exc.code], exc.lineno) from None
    if not root:
        raise XmlError("empty document", 1)
    return root[0]
