"""The only module that calls ``can.Bus``: turns a configuration string into an open bus, and
reads one (``BusReader``).

``virtual:R1`` (the default, in-process), ``socketcan:can0`` (real hardware), or any python-can
interface as ``interface:channel[,key=value...]`` e.g. ``pcan:PCAN_USBBUS1,bitrate=1000000``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Callable
from typing import Any

import can

__all__ = ["BusOpenError", "BusReader", "BusSpecError", "open_bus", "parse_bus_spec"]

log = logging.getLogger(__name__)


class BusSpecError(ValueError):
    """A bus configuration string that cannot be understood."""


class BusOpenError(OSError):
    """The interface exists but the bus cannot be opened (no device, no permission...)."""


def parse_bus_spec(spec: str) -> tuple[str, str, dict[str, Any]]:
    """Split ``interface:channel,key=value`` into its parts; integers are converted."""
    interface, sep, rest = spec.partition(":")
    if not sep or not interface or not rest:
        raise BusSpecError(f"bus {spec!r}: expected 'interface:channel', e.g. 'virtual:R1'")
    channel, *options = rest.split(",")
    if not channel:
        raise BusSpecError(f"bus {spec!r}: empty channel")
    kwargs: dict[str, Any] = {}
    for option in options:
        key, eq, value = option.partition("=")
        if not eq or not key:
            raise BusSpecError(f"bus {spec!r}: option {option!r} is not key=value")
        kwargs[key] = int(value) if value.isdigit() else value
    return interface, channel, kwargs


def open_bus(spec: str) -> can.BusABC:
    """Open the bus a spec names. Raises BusSpecError (bad string) or BusOpenError."""
    interface, channel, kwargs = parse_bus_spec(spec)
    if interface not in can.VALID_INTERFACES:
        raise BusSpecError(
            f"bus {spec!r}: unknown interface {interface!r}; "
            f"known: {', '.join(sorted(can.VALID_INTERFACES))}"
        )
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except (OSError, can.CanError, ImportError) as exc:
        raise BusOpenError(f"bus {spec!r} cannot be opened: {exc}") from exc


RX_TIMEOUT_S = 0.25  # a reader's receive time-out: only how fast it notices a stop
MAX_BATCH = 256  # frames handed over at once at most (a flood still gets handed over)


class BusReader:
    """A thread that reads a bus and hands its frames over in batches.

    Each wake-up takes the frame that woke it and every frame already waiting behind it
    (``recv(0)``), then calls ``on_batch`` once: in the thread, or with ``loop`` in that event
    loop (one ``call_soon_threadsafe`` per batch). python-can's Notifier hands frames over one
    by one, which costs a thread hand-over per frame. The receive time-out only bounds how long
    ``stop`` waits: an idle bus costs one wake-up per ``timeout``, no polling.
    """

    def __init__(
        self,
        bus: can.BusABC,
        on_batch: Callable[[list[can.Message]], object],
        *,
        loop: asyncio.AbstractEventLoop | None = None,
        timeout: float = RX_TIMEOUT_S,
        name: str = "can-reader",
    ) -> None:
        self.bus = bus
        self.on_batch = on_batch
        self.loop = loop
        self.timeout = timeout
        self.errors = 0
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    @property
    def native_id(self) -> int | None:
        return self._thread.native_id

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float | None = None) -> None:
        """Ask the thread to stop and wait for it (at most one receive time-out, plus)."""
        self._stopped.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(self.timeout * 4 if timeout is None else timeout)

    def _run(self) -> None:
        bus, stopped = self.bus, self._stopped
        while not stopped.is_set():
            try:
                msg = bus.recv(self.timeout)
                if msg is None:
                    continue
                batch = [msg]
                while len(batch) < MAX_BATCH and (more := bus.recv(0)) is not None:
                    batch.append(more)
            except Exception as exc:
                if stopped.is_set():
                    break
                self.errors += 1
                log.warning("CAN reader on %s: %s", bus.channel_info, exc)
                stopped.wait(self.timeout)  # a persistent error must not become a hot loop
                continue
            self._hand_over(batch)

    def _hand_over(self, batch: list[can.Message]) -> None:
        loop = self.loop
        if loop is None:
            try:
                self.on_batch(batch)
            except Exception:
                log.exception("CAN reader on %s: handler failed", self.bus.channel_info)
            return
        if not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self.on_batch, batch)
