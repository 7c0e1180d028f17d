"""What PNML files from different tools look like, in one place: the net types they declare and
how they write a label's value. Shared by the reader (``pnml``) and the writer (``pnml_writer``).

Real files differ from the standard's examples: ProM writes the core-model type and no
namespace, WoPeD an old type URI and its own namespace, PIPE ``type="P/T net"`` with values in
``<value>Default,2</value>``; TINA and the Model Checking Contest write the standard.
"""

from __future__ import annotations

from petri_nets.xmlsafe import Node

__all__ = [
    "PNML_NS",
    "PTNET_TYPE",
    "TOOL",
    "TOOL_VERSION",
    "is_pt_type",
    "label_value",
    "parse_count",
    "text_of",
]

PNML_NS = "http://www.pnml.org/version-2009/grammar/pnml"
PTNET_TYPE = "http://www.pnml.org/version-2009/grammar/ptnet"
TOOL = "guidebot"
TOOL_VERSION = "1"

# The last part of a type URI (lower case) that means a place/transition net: the standard's
# ptnet and core model (ProM), the 2004 drafts' ptNet/ptNetb (WoPeD, LoLA), and the bare names
# PIPE and TAPAAL write ("P/T net") or pnapi ("PTNet").
_PT_TYPES = frozenset({"ptnet", "ptnetb", "pnmlcoremodel", "coremodel", "p/tnet"})


def is_pt_type(net_type: str) -> bool:
    """True for any spelling of a place/transition (or core-model) net type; "" counts too."""
    squeezed = net_type.strip().lower().replace(" ", "")
    if not squeezed or squeezed in _PT_TYPES:
        return True
    return squeezed.rstrip("/").rsplit("/", 1)[-1].removesuffix(".pntd") in _PT_TYPES


def text_of(holder: Node) -> str:
    """A label element's stripped value: ``<text>`` (standard), ``<value>`` (PIPE), or the text
    written directly inside."""
    inner = holder.find("text") or holder.find("value") or holder
    return inner.text.strip()


def label_value(node: Node, tag: str) -> str | None:
    """The value of ``node``'s label ``tag``, None when it has no such label."""
    holder = node.find(tag)
    return None if holder is None else text_of(holder)


def parse_count(text: str) -> int | None:
    """A marking or weight: ``3`` (standard), ``Default,3`` (PIPE: token class, count; more
    classes may follow and must all be 0); None when it is not a natural number."""
    text = text.strip()
    if text.isdigit():
        return int(text)
    parts = [part.strip() for part in text.split(",")]
    if len(parts) < 2 or len(parts) % 2:
        return None
    counts = dict(zip(parts[::2], parts[1::2], strict=True))
    if not all(n.isdigit() for n in counts.values()):
        return None
    if any(int(n) for name, n in counts.items() if name != "Default"):
        return None  # coloured tokens: not a place/transition net
    return int(counts.get("Default", "0"))
