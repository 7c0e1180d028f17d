"""Site files: YAML in (with line numbers for every error), YAML out.

A site is read with libyaml's event parser (C, one short call per event) but its node tree is
composed by PyYAML's Python composer: libyaml's own composer builds the whole tree of a
10 000-node site in one native call (about 50 ms without letting any other thread run, the
server's event loop included). The tree and the data are then freed a piece at a time
(guidebot/site/dispose.py). The result and the errors (with their lines) are those of
``yaml.CSafeLoader``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import orjson
import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from guidebot.site import jsonio
from guidebot.site.dispose import dispose
from guidebot.site.schema import Site
from guidebot.site.validate import SiteInvalid, SiteIssue, validate_site

__all__ = [
    "MAX_SITE_BYTES",
    "dump_site",
    "load_site_file",
    "load_site_text",
    "load_yaml",
    "yaml_as_json",
]

MAX_SITE_BYTES = 5_000_000
MAX_ALIASES = 100
"""Aliases (``*name``) a site may use: enough for shared settings, too few for an alias bomb
(nested aliases that expand to billions of nodes once validated)."""
MAX_DEPTH = 32
"""Nesting of mappings and lists; a site needs about 6."""


def _libyaml_parser() -> Any:
    """libyaml's parser, when PyYAML was built with it (its wheels are)."""
    try:
        from yaml import cyaml
    except ImportError:  # pragma: no cover
        return None
    return getattr(cyaml, "CParser", None)


_CParser: Any = _libyaml_parser()


if _CParser is not None:

    class SlicedLoader(Composer, _CParser, SafeConstructor, Resolver):  # type: ignore[misc]
        """``yaml.CSafeLoader`` with the Python composer first in line (CParser has its own
        ``get_single_node``/``compose_node``, one native call for the whole tree); the
        composer pulls libyaml's events one at a time."""

        def __init__(self, stream: str | bytes) -> None:
            _CParser.__init__(self, stream)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)

        def get_single_data(self) -> Any:
            box = [self.get_single_node()]
            try:
                return self.construct_document(box[0]) if box[0] is not None else None
            finally:
                dispose(box)  # the node tree: some 300 000 objects

    LOADER: Any = SlicedLoader
else:  # no libyaml: the pure-Python loader lets other threads run anyway
    LOADER = yaml.SafeLoader


def load_yaml(text: str) -> Any:
    """``yaml.load(text, Loader=yaml.CSafeLoader)`` (same data, same errors) without any
    native call that holds the GIL for long."""
    try:
        return yaml.load(text, Loader=LOADER)  # a safe loader: plain data only
    except yaml.composer.ComposerError:
        # Undefined alias, duplicate anchor, several documents: libyaml words these itself.
        return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def _check_structure(text: str, loader_class: Any) -> None:
    """Refuse alias bombs and absurd nesting before building any object (located errors)."""
    aliases = depth = 0
    for event in yaml.parse(text, Loader=loader_class):
        problem = None
        if isinstance(event, yaml.AliasEvent):
            aliases += 1
            problem = f"more than {MAX_ALIASES} aliases" if aliases > MAX_ALIASES else None
        elif isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            problem = f"nested deeper than {MAX_DEPTH} levels" if depth > MAX_DEPTH else None
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
        if problem is not None:
            mark = event.start_mark
            raise SiteInvalid(
                [SiteIssue("(document)", problem, mark.line + 1 if mark is not None else None)]
            )


def _line_finder(root: yaml.Node | None) -> Any:
    """Map a loc path (keys and indexes) to the 1-based line of the deepest node found."""

    def find(loc: tuple[str | int, ...]) -> int | None:
        node = root
        if node is None:
            return None
        line = node.start_mark.line + 1
        for part in loc:
            nxt: yaml.Node | None = None
            if isinstance(node, yaml.MappingNode) and isinstance(part, str):
                for key, value in node.value:
                    if isinstance(key, yaml.ScalarNode) and key.value == part:
                        nxt = value
                        line = key.start_mark.line + 1
                        break
            elif isinstance(node, yaml.SequenceNode) and isinstance(part, int):
                if 0 <= part < len(node.value):
                    nxt = node.value[part]
            if nxt is None:
                break
            node = nxt
            line = max(line, node.start_mark.line + 1)
        return line

    return find


def load_site_text(text: str, parsed: bytes | None = None) -> Site:
    """Parse a YAML site; raises SiteInvalid listing every problem with its line.

    ``parsed``: the same document already read as JSON by ``yaml_as_json`` (in another
    process); it is only decoded and validated here."""
    if len(text.encode()) > MAX_SITE_BYTES:
        raise SiteInvalid([SiteIssue("(document)", f"larger than {MAX_SITE_BYTES} bytes")])
    loader_class = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when present
    if parsed is not None:
        data = jsonio.loads(parsed)
    else:
        try:
            _check_structure(text, loader_class)
            data = load_yaml(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = mark.line + 1 if mark is not None else None
            raise SiteInvalid([SiteIssue("(document)", f"not valid YAML: {exc}", line)]) from None
    if not isinstance(data, dict):
        raise SiteInvalid([SiteIssue("(document)", "a site file is a mapping at top level", 1)])

    finder: list[Any] = []

    def lines(loc: tuple[str | int, ...]) -> int | None:
        # Only a refused file pays for the node tree that gives line numbers (built once).
        if not finder:
            finder.append(_line_finder(yaml.compose(text, Loader=loader_class)))
        return finder[0](loc)  # type: ignore[no-any-return]

    box = [data]
    del data
    try:
        return validate_site(box[0], lines=lines)
    finally:
        dispose(box)


def yaml_as_json(text: str) -> bytes | None:
    """The YAML site document as JSON (to be read with ``load_site_text(text, parsed)``), or
    None when ``load_site_text`` must read it itself: a file it would refuse (alias bomb,
    nesting, broken YAML, not a mapping: the errors and their lines come from there) or data
    that JSON would not carry exactly (dates, sets, non-string keys, NaN).

    Meant for a worker process, where libyaml's one-call composer holds no one's GIL."""
    try:
        _check_structure(text, getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        if not isinstance(data, dict):
            return None
        raw = orjson.dumps(data, option=orjson.OPT_PASSTHROUGH_DATETIME)
        return raw if orjson.loads(raw) == data else None
    except Exception:  # whatever it is, load_site_text decides (and words the error)
        return None


def load_site_file(path: str | Path) -> Site:
    return load_site_text(Path(path).read_text(encoding="utf-8"))


def dump_site(site: Site) -> str:
    """YAML of a site, defaults left out so hand-written files stay short."""
    data = site.model_dump(mode="json", exclude_defaults=True)
    data = {"name": site.name, **data}
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(data, Dumper=dumper, sort_keys=False, allow_unicode=True, width=100)
