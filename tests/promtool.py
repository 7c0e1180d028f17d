"""Prometheus's own linter on a scrape: ``promtool check metrics`` (Debian's ``prometheus``
package, installed by scripts/system-deps.sh)."""

from __future__ import annotations

import asyncio
import shutil


async def promtool_accepts(scrape: str) -> None:
    """Fail with promtool's own words when it finds a problem in ``scrape``."""
    promtool = shutil.which("promtool")
    assert promtool, "promtool not found: scripts/system-deps.sh installs Debian's prometheus"
    check = await asyncio.create_subprocess_exec(
        promtool,
        "check",
        "metrics",
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    output, _ = await check.communicate(scrape.encode())
    assert check.returncode == 0, output.decode()
