"""The robots' tokens a site names: stored and served as SHA-256 digests, refused in production
when anyone can know them, and kept in step with the server's token store as the site changes."""

from __future__ import annotations

from backend.auth import Role, TokenStore, is_digest, token_digest
from backend.settings import published_tokens, weak_secret
from guidebot.site.schema import Site
from guidebot.site.validate import SiteInvalid, SiteIssue

__all__ = [
    "InsecureSite",
    "hash_robot_tokens",
    "secure_robot_tokens",
    "sync_robot_tokens",
    "weak_robot_tokens",
]


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


def secure_robot_tokens(site: Site, *, development: bool) -> Site:
    """A site about to be stored (an upload, a publish): robot tokens hashed; outside
    development, weak ones refused (SiteInvalid). Run it off the loop: with a thousand robots,
    hashing and copying them takes 10-15 ms."""
    if not development and (problems := weak_robot_tokens(site)):
        raise SiteInvalid([SiteIssue("robots", p) for p in problems])
    return hash_robot_tokens(site)


def sync_robot_tokens(tokens: TokenStore, site: Site, known: dict[str, str]) -> None:
    """Robots' token digests come from the site: add new ones, drop removed or changed ones.
    ``known`` (digest to robot name) is the caller's record of what it added before."""
    wanted = {token_digest(r.token): r.name for r in site.robots}
    for digest in list(known):
        if wanted.get(digest) != known[digest]:
            tokens.remove(digest)
            del known[digest]
    for digest, name in wanted.items():
        if digest not in known:
            tokens.add(digest, name, Role.ROBOT)
            known[digest] = name
