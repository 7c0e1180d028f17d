"""A folder of PNML nets, parsed and compiled once, recompiled when a file changes.

Starting a net costs a dict lookup and one ``stat`` (to notice edits): no XML at start. A file
edited into an invalid net keeps the last good version running and reports the problems
(hot reload = validate, then swap).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

from petri_nets.compiled import CompiledNet, compile_net
from petri_nets.model import Problem
from petri_nets.pnml import read_pnml_file
from petri_nets.templates import compile_json
from petri_nets.validate import check_params, validate

__all__ = ["DEFAULT_LIBRARY", "NetLibrary", "UnknownNet", "load_net"]

log = logging.getLogger(__name__)

DEFAULT_LIBRARY = Path(__file__).with_name("library")


class UnknownNet(KeyError):
    """No net of that name in the library."""


def load_net(path: str | Path, name: str | None = None) -> tuple[CompiledNet | None, list[Problem]]:
    """Read, validate and compile one file; the net is None when there are problems."""
    doc, problems = read_pnml_file(path)
    if doc is None:
        return None, problems
    problems += validate(doc)
    if problems:
        return None, sorted(problems)
    return compile_net(doc, name or Path(path).stem), []


@dataclass
class _Entry:
    path: Path
    stamp: tuple[int, int]
    net: CompiledNet | None
    problems: list[Problem] = field(default_factory=list)


class NetLibrary:
    """Nets by name (the file stem): ``library.get("give_tour")``."""

    def __init__(self, folder: str | Path = DEFAULT_LIBRARY, *, watch: bool = True) -> None:
        self.folder = Path(folder)
        self.watch = watch
        self._entries: dict[str, _Entry] = {}
        self.reload()

    def reload(self) -> list[Problem]:
        """(Re)load every file of the folder; returns all problems."""
        if not self.folder.is_dir():
            raise FileNotFoundError(f"net library {self.folder} is not a folder")
        seen = set()
        for path in sorted(self.folder.glob("*.pnml")):
            seen.add(path.stem)
            self._load(path.stem, path)
        for gone in set(self._entries) - seen:
            del self._entries[gone]
        return self.problems()

    def _load(self, name: str, path: Path) -> _Entry:
        try:
            st = os.stat(path)
        except OSError:
            st = None
        stamp = (st.st_mtime_ns, st.st_size) if st else (0, 0)
        net, problems = load_net(path, name)
        old = self._entries.get(name)
        if net is None and old is not None and old.net is not None:
            log.error(
                "net %s: keeping the last good version; %s", name, "; ".join(map(str, problems))
            )
            net = old.net
        entry = _Entry(path, stamp, net, problems)
        self._entries[name] = entry
        return entry

    def add_file(self, path: str | Path) -> str:
        """Add a net that lives outside the folder (``guidebot petri run FILE``); its name."""
        path = Path(path)
        self._load(path.stem, path)
        return path.stem

    def problems_of(self, name: str) -> list[Problem]:
        entry = self._entries.get(name)
        return list(entry.problems) if entry else []

    def names(self) -> list[str]:
        return sorted(name for name, e in self._entries.items() if e.net is not None)

    def problems(self) -> list[Problem]:
        """Problems of every file, plus cross-net ones (unknown sub-nets, wrong parameters)."""
        out = [p for e in self._entries.values() for p in e.problems]
        for entry in self._entries.values():
            if entry.net is None:
                continue
            doc = entry.net.doc
            for place in doc.places:
                action = place.action
                if action is None or action.kind != "run" or not action.net:
                    continue
                child = self._entries.get(action.net)
                if child is None or child.net is None:
                    out.append(
                        Problem(
                            doc.file,
                            action.line,
                            f"place {place.id}: net {action.net!r} is not in the library",
                        )
                    )
                    continue
                body, _ = compile_json(action.body)
                out += check_params(
                    child.net.doc, body, line=action.line, file=doc.file, caller=f"place {place.id}"
                )
        return sorted(out)

    def get(self, name: str) -> CompiledNet:
        """The compiled net; re-read first if its file changed since it was loaded."""
        entry = self._entries.get(name)
        if entry is None:
            path = self.folder / f"{name}.pnml"
            if not self.watch or not path.is_file():
                raise UnknownNet(name)
            entry = self._load(name, path)
        elif self.watch:
            try:
                st = os.stat(entry.path)
                stamp = (st.st_mtime_ns, st.st_size)
            except OSError:
                stamp = (0, 0)
            if stamp != entry.stamp:
                entry = self._load(name, entry.path)
        if entry.net is None:
            raise UnknownNet(f"{name} (invalid: {'; '.join(map(str, entry.problems))})")
        return entry.net
