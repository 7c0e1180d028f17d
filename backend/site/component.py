"""The site editor's services as one app component (after the server brain): the shared
draft and the rollout of published versions to the robots. Listed in backend.app.COMPONENTS."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from backend.auth import Role
from backend.site.draft import SiteDrafts
from backend.site.rollout import RolloutTracker

__all__ = ["site_editor"]


@contextlib.asynccontextmanager
async def site_editor(app: FastAPI) -> AsyncIterator[None]:
    hub = app.state.hub
    sites = app.state.sites
    drafts = SiteDrafts(sites, app.state.store)
    await drafts.load()

    def connected_robots() -> set[str]:
        return {c.name for c in hub.clients.values() if c.role is Role.ROBOT}

    endpoint = hub.endpoint("site_editor")
    rollout = RolloutTracker(endpoint, sites, connected_robots)
    await rollout.start()
    sites.on_change(rollout.on_site)
    app.state.site_drafts = drafts
    app.state.site_rollout = rollout
    try:
        yield
    finally:
        await rollout.stop()
        endpoint.close()
