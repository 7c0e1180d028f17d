"""The server's persistence: a write-behind store for tasks, history, events and robots out of
service, plus the site document.

Bus handlers must not block, so ``record`` and ``record_event`` only queue; a background task
writes batches in one transaction each. Overflow rule: task snapshots coalesce per task (the
latest wins, so they are bounded by the number of tasks); history and event rows are bounded
by ``max_pending`` and the oldest unwritten ones are dropped (counted in ``dropped``, logged).

Retention: with ``retention_s`` the event log is pruned every ``prune_every_s`` in the
background, in chunks of ``PRUNE_CHUNK`` rows (each its own short transaction), keeping what
the next start replays (``lock_holders``: this life's ``server_started`` and the area rows
after it; the console's alerts: ``KEPT_KINDS``) and what the reports' rollups have not folded
yet (after ``report_cursor``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

from sqlalchemy import (
    Insert,
    and_,
    delete,
    false,
    func,
    insert,
    not_,
    or_,
    select,
    text,
    update,
)
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.exc import OperationalError, StatementError

from backend.db.models import (
    EventRow,
    ReportCursorRow,
    RobotServiceRow,
    SiteDraftRow,
    SiteRow,
    SiteVersionRow,
    TaskHistoryRow,
    TaskRow,
)
from backend.db.session import JsonText, UnstorableJson, log_failure, unstorable
from backend.site.offloop import off_loop
from backend.tasks.model import FINAL_STATES, Task, TaskState
from guidebot.service import Service
from guidebot.site import jsonio

__all__ = ["DbStore"]

log = logging.getLogger(__name__)

UPSERT_CHUNK = 500
"""Rows per INSERT ... ON CONFLICT statement (SQLite allows 32766 bound parameters)."""

PRUNE_CHUNK = 5000
"""Event rows deleted per transaction: a SQLite writer holds the file only that long."""

LOCK_KINDS = ("area_granted", "area_released", "area_force_released")
"""What ``lock_holders`` replays after the last ``server_started``."""

KEPT_KINDS = ("alert_raised", "alert_acked", "alert_resolved")
"""Never pruned: the alert store replays every alert from the log at start (backend/alerts.py
``LOGGED_KINDS``), to resolve what the last life left open and keep their history."""

TASK_FIELDS = (
    "kind",
    "params",
    "priority",
    "requester",
    "seq",
    "robot",
    "pinned_robot",
    "internal",
    "net",
    "reason",
    "created_at",
    "updated_at",
    "started_at",
    "ended_at",
)


class DbStore(Service):
    def __init__(
        self,
        sessionmaker: Any,
        *,
        max_pending: int = 100_000,
        epoch: Callable[[], int | None] | None = None,
        retention_s: float | None = None,
        prune_every_s: float = 3600.0,
        audit_kinds: tuple[str, ...] = (),
        audit_retention_s: float | None = None,
    ) -> None:
        """``epoch``: with several server processes, the leader epoch this process won (None
        once it has lost it): each write checks it against the leader row in its transaction,
        so a paused old leader's late writes are refused (docs/scaling.md, "Fencing").
        ``retention_s``: event rows older than this are deleted, every ``prune_every_s`` (the
        first time that long after the start); None keeps them all. ``audit_kinds``: the
        audit trail's rows (docs/security.md "Audit"), kept ``audit_retention_s`` instead
        (None: for ever)."""
        super().__init__()
        self.sessionmaker = sessionmaker
        self.max_pending = max_pending
        self.epoch = epoch
        self.retention_s = retention_s
        self.prune_every_s = prune_every_s
        self.audit_kinds = audit_kinds
        self.audit_retention_s = audit_retention_s if audit_kinds else None
        self.pruned = 0
        """Event rows deleted by retention since the start."""
        self._service: dict[str, dict[str, Any]] = {}
        self.fenced = 0
        """Rows not written because this process no longer led when they were flushed."""
        self._tasks: dict[str, dict[str, Any]] = {}
        self._history: deque[dict[str, Any]] = deque()
        self._events: deque[dict[str, Any]] = deque()
        self._wake = asyncio.Event()
        self._flush_lock = asyncio.Lock()
        self.dropped = 0
        self.written = 0
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        """Called with every event row as it is recorded (the console's live event log)."""

    # --- write-behind --------------------------------------------------------------------
    def record(
        self,
        task: Task,
        event: str,
        detail: dict[str, Any] | None = None,
        at: float | None = None,
    ) -> None:
        """A task changed: its snapshot and one history row. The event row also carries what
        the reports fold (backend/reports/): the kind, tour, point and language of a new task,
        why one ended, and ``detail`` (a tour's progress: index, total, poi, stage). ``at``:
        when it happened, for news that leaves the task's ``updated_at`` as it was (a point
        reached); default the task's last change."""
        snapshot = {f: getattr(task, f) for f in TASK_FIELDS}
        snapshot["params"] = dict(task.params)
        snapshot["state"] = task.state.value
        self._tasks[task.id] = snapshot
        self._append(
            self._history,
            {
                "task_id": task.id,
                "at": task.updated_at if at is None else at,
                "event": event,
                "state": task.state.value,
                "robot": task.robot,
                "reason": task.reason,
            },
        )
        data: dict[str, Any] = {"task_id": task.id, "state": task.state.value, "robot": task.robot}
        if event == "created":  # who asked: a person's token name, a panel, a robot, a button
            data["requester"] = task.requester
            data["kind"] = task.kind
            for key in ("tour", "poi", "lang"):
                if isinstance(value := task.params.get(key), str):
                    data[key] = value
        if task.reason and task.state in FINAL_STATES:
            data["reason"] = task.reason[:200]
        if detail:
            data.update(detail)
        self.record_event("task_" + event, "task_manager", data)

    def record_service(self, robot: str, out_of_service: bool, by: str = "") -> None:
        """Staff took ``robot`` out of service or put it back (the latest word per robot)."""
        self._service[robot] = {
            "robot": robot,
            "out_of_service": out_of_service,
            "by": by[:64],
            "at": time.time(),
        }
        self._wake.set()

    def record_event(self, kind: str, source: str, data: dict[str, Any]) -> None:
        row = {"at": time.time(), "kind": kind[:64], "source": source, "data": data}
        self._append(self._events, row)
        for listener in self.listeners:
            listener(row)

    def _append(self, rows: deque[dict[str, Any]], row: dict[str, Any]) -> None:
        if len(rows) >= self.max_pending:
            rows.popleft()
            self.dropped += 1
            if self.dropped == 1 or self.dropped % 1000 == 0:
                log.error("database writer behind: %d rows dropped so far", self.dropped)
        rows.append(row)
        self._wake.set()

    async def on_start(self) -> None:
        self.on_cleanup(self.flush)  # after the writer has stopped: write what is pending
        self.spawn(self._run(), name="db-writer")
        if self.retention_s is not None or self.audit_retention_s is not None:
            self.spawn(self._prune_periodically(), name="db-retention")

    async def _prune_periodically(self) -> None:
        def before(keep_s: float | None) -> float | None:
            return None if keep_s is None else time.time() - keep_s

        while True:
            await asyncio.sleep(self.prune_every_s)
            try:
                await self.prune_events(
                    before(self.retention_s), audit_older_than=before(self.audit_retention_s)
                )
            except Exception as exc:
                log_failure(
                    log,
                    exc,
                    "event log retention failed; trying again in %.0f s",
                    self.prune_every_s,
                )

    async def _run(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            try:
                await self.flush()
            except Exception as exc:  # the rows stay queued
                log_failure(log, exc, "database write failed; retrying in 1 s")
                await asyncio.sleep(1.0)
                self._wake.set()

    async def flush(self) -> None:
        async with self._flush_lock:
            if not (self._tasks or self._history or self._events or self._service):
                return
            tasks, self._tasks = self._tasks, {}
            service, self._service = self._service, {}
            history = list(self._history)
            events = list(self._events)
            try:
                async with self.sessionmaker() as session, session.begin():
                    if self.epoch is not None and not await self._still_leading(session):
                        self._drop_fenced(tasks, history, events)
                        return
                    if service:
                        await session.execute(_upsert_service(session, list(service.values())))
                    if tasks:
                        rows = [{"id": task_id, **snap} for task_id, snap in tasks.items()]
                        for i in range(0, len(rows), UPSERT_CHUNK):
                            await session.execute(_upsert(session, rows[i : i + UPSERT_CHUNK]))
                    if history:
                        await session.execute(insert(TaskHistoryRow), history)
                    if events:
                        await session.execute(insert(EventRow), events)
            except Exception:
                for task_id, snap in tasks.items():
                    self._tasks.setdefault(task_id, snap)
                for robot, row in service.items():
                    self._service.setdefault(robot, row)
                raise
            for _ in history:
                self._history.popleft()
            for _ in events:
                self._events.popleft()
            self.written += len(tasks) + len(history) + len(events) + len(service)

    async def prune_events(
        self, older_than: float | None, *, audit_older_than: float | None = None
    ) -> int:
        """Delete event rows recorded before ``older_than`` (seconds since the epoch), and the
        audit trail's (``audit_kinds``) before ``audit_older_than`` instead (None: none of
        them), a chunk per transaction, except what the next start replays (locks, alerts);
        returns how many. A process that no longer leads deletes nothing."""
        due = []
        if older_than is not None:
            due.append(and_(EventRow.kind.not_in(self.audit_kinds), EventRow.at < older_than))
        if audit_older_than is not None and self.audit_kinds:
            due.append(and_(EventRow.kind.in_(self.audit_kinds), EventRow.at < audit_older_than))
        if not due:
            return 0
        total = 0
        while True:
            async with self.sessionmaker() as session, session.begin():
                if self.epoch is not None and not await self._still_leading(session):
                    return total
                life = (
                    await session.execute(
                        select(func.max(EventRow.id)).where(EventRow.kind == "server_started")
                    )
                ).scalar() or 0
                replayed = and_(
                    EventRow.id >= life, EventRow.kind.in_((*LOCK_KINDS, "server_started"))
                )
                folded = await session.scalar(
                    select(ReportCursorRow.last_event_id).where(ReportCursorRow.id == 1)
                )
                unfolded = EventRow.id > folded if folded is not None else false()
                ids = list(
                    (
                        await session.execute(
                            select(EventRow.id)
                            .where(
                                or_(*due),
                                not_(replayed),
                                not_(unfolded),  # the reports' rollups have not read it yet
                                EventRow.kind.not_in(KEPT_KINDS),
                            )
                            .order_by(EventRow.id)
                            .limit(PRUNE_CHUNK)
                        )
                    ).scalars()
                )
                if ids:
                    await session.execute(delete(EventRow).where(EventRow.id.in_(ids)))
            total += len(ids)
            self.pruned += len(ids)
            if len(ids) < PRUNE_CHUNK:
                if total:
                    log.info("event log retention: %d rows deleted", total)
                return total
            await asyncio.sleep(0)  # let the writer and readers in between chunks

    async def _still_leading(self, session: Any) -> bool:
        """The leader row names our epoch; ``FOR SHARE`` holds a new leader's epoch bump until
        this transaction ends, so it either sees these rows or they are not written."""
        assert self.epoch is not None
        mine = self.epoch()
        current = (
            await session.execute(text("SELECT epoch FROM guidebot_leader WHERE id = 1 FOR SHARE"))
        ).scalar()
        return mine is not None and current == mine

    def _drop_fenced(
        self, tasks: dict[str, Any], history: list[dict[str, Any]], events: list[dict[str, Any]]
    ) -> None:
        for _ in history:
            self._history.popleft()
        for _ in events:
            self._events.popleft()
        count = len(tasks) + len(history) + len(events)
        self.fenced += count
        log.warning("database: %d row(s) not written: this process no longer leads (fenced)", count)

    # --- reads ---------------------------------------------------------------------------
    async def load_open_tasks(self) -> list[Task]:
        """Tasks not yet finished, for the Task Manager after a restart."""
        finals = [s.value for s in FINAL_STATES]
        async with self.sessionmaker() as session:
            rows = (
                await session.execute(select(TaskRow).where(TaskRow.state.not_in(finals)))
            ).scalars()
            return [_task(row) for row in rows]

    async def _flush_for_read(self) -> None:
        """Write what is pending before a read, so the read is as current as memory. When the
        database stays locked past its busy time-out (another writer's long transaction on a
        loaded machine), the read goes on with what is written: a moment behind, not an error
        for the page asking; the pending rows stay queued and the writer tries again."""
        try:
            await self.flush()
        except OperationalError as exc:
            log.warning("database busy, reading what is written so far: %s", exc.orig)
            self._wake.set()

    async def list_tasks(
        self,
        *,
        states: list[str] | None = None,
        exclude_states: list[str] | None = None,
        robot: str | None = None,
        include_internal: bool = True,
        owner: tuple[str | None, str | None] | None = None,
        offset: int = 0,
        limit: int = 100,
    ) -> tuple[int, list[Task]]:
        """Stored tasks, newest change first, filtered; returns (total matching, page).

        ``owner`` = (requester, robot): only tasks that one requested or that robot runs.
        Pending changes are written first, so the page is as current as memory.
        """
        await self._flush_for_read()
        query = select(TaskRow)
        if states:
            query = query.where(TaskRow.state.in_(states))
        if exclude_states:
            query = query.where(TaskRow.state.not_in(exclude_states))
        if robot is not None:
            query = query.where(TaskRow.robot == robot)
        if not include_internal:
            query = query.where(TaskRow.internal.is_(False))
        if owner is not None:
            requester, runs = owner
            query = query.where(
                or_(TaskRow.requester == (requester or ""), TaskRow.robot == runs)
                if runs is not None
                else TaskRow.requester == (requester or "")
            )
        counted = select(func.count()).select_from(query.subquery())
        page = query.order_by(TaskRow.updated_at.desc(), TaskRow.seq.desc())
        async with self.sessionmaker() as session:
            total = int((await session.execute(counted)).scalar() or 0)
            rows = (await session.execute(page.offset(offset).limit(limit))).scalars()
            return total, [_task(row) for row in rows]

    async def max_seq(self) -> int:
        async with self.sessionmaker() as session:
            return int((await session.execute(select(func.max(TaskRow.seq)))).scalar() or 0)

    async def task(self, task_id: str) -> Task | None:
        async with self.sessionmaker() as session:
            row = await session.get(TaskRow, task_id)
            return _task(row) if row is not None else None

    async def history(self, task_id: str) -> list[dict[str, Any]]:
        await self._flush_for_read()
        async with self.sessionmaker() as session:
            rows = (
                await session.execute(
                    select(TaskHistoryRow)
                    .where(TaskHistoryRow.task_id == task_id)
                    .order_by(TaskHistoryRow.id)
                )
            ).scalars()
            return [
                {
                    "at": r.at,
                    "event": r.event,
                    "state": r.state,
                    "robot": r.robot,
                    "reason": r.reason,
                }
                for r in rows
            ]

    async def events(
        self,
        *,
        after_id: int = 0,
        before_id: int | None = None,
        limit: int = 100,
        kind: str | None = None,
        latest: bool = False,
        source: str | None = None,
    ) -> list[dict[str, Any]]:
        """Events after ``after_id`` (and before ``before_id``) in id order; ``latest``: the
        last ``limit`` of them; ``source``: only those of that source (a person's account)."""
        await self._flush_for_read()
        query = select(EventRow).where(EventRow.id > after_id)
        if source:
            query = query.where(EventRow.source == source)
        if before_id is not None:
            query = query.where(EventRow.id < before_id)
        if kind:
            query = query.where(EventRow.kind == kind)
        order = EventRow.id.desc() if latest else EventRow.id
        async with self.sessionmaker() as session:
            rows = list((await session.execute(query.order_by(order).limit(limit))).scalars())
            if latest:
                rows.reverse()
            return [
                {"id": r.id, "at": r.at, "kind": r.kind, "source": r.source, "data": r.data}
                for r in rows
            ]

    async def lock_holders(self) -> dict[str, str]:
        """Area -> robot: the restricted areas held when the last server life ended, replayed
        from its grants and releases in the event log (a life's restored locks are logged as
        grants too, so the chain holds across several restarts). Call it before this life's
        ``server_started`` is recorded."""
        await self.flush()
        kinds = ("area_granted", "area_released", "area_force_released")
        async with self.sessionmaker() as session:
            since = (
                await session.execute(
                    select(func.max(EventRow.id)).where(EventRow.kind == "server_started")
                )
            ).scalar() or 0
            rows = (
                await session.execute(
                    select(EventRow.kind, EventRow.data)
                    .where(EventRow.id > since, EventRow.kind.in_(kinds))
                    .order_by(EventRow.id)
                )
            ).all()
        holders: dict[str, str] = {}
        for kind, data in rows:
            area, robot = (data or {}).get("area"), (data or {}).get("robot")
            if not isinstance(area, str) or not isinstance(robot, str):
                continue
            if kind == "area_granted":
                holders[area] = robot
            elif holders.get(area) == robot:
                del holders[area]
        return holders

    async def out_of_service(self) -> dict[str, str]:
        """Robots staff left out of service -> who took them out (for the next start)."""
        await self.flush()
        async with self.sessionmaker() as session:
            rows = await session.execute(
                select(RobotServiceRow.robot, RobotServiceRow.by).where(
                    RobotServiceRow.out_of_service.is_(True)
                )
            )
            return {robot: by for robot, by in rows}

    async def load_site(self) -> tuple[int, dict[str, Any]] | None:
        async with self.sessionmaker() as session:
            row = await session.get(SiteRow, 1)
            return (row.version, row.data) if row is not None else None

    async def save_site(self, data: dict[str, Any], *, by: str = "", note: str = "") -> int:
        """Store ``data`` as the next version; UnstorableJson if a JSON column cannot hold it."""
        with _storable():
            return await self._save_site(data, by=by, note=note)

    async def _save_site(self, data: dict[str, Any], *, by: str, note: str) -> int:
        """Store a new site document and keep it in the history; returns its version.

        The document is written to JSON in a thread, once for both rows, and the stored one is
        never read back: for a 10 000-node site either would hold the event loop 10-40 ms."""
        now = time.time()
        try:
            document = JsonText(await off_loop(jsonio.dumps, data))
        except (TypeError, ValueError) as exc:  # orjson's refusal: an integer beyond 64 bits
            raise unstorable(exc) from None
        async with self.sessionmaker() as session, session.begin():
            current = await session.scalar(select(SiteRow.version).where(SiteRow.id == 1))
            version = 1 if current is None else current + 1
            if current is None:
                await session.execute(
                    insert(SiteRow).values(id=1, version=version, data=document, updated_at=now)
                )
            else:
                await session.execute(
                    update(SiteRow)
                    .where(SiteRow.id == 1)
                    .values(version=version, data=document, updated_at=now)
                )
            await session.execute(
                insert(SiteVersionRow).values(
                    version=version, data=document, published_by=by, published_at=now, note=note
                )
            )
            return version

    async def site_versions(self) -> list[dict[str, Any]]:
        """Every kept version, newest first, without the documents."""
        async with self.sessionmaker() as session:
            rows = await session.execute(
                select(
                    SiteVersionRow.version,
                    SiteVersionRow.published_by,
                    SiteVersionRow.published_at,
                    SiteVersionRow.note,
                ).order_by(SiteVersionRow.version.desc())
            )
            return [
                {"version": v, "published_by": by, "published_at": at, "note": note}
                for v, by, at, note in rows
            ]

    async def site_version(self, version: int) -> dict[str, Any] | None:
        """One kept version's document, or None."""
        async with self.sessionmaker() as session:
            row = await session.get(SiteVersionRow, version)
            return row.data if row is not None else None

    async def load_draft(self) -> SiteDraftRow | None:
        async with self.sessionmaker() as session:
            return await session.get(SiteDraftRow, 1)

    async def save_draft(
        self, data: dict[str, Any], *, revision: int, base_version: int, by: str
    ) -> None:
        """Store the draft as ``revision`` (the caller checked the previous one);
        UnstorableJson if a JSON column cannot hold it."""
        with _storable():
            await self._save_draft(data, revision=revision, base_version=base_version, by=by)

    async def _save_draft(
        self, data: dict[str, Any], *, revision: int, base_version: int, by: str
    ) -> None:
        async with self.sessionmaker() as session, session.begin():
            row = await session.get(SiteDraftRow, 1)
            if row is None:
                row = SiteDraftRow(id=1)
                session.add(row)
            row.revision = revision
            row.base_version = base_version
            row.data = data
            row.updated_by = by
            row.updated_at = time.time()


@contextlib.contextmanager
def _storable() -> Iterator[None]:
    """SQLAlchemy wraps what the JSON serializer raised: give the caller the plain reason."""
    try:
        yield
    except StatementError as exc:
        if isinstance(exc.orig, UnstorableJson):
            raise exc.orig from None
        raise


def _upsert(session: Any, rows: list[dict[str, Any]]) -> Insert:
    """INSERT ... ON CONFLICT (id) DO UPDATE: one statement for a batch of task snapshots."""
    dialect = session.bind.dialect.name
    module = postgresql if dialect == "postgresql" else sqlite
    statement = module.insert(TaskRow).values(rows)
    updated = {key: statement.excluded[key] for key in (*TASK_FIELDS, "state")}
    return statement.on_conflict_do_update(index_elements=[TaskRow.id], set_=updated)


def _upsert_service(session: Any, rows: list[dict[str, Any]]) -> Insert:
    """INSERT ... ON CONFLICT (robot) DO UPDATE for the robots' service rows."""
    dialect = session.bind.dialect.name
    module = postgresql if dialect == "postgresql" else sqlite
    statement = module.insert(RobotServiceRow).values(rows)
    updated = {key: statement.excluded[key] for key in ("out_of_service", "by", "at")}
    return statement.on_conflict_do_update(index_elements=[RobotServiceRow.robot], set_=updated)


def _task(row: TaskRow) -> Task:
    task = Task(
        id=row.id,
        kind=row.kind,
        params=dict(row.params or {}),
        priority=row.priority,
        requester=row.requester,
        seq=row.seq,
        state=TaskState(row.state),
        robot=row.robot,
        pinned_robot=row.pinned_robot,
        internal=row.internal,
        net=row.net,
        reason=row.reason,
        created_at=row.created_at,
        updated_at=row.updated_at,
        started_at=row.started_at,
        ended_at=row.ended_at,
    )
    return task
