"""`guidebot bench modbus` keeps working: a short run prints the agreed JSON line."""

from __future__ import annotations

import asyncio
import json
import sys


async def test_bench_modbus_prints_its_result_line() -> None:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "guidebot.cli",
        "bench",
        "modbus",
        "--modules",
        "3",
        "--period-ms",
        "50",
        "--seconds",
        "2",
        "--json",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(process.communicate(), 90)
    assert process.returncode == 0, err.decode()
    result = json.loads(out.decode().strip().splitlines()[-1])
    assert list(result) == ["modules", "period_ms", "jitter_ms", "cpu_percent", "detect_ms"]
    assert result["modules"] == 3
    assert result["period_ms"] == 50
    assert set(result["jitter_ms"]) == {"p50", "p99"}
    # Every press lasted filter + period + 200 ms: each was detected, after at least the filter.
    assert result["detect_ms"]["p50"] >= 200
