"""The editors' draft of the site: edits land here, ``publish`` makes it the live site.

One shared draft with a revision number (optimistic concurrency): an editor saves with the
revision it started from; if someone saved in between, the save is refused (StaleDraft) and
nothing is lost on either side. A draft may be invalid (that is what editing looks like); its
problems are reported with every save, and publishing an invalid draft is refused.
"""

from __future__ import annotations

import copy
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from backend.site.offloop import off_loop
from backend.site.service import SiteService
from guidebot.site.bulk import dump_site_doc
from guidebot.site.schema import Site
from guidebot.site.validate import SiteInvalid, SiteIssue, validate_site

__all__ = ["DraftState", "SiteDrafts", "StaleDraft", "check_document"]

KEEP_REVISIONS = 50
"""Draft revisions kept in memory as merge bases for a stale editor."""


class StaleDraft(Exception):
    """The draft (or the live site) changed since the editor loaded it."""

    def __init__(self, message: str, current: DraftState) -> None:
        super().__init__(message)
        self.current = current


@dataclass
class DraftState:
    data: dict[str, Any]
    revision: int
    base_version: int
    updated_by: str = ""
    updated_at: float = field(default_factory=time.time)

    def as_dict(self) -> dict[str, Any]:
        return {
            "draft": self.data,
            "revision": self.revision,
            "base_version": self.base_version,
            "updated_by": self.updated_by,
            "updated_at": self.updated_at,
        }


class DraftStore(Protocol):
    async def load_draft(self) -> Any: ...

    async def save_draft(
        self, data: dict[str, Any], *, revision: int, base_version: int, by: str
    ) -> None: ...


def check_document(data: Any) -> list[SiteIssue]:
    """Every problem of a site document: the checks of ``guidebot site check``."""
    try:
        validate_site(data)
    except SiteInvalid as exc:
        return exc.issues
    return []


Secure = Callable[[Site], Site]


class SiteDrafts:
    def __init__(self, sites: SiteService, store: DraftStore | None = None) -> None:
        self.sites = sites
        self.store = store
        self.state = DraftState(sites.site.model_dump(mode="json"), 0, sites.version)
        self._revisions: OrderedDict[int, dict[str, Any]] = OrderedDict()

    async def load(self) -> None:
        """The stored draft, if any; else a fresh copy of the live site."""
        row = await self.store.load_draft() if self.store is not None else None
        if row is not None:
            self.state = DraftState(
                row.data, row.revision, row.base_version, row.updated_by, row.updated_at
            )
        self._remember()

    def revision_data(self, revision: int) -> dict[str, Any] | None:
        """A recent revision's document (the base of a three-way merge), or None."""
        data = self._revisions.get(revision)
        return copy.deepcopy(data) if data is not None else None

    def _remember(self) -> None:
        self._revisions[self.state.revision] = copy.deepcopy(self.state.data)
        while len(self._revisions) > KEEP_REVISIONS:
            self._revisions.popitem(last=False)

    def _check_revision(self, revision: int) -> None:
        s = self.state
        if revision != s.revision:
            when = time.strftime("%H:%M:%S", time.localtime(s.updated_at))
            raise StaleDraft(
                f"the draft was changed by {s.updated_by or 'someone'} at {when} "
                f"(revision {s.revision}; your edits are based on revision {revision}): "
                "reload it, or merge your changes into it",
                s,
            )

    async def _store(self, data: dict[str, Any], base_version: int, by: str) -> DraftState:
        before = self.state
        self.state = mine = DraftState(data, before.revision + 1, base_version, by)
        self._remember()
        if self.store is not None:
            try:
                await self.store.save_draft(
                    data, revision=mine.revision, base_version=base_version, by=by
                )
            except BaseException:
                # Not stored (e.g. UnstorableJson): the draft stays as it was.
                self._revisions.pop(mine.revision, None)
                if self.state is mine:
                    self.state = before
                raise
        return mine

    async def save(self, data: dict[str, Any], *, revision: int, by: str) -> DraftState:
        """Replace the draft; StaleDraft if ``revision`` is not the current one."""
        self._check_revision(revision)
        return await self._store(data, self.state.base_version, by)

    async def reset(self, *, by: str) -> DraftState:
        """Throw the draft away: a fresh copy of the live site."""
        return await self._store(await self._live_doc(), self.sites.version, by)

    async def _live_doc(self) -> dict[str, Any]:
        return await off_loop(dump_site_doc, self.sites.site)

    async def publish(self, *, revision: int, by: str, secure: Secure, note: str = "") -> int:
        """Make the draft live (a new kept version); SiteInvalid with every problem if broken,
        StaleDraft if the draft or the live site moved since the editor loaded them."""
        self._check_revision(revision)
        if self.state.base_version != self.sites.version:
            raise StaleDraft(
                f"the live site is at version {self.sites.version} (published by "
                f"{self.sites.published_by or 'someone'}) but this draft was started from "
                f"version {self.state.base_version}: start a new draft from the live site",
                self.state,
            )
        site = await off_loop(secure, await self.sites.validate(self.state.data))
        await self.sites.replace(site, by=by, note=note)
        await self._store(await self._live_doc(), self.sites.version, by)
        return self.sites.version

    async def rollback(self, data: dict[str, Any], *, version: int, by: str, secure: Secure) -> int:
        """Publish a kept version's document again (as a new version); the draft follows."""
        site = await off_loop(secure, await self.sites.validate(data))
        await self.sites.replace(site, by=by, note=f"rollback to version {version}")
        await self._store(await self._live_doc(), self.sites.version, by)
        return self.sites.version
