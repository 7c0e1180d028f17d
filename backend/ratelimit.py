"""Rate limits: task creation per requester, failed sign-ins per network address.

A token bucket per key: ``burst`` actions at once, refilled at ``per_minute``. Keys are bounded
(``max_keys``): the least recently used key is forgotten first, so a flood of new addresses or
names costs memory once, not forever (docs/security.md, "Rate limits").
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["RateLimited", "RateLimiter"]


class RateLimited(Exception):
    """Too many actions; ``retry_after`` seconds until the next one is allowed."""

    def __init__(self, what: str, retry_after: float) -> None:
        self.retry_after = max(1, int(retry_after + 0.999))
        super().__init__(f"{what}; try again in {self.retry_after} s")


@dataclass(slots=True)
class _Bucket:
    tokens: float
    at: float


class RateLimiter:
    """Token buckets by key. ``per_minute <= 0`` disables the limit."""

    def __init__(
        self,
        *,
        per_minute: float,
        burst: int,
        max_keys: int = 10_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.rate = per_minute / 60.0
        self.burst = max(1, burst)
        self.max_keys = max_keys
        self.clock = clock
        self._buckets: OrderedDict[str, _Bucket] = OrderedDict()

    @property
    def enabled(self) -> bool:
        return self.rate > 0

    def _bucket(self, key: str) -> _Bucket:
        now = self.clock()
        bucket = self._buckets.get(key)
        if bucket is None:
            bucket = _Bucket(float(self.burst), now)
            self._buckets[key] = bucket
            while len(self._buckets) > self.max_keys:
                self._buckets.popitem(last=False)
        else:
            bucket.tokens = min(self.burst, bucket.tokens + (now - bucket.at) * self.rate)
            bucket.at = now
            self._buckets.move_to_end(key)
        return bucket

    def wait_time(self, key: str) -> float:
        """Seconds before ``key`` may act again (0: now), without spending anything."""
        if not self.enabled:
            return 0.0
        bucket = self._bucket(key)
        return 0.0 if bucket.tokens >= 1 else (1 - bucket.tokens) / self.rate

    def spend(self, key: str, what: str) -> None:
        """Count one action of ``key``; raises RateLimited (nothing spent) when over."""
        if not self.enabled:
            return
        bucket = self._bucket(key)
        if bucket.tokens < 1:
            raise RateLimited(what, (1 - bucket.tokens) / self.rate)
        bucket.tokens -= 1

    def forget(self, key: str) -> None:
        self._buckets.pop(key, None)
