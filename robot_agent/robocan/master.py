"""The RoboCAN master: discovers modules from their frames, queries and configures them,
loads their drivers, watches their time-outs and routes data frames (RoboCAN paper, section 6).

Receiving is split in two so that no module can starve another: a reader thread
(``busopen.BusReader``) only sorts frames into one bounded queue per CAN ID (overflow rule: the
oldest frame is dropped and counted) and wakes the event loop once per batch, and one asyncio
task drains the queues round-robin. The time-out check sleeps until the next deadline.

The module table's data (states, transitions, rows, counters) lives in modtable.py. What stays
here (about 700 lines) is one class on purpose: receiving, bring-up, block transfers and the
time-out check all read and write the same module table, queues and pending answers, in one
event loop, and splitting them into mixins would scatter that state without separating it.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import logging
import threading
import time
from typing import Any

import can

from guidebot.bus import BusEndpoint
from guidebot.service import Service
from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState
from robot_agent.robocan.busopen import BusReader
from robot_agent.robocan.drivers import Driver, DriverConfig, DriverRegistry, UnknownDriver
from robot_agent.robocan.modtable import (
    TRANSITIONS,
    CommandFailed,
    Counters,
    IllegalTransition,
    Module,
    ModuleState,
    module_kind_name,
)

__all__ = [
    "CommandFailed",
    "Counters",
    "IllegalTransition",
    "Master",
    "Module",
    "ModuleState",
    "module_kind_name",
]

log = logging.getLogger(__name__)

QUEUE_PER_ID = 256  # frames buffered per CAN ID before the oldest is dropped
DRAIN_BATCH = 16  # frames taken from one ID before moving to the next (fairness)
QUERY_ATTEMPTS = 3
RETRY_FAILED_S = 1.0
SUPERVISE_MAX_S = 1.0  # longest sleep of the time-out check (it wakes at the next deadline)
DEADLINE_EPS_S = 0.001  # wake this much after a deadline, so that it has surely passed
STALL_S = 0.05  # a supervisor tick this late means the process itself was not running
SLAVE_BLOCK_TYPES = frozenset({p.BlockType.DESCRIPTION})  # blocks a master takes from a slave
REFUSALS = frozenset({p.EndStatus.REFUSED, p.EndStatus.UNKNOWN_TYPE, p.EndStatus.TOO_LONG})


def _set_done(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class Master(Service):
    """One master per CAN bus, with the service life cycle (start and stop, or ``async with``)."""

    def __init__(
        self,
        bus: can.BusABC,
        endpoint: BusEndpoint,
        *,
        config: DriverConfig | None = None,
        registry: DriverRegistry | None = None,
        recorder: can.Listener | None = None,
        announce: bool = True,
        name: str | None = None,
    ) -> None:
        super().__init__()
        self.bus = bus
        self.name = name or str(bus.channel_info)
        self.endpoint = endpoint
        self.config = config or DriverConfig()
        self.registry = registry or DriverRegistry()
        self.recorder = recorder
        self.announce = announce
        self.modules: dict[int, Module] = {}
        self.counters = Counters()
        self.drivers: dict[type[Driver], Driver] = {}
        self._queues: dict[int, collections.deque[can.Message]] = {}
        self._arrivals: dict[int, float] = {}  # written by the reader thread
        self._queue_lock = threading.Lock()
        self._record_lock = threading.Lock()
        self._wake = asyncio.Event()
        self._wake_pending = False  # a wake-up of the drain task is already on its way
        self._supervise_at = 0.0  # when the supervisor plans to wake (monotonic)
        self._supervisor: asyncio.Future[None] | None = None  # its sleep, to cut it short
        self._loop: asyncio.AbstractEventLoop | None = None
        self.reader: BusReader | None = None
        self._bring_up: dict[int, asyncio.Task[None]] = {}
        self._acks: dict[tuple[int, int, int], asyncio.Future[int]] = {}
        self._descriptions: dict[int, asyncio.Future[bytes]] = {}
        self._receivers: dict[int, tuple[BlockReceiver, float]] = {}
        self._senders: dict[int, tuple[BlockSender, asyncio.Event]] = {}
        self._last_warning: dict[str, float] = {}

    # --- life cycle -------------------------------------------------------------------

    async def on_start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self.reader = BusReader(self.bus, self._on_frames_thread, name="robocan-reader")
        self.reader.start()
        self.on_cleanup(self._close)
        self.spawn(self._drain(), name="robocan-drain")
        self.spawn(self._supervise(), name="robocan-supervise")
        if self.announce:
            # Every slave drops to DISABLED and is re-queried: a restarted master never
            # inherits motors it did not command itself.
            self.send(p.BROADCAST_ID, bytes([p.Op.MASTER_START]))

    async def on_stop(self) -> None:
        for task in self._bring_up.values():
            task.cancel()
        for task in list(self._bring_up.values()):
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._bring_up.clear()

    async def _close(self) -> None:
        """After the tasks: the reader thread, then the drivers."""
        if self.reader is not None:
            await asyncio.to_thread(self.reader.stop)
        for driver in self.drivers.values():
            driver.close()

    # --- sending ----------------------------------------------------------------------

    def send(self, can_id: int, data: bytes) -> bool:
        """Put one frame on the bus; a send error is counted and logged, never raised."""
        msg = can.Message(
            arbitration_id=can_id,
            data=data,
            is_extended_id=False,
            is_rx=False,
            timestamp=time.time(),
        )
        try:
            self.bus.send(msg, timeout=0.05)
        except can.CanError as exc:
            self.counters.send_errors += 1
            self._warn("send", f"send to 0x{can_id:03X} failed: {exc}")
            return False
        self.counters.frames_tx += 1
        module = self.modules.get(can_id - 1)
        if module is not None:
            module.frames_tx += 1
        self._record(msg)
        return True

    def _record(self, msg: can.Message) -> None:
        """Log a frame; a failing log writer is counted, never allowed to stop the master."""
        if self.recorder is None:
            return
        try:
            with self._record_lock:
                self.recorder.on_message_received(msg)
        except Exception as exc:
            self.counters.record_errors += 1
            self._warn("record", f"recording failed: {exc}")

    def send_to(self, module_id: int, data: bytes) -> bool:
        return self.send(module_id + 1, data)

    async def command(
        self, module_id: int, data: bytes, *, retries: int = p.COMMAND_RETRIES
    ) -> None:
        """Send a configuration command and wait for its ACK; raises CommandFailed."""
        element = data[1] if len(data) > 1 else p.MODULE
        key = (module_id, data[0], element)
        assert self._loop is not None
        for _ in range(retries):
            future: asyncio.Future[int] = self._loop.create_future()
            self._acks[key] = future
            self.send_to(module_id, data)
            try:
                # asyncio.timeout, not wait_for: on Python 3.11 wait_for returns the result
                # and swallows a cancellation that arrives in the same loop pass as the ACK.
                async with asyncio.timeout(p.COMMAND_TIMEOUT_S):
                    status = await future
            except TimeoutError:
                continue
            finally:
                self._acks.pop(key, None)
            if status == p.AckStatus.OK and data[0] == p.Op.SET_PARAM:
                element, param, value = p.parse_set_param(data)
                module = self.modules.get(module_id)
                if module is not None and element == p.MODULE and param == p.Param.WATCHDOG_MS:
                    module.watchdog_s = value / 1000  # its time-out follows its new period
                    self._reschedule()
            if status != p.AckStatus.OK:
                raise CommandFailed(
                    f"module 0x{module_id:02X} refused 0x{data[0]:02X}: "
                    f"{p.AckStatus(status).name if status <= max(p.AckStatus) else status}"
                )
            return
        raise CommandFailed(f"module 0x{module_id:02X} did not acknowledge 0x{data[0]:02X}")

    async def send_block(self, module_id: int, block_type: int, data: bytes) -> None:
        """Master -> slave block transfer (e.g. a firing sequence); raises CommandFailed."""
        sender = BlockSender(block_type, data)
        done = asyncio.Event()
        self._senders[module_id] = (sender, done)
        try:
            for _ in range(p.BLOCK_RETRIES):
                self.send_to(module_id, sender.start())
                while sender.state is BlockState.ACTIVE:
                    done.clear()
                    try:
                        async with asyncio.timeout(p.BLOCK_TIMEOUT_S * 2):
                            await done.wait()
                    except TimeoutError:
                        break
                if sender.state is BlockState.DONE:
                    return
                if sender.end_status in REFUSALS:  # sending it again cannot help
                    raise CommandFailed(
                        f"module 0x{module_id:02X} refused block type {block_type}: "
                        f"{sender.end_status.name}"
                    )
                sender = BlockSender(block_type, data)
                self._senders[module_id] = (sender, done)
            raise CommandFailed(f"block transfer to 0x{module_id:02X} failed")
        finally:
            self._senders.pop(module_id, None)

    # --- receiving --------------------------------------------------------------------

    def _on_frames_thread(self, batch: list[can.Message]) -> None:
        """The reader thread: sort the frames into their ID's bounded queue, no more."""
        now = time.monotonic()
        arrivals = self._arrivals
        with self._queue_lock:
            for msg in batch:
                key = (
                    -1
                    if (msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame)
                    else msg.arbitration_id
                )
                arrivals[key] = now
                queue = self._queues.get(key)
                if queue is None:
                    queue = self._queues[key] = collections.deque(maxlen=QUEUE_PER_ID)
                if len(queue) == QUEUE_PER_ID:
                    self.counters.overflow += 1
                queue.append(msg)
        if self.recorder is not None:
            for msg in batch:
                self._record(msg)
        # One wake-up of the event loop per batch, not per frame: the drain task clears the
        # flag before it empties the queues, so a frame queued after that wakes it again.
        if self._wake_pending:
            return
        self._wake_pending = True
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._wake.set)

    async def _drain(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            while True:
                self._wake_pending = False
                batch: list[can.Message] = []
                with self._queue_lock:
                    for queue in self._queues.values():
                        for _ in range(min(DRAIN_BATCH, len(queue))):
                            batch.append(queue.popleft())
                if not batch:
                    break
                for msg in batch:
                    try:
                        self._handle(msg)
                    except Exception:
                        self.counters.bad_frame += 1
                        log.exception("robocan: frame 0x%03X broke its handler", msg.arbitration_id)
                await asyncio.sleep(0)

    def _handle(self, msg: can.Message) -> None:
        self.counters.frames_rx += 1
        can_id = msg.arbitration_id
        if msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame:
            self.counters.bad_frame += 1
            self._warn("bad", f"ignored error/extended/remote frame 0x{can_id:X}")
            return
        if not p.is_module_id(can_id):
            self.counters.unknown_id += 1
            self._warn("id", f"ignored frame with ID 0x{can_id:03X} (not a slave ID)")
            return
        data = bytes(msg.data)
        module = self.modules.get(can_id)
        now = time.monotonic()
        try:
            op = p.check_length(data)
        except p.ProtocolError as exc:
            self._bad(module, f"0x{can_id:02X}: {exc}" if module is None else str(exc))
            return
        if op in p.MASTER_OPS:
            # Only a master sends these: another master, or a module echoing commands. It
            # creates no module entry and refreshes none.
            self._bad(module, f"master opcode 0x{op:02X} from slave ID 0x{can_id:03X}")
            return
        if module is None:
            module = self.modules[can_id] = Module(can_id)
            self._start_bring_up(module)
            self._reschedule()
        module.last_seen = now
        module.frame_time = msg.timestamp or time.time()  # an interface may give no timestamp
        module.frames_rx += 1
        if module.state is ModuleState.LOST or (
            module.state is ModuleState.FAILED and now >= module.retry_at
        ):
            self._requery(module)
            self._reschedule()
        if op == p.Op.WATCHDOG:
            self._on_watchdog(
                module,
                p.SlaveState(data[0] & 0x0F)
                if (data[0] & 0x0F) in (0, 1)
                else p.SlaveState.DISABLED,
            )
        elif op == p.Op.ACK:
            future = self._acks.get((can_id, data[1], data[2]))
            if future is not None and not future.done():
                future.set_result(data[3])
                if data[1] == p.Op.ENABLE and data[2] == p.MODULE and data[3] == p.AckStatus.OK:
                    # ONLINE with the ACK itself (section 4.5), not a loop turn later when the
                    # bring-up resumes: a frame the module sends right after it is routed.
                    self._go_online(module)
        elif op == p.Op.BLOCK_START:
            self._on_block_start(module, data)
        elif op == p.Op.BLOCK_DATA:
            self._on_block_data(module, data)
        elif op in (p.Op.BLOCK_FLOW, p.Op.BLOCK_END):
            entry = self._senders.get(can_id)
            if entry is None:
                self.counters.block_errors += 1
                return
            sender, done = entry
            try:
                frames = sender.on_frame(data)
            except p.ProtocolError as exc:
                self.counters.block_errors += 1
                self._warn(f"blk{can_id}", f"module 0x{can_id:02X}: {exc}")
                return
            for frame in frames:
                self.send_to(can_id, frame)
            done.set()
        else:
            self._on_data(module, op, data)

    def _on_data(self, module: Module, op: int, data: bytes) -> None:
        """A data frame: to the driver of the element it names (section 5). A frame naming an
        element that does not exist or is of another kind is a bad frame."""
        if module.state is not ModuleState.ONLINE:
            self.counters.not_online += 1
            return
        assert module.description is not None
        element = module.description.data_element(op, data)
        if element is None:
            self._bad(module, f"0x{op:02X} frame names no element of a kind that sends it")
            return
        if op == p.Op.FAULT:
            module.faults += 1
            self._warn(
                f"fault{module.module_id}",
                f"module 0x{module.module_id:02X} element {element}: fault code {data[2]}",
            )
            return
        driver = module.element_drivers.get(element)
        if driver is None:
            return  # a kind without a driver: logged when the module came up
        try:
            driver.on_frame(module, element, data)
        except p.ProtocolError as exc:
            self._bad(module, str(exc))
        except Exception:
            self.counters.driver_errors += 1
            log.exception("robocan: driver %s failed on a frame", type(driver).__name__)

    def _bad(self, module: Module | None, text: str) -> None:
        self.counters.bad_frame += 1
        key = "bad"
        if module is not None:
            module.errors += 1
            key = f"bad{module.module_id}"
            text = f"module 0x{module.module_id:02X}: {text}"
        self._warn(key, text)

    def _on_watchdog(self, module: Module, state: p.SlaveState) -> None:
        previous, module.slave_state = module.slave_state, state
        if (
            module.state is ModuleState.ONLINE
            and not module.disabling
            and state is p.SlaveState.DISABLED
            and previous is p.SlaveState.ENABLED
        ):
            # It rebooted faster than its time-out: treat as lost and configure it again.
            self._lose(module, "module reset")
            self._requery(module)

    def _on_block_start(self, module: Module, data: bytes) -> None:
        try:
            receiver = BlockReceiver(data, types=SLAVE_BLOCK_TYPES)
        except p.ProtocolError as exc:
            self.counters.block_errors += 1
            self._warn(f"blk{module.module_id}", f"module 0x{module.module_id:02X}: {exc}")
            return
        if receiver.state is BlockState.FAILED:  # refused at once: unknown type, too long
            self.send_to(module.module_id, receiver.first_reply())
            self._block_progress(module, receiver)
            return
        self._receivers[module.module_id] = (receiver, time.monotonic())
        self._reschedule()
        self.send_to(module.module_id, receiver.first_reply())
        self._block_progress(module, receiver)

    def _on_block_data(self, module: Module, data: bytes) -> None:
        entry = self._receivers.get(module.module_id)
        if entry is None:
            self.counters.block_errors += 1
            return
        receiver = entry[0]
        self._receivers[module.module_id] = (receiver, time.monotonic())
        for frame in receiver.on_data(data):
            self.send_to(module.module_id, frame)
        self._block_progress(module, receiver)

    def _block_progress(self, module: Module, receiver: BlockReceiver) -> None:
        if receiver.state is BlockState.ACTIVE:
            return
        self._receivers.pop(module.module_id, None)
        if receiver.state is BlockState.FAILED:
            self.counters.block_errors += 1
            self._warn(f"blk{module.module_id}", f"block from 0x{module.module_id:02X} failed")
            return
        if receiver.block_type == p.BlockType.DESCRIPTION:
            future = self._descriptions.get(module.module_id)
            if future is not None and not future.done():
                future.set_result(receiver.data)

    # --- module life cycle ------------------------------------------------------------

    def _transition(self, module: Module, target: ModuleState) -> None:
        if target not in TRANSITIONS[module.state]:
            raise IllegalTransition(module.module_id, module.state, target)
        module.state = target

    def _requery(self, module: Module) -> None:
        """Back to QUERYING (a lost, reset or failed module) and a new bring-up."""
        self._transition(module, ModuleState.QUERYING)
        module.requeried += 1
        self.counters.modules_requeried += 1
        self._start_bring_up(module)

    def _start_bring_up(self, module: Module) -> None:
        old = self._bring_up.get(module.module_id)
        if old is not None and not old.done():
            old.cancel()
        self._bring_up[module.module_id] = asyncio.create_task(
            self._run_bring_up(module), name=f"robocan-bring-up-{module.module_id:02x}"
        )

    async def _run_bring_up(self, module: Module) -> None:
        try:
            await self._query_and_configure(module)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            if module.state in (ModuleState.QUERYING, ModuleState.CONFIGURING):
                self._transition(module, ModuleState.FAILED)
                module.retry_at = time.monotonic() + RETRY_FAILED_S
                module.errors += 1
                log.warning("robocan: module 0x%02X failed to come up: %s", module.module_id, exc)

    async def _query_and_configure(self, module: Module) -> None:
        assert self._loop is not None
        raw: bytes | None = None
        for _ in range(QUERY_ATTEMPTS):
            future: asyncio.Future[bytes] = self._loop.create_future()
            self._descriptions[module.module_id] = future
            self.send_to(module.module_id, bytes([p.Op.QUERY]))
            try:
                async with asyncio.timeout(1.0):
                    raw = await future
                break
            except TimeoutError:
                continue
            finally:
                self._descriptions.pop(module.module_id, None)
        if raw is None:
            raise CommandFailed("no description")
        module.description = p.Description.decode(raw)
        self._transition(module, ModuleState.CONFIGURING)
        module.drivers, module.element_drivers = [], {}
        for index, element in enumerate(module.description.elements):
            driver = self._driver_for(element.kind_name)
            if driver is None:
                continue
            if driver not in module.drivers:
                module.drivers.append(driver)
            module.element_drivers[index] = driver
            await driver.configure(module, index, element)
        module.disabling, module.enabling = False, True
        await self.command(module.module_id, p.enable(p.MODULE, True))
        # the ACK made it ONLINE already (_go_online)

    def _go_online(self, module: Module) -> None:
        """The module acknowledged ENABLE: ONLINE now, drivers told, status published."""
        if not module.enabling or module.state not in (
            ModuleState.CONFIGURING,
            ModuleState.DISABLED,
        ):
            return
        module.enabling = False
        self._transition(module, ModuleState.ONLINE)
        module.online_since = time.monotonic()
        module.announced = True
        for driver in module.drivers:
            try:
                driver.on_online(module)
            except Exception:
                self.counters.driver_errors += 1
                log.exception("robocan: driver %s failed going online", type(driver).__name__)
        self._publish_status(module)

    def _driver_for(self, kind: str) -> Driver | None:
        try:
            cls = self.registry.driver_class(kind)
        except UnknownDriver as exc:
            self._warn(f"drv{kind}", str(exc))
            return None
        driver = self.drivers.get(cls)
        if driver is None:
            driver = self.drivers[cls] = cls(self, self.endpoint, self.config)
            driver.start()
        return driver

    def _lose(self, module: Module, reason: str) -> None:
        task = self._bring_up.pop(module.module_id, None)
        if task is not None and not task.done() and task is not asyncio.current_task():
            task.cancel()
        was_online = module.state is ModuleState.ONLINE
        self._transition(module, ModuleState.LOST)
        module.lost += 1
        self.counters.modules_lost += 1
        module.online_since = None
        if was_online:
            for driver in module.drivers:
                try:
                    driver.on_lost(module, reason)
                except Exception:
                    self.counters.driver_errors += 1
                    log.exception("robocan: driver %s failed on loss", type(driver).__name__)
        if module.announced:
            self._publish_status(module)
        log.warning("robocan: module 0x%02X (%s) lost: %s", module.module_id, module.name, reason)

    def _next_deadline(self, now: float) -> float:
        """The earliest time a module can time out or a block receiver must ask again."""
        deadline = now + SUPERVISE_MAX_S
        arrivals = self._arrivals
        for module in self.modules.values():
            if module.state is not ModuleState.LOST:
                seen = max(module.last_seen, arrivals.get(module.module_id, 0.0))
                deadline = min(deadline, seen + module.lost_timeout_s)
        for _, last in self._receivers.values():
            deadline = min(deadline, last + p.BLOCK_TIMEOUT_S)
        return deadline + DEADLINE_EPS_S

    def _reschedule(self) -> None:
        """A deadline may now come before the supervisor's planned wake-up: wake it."""
        sleep = self._supervisor
        if sleep is not None and not sleep.done():
            if self._next_deadline(time.monotonic()) < self._supervise_at:
                sleep.set_result(None)

    async def _supervise(self) -> None:
        """Time-outs. The task sleeps until the next deadline (a frame only moves deadlines
        later; a new module, a module back from lost, a new block or a shorter watchdog period
        wakes it earlier). Time during which this process was not scheduled (a stalled event
        loop, a loaded machine) does not count against the modules: the master cannot tell
        silence from its own absence, so when a wake-up comes more than STALL_S late the whole
        sleep it overran is credited to every module instead of declaring everyone lost."""
        loop = asyncio.get_running_loop()
        while True:
            start = time.monotonic()
            self._supervise_at = max(self._next_deadline(start), start + DEADLINE_EPS_S)
            sleep = self._supervisor = loop.create_future()
            timer = loop.call_at(self._supervise_at, _set_done, sleep)  # loop.time: monotonic
            try:
                await sleep
            finally:
                timer.cancel()
                self._supervisor = None
            now = time.monotonic()
            if now - self._supervise_at > STALL_S:
                self.counters.stalls += 1
                for module in self.modules.values():
                    module.last_seen = min(module.last_seen + (now - start), now)
            for module in list(self.modules.values()):
                # a frame already received by the reader thread but not yet drained counts
                seen = max(module.last_seen, self._arrivals.get(module.module_id, 0.0))
                if module.state is not ModuleState.LOST and now - seen > module.lost_timeout_s:
                    self._lose(module, "time-out")
            for module_id, (receiver, last) in list(self._receivers.items()):
                if now - last > p.BLOCK_TIMEOUT_S:
                    self._receivers[module_id] = (receiver, now)
                    for frame in receiver.on_timeout():
                        self.send_to(module_id, frame)
                    owner = self.modules.get(module_id)
                    if owner is not None:
                        self._block_progress(owner, receiver)

    def _publish_status(self, module: Module) -> None:
        self.endpoint.publish(
            "module_status",
            {
                "module_id": module.module_id,
                "name": module.name,
                "state": module.state.value
                if module.state in (ModuleState.ONLINE, ModuleState.DISABLED)
                else "lost",
                "critical": module.critical,
            },
        )

    def _warn(self, key: str, text: str) -> None:
        """Log odd traffic at most once a second per kind, so a flood cannot flood the log."""
        now = time.monotonic()
        if now - self._last_warning.get(key, 0.0) >= 1.0:
            self._last_warning[key] = now
            log.warning("robocan: %s", text)

    async def set_enabled(self, module_id: int, on: bool) -> None:
        """Disable an online module (it stays attached and watched, publishes nothing, its
        drivers are told as for a loss) or enable it again. Raises IllegalTransition or
        CommandFailed."""
        module = self.modules.get(module_id)
        if module is None:
            raise KeyError(f"no module 0x{module_id:02X} on this bus")
        target = ModuleState.ONLINE if on else ModuleState.DISABLED
        if target not in TRANSITIONS[module.state]:
            raise IllegalTransition(module_id, module.state, target)
        module.disabling, module.enabling = not on, on
        try:
            await self.command(module_id, p.enable(p.MODULE, on))
        finally:
            module.enabling = False
        if on:
            return  # the ACK made it ONLINE (_go_online)
        self._transition(module, target)
        for driver in module.drivers:
            try:
                driver.on_lost(module, "disabled by the master")
            except Exception:
                self.counters.driver_errors += 1
                log.exception("robocan: driver %s failed", type(driver).__name__)
        self._publish_status(module)

    # --- queries for the agent and tests ----------------------------------------------

    def module_table(self) -> list[dict[str, Any]]:
        """One row per module: ID, name, kind, firmware, state and its counters."""
        return [m.to_dict() for m in sorted(self.modules.values(), key=lambda m: m.module_id)]

    def status(self) -> dict[str, Any]:
        """What this master knows, for people: its bus, counters and module table."""
        return {
            "bus": self.name,
            "counters": dataclasses.asdict(self.counters),
            "modules": self.module_table(),
        }

    def online(self) -> set[int]:
        return {m.module_id for m in self.modules.values() if m.state is ModuleState.ONLINE}

    def driver(self, cls: type[Driver]) -> Driver | None:
        return self.drivers.get(cls)

    def drivers_of(self, kind: type[Driver]) -> list[Driver]:
        return [d for d in self.drivers.values() if isinstance(d, kind)]
