"""``guidebot building-sim``: run the building simulator, press its buttons, inject faults.

    guidebot building-sim --site sites/demo_museum.yaml [--time-scale 5] [--control-port 15080]
    guidebot building-sim press button_entrance --ms 300
    guidebot building-sim fault otb_first offline

Once listening, the simulator prints one JSON line: {"ready": true, "control": URL,
"modules": {id: port}}, so launchers and benchmarks can find the ports it bound.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import sys
from pathlib import Path

import click
import httpx

from guidebot.site.building_config import BuildingConfigError, load_building_file

__all__ = ["building_sim"]

DEFAULT_CONTROL_PORT = 15080
DEFAULT_URL = f"http://127.0.0.1:{DEFAULT_CONTROL_PORT}"


@click.group("building-sim", invoke_without_command=True)
@click.option("--site", "site_path", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--time-scale", type=click.FloatRange(min=0.001), default=1.0, show_default=True)
@click.option("--control-port", type=click.IntRange(0, 65535), default=DEFAULT_CONTROL_PORT)
@click.option("--port-zero", is_flag=True, help="Bind every module to a free port (tests).")
@click.option("--scenario", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.pass_context
def building_sim(
    ctx: click.Context,
    site_path: Path | None,
    time_scale: float,
    control_port: int,
    port_zero: bool,
    scenario: Path | None,
) -> None:
    """Serve every Modbus I/O module of a site on 127.0.0.1, with live doors and elevators."""
    if ctx.invoked_subcommand is not None:
        return
    if site_path is None:
        raise click.UsageError("--site FILE is required to run the simulator")
    try:
        config = load_building_file(site_path)
    except BuildingConfigError as exc:
        raise click.ClickException(str(exc)) from None
    if not config.modules:
        raise click.ClickException(f"site {site_path} has no Modbus modules to simulate")
    try:
        asyncio.run(_serve(config, time_scale, control_port, port_zero, scenario))
    except OSError as exc:
        raise click.ClickException(f"cannot listen: {exc}") from None


async def _serve(
    config: object, time_scale: float, control_port: int, port_zero: bool, scenario: Path | None
) -> None:
    from building_sim.control import serve_control
    from building_sim.scenario import ScenarioError, load_scenario, run_scenario
    from building_sim.simulator import BuildingSimulator

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    async with (
        BuildingSimulator(config, time_scale=time_scale, port_zero=port_zero) as sim,  # type: ignore[arg-type]
        serve_control(sim, port=control_port) as url,
    ):
        steps = []
        if scenario is not None:
            try:
                steps = load_scenario(scenario, sim)
            except ScenarioError as exc:
                raise click.ClickException(str(exc)) from None
        print(json.dumps({"ready": True, "control": url, "modules": sim.ports}), flush=True)
        player = asyncio.create_task(run_scenario(sim, steps)) if steps else None
        try:
            await stop.wait()
        finally:
            if player is not None:
                player.cancel()
                await asyncio.gather(player, return_exceptions=True)


def _post(url: str, path: str, body: dict[str, object]) -> None:
    try:
        reply = httpx.post(f"{url}{path}", json=body, timeout=5.0)
    except httpx.HTTPError as exc:
        raise click.ClickException(f"building simulator not reachable at {url}: {exc}") from None
    if reply.status_code >= 400:
        try:
            detail = reply.json().get("detail", reply.text)
        except ValueError:
            detail = reply.text
        raise click.ClickException(f"{reply.status_code}: {detail}")
    click.echo(json.dumps(reply.json()))


@building_sim.command("press")
@click.argument("button")
@click.option("--ms", type=click.FloatRange(min=1), default=300.0, show_default=True)
@click.option("--url", default=DEFAULT_URL, show_default=True, help="Control API of the simulator.")
def press(button: str, ms: float, url: str) -> None:
    """Press BUTTON for --ms milliseconds."""
    _post(url, f"/buttons/{button}/press", {"ms": ms})


@building_sim.command("fault")
@click.argument("module")
@click.argument("kind", type=click.Choice(["none", "offline", "slow", "exception"]))
@click.option("--delay-ms", type=click.FloatRange(min=0), default=0.0)
@click.option("--code", type=click.IntRange(1, 11), default=4, show_default=True)
@click.option("--url", default=DEFAULT_URL, show_default=True, help="Control API of the simulator.")
def fault(module: str, kind: str, delay_ms: float, code: int, url: str) -> None:
    """Inject a fault into MODULE (kind "none" clears it)."""
    _post(url, f"/modules/{module}/fault", {"kind": kind, "delay_ms": delay_ms, "code": code})


if __name__ == "__main__":  # pragma: no cover
    sys.exit(building_sim())
