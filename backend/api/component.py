"""What the server brain (backend/brain.py) is made of: the site as first stored, robot
tokens, the hub messages the event log keeps, robot link announcements, offline locks."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from fastapi import FastAPI

from backend.auth import Role, TokenStore, is_digest, token_digest
from backend.db import DbStore
from backend.settings import published_tokens, weak_secret
from backend.site.service import EMPTY_SITE, SiteService
from backend.traffic.manager import TrafficManager
from guidebot.payloads.tasks import RobotLink
from guidebot.site.schema import Site
from guidebot.site.validate import validate_site
from guidebot.site.yamlio import load_site_file

__all__ = [
    "LOGGED_BROADCASTS",
    "LOGGED_TYPES",
    "InsecureSite",
    "hash_robot_tokens",
    "watch_offline_locks",
    "weak_robot_tokens",
]

log = logging.getLogger(__name__)

LOGGED_TYPES = (
    "battery_low",
    "battery_panic",
    "robot_fault",
    "area_yield",
    "robot_connected",
    "robot_disconnected",
    "call_elevator",  # the reports' elevator waits: a call until its elevator_in_position
)
"""Hub messages copied into the event log (task changes and lock changes are logged directly)."""
LOGGED_BROADCASTS = ("door_opened", "door_closed", "elevator_in_position", "node_reached")
"""Also logged, broadcasts only (not the replies to one requester): the fleet's safety
invariants are checked on them (guidebot/invariants.py, docs/server.md "Events")."""


class InsecureSite(RuntimeError):
    """A production start with robot tokens anyone can know."""


def hash_robot_tokens(site: Site) -> Site:
    """The site as stored and served: robot tokens replaced by their SHA-256 digests."""
    if all(is_digest(r.token) for r in site.robots):
        return site
    robots = [r.model_copy(update={"token": token_digest(r.token)}) for r in site.robots]
    return site.model_copy(update={"robots": robots})


def weak_robot_tokens(site: Site) -> list[str]:
    """Why robots' tokens are not production secrets (plain tokens: length and defaults;
    digests: the digests of the tokens published with GuideBot)."""
    published = {token_digest(t) for t in published_tokens()}
    problems = []
    for robot in site.robots:
        if is_digest(robot.token):
            if robot.token in published:
                problems.append(
                    f"robot {robot.name!r}: its token is a default published with GuideBot"
                )
        elif why := weak_secret(robot.token):
            problems.append(f"robot {robot.name!r}: its token {why}")
    return problems


async def _initial_site(app: FastAPI, store: DbStore) -> tuple[Site, int]:
    """The database wins; a site file is imported only into an empty database."""
    stored = await store.load_site()
    if stored is not None:
        version, data = stored
        site = validate_site(data)
        hashed = hash_robot_tokens(site)
        if hashed is not site:  # stored before tokens were hashed: store the digests now
            version = await store.save_site(hashed.model_dump(mode="json"))
        return hashed, version
    path = getattr(app.state.settings, "site", None)
    site = load_site_file(path) if path else validate_site(EMPTY_SITE)
    site = hash_robot_tokens(site)
    version = await store.save_site(site.model_dump(mode="json"))
    return site, version


def _sync_robot_tokens(tokens: TokenStore, site: Site, known: dict[str, str]) -> None:
    """Robots' token digests come from the site: add new ones, drop removed or changed ones."""
    wanted = {token_digest(r.token): r.name for r in site.robots}
    for digest in list(known):
        if wanted.get(digest) != known[digest]:
            tokens.remove(digest)
            del known[digest]
    for digest, name in wanted.items():
        if digest not in known:
            tokens.add(digest, name, Role.ROBOT)
            known[digest] = name


def announce_links(
    hub: Any, accept: Callable[[Any], bool], *, name: str = "link_watcher"
) -> Callable[[], None]:
    """Publish robot_connected / robot_disconnected when the hub link of a robot that ``accept``
    takes comes up or goes (a hub connection event, no polling). Returns the unsubscribe
    function."""
    endpoint = hub.endpoint(name)

    def changed(client: Any, connected: bool) -> None:
        if client.role is not Role.ROBOT or not accept(client):
            return
        kind = "robot_connected" if connected else "robot_disconnected"
        endpoint.publish(kind, RobotLink(robot=client.name))

    unsubscribe = hub.on_connection(changed)

    def stop() -> None:
        unsubscribe()
        endpoint.close()

    return stop


def announce_robot_links(hub: Any, sites: SiteService) -> Callable[[], None]:
    """The links of the robots the site names (a robot the site does not know is refused)."""
    return announce_links(hub, lambda client: sites.site.robot(client.name) is not None)


async def watch_offline_locks(
    traffic: TrafficManager, grace_s: float, period_s: float = 1.0
) -> None:
    """Decide, once a second, about locks whose holder has been offline for ``grace_s``."""
    while True:
        await asyncio.sleep(period_s)
        try:
            traffic.check_offline_locks(grace_s)
        except Exception:
            log.exception("offline lock check failed")
