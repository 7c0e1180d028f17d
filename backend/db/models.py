"""Database tables: the site document, tasks, their history, the event log, which robots
staff took out of service, what staff closed (building modes) and the published nets."""

from __future__ import annotations

from typing import Any

from sqlalchemy import JSON, Boolean, Float, Index, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

__all__ = [
    "AccountRow",
    "AccountSessionRow",
    "Base",
    "ClosureRow",
    "EventRow",
    "NetVersionRow",
    "PasskeyRow",
    "ReportCursorRow",
    "ReportDayRow",
    "ReportRollupRow",
    "RobotServiceRow",
    "SiteDraftRow",
    "SiteRow",
    "SiteVersionRow",
    "TaskHistoryRow",
    "TaskRow",
]


class Base(DeclarativeBase):
    pass


class SiteRow(Base):
    """The current site (one row, id 1); ``version`` grows with every accepted edit."""

    __tablename__ = "site"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    version: Mapped[int] = mapped_column(Integer, default=1)
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_at: Mapped[float] = mapped_column(Float)


class SiteVersionRow(Base):
    """Every published site version, kept: who published it, when, and the whole document."""

    __tablename__ = "site_versions"
    version: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    published_by: Mapped[str] = mapped_column(String(64), default="")
    published_at: Mapped[float] = mapped_column(Float)
    note: Mapped[str] = mapped_column(Text, default="")


class NetVersionRow(Base):
    """Every net published from the RoboGraph editor (docs/nets.md): the newest version of a
    net is its live one; ``seq`` orders publications across nets (the library's version)."""

    __tablename__ = "net_versions"
    __table_args__ = (UniqueConstraint("net", "version", name="uq_net_versions_net_version"),)
    seq: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    net: Mapped[str] = mapped_column(String(100), index=True)
    version: Mapped[int] = mapped_column(Integer)
    pnml: Mapped[str] = mapped_column(Text)
    published_by: Mapped[str] = mapped_column(String(64), default="")
    published_at: Mapped[float] = mapped_column(Float)
    note: Mapped[str] = mapped_column(Text, default="")


class SiteDraftRow(Base):
    """The editors' shared draft (one row, id 1): ``revision`` is its optimistic-lock tag."""

    __tablename__ = "site_draft"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    revision: Mapped[int] = mapped_column(Integer)
    base_version: Mapped[int] = mapped_column(Integer)
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_by: Mapped[str] = mapped_column(String(64), default="")
    updated_at: Mapped[float] = mapped_column(Float)


class TaskRow(Base):
    __tablename__ = "tasks"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    kind: Mapped[str] = mapped_column(String(32))
    params: Mapped[dict[str, Any]] = mapped_column(JSON)
    priority: Mapped[int] = mapped_column(Integer)
    requester: Mapped[str] = mapped_column(String(64), default="", index=True)
    seq: Mapped[int] = mapped_column(Integer)
    state: Mapped[str] = mapped_column(String(16), index=True)
    robot: Mapped[str | None] = mapped_column(String(64), nullable=True)
    pinned_robot: Mapped[str | None] = mapped_column(String(64), nullable=True)
    internal: Mapped[bool] = mapped_column(Boolean, default=False)
    net: Mapped[str] = mapped_column(String(64), default="")
    reason: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[float] = mapped_column(Float)
    updated_at: Mapped[float] = mapped_column(Float, index=True)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    ended_at: Mapped[float | None] = mapped_column(Float, nullable=True)


class TaskHistoryRow(Base):
    """One row per state change of a task."""

    __tablename__ = "task_history"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    task_id: Mapped[str] = mapped_column(String(32), index=True)
    at: Mapped[float] = mapped_column(Float)
    event: Mapped[str] = mapped_column(String(32))
    state: Mapped[str] = mapped_column(String(16))
    robot: Mapped[str | None] = mapped_column(String(64), nullable=True)
    reason: Mapped[str] = mapped_column(Text, default="")


class EventRow(Base):
    """The event log shown to staff: task changes, locks, battery alarms, faults."""

    __tablename__ = "events"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    at: Mapped[float] = mapped_column(Float, index=True)
    kind: Mapped[str] = mapped_column(String(64))
    source: Mapped[str] = mapped_column(String(64), default="")
    data: Mapped[dict[str, Any]] = mapped_column(JSON)


