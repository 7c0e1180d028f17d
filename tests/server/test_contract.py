"""The REST contract as a third-party client reads it from the OpenAPI document: the token is
checked first, a method a route does not take is 405 with the route's own Allow, every status
an operation answers is listed, and request bodies are closed objects of strict values."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx

from backend.testing import RunningServer, running_server

from .conftest import PANEL_TOKEN, server_settings

METHODS = ("get", "put", "post", "delete", "patch")
Schema = dict[str, Any]


def concrete(path: str) -> str:
    """A path with its parameters filled with ids that exist nowhere (a version: a number)."""
    return re.sub(r"\{[a-z_]+\}", "zz-none", path.replace("{version}", "999"))


def operations(openapi: Schema) -> Iterator[tuple[str, str, Schema]]:
    for path, item in openapi["paths"].items():
        for method, operation in item.items():
            if method in METHODS:
                yield method.upper(), path, operation


def resolve(openapi: Schema, schema: Schema) -> Schema:
    while "$ref" in schema:
        schema = openapi["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    return schema


def without_null(openapi: Schema, schema: Schema) -> Schema:
    """``X | None`` as ``X``."""
    schema = resolve(openapi, schema)
    choices = [s for s in schema.get("anyOf", []) if s.get("type") != "null"]
    return resolve(openapi, choices[0]) if len(choices) == 1 else schema


def json_body(openapi: Schema, operation: Schema) -> Schema | None:
    content = operation.get("requestBody", {}).get("content", {})
    if "application/json" not in content:
        return None
    return without_null(openapi, content["application/json"]["schema"])


BAD_VALUES: dict[str, list[Any]] = {
    "integer": [True, "2", 2.5],
    "boolean": [1, "true"],
    "number": [True, "2.5"],
}


def strictness_cases(
    openapi: Schema, schema: Schema, where: tuple[str | int, ...] = (), depth: int = 0
) -> Iterator[tuple[Any, tuple[str | int, ...], str]]:
    """(a body, the place of its one mistake, what is wrong) for every closed object and
    every integer, boolean and number of a request body's schema, nested objects included."""
    schema = without_null(openapi, schema)
    if schema.get("type") != "object" or depth > 3:
        return
    if "properties" in schema:
        yield {"zz_unknown": 1}, (*where, "zz_unknown"), "extra key"
    for name, prop in schema.get("properties", {}).items():
        prop = without_null(openapi, prop)
        for bad in BAD_VALUES.get(prop.get("type", ""), []):
            yield {name: bad}, (*where, name), f"{prop['type']} given {bad!r}"
        if prop.get("type") == "object":
            for body, place, what in strictness_cases(openapi, prop, (*where, name), depth + 1):
                yield {name: body}, place, what
        items = prop.get("items")
        if prop.get("type") == "array" and items is not None:
            for body, place, what in strictness_cases(openapi, items, (*where, name, 0), depth + 1):
                yield {name: [body]}, place, what


async def test_request_bodies_are_closed_objects_of_strict_values(
    lenient: RunningServer,
) -> None:
    """Walks every JSON request body of the OpenAPI document: an unknown key, ``true`` or
    ``"2"`` for an integer, ``1`` for a boolean, each answers 422 naming its place (it used to
    roll the site back to version 1 for ``{"version": true}``)."""
    openapi = lenient.app.openapi()
    admin = {"Authorization": f"Bearer {lenient.admin_token}"}
    lax: list[str] = []
    checked = 0
    async with httpx.AsyncClient(base_url=lenient.url, headers=admin, timeout=10) as http:
        for method, path, operation in operations(openapi):
            schema = json_body(openapi, operation)
            if schema is None:
                continue
            if schema.get("type") == "object" and "properties" in schema:
                if schema.get("additionalProperties") is not False:
                    lax.append(f"{method} {path}: the body schema is not closed")
            for body, place, what in strictness_cases(openapi, schema):
                checked += 1
                answer = await http.request(method, concrete(path), json=body)
                places = (
                    [tuple(e["loc"][1:]) for e in answer.json()["detail"]]
                    if answer.status_code == 422 and isinstance(answer.json()["detail"], list)
                    else []
                )
                if place not in places:
                    lax.append(f"{method} {path} {place} ({what}) -> {answer.status_code}")
    assert lax == []
    assert checked > 30  # every body was walked, nested ones too


async def test_an_unknown_query_parameter_is_refused_naming_what_the_route_takes(
    lenient: RunningServer,
) -> None:
    """``GET /api/tasks?states=done`` (for ``state``) answered every task, 200: a client took
    the whole list for the finished ones. Every operation now answers a query parameter it
    does not declare with 422 ``extra_forbidden`` at ``["query", name]``, after the token
    check (401 without one); a declared one, and ``?token=``, still pass."""
    openapi = lenient.app.openapi()
    admin = {"Authorization": f"Bearer {lenient.admin_token}"}
    wrong: list[str] = []
    async with httpx.AsyncClient(base_url=lenient.url, timeout=10) as http:
        for method, path, operation in operations(openapi):
            if operation.get("x-open-query"):  # another party's redirect (the SSO callback)
                continue
            url = concrete(path)
            answer = await http.request(method, url, params={"zz_unknown": "1"}, headers=admin)
            detail = answer.json().get("detail") if answer.status_code == 422 else None
            if not (
                isinstance(detail, list)
                and {"loc": ["query", "zz_unknown"], "type": "extra_forbidden"}.items()
                <= detail[0].items()
            ):
                wrong.append(f"{method} {path} -> {answer.status_code} {answer.text[:120]}")
        no_token = await http.get("/api/tasks", params={"states": "done"})
        misspelt = await http.get("/api/tasks", params={"states": "done"}, headers=admin)
        spelt = await http.get("/api/tasks", params={"state": "done"}, headers=admin)
        by_query = await http.get("/api/tasks", params={"token": lenient.admin_token})
    assert wrong == []
    assert no_token.status_code == 401
    assert misspelt.status_code == 422
    assert "takes include_internal, limit, offset, robot, state, token" in misspelt.text
    assert spelt.status_code == 200 and by_query.status_code == 200


