"""A folder of PNML nets, parsed and compiled once, recompiled when a file changes.

Starting a net costs a dict lookup and one ``stat`` (to notice edits): no XML at start. A file
edited into an invalid net keeps the last good version running and reports the problems
(hot reload = validate, then swap).

Nets published from the editor (docs/nets.md, "Publish") are installed in memory with
``install``: they stand in front of the folder's net of the same name (or add a new one). The
table of installed nets is replaced, never changed, by each install: a running task holds the
table it started with (``installed``) and starts its sub-nets from it (``get(name, pin)``), so
a tour running when a net is published finishes on the versions it began with, and the next
task starts on the new ones.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from petri_nets.compiled import CompiledNet, compile_net
from petri_nets.model import Problem
from petri_nets.pnml import read_pnml, read_pnml_file
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
        self.installed: Mapping[str, CompiledNet] = {}
        """Nets published from the editor, by name (replaced whole by each install)."""
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

    def install(self, nets: dict[str, bytes | str]) -> list[Problem]:
        """Put published nets (name -> PNML text) in front of the folder's, all or none.

        Each is read and validated as a file is; then the library with them in place must not
        gain a cross-net problem (a sub-net missing, a caller's parameters no longer fitting).
        Returns the problems (nothing changed) or [] (every net installed)."""
        prepared = self.prepare(nets)
        return prepared if isinstance(prepared, list) else self.commit(prepared)

    def prepare(self, nets: dict[str, bytes | str]) -> dict[str, CompiledNet] | list[Problem]:
        """Read, validate and compile published nets without touching the library (safe in a
        thread): the compiled nets, or every problem."""
        compiled: dict[str, CompiledNet] = {}
        problems: list[Problem] = []
        for name, data in nets.items():
            doc, found = read_pnml(data, f"{name}.pnml")
            if doc is not None:
                found += validate(doc)
            if doc is None or found:
                problems += found
            else:
                compiled[name] = compile_net(doc, name)
        return sorted(problems) if problems else compiled

    def commit(self, nets: Mapping[str, CompiledNet]) -> list[Problem]:
        """Install prepared nets unless the library gains a cross-net problem with them
        (returned; nothing changed then)."""
        before = set(map(str, self.problems()))
        table = {**self.installed, **nets}
        added = [p for p in self._cross_problems(table) if str(p) not in before]
        if not added:
            self.installed = table
        return added

    def problems_of(self, name: str) -> list[Problem]:
        entry = self._entries.get(name)
        return list(entry.problems) if entry else []

    def names(self) -> list[str]:
        folder = {name for name, e in self._entries.items() if e.net is not None}
        return sorted(folder | set(self.installed))

    def _nets(self, installed: Mapping[str, CompiledNet]) -> dict[str, CompiledNet]:
        """The nets a start finds: installed ones in front of the folder's."""
        nets = {name: e.net for name, e in self._entries.items() if e.net is not None}
        return {**nets, **installed}

    def problems(self) -> list[Problem]:
        """Problems of every file, plus cross-net ones (unknown sub-nets, wrong parameters)."""
        return self._cross_problems(self.installed)

    def _cross_problems(self, installed: Mapping[str, CompiledNet]) -> list[Problem]:
        out = [p for name, e in self._entries.items() if name not in installed for p in e.problems]
        nets = self._nets(installed)
        for net in nets.values():
            doc = net.doc
            for place in doc.places:
                action = place.action
                if action is None or action.kind != "run" or not action.net:
                    continue
                child = nets.get(action.net)
                if child is None:
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
                    child.doc, body, line=action.line, file=doc.file, caller=f"place {place.id}"
                )
        return sorted(out)

    def get(self, name: str, pin: Mapping[str, CompiledNet] | None = None) -> CompiledNet:
        """The compiled net: an installed one (from ``pin``, the ``installed`` table a task
        started with, if given), else the folder's, re-read first if its file changed."""
        installed = self.installed if pin is None else pin
        net = installed.get(name)
        if net is not None:
            return net
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
