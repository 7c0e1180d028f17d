"""Server settings from the environment (prefix ``GUIDEBOT_``) and command-line flags.

Nothing is read at import time: ``Settings()`` reads the environment when it is built, so tests
pass their own instance to ``create_app(settings)``.

Outside development (``GUIDEBOT_ENVIRONMENT`` anything but ``development``) the server refuses
to start with a missing or default secret and names it (docs/security.md).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import yaml
from pydantic import BaseModel, Field, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from backend.auth import PERSON_ROLES, Role
from guidebot.paths import SITES_DIR, WEB_DIR

__all__ = [
    "DEFAULT_ADMIN_TOKEN",
    "MIN_PRODUCTION_TOKEN_LENGTH",
    "Settings",
    "StaticToken",
    "describe_errors",
    "published_tokens",
]

# Good enough on a developer's laptop, refused anywhere else (see Settings._refuse_default_secrets).
DEFAULT_ADMIN_TOKEN = "dev-admin-token"
MIN_PRODUCTION_TOKEN_LENGTH = 16
DEFAULT_SITE_DIR = "guidebot-site"
"""The site folder of a server started without a site file or ``--site-dir``."""


@cache
def published_tokens() -> frozenset[str]:
    """Tokens anyone can read in this repository: the dev admin token and the shipped sites'."""
    found = {DEFAULT_ADMIN_TOKEN}
    for path in sorted(SITES_DIR.glob("*.yaml")):
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError):
            continue
        robots = data.get("robots") if isinstance(data, dict) else None
        for robot in robots if isinstance(robots, list) else []:
            if isinstance(robot, dict) and isinstance(robot.get("token"), str):
                found.add(robot["token"])
    return frozenset(found)


def weak_secret(token: str) -> str | None:
    """Why ``token`` is not a production secret, or None if it is acceptable."""
    if token in published_tokens():
        return "is a default published with GuideBot"
    if len(token) < MIN_PRODUCTION_TOKEN_LENGTH:
        return f"is shorter than {MIN_PRODUCTION_TOKEN_LENGTH} characters"
    return None