async def test_the_token_is_checked_before_the_body(lenient: RunningServer) -> None:
    """A body that is not JSON (or not even text) is 401 without a token and 403 for a role
    the operation is not for, as any other body: the token first, everywhere."""
    openapi = lenient.app.openapi()
    wrong: list[str] = []
    async with httpx.AsyncClient(base_url=lenient.url, timeout=10) as http:
        for method, path, operation in operations(openapi):
            if "requestBody" not in operation or "401" not in operation["responses"]:
                continue
            if operation.get("x-sign-in"):
                continue  # signing in: the credentials are the body (test_accounts.py)
            for body in (b"{not json", b"\xff\xfe\xfa"):
                headers = {"Content-Type": "application/json"}
                answer = await http.request(method, concrete(path), content=body, headers=headers)
                if answer.status_code != 401:
                    wrong.append(f"no token: {method} {path} -> {answer.status_code}")
                headers["Authorization"] = f"Bearer {PANEL_TOKEN}"
                answer = await http.request(method, concrete(path), content=body, headers=headers)
                if answer.status_code not in (403, 422, 429):  # 429: the panel's task limit
                    wrong.append(f"panel: {method} {path} -> {answer.status_code}")
                if path.startswith("/api/site") and answer.status_code != 403:
                    wrong.append(f"panel: {method} {path} -> {answer.status_code}, not 403")
    assert wrong == []


async def test_a_method_an_api_route_does_not_take_is_405_with_its_own_allow(
    lenient: RunningServer,
) -> None:
    """``GET /api/nets/kill`` answered the web files' ``405 Allow: GET, HEAD``; now every
    /api path answers the methods it does not take with 405 and its real Allow, OPTIONS with
    204 and the same Allow, and a path no route has with a JSON 404."""
    openapi = lenient.app.openapi()
    wrong: list[str] = []
    async with httpx.AsyncClient(base_url=lenient.url, timeout=10) as http:
        for path in openapi["paths"]:
            if not path.startswith("/api/"):
                continue
            # Every template the filled path matches (uploads/plan is also uploads/{name}).
            taken = {
                m.upper()
                for other, item in openapi["paths"].items()
                if re.fullmatch(re.sub(r"\{[a-z_]+\}", "[^/]+", other), concrete(path))
                for m in item
                if m in METHODS
            }
            allow = taken | {"OPTIONS"} | ({"HEAD"} if "GET" in taken else set())
            url = concrete(path)
            for method in {m.upper() for m in METHODS} - taken:
                answer = await http.request(method, url)
                got = set(answer.headers.get("allow", "").replace(" ", "").split(","))
                if answer.status_code != 405 or got != allow:
                    wrong.append(f"{method} {path} -> {answer.status_code} Allow {got}")
            answer = await http.options(url)
            got = set(answer.headers.get("allow", "").replace(" ", "").split(","))
            if answer.status_code != 204 or got != allow:
                wrong.append(f"OPTIONS {path} -> {answer.status_code} Allow {got}")
        missing = await http.post("/api/no/such/thing")
    assert wrong == []
    assert missing.status_code == 404 and missing.json() == {"detail": "Not Found"}


async def test_each_operation_lists_the_statuses_of_its_kind(lenient: RunningServer) -> None:
    """Public operations (the site's pictures) promise no 401/403 and answer without a token;
    the uploads list the 415 they answer for a missing content type."""
    openapi = lenient.app.openapi()
    media = openapi["paths"]["/media/{name}"]["get"]["responses"]
    assert not {"401", "403", "429"} & set(media)
    for path in ("/api/site/uploads/plan", "/api/site/uploads/media"):
        assert "415" in openapi["paths"][path]["post"]["responses"], path
    for method, path, operation in operations(openapi):
        if path.startswith("/api/") and path != "/api/health":
            assert {"401", "403"} <= set(operation["responses"]), (method, path)
    admin = {"Authorization": f"Bearer {lenient.admin_token}"}
    async with httpx.AsyncClient(base_url=lenient.url, timeout=10) as http:
        assert (await http.get("/media/no-such-picture.png")).status_code == 404
        untyped = await http.post("/api/site/uploads/plan", content=b"\x89PNG", headers=admin)
    assert untyped.status_code == 415


async def test_a_simulator_that_does_not_answer_is_a_documented_502(tmp_path: Path) -> None:
    settings = server_settings(tmp_path)
    settings.building_sim_url = "http://127.0.0.1:1"  # nothing listens on port 1
    async with running_server(settings) as server:
        responses = server.app.openapi()["paths"]["/api/building/simulator/press"]["post"]
        async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
            answer = await http.post(
                "/api/building/simulator/press",
                json={"button": "b1"},
                headers={"Authorization": f"Bearer {server.admin_token}"},
            )
    assert answer.status_code == 502
    assert "502" in responses["responses"]
