"""One rule per action, wherever it arrives from: docs/server.md's REST table, docs/protocol.md's
publish table, the routes' token checks, the hub's publish check and the server's answers must
all say the same (backend/actions.py)."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
from fastapi import FastAPI
from fastapi.routing import APIRoute, iter_route_contexts

from backend.actions import RULES, SERVER_ROLES, allowed_roles
from backend.auth import Role, RoleCheck
from backend.hub.permissions import ALWAYS, may_publish
from backend.testing import RunningServer
from guidebot.client import HubClient, HubError
from guidebot.messages import known_types
from guidebot.paths import ROOT

from .conftest import (
    GUI_TOKEN,
    MODULE_TOKEN,
    OPERATOR_TOKEN,
    PANEL_TOKEN,
    PERSON_TOKENS,
    server_settings,
)

ROLES = (
    Role.ADMIN,
    Role.OPERATOR,
    Role.PANEL,
    Role.ROBOT,
    Role.GUI,
    Role.MODULE,
    Role.INSTALLER,
    Role.AUTHOR,
    Role.VIEWER,
)
"""The role columns of docs/server.md's table, in order."""
ROBOT_NAME = "R1"
TOKENS = {
    Role.OPERATOR: OPERATOR_TOKEN,
    Role.PANEL: PANEL_TOKEN,
    Role.ROBOT: "robot-R1-demo-token",
    Role.GUI: GUI_TOKEN,
    Role.MODULE: MODULE_TOKEN,
    **PERSON_TOKENS,
}
NO = "—"


def table(doc: Path, header: str) -> list[list[str]]:
    """The rows (cells stripped) of the Markdown table whose header row starts ``header``."""
    lines = doc.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header))
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


@dataclass(frozen=True)
class RestRow:
    operations: tuple[tuple[str, str], ...]
    rule: str
    """An action of backend/actions.py, or "public" (no token)."""
    roles: frozenset[Role]


def rest_table() -> list[RestRow]:
    rows = []
    for cells in table(ROOT / "docs" / "server.md", "| operations | rule |"):
        operations = tuple(re.findall(r"`(GET|PUT|POST|DELETE) (/[^`]*)`", cells[0]))
        assert operations, cells[0]
        rule = cells[1].strip("`")
        roles = frozenset(r for r, cell in zip(ROLES, cells[2:], strict=True) if cell != NO)
        rows.append(RestRow(operations, rule, roles))
    return rows


def hub_table() -> dict[Role, frozenset[str] | None]:
    """Role -> the types docs/protocol.md lets it publish (None: every registered type)."""
    found: dict[Role, frozenset[str] | None] = {}
    for cells in table(ROOT / "docs" / "protocol.md", "| role | may publish |"):
        types = frozenset(re.findall(r"`([a-z_]+)`", cells[1]))
        every = cells[1].startswith("every registered type")
        for role in cells[0].split(", "):
            found[Role(role)] = None if every else types
    return found


def server_only_list() -> frozenset[str]:
    text = (ROOT / "docs" / "protocol.md").read_text()
    paragraph = text[text.index("Server-only (no remote client") :].split("\n\n")[0]
    return frozenset(re.findall(r"`([a-z_]+)`", paragraph))


def role_check(route: APIRoute) -> RoleCheck | None:
    """The token check among a route's dependencies (None: a public route)."""
    pending = list(route.dependant.dependencies)
    while pending:
        dependant = pending.pop()
        if hasattr(dependant.call, "roles"):
            return dependant.call  # type: ignore[return-value]
        pending.extend(dependant.dependencies)
    return None


def api_routes(app: FastAPI) -> Iterator[tuple[str, str, APIRoute]]:
    for context in iter_route_contexts(app.routes):
        route = context.original_route if hasattr(context, "original_route") else context
        if isinstance(route, APIRoute):
            for method in sorted(route.methods):
                yield method, route.path.replace("{name:path}", "{name}"), route


def test_the_hub_publishes_what_docs_protocol_says_for_every_role_and_type() -> None:
    documented = hub_table()
    assert set(documented) == set(Role)
    registered = known_types()
    for role, types in documented.items():
        assert types is None or types <= registered, (role, sorted(types - registered))
        for type_ in registered:
            says = types is None or type_ in types or type_ in ALWAYS
            assert may_publish(role, type_) is says, (role.value, type_)
    remote = {t for t in registered if any(may_publish(r, t) for r in set(Role) - SERVER_ROLES)}
    assert server_only_list() == registered - remote - ALWAYS


