"""Visitor arrivals for a planned day: a profile (tour requests per hour) drawn into a seeded
list of requests, each with how many points its visitors follow before they stop
(docs/planning.md, "The profile")."""

from __future__ import annotations

import random
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from guidebot.site.schema import Site

__all__ = ["Pace", "PlanError", "Profile", "Request", "draw", "load_profile", "parse_profile"]


class PlanError(ValueError):
    """A profile, a recording or an option the planner cannot use; the text says why."""


@dataclass(frozen=True, slots=True)
class Pace:
    """Real over nominal seconds, for legs and for explanations: the two factors the ETA model
    learns from a running fleet (1.0: as predicted)."""

    move: float = 1.0
    talk: float = 1.0


@dataclass(frozen=True, slots=True)
class Request:
    """One tour request: when (seconds from the day's start), which tour, and how many of its
    points the visitors follow (the tour ends after that point's explanation)."""

    at: float
    tour: str
    follow: int
    ref: str = ""
    """The recorded task's id (a recorded day), else empty."""


@dataclass(frozen=True, slots=True)
class Profile:
    name: str
    start_hour: float
    hours: list[dict[str, int]]
    """hours[h]: tour id -> requests in hour h of the day."""
    stop_following: float
    """Share of visitors who answer "no" at each "continue the tour?"."""
    patience_min: float | None
    """A visitor still waiting for a robot this long leaves (abandoned); None: never."""
    queue_limit: int | None
    """A request is refused when this many already wait; None: never."""
    spacing: str
    """"random" (uniform in the hour, seeded) or "even" (evenly spread in the hour)."""
    seed: int
    pace: Pace = Pace()
    """How much slower than nominal the fleet's legs and explanations run."""


_KEYS = {
    "pace",
    "name",
    "start_hour",
    "hours",
    "tours",
    "stop_following",
    "patience_min",
    "queue_limit",
    "spacing",
    "seed",
}


def _number(data: dict[str, Any], key: str, default: float | None, low: float, high: float) -> Any:
    value = data.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
        raise PlanError(f"profile: {key} must be a number from {low:g} to {high:g} (got {value!r})")
    return value


def parse_profile(data: Any, site: Site) -> Profile:
    """A profile checked against ``site``: every tour it names must exist there."""
    if not isinstance(data, dict):
        raise PlanError("profile: expected a mapping with 'hours' (see docs/planning.md)")
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise PlanError(f"profile: unknown key(s) {', '.join(unknown)}; known: {sorted(_KEYS)}")
    tours = data.get("tours")
    shares: dict[str, float] = {}
    if tours is not None:
        if not isinstance(tours, dict) or not tours:
            raise PlanError("profile: tours must map tour ids to shares, e.g. {ground: 0.5}")
        for tour, share in tours.items():
            if isinstance(share, bool) or not isinstance(share, int | float) or share < 0:
                raise PlanError(f"profile: tours.{tour} must be a share >= 0 (got {share!r})")
            shares[str(tour)] = float(share)
        if sum(shares.values()) <= 0:
            raise PlanError("profile: the tour shares add up to 0")
    raw_hours = data.get("hours")
    if not isinstance(raw_hours, list) or not raw_hours:
        raise PlanError("profile: hours must be a list, one entry per hour of the day")
    hours: list[dict[str, int]] = []
    for h, entry in enumerate(raw_hours):
        if isinstance(entry, int) and not isinstance(entry, bool) and entry >= 0:
            if not shares:
                raise PlanError(f"profile: hours[{h}] is a count; give 'tours' shares to split it")
            hours.append(_split(entry, shares))
        elif isinstance(entry, dict):
            counts: dict[str, int] = {}
            for tour, n in entry.items():
                if isinstance(n, bool) or not isinstance(n, int) or n < 0:
                    raise PlanError(f"profile: hours[{h}].{tour} must be a count >= 0 (got {n!r})")
                counts[str(tour)] = n
            hours.append(counts)
        else:
            raise PlanError(
                f"profile: hours[{h}] must be a count or a mapping tour -> count (got {entry!r})"
            )
    named = set(shares) | {t for counts in hours for t in counts}
    missing = sorted(t for t in named if site.tour(t) is None)
    if missing:
        known = ", ".join(t.id for t in site.tours) or "none"
        raise PlanError(f"profile: unknown tour(s) {', '.join(missing)}; the site's tours: {known}")
    spacing = data.get("spacing", "random")
    if spacing not in ("random", "even"):
        raise PlanError(f"profile: spacing must be random or even (got {spacing!r})")
    seed = data.get("seed", 1)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise PlanError(f"profile: seed must be an integer (got {seed!r})")
    limit = _number(data, "queue_limit", None, 1, 1_000_000)
    pace = data.get("pace") or {}
    if not isinstance(pace, dict) or set(pace) - {"move", "talk"}:
        raise PlanError(f"profile: pace must be {{move: FACTOR, talk: FACTOR}} (got {pace!r})")
    factors = {k: float(_number(pace, k, 1.0, 0.1, 10.0)) for k in ("move", "talk")}
    return Profile(
        name=str(data.get("name") or "profile"),
        start_hour=float(_number(data, "start_hour", 9, 0, 23)),
        hours=hours,
        stop_following=float(_number(data, "stop_following", 0.0, 0.0, 1.0)),
        patience_min=_number(data, "patience_min", None, 0.1, 24 * 60),
        queue_limit=None if limit is None else int(limit),
        spacing=str(spacing),
        seed=seed,
        pace=Pace(**factors),
    )


def load_profile(path: str | Path, site: Site) -> Profile:
    """Read a profile YAML file (PlanError if it is missing, not YAML or wrong)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise PlanError(f"profile {path}: {exc.strerror or exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise PlanError(f"profile {path}: not YAML ({exc})") from None
    return parse_profile(data, site)


def _split(total: int, shares: dict[str, float]) -> dict[str, int]:
    """``total`` requests split by ``shares`` (largest remainders, so the counts add up)."""
    weight = sum(shares.values())
    exact = {t: total * s / weight for t, s in shares.items()}
    counts = {t: int(v) for t, v in exact.items()}
    left = total - sum(counts.values())
    for tour in sorted(exact, key=lambda t: counts[t] - exact[t])[:left]:
        counts[tour] += 1
    return counts


def draw(profile: Profile, site: Site) -> list[Request]:
    """The day's requests in time order, the same for every fleet size and policy (seeded)."""
    rng = random.Random(profile.seed)
    out: list[Request] = []
    for h, counts in enumerate(profile.hours):
        times: list[tuple[float, str]] = []
        for tour, n in counts.items():
            for k in range(n):
                offset = (k + 0.5) * 3600 / n if profile.spacing == "even" else rng.random() * 3600
                times.append((h * 3600 + offset, tour))
        for at, tour in sorted(times):
            out.append(Request(at, tour, follow_count(rng, site, tour, profile.stop_following)))
    out.sort(key=lambda r: r.at)
    return out


def follow_count(rng: random.Random, site: Site, tour: str, stop_share: float) -> int:
    """How many points a group follows: each "continue?" (before every point but the first)
    is a "no" with probability ``stop_share``."""
    found = site.tour(tour)
    points = len(found.points) if found else 1
    follow = 1
    while follow < points and (stop_share <= 0 or rng.random() >= stop_share):
        follow += 1
    return follow
