"""The typed application state (backend/state.py): every name the server puts on app.state is
declared with its type, and reads as before (None while its part does not run)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from starlette.applications import Starlette

from backend.app import create_app
from backend.settings import Settings
from backend.state import AppState, app_state

BACKEND = Path(__file__).resolve().parents[2] / "backend"
ASSIGNED = re.compile(r"\bapp\.state\.(\w+)\s*=[^=]|\bapp\.state\.(\w+),\s*app\.state\.(\w+)\s*=")


def test_every_name_put_on_app_state_is_declared() -> None:
    assigned = set()
    for path in BACKEND.rglob("*.py"):
        for match in ASSIGNED.finditer(path.read_text()):
            assigned.update(name for name in match.groups() if name)
    assert assigned, "the scan found no assignment: has app.state moved?"
    assert assigned <= set(AppState.__annotations__), assigned - set(AppState.__annotations__)


def test_a_part_that_does_not_run_reads_as_none_and_the_others_raise() -> None:
    state = AppState()
    assert state.leadership is None
    assert state.building is None
    assert state.fenced_endpoints == []
    with pytest.raises(AttributeError, match="hub"):
        _ = state.hub
    with pytest.raises(AttributeError, match="no_such_part"):
        _ = state.no_such_part  # type: ignore[attr-defined]


def test_the_typed_state_is_the_apps_own_values() -> None:
    bare = Starlette()
    bare.state.leadership = "leader"
    view = app_state(bare)
    assert view.leadership == "leader"
    view.building = "written through the view"  # type: ignore[assignment]
    assert bare.state.building == "written through the view"

    app = create_app(Settings(admin_token="x" * 32))
    assert app_state(app) is app.state
    assert app_state(app).settings is app.state.settings
