"""bench traffic, briefly: its JSON names every figure, including the loop stalls of a site
publish and load on the running server (both must succeed, or the bench fails) and how long
the robots following the site from another process took to confirm each version."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from backend.testing import RunningServer
from bench.traffic import main, site_followers


def test_bench_traffic_reports_paths_and_loop_stalls() -> None:
    args = ["--nodes", "400", "--robots", "5", "--queries", "50", "--seconds", "1", "--json"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output.strip().splitlines()[-1])
    for key in ("any_pair_path_ms", "any_pair_path_cpu_ms", "destination_lookup_ms"):
        assert figures[key]["p50"] is not None and figures[key]["p99"] >= figures[key]["p50"]
    for key in ("idle_max_stall_ms", "publish_max_stall_ms", "load_max_stall_ms"):
        assert figures[key] >= 0.0
    windows = figures["stalls"]
    for name in ("publish", "load", "idle"):
        assert windows[name]["max"] >= windows[name]["p999"] and windows[name]["over_20"] >= 0
    # the idle reference lasts as long as the longer of the two reloads
    assert windows["idle"]["seconds"] >= max(
        windows["publish"]["seconds"], windows["load"]["seconds"]
    )
    assert figures["build_workers_s"] > 0.0
    # --followers defaults to 20, at most --robots: all five confirmed both versions
    assert figures["rollout_ms"]["publish"] > 0.0 and figures["rollout_ms"]["load"] > 0.0


async def test_site_followers_refused_by_the_hub_stop_the_bench(server: RunningServer) -> None:
    """A follower whose token the hub refuses ends the followers' process (HubClient.start
    raises the refusal), and the bench fails saying so instead of measuring without it."""
    with pytest.raises(RuntimeError, match="did not start"):
        async with site_followers(server.ws_url, [("R1", "not-a-token-of-this-site")]):
            pass
