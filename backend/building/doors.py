"""What the BuildingInterface knows of each automatic door: its state and who holds it open.

Safety rules (docs/building.md, "Doors"):
- a door is **open** for the fleet only when its ``is_open`` sensor says so in a sample read
  after the interface last cleared the open coil (a stale "open" can never survive a close);
  without a sensor, ``open_time_s`` after the interface set the coil;
- it is **closed** as soon as the interface clears the coil, when the sensor falls, when a
  sensorless door's coil reads back cleared, or when the sensor's module goes offline (then
  published ``sensed: false``: not passable, though the door may still stand open);
- a clear that could not be written (the module was offline) leaves the coil set, so the door
  may stand open: its sensor is not believed until the coil is cleared when the module is back,
  or set again for a new ``open_door`` (otherwise the first sample after the module's return
  would announce the door open a moment before the interface closes it: the soak saw a robot
  drive on such an announcement);
- robots hold a door from ``open_door`` until ``release_door``; the coil is cleared when the
  last holder lets go, when a holder has held it ``max_hold_s`` (a lost robot), or when a
  holder's agent restarted and it does not stand on the door's node (BuildingInterface);
- a holder that lets go while its ``open_door`` still waits for the door withdrew it
  (``DoorReleased``): the door did not fail (a virtual plan day saw a robot's goal cancelled
  right after it asked, and the wait's time-out closed the working door as trouble); so are
  the waiting ``open_door`` requests of the holders the fire alarm drops (``release_all`` with
  ``withdraw``: an evacuation raised door trouble and an alert for doors nobody wanted), and
  so are those of every holder when staff close the door (``close_door``: they did not fail,
  the door was closed on purpose; each is answered ``door_closed``, ``DoorShut``, so a robot
  waiting in front asks again); but a holder the fire alarm drops that is not evacuating
  (outside the alarm's zone) still wants the door: its waiting ``open_door`` is refused at once
  with the alarm's reason (``DoorRefused``: a ``command_failed``), where it used to get no
  answer and wait its whole ``wait_timeout_s``; a request dropped while its coil is still being
  written gets the same answer when it comes to wait.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Collection
from dataclasses import dataclass, field

from guidebot.site.building import Door

__all__ = ["STALE_MARGIN_S", "DoorKeeper", "DoorRefused", "DoorReleased", "DoorShut"]

STALE_MARGIN_S = 0.02
"""A sample slotted within this of a close write may have been read before it (timers fire a
little early): it does not count."""


class DoorReleased(Exception):
    """The holder let the door go (or the fire alarm dropped it, or staff closed the door)
    while its open_door waited for it: withdrawn, not failed. The text says why."""


class DoorShut(DoorReleased):
    """Staff closed the door while the holder's open_door waited for it: withdrawn (no
    failure of the door), but the holder still wants it, so it is told the door is closed
    (``door_closed`` in answer to its request) and asks again."""


class DoorRefused(Exception):
    """The door was taken from a holder that still wants it (the fire alarm holds its node)
    while its open_door waited: refused at once, the text is the reason the requester is told."""


@dataclass
class DoorKeeper:
    """One door's state as published (door_opened / door_closed) and its holders."""

    door: Door
    publish: Callable[[str, bool, bool], None]
    """Called with (door id, open, sensed) on every change of the published state."""
    is_open: bool | None = None
    sensed: bool = True
    """False while the state is "closed" only because the sensor cannot be read."""
    closed_at: float = -math.inf
    """time.monotonic() of the last coil clear (inf while a clear is being written, and after
    one failed until the coil is written again)."""
    coil_left_set: bool = False
    """A clear failed: the coil is still set (cleared when its module is back)."""
    set_at: float = -math.inf
    """time.monotonic() of the last coil set (sensorless doors)."""
    holders: dict[str, asyncio.TimerHandle] = field(default_factory=dict)
    _waiters: dict[asyncio.Future[None], str] = field(default_factory=dict)
    """Each open_door waiting for the door -> its holder."""
    _opening: dict[str, Exception | None] = field(default_factory=dict)
    """Holders whose open_door is between ``hold`` and ``wait_open`` (its coil being written)
    -> why they were dropped meanwhile (None: not dropped). A refusal that came then is the
    answer ``wait_open`` gives (CI: the fire alarm dropped R2 while its coil was written, and
    R2 got no answer at all)."""
    _open_timer: asyncio.TimerHandle | None = None

    def state(self, is_open: bool, *, sensed: bool = True) -> None:
        """Set the published state; tells everyone on a change, wakes open waiters."""
        if is_open == self.is_open and sensed == self.sensed:
            return
        self.is_open, self.sensed = is_open, sensed
        self.publish(self.door.id, is_open, sensed)
        if is_open:
            for future in self._waiters:
                if not future.done():
                    future.set_result(None)

    def sensor(self, value: int, t: float) -> None:
        """A (filtered) sample of the is_open sensor slotted at ``t``."""
        if t > self.closed_at + STALE_MARGIN_S:
            self.state(value == 1)

    def coil(self, value: int, t: float) -> None:
        """A sample of the open coil: a sensorless door closes when it reads back cleared."""
        if self.door.is_open is None and value == 0 and t > self.set_at + STALE_MARGIN_S:
            self.state(False)

    def coil_set(self, now: float) -> None:
        """The interface set the coil; a sensorless door counts as open ``open_time_s`` later."""
        self.set_at = now
        if self.coil_left_set:
            self.coil_left_set = False
            self.closed_at = now  # the coil is ours again: samples read from now on count
        if self.door.is_open is None and not self.is_open and self._open_timer is None:
            self._open_timer = asyncio.get_running_loop().call_later(
                self.door.open_time_s, self._sensorless_open
            )

    def _sensorless_open(self) -> None:
        self._open_timer = None
        if self.holders and self.closed_at != math.inf:
            self.state(True)

    def closing(self) -> None:
        """The interface is about to clear the coil: closed from now on."""
        if self._open_timer is not None:
            self._open_timer.cancel()
            self._open_timer = None
        self.closed_at = math.inf
        self.state(False)

    def cleared(self, now: float) -> None:
        """The coil clear was written: samples read from now on count again."""
        self.closed_at = now
        self.coil_left_set = False

    def clear_failed(self) -> None:
        """The coil clear could not be written: no sample counts until the coil is written."""
        self.closed_at = math.inf
        self.coil_left_set = True

    def lost(self, now: float) -> None:
        """The sensor's module stopped answering: the door counts as closed (not sensed)."""
        self.closed_at = max(self.closed_at, now) if self.closed_at != math.inf else math.inf
        self.state(False, sensed=False)

    async def wait_open(self, timeout_s: float, holder: str = "") -> None:
        """Until the door is open: TimeoutError after ``timeout_s``, DoorReleased as soon as
        ``holder`` lets it go (its request withdrawn), or at once if it already did (while the
        coil was being written)."""
        dropped = self._opening.pop(holder, None)
        if holder and holder not in self.holders:
            raise dropped or DoorReleased(f"{holder} no longer holds it")
        if self.is_open:
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._waiters[future] = holder
        try:
            await asyncio.wait_for(future, timeout_s)
        finally:
            del self._waiters[future]

    def _withdraw(self, holders: set[str], why: str, error: type[Exception] = DoorReleased) -> None:
        """Wake the open_door waits of ``holders`` with ``error(why)``."""
        for future, waiting in self._waiters.items():
            if waiting in holders and not future.done():
                future.set_exception(error(why))
        for holder in holders:  # not waiting yet: told when it comes to wait (the first why)
            if holder in self._opening and self._opening[holder] is None:
                self._opening[holder] = error(why)

    def hold(self, holder: str, expire: Callable[[], None]) -> None:
        """(Re)start ``holder``'s hold; ``expire`` runs if it is not released in time."""
        old = self.holders.pop(holder, None)
        if old is not None:
            old.cancel()
        self._opening[holder] = None
        self.holders[holder] = asyncio.get_running_loop().call_later(self.door.max_hold_s, expire)

    def release(self, holder: str) -> bool:
        """Drop ``holder``; True when nobody holds the door any more."""
        timer = self.holders.pop(holder, None)
        if timer is not None:
            timer.cancel()
            self._withdraw({holder}, f"{holder} let it go")
        return not self.holders

    def release_all(
        self,
        *,
        withdraw: str = "",
        shut: str = "",
        refuse: str = "",
        spare: Collection[str] = (),
    ) -> None:
        """Drop every holder. With ``withdraw`` (why: the fire alarm), their ``open_door``
        requests still waiting for the door are withdrawn too, as if each holder had let go:
        their time-out is no failure of the door. ``shut`` (why: staff's close) withdraws
        them with DoorShut: each holder is told the door closed, and asks again if it still
        wants it (a robot waiting in front used to wait for its whole time-out, 600 s, for an
        answer that never came). With ``refuse`` (a reason: the
        fire alarm's), the waiting requests of holders not in ``spare`` (those evacuating, who
        want no door any more: withdrawn) are refused with it at once: they still want the
        door, and told nothing they would wait for it in vain."""
        holders = set(self.holders)
        for timer in self.holders.values():
            timer.cancel()
        self.holders.clear()
        if refuse:
            self._withdraw(holders - set(spare), refuse, DoorRefused)
        if withdraw:
            self._withdraw(holders, withdraw)
        if shut:
            self._withdraw(holders, shut, DoorShut)
        if self._open_timer is not None:
            self._open_timer.cancel()
            self._open_timer = None
