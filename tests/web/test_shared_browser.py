"""The browser fixtures themselves (tests/web/conftest.py): the browser tests of one pytest
process share its Chromium and event loop, and yet a test starts as if it had them to itself:
no context left open, no task of the test before still running, no thread of its executor
left. Run as a pytest session of its own, so that the two tests run in this order, in one
process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

ROOT = Path(__file__).resolve().parents[2]

TWO_TESTS = """
import asyncio
import threading
import time

FIRST = {}


async def test_first(browser, open_page):
    FIRST["browser"] = browser
    FIRST["loop"] = asyncio.get_running_loop()
    FIRST["task"] = asyncio.create_task(asyncio.sleep(3600), name="left-behind")
    await asyncio.get_running_loop().run_in_executor(None, time.sleep, 0)
    main = threading.main_thread()
    FIRST["threads"] = {t for t in threading.enumerate() if not t.daemon and t is not main}
    watch = await open_page("")
    await watch.page.context.add_cookies(
        [{"name": "seen", "value": "1", "url": "http://127.0.0.1/"}]
    )


async def test_second(browser, open_page):
    assert browser is FIRST["browser"] and browser.is_connected()
    assert asyncio.get_running_loop() is FIRST["loop"]
    assert FIRST["task"].cancelled()
    assert FIRST["threads"] and not any(t.is_alive() for t in FIRST["threads"])
    assert browser.contexts == []
    watch = await open_page("")
    assert await watch.page.context.cookies() == []
"""

INI = """[pytest]
asyncio_mode = auto
asyncio_default_fixture_loop_scope = function
markers = browser: tests that drive headless Chromium
filterwarnings = error
"""


def test_browser_tests_share_chromium_and_loop_but_start_clean(tmp_path: Path) -> None:
    (tmp_path / "pytest.ini").write_text(INI)
    (tmp_path / "test_two.py").write_text(TWO_TESTS)
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "web.conftest", "-q", "-p", "no:cacheprovider"],
        cwd=tmp_path,
        env={"PATH": "/usr/bin:/bin", "PYTHONPATH": f"{ROOT}:{ROOT / 'tests'}"},
        capture_output=True,
        text=True,
        timeout=100,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "2 passed" in run.stdout
