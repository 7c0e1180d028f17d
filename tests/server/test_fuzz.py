"""Property-based fuzz of the REST API from its own OpenAPI schema: no input gives a 5xx."""

from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor

import requests
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from backend.testing import RunningServer

from .conftest import OPERATOR_TOKEN, PANEL_TOKEN

MAX_EXAMPLES = 250


def fuzz(base_url: str, openapi: dict[str, object], tokens: list[str]) -> list[str]:
    """Runs in a worker thread (requests is blocking); returns the failures found."""
    schema = schemathesis.openapi.from_dict(openapi).include(path_regex="^/api/(?!hub)")
    failures: list[str] = []
    session = requests.Session()

    @settings(
        max_examples=MAX_EXAMPLES,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        database=None,
    )
    @given(case=schema.as_strategy(), token=st.sampled_from(tokens))
    def check(case: schemathesis.Case, token: str) -> None:
        response = case.call(
            base_url=base_url,
            session=session,
            headers={"Authorization": f"Bearer {token}"},
            timeout=10,
        )
        if response.status_code >= 500:
            failures.append(f"{case.method} {case.formatted_path} -> {response.status_code}")
        assert response.status_code < 500, response.text[:500]

    try:
        check()
    finally:
        session.close()
    return failures


async def test_no_input_gives_a_server_error(server: RunningServer) -> None:
    openapi = server.app.openapi()
    tokens = [server.admin_token, OPERATOR_TOKEN, PANEL_TOKEN, "robot-R1-demo-token"]
    executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fuzz")
    try:
        loop = asyncio.get_running_loop()
        failures = await loop.run_in_executor(executor, fuzz, server.url, openapi, tokens)
    finally:
        executor.shutdown(wait=True)
    assert failures == []
    # The fuzzing changed the site through the API; the server still answers sanely.
    assert server.app.state.sites.site.name
