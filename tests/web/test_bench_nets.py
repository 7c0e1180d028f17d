"""``guidebot bench nets``: its result line, on a small net (the figures are the bench's job)."""

from __future__ import annotations

import pytest

from bench.nets import run

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def test_bench_nets_opens_and_rechecks_a_net_in_the_browser() -> None:
    result = await run(places=20, rounds=2, robots=3)
    assert result["places"] == 20 and result["rounds"] == 2 and result["robots"] == 3
    assert result["open_ms"]["p50"] > 0 and result["check_ms"]["p50"] > 0
    assert result["publish_ms"]["p50"] > 0
