"""Fixtures of the RoboGraph tests (the rig itself is in rig.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from .rig import Rig, make_rig


@pytest.fixture
def rig() -> Iterator[Rig]:
    """The real library, nobody answering (tests play the robot by hand)."""
    r = make_rig()
    yield r
    r.dispatch.close()