def test_every_route_checks_the_rule_docs_server_names_for_it() -> None:
    from backend.app import create_app

    documented = {op: row for row in rest_table() for op in row.operations}
    seen = set()
    for method, path, route in api_routes(create_app(server_settings(ROOT))):
        row = documented.get((method, path))
        assert row is not None, f"{method} {path} is missing from docs/server.md's table"
        seen.add((method, path))
        check = role_check(route)
        if row.rule == "public":
            assert check is None, f"{method} {path} checks a token but the docs say public"
            assert row.roles == set(ROLES)
            continue
        assert check is not None, f"{method} {path} checks no token"
        assert check.action == row.rule, (method, path)
        assert check.roles == allowed_roles(row.rule) == row.roles, (method, path)
    assert seen == set(documented), sorted(set(documented) - seen)


def test_an_action_over_rest_and_over_the_hub_is_allowed_to_the_same_roles() -> None:
    hub = hub_table()
    shared = [row for row in rest_table() if row.rule in known_types()]
    assert {row.rule for row in shared} == {"task_request", "kill_petri_net"}
    for row in shared:
        over_hub = {r for r, types in hub.items() if types is None or row.rule in types}
        assert row.roles == over_hub, row.rule
        assert {r for r in Role if may_publish(r, row.rule)} == row.roles, row.rule
    assert set(RULES) >= {row.rule for row in rest_table() if row.rule != "public"}


def concrete(path: str) -> str:
    """A path with its parameters filled: ids that exist nowhere, the robot's own name."""
    path = path.replace("{name}", ROBOT_NAME).replace("{version}", "999")
    return re.sub(r"\{[a-z_]+\}", "zz-none", path)


async def test_the_server_answers_each_role_as_the_docs_say(lenient: RunningServer) -> None:
    """Every documented operation, called with a token of every role and with none: 403
    exactly for the roles the docs leave out, 401 without a token unless public. Bodies are
    an empty object: nothing is changed."""
    tokens = {**TOKENS, Role.ADMIN: lenient.admin_token}
    wrong: list[str] = []
    async with httpx.AsyncClient(base_url=lenient.url, timeout=10) as http:
        for row in rest_table():
            for method, path in row.operations:
                url = concrete(path)
                answer = await http.request(method, url, json={} if method != "GET" else None)
                if (answer.status_code == 401) is (row.rule == "public"):
                    wrong.append(f"no token: {method} {url} -> {answer.status_code}")
                for role, token in tokens.items():
                    answer = await http.request(
                        method,
                        url,
                        json={} if method != "GET" else None,
                        headers={"Authorization": f"Bearer {token}"},
                    )
                    if (answer.status_code == 403) is (role in row.roles):
                        wrong.append(f"{role.value}: {method} {url} -> {answer.status_code}")
    assert wrong == []


async def test_an_operator_may_not_kill_a_net_over_the_hub_as_over_rest(
    lenient: RunningServer,
) -> None:
    async with HubClient(lenient.ws_url, OPERATOR_TOKEN) as operator:
        with pytest.raises(HubError) as refused:
            await operator.request(
                "kill_petri_net", {"instance_id": "R1-waiting-1"}, destination=ROBOT_NAME
            )
    assert refused.value.code == "forbidden_type"
    async with httpx.AsyncClient(base_url=lenient.url, timeout=10) as http:
        answer = await http.post(
            "/api/nets/kill",
            json={"target": ROBOT_NAME, "instance_id": "R1-waiting-1"},
            headers={"Authorization": f"Bearer {OPERATOR_TOKEN}"},
        )
    assert answer.status_code == 403


async def test_a_panel_requests_over_the_hub_on_the_rest_terms(lenient: RunningServer) -> None:
    poi = lenient.app.state.sites.site.pois[0].id
    async with HubClient(lenient.ws_url, PANEL_TOKEN) as panel:
        answer = await panel.request("task_request", {"kind": "go_to_poi", "params": {"poi": poi}})
        assert answer.type == "task_event"
        for payload, code in [
            ({"kind": "charge"}, "forbidden_request"),
            ({"kind": "go_to_poi", "params": {"poi": poi}, "priority": 6}, "forbidden_request"),
            ({"kind": "go_to_poi", "params": {"poi": poi}, "requester": "x"}, "impersonation"),
        ]:
            with pytest.raises(HubError) as refused:
                await panel.request("task_request", payload)
            assert refused.value.code == code, payload
    task = lenient.app.state.task_manager.get(answer.payload["task_id"])
    assert task.requester == "panel-1"