def describe_errors(exc: ValidationError) -> str:
    """A settings error for people, without the values (they may be secrets)."""
    lines = []
    for err in exc.errors(include_url=False, include_input=False, include_context=False):
        where = ".".join(str(p) for p in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        lines.append(f"{where}: {msg}" if where else msg)
    return "\n".join(lines)


class StaticToken(BaseModel):
    """A bearer token known from configuration: who holds it and in which role."""

    token: str = Field(min_length=8)
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")
    role: Role


class Settings(BaseSettings):
    """Everything the server needs to start; ``GUIDEBOT_TOKENS`` is a JSON list of tokens."""

    model_config = SettingsConfigDict(env_prefix="GUIDEBOT_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    db_url: str = "sqlite+aiosqlite:///./guidebot.db"
    site: Path | None = None
    site_dir: Path | None = None
    """The site folder: plan and media paths are relative to it, uploads are stored in its
    ``uploads/``. Default: the site file's folder, else ./guidebot-site (see ``files_dir``)."""
    environment: str = Field(default="development", pattern=r"^[A-Za-z0-9_.-]{1,32}$")
    admin_token: str = DEFAULT_ADMIN_TOKEN
    tokens: list[StaticToken] = Field(default_factory=list)
    metrics_token: str | None = Field(default=None, min_length=8)
    """Bearer token that may only read GET /metrics (docs/metrics.md)."""
    web_dir: Path = WEB_DIR
    # Hub (docs/protocol.md): per-client outbound queue, batching and limits.
    hub_queue_size: int = Field(default=4096, ge=8)
    hub_coalesce_after: int = Field(default=256, ge=0)
    hub_batch_max: int = Field(default=512, ge=1)
    hub_linger_ms: float = Field(default=0.0, ge=0, le=100)
    hub_max_message_bytes: int = Field(default=1 << 20, ge=1024)
    hub_send_timeout_s: float = Field(default=10.0, gt=0, le=300)
    # The hub's own WebSocket listener (docs/protocol.md "Connecting"): /ws without ASGI, for
    # robots and modules; None: off, 0: any free port (tests).
    hub_ws_port: int | None = Field(default=None, ge=0, le=65535)
    log_level: str = "info"
    access_log: bool = True
    """uvicorn's line per HTTP request (``guidebot demo`` turns it off)."""
    # Event log retention (docs/server.md "Persistence and restart"): rows older than this many
    # days are deleted in the background every event_prune_every_s; 0 keeps them all.
    event_retention_days: float = Field(default=30.0, ge=0)
    event_prune_every_s: float = Field(default=3600.0, gt=0)
    # The audit trail's rows (people's sign-ins and actions, docs/security.md "Audit") are kept
    # this many days instead; 0 keeps them all.
    audit_retention_days: float = Field(default=365.0, ge=0)
    # How often the event log is folded into the reports' hourly rollups (docs/reports.md);
    # a report folds what is left first, so this only keeps that short.
    report_rollup_every_s: float = Field(default=60.0, gt=0)
    # Worker processes for a large site's route tables and YAML import (0: threads only,
    # docs/server.md "Path search").
    site_workers: int = Field(default=2, ge=0, le=32)
    # BuildingInterface (docs/building.md): poll the site's Modbus modules; input filter.
    building_enabled: bool = True
    building_filter_ms: float = Field(default=200.0, ge=0, le=5000)
    # Security (docs/security.md): rate limits and request sizes.
    sign_in_failures_per_minute: float = Field(default=10.0, ge=0)
    sign_in_failure_burst: int = Field(default=10, ge=1)
    task_requests_per_minute: float = Field(default=10.0, ge=0)
    task_request_burst: int = Field(default=5, ge=1)
    max_body_bytes: int = Field(default=64 * 1024, ge=1024)
    # People's accounts (docs/security.md, "Accounts"): session expiry, password length.
    session_idle_minutes: float = Field(default=120.0, gt=0)
    session_max_hours: float = Field(default=12.0, gt=0)
    password_min_length: int = Field(default=12, ge=8, le=128)
    # Passkeys: the host name they are for and the pages' origin (default: as the browser
    # asked, from the Host header; set both behind a TLS proxy: docs/security.md).
    passkey_rp_id: str | None = Field(default=None, pattern=r"^[a-z0-9.-]{1,253}$")
    passkey_origin: str | None = Field(default=None, pattern=r"^https?://[^/\s]+$")
    # Single sign-on (OpenID Connect, docs/security.md "Single sign-on"): off without an issuer.
    oidc_issuer: str | None = Field(default=None, pattern=r"^https?://\S+$")
    oidc_client_id: str = Field(default="guidebot", min_length=1, max_length=256)
    oidc_client_secret: str | None = Field(default=None, min_length=1)
    oidc_name: str = Field(default="single sign-on", min_length=1, max_length=64)
    oidc_groups_claim: str = Field(default="groups", min_length=1, max_length=64)
    oidc_roles: dict[str, str] = Field(default_factory=dict)
    """The provider's group -> GuideBot role (admin, operator, installer, author, viewer)."""
    oidc_redirect_uri: str | None = Field(default=None, pattern=r"^https?://\S+$")

    @field_validator("oidc_roles")
    @classmethod
    def _known_person_roles(cls, roles: dict[str, str]) -> dict[str, str]:
        """A group mapped to a role a person cannot have stops the start, naming it (a typo
        would otherwise sign that group's people in as nobody, or crash the server later)."""
        allowed = sorted(r.value for r in PERSON_ROLES)
        bad = {group: role for group, role in roles.items() if role not in allowed}
        if bad:
            named = ", ".join(f"group {g!r} -> {r!r}" for g, r in sorted(bad.items()))
            raise ValueError(
                f"GUIDEBOT_OIDC_ROLES: unknown role ({named}): the roles are "
                f'{", ".join(allowed)} (docs/security.md, "Single sign-on")'
            )
        return roles

    # Traffic Manager: release a lock whose holder went offline before entering its area.
    lock_offline_grace_s: float = Field(default=30.0, gt=0)
    # Trouble (docs/server.md, "Building modes and trouble"): the longest a door that did not
    # open or a lift that did not come stays closed unless seen working before (its first
    # failure a twelfth of it, each next one in a row twice as long: backend/closures/trouble.py).
    trouble_hold_s: float = Field(default=120.0, gt=0)
    # Bookings (docs/server.md, "Bookings"): the venue's time zone (an IANA name) booked times
    # are read in; how long before its time a booking is checked (and flagged to staff).
    timezone: str = Field(default="UTC", min_length=1, max_length=64)
    booking_check_lead_s: float = Field(default=900.0, gt=0, le=86400)
    # After a restart: how long area requests wait for the robots that had tasks to resync.
    lock_resync_s: float = Field(default=10.0, ge=0, le=300)
    # Scale-out (docs/scaling.md): Redis between processes, leadership through PostgreSQL.
    broker_url: str | None = Field(default=None, pattern=r"^rediss?://")
    process_name: str | None = Field(default=None, pattern=r"^[A-Za-z0-9_.:-]{1,64}$")
    leader_poll_s: float = Field(default=1.0, gt=0, le=30)
    # The leader's lease: PostgreSQL ends a leader session idle this long (a paused leader).
    leader_lease_s: float = Field(default=4.0, gt=0, le=300)

    @property
    def development(self) -> bool:
        return self.environment == "development"

    def files_dir(self) -> Path:
        """The site folder, absolute: ``site_dir``, else the site file's folder, else
        ./guidebot-site (a server started without a site file still takes uploads)."""
        if self.site_dir is not None:
            return self.site_dir.resolve()
        if self.site is not None:
            return self.site.resolve().parent
        return Path(DEFAULT_SITE_DIR).resolve()

    # VDA 5050 vehicles (docs/vda5050.md): their MQTT broker; TLS with mqtts://.
    mqtt_url: str | None = Field(default=None, pattern=r"^mqtts?://")
    mqtt_username: str | None = None
    mqtt_password: str | None = None
    mqtt_cafile: str | None = None
    """The CA certificates that sign an mqtts:// broker's (default: the system's)."""
    # Staff console: the building simulator's control API (demo/tests), for "press a button".
    building_sim_url: str | None = None

    @model_validator(mode="after")
    def _refuse_default_secrets(self) -> Settings:
        if self.broker_url and not self.db_url.startswith(("postgresql", "postgres:")):
            raise ValueError(
                "GUIDEBOT_BROKER_URL needs a PostgreSQL GUIDEBOT_DB_URL (leadership is an advisory"
                " lock in PostgreSQL; docs/scaling.md)"
            )
        if self.broker_url and self.leader_lease_s < 2 * self.leader_poll_s:
            raise ValueError(
                "GUIDEBOT_LEADER_LEASE_S must be at least twice GUIDEBOT_LEADER_POLL_S (the leader"
                " renews its lease once per poll; docs/scaling.md)"
            )
        if len(self.admin_token) < 8:
            raise ValueError("GUIDEBOT_ADMIN_TOKEN must be at least 8 characters")
        if self.development:
            return self
        problems = []
        if self.admin_token == DEFAULT_ADMIN_TOKEN:
            problems.append("GUIDEBOT_ADMIN_TOKEN is missing (the development default is set)")
        elif why := weak_secret(self.admin_token):
            problems.append(f"GUIDEBOT_ADMIN_TOKEN {why}")
        for static in self.tokens:
            if why := weak_secret(static.token):
                problems.append(f"GUIDEBOT_TOKENS: the token of {static.name!r} {why}")
        if problems:
            raise ValueError(
                f"refusing to start with environment={self.environment!r}: "
                + "; ".join(problems)
                + " (set real secrets, or GUIDEBOT_ENVIRONMENT=development)"
            )
        return self