Index("ix_events_kind", EventRow.kind)


class ReportRollupRow(Base):
    """One figure of one hour, folded from the event log (backend/reports/): ``n`` events or
    facts and their ``total`` (seconds, metres). The reports read these, not the raw events,
    so a year's figure sums a few hundred thousand small rows (docs/reports.md)."""

    __tablename__ = "report_rollups"
    metric: Mapped[str] = mapped_column(String(32), primary_key=True)
    hour: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    """Unix seconds of the hour's start (UTC-aligned)."""
    key: Mapped[str] = mapped_column(String(160), primary_key=True)
    n: Mapped[int] = mapped_column(Integer, default=0)
    total: Mapped[float] = mapped_column(Float, default=0.0)


class ReportDayRow(Base):
    """The same figures summed per UTC day: a year's report reads 365 rows per key, not 8760."""

    __tablename__ = "report_days"
    metric: Mapped[str] = mapped_column(String(32), primary_key=True)
    day: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    """Unix seconds of the UTC day's start."""
    key: Mapped[str] = mapped_column(String(160), primary_key=True)
    n: Mapped[int] = mapped_column(Integer, default=0)
    total: Mapped[float] = mapped_column(Float, default=0.0)


class ReportCursorRow(Base):
    """How far the rollups have read the event log (one row, id 1): the last event folded and
    the fold's open state (robots' activities, tours under way, lock requests not granted)."""

    __tablename__ = "report_cursor"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    last_event_id: Mapped[int] = mapped_column(Integer)
    state: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_at: Mapped[float] = mapped_column(Float)


class RobotServiceRow(Base):
    """A robot staff took out of service or put back (the latest word per robot)."""

    __tablename__ = "robot_service"
    robot: Mapped[str] = mapped_column(String(64), primary_key=True)
    out_of_service: Mapped[bool] = mapped_column(Boolean)
    by: Mapped[str] = mapped_column(String(64), default="")
    at: Mapped[float] = mapped_column(Float)


class ClosureRow(Base):
    """A building mode staff set: an area, nodes, a door or an elevator closed to robots, now
    or between two times (backend/closures). Deleted when staff reopen it."""

    __tablename__ = "closures"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    """The closure as shown (backend.closure.Closure)."""
    end: Mapped[float | None] = mapped_column(Float, nullable=True)


class AccountRow(Base):
    """A person who signs in (backend/accounts): their role, their password's argon2 hash
    (empty: no password), whether an admin disabled them, their last sign-in."""

    __tablename__ = "accounts"
    name: Mapped[str] = mapped_column(String(32), primary_key=True)
    display_name: Mapped[str] = mapped_column(String(128), default="")
    role: Mapped[str] = mapped_column(String(16))
    password_hash: Mapped[str] = mapped_column(String(256), default="")
    disabled: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[float] = mapped_column(Float)
    changed_at: Mapped[float] = mapped_column(Float)
    last_sign_in: Mapped[float | None] = mapped_column(Float, nullable=True)


class AccountSessionRow(Base):
    """A signed-in browser: the SHA-256 digest of its cookie (never the cookie; its CSRF
    token is derived from the digest), when it began and was last used, from where."""

    __tablename__ = "account_sessions"
    digest: Mapped[str] = mapped_column(String(80), primary_key=True)
    account: Mapped[str] = mapped_column(String(32), index=True)
    created_at: Mapped[float] = mapped_column(Float)
    seen_at: Mapped[float] = mapped_column(Float)
    address: Mapped[str] = mapped_column(String(64), default="")


class PasskeyRow(Base):
    """A person's passkey (WebAuthn credential): its id and public key (nothing secret: the
    private key never leaves the authenticator), its signature counter, when it was last used."""

    __tablename__ = "account_passkeys"
    credential_id: Mapped[str] = mapped_column(String(1400), primary_key=True)
    """base64url, as the browser names it."""
    account: Mapped[str] = mapped_column(String(32), index=True)
    public_key: Mapped[str] = mapped_column(Text)
    """The COSE public key, base64url."""
    sign_count: Mapped[int] = mapped_column(Integer, default=0)
    label: Mapped[str] = mapped_column(String(64), default="")
    created_at: Mapped[float] = mapped_column(Float)
    last_used: Mapped[float | None] = mapped_column(Float, nullable=True)
