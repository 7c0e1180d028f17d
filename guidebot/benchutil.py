"""Small helpers every benchmark uses: percentiles, the closing JSON line, a loop-stall probe."""

from __future__ import annotations

import asyncio
import contextlib
import json
import statistics
import time
from collections.abc import Sequence
from typing import Any


def percentiles(samples: Sequence[float], digits: int = 3) -> dict[str, float | None]:
    """p50 and p99 of samples (None when there are none), rounded for printing."""
    if not samples:
        return {"p50": None, "p99": None}
    ordered = sorted(samples)
    p99_index = min(len(ordered) - 1, max(0, round(0.99 * len(ordered)) - 1))
    return {
        "p50": round(statistics.median(ordered), digits),
        "p99": round(ordered[p99_index], digits),
    }


def print_result(result: dict[str, Any]) -> None:
    """The benchmark's last line: one JSON object."""
    print(json.dumps(result, sort_keys=False), flush=True)


class LoopStall:
    """How late a 1 ms ticker on the running event loop ran while the block ran: how long
    anything else on that loop would have waited (the longest, and every tick's lateness).

        async with LoopStall() as probe:
            await something()
        probe.max_ms, probe.over(20.0), probe.seconds
    """

    def __init__(self, tick_s: float = 0.001) -> None:
        self.tick_s = tick_s
        self.lates_ms: list[float] = []
        self.seconds = 0.0
        self._task: asyncio.Task[None] | None = None

    async def _tick(self) -> None:
        clock = time.perf_counter
        while True:
            t0 = clock()
            await asyncio.sleep(self.tick_s)
            late = (clock() - t0 - self.tick_s) * 1000
            self.lates_ms.append(late)

    @property
    def max_ms(self) -> float:
        """The longest stall (0 when no tick ran)."""
        return max(self.lates_ms, default=0.0)

    def percentile(self, q: float) -> float:
        """The tick lateness below which a fraction ``q`` of the ticks stayed (ms)."""
        ordered = sorted(self.lates_ms) or [0.0]
        return ordered[int(q * (len(ordered) - 1))]

    def over(self, ms: float) -> int:
        """Ticks later than ``ms``."""
        return sum(1 for late in self.lates_ms if late > ms)

    async def __aenter__(self) -> LoopStall:
        self._task = asyncio.get_running_loop().create_task(self._tick())
        await asyncio.sleep(0)  # the ticker is running before the measured work starts
        self.seconds = time.perf_counter()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.seconds = time.perf_counter() - self.seconds
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
