"""Small helpers every benchmark uses: percentiles and the closing JSON line."""

from __future__ import annotations

import json
import statistics
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
