"""``guidebot robot``: run one robot agent until Ctrl-C or SIGTERM."""

from __future__ import annotations

import asyncio
import logging
import signal
from pathlib import Path

import click

from robot_agent.agent import AgentConfig, RobotAgent
from robot_agent.gui import VisitorAnswer

__all__ = ["robot", "run_agent"]


async def run_agent(config: AgentConfig, *, ready: asyncio.Event | None = None) -> None:
    """Run until SIGINT/SIGTERM; every module is stopped in reverse order on the way out."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        async with RobotAgent(config) as agent:
            gui = agent.screen_server.url if agent.screen_server else "-"
            click.echo(f"robot {config.name} ready: server={config.server or '-'} gui={gui}")
            if ready is not None:
                ready.set()
            await stop.wait()
            click.echo(f"robot {config.name} stopping")
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


@click.command()
@click.option("--name", required=True, help="Robot name as the site knows it (R1, ...).")
@click.option("--server", default=None, help="Central server URL, e.g. http://127.0.0.1:8000.")
@click.option("--token", default=None, envvar="GUIDEBOT_ROBOT_TOKEN", help="Bearer token.")
@click.option(
    "--can",
    "can_spec",
    default=None,
    help="CAN bus: virtual:R1 (default with --simulate) or socketcan:can0.",
)
@click.option("--no-can", is_flag=True, help="No CAN at all: a bare simulated base (light).")
@click.option("--simulate/--no-simulate", default=False, help="Bring simulated RoboCAN modules.")
@click.option("--time-scale", type=click.FloatRange(min=0.01), default=1.0, show_default=True)
@click.option("--gui-port", type=click.IntRange(0, 65535), default=None, help="Touch screen port.")
@click.option("--start-node", default=None, help="Map node where the robot starts.")
@click.option("--site", type=click.Path(exists=True, path_type=Path), default=None)
@click.option("--battery-level", type=click.FloatRange(0, 1), default=None)
@click.option("--state-period", type=click.FloatRange(min=0.05), default=1.0, show_default=True)
@click.option(
    "--visitor",
    type=click.Choice(["yes", "no"]),
    default=None,
    help="Demo: a simulated visitor answers the touch screen's question with this.",
)
@click.option(
    "--offline-requests",
    type=click.Choice(["queue", "refuse"]),
    default="queue",
    show_default=True,
    help="Touch-screen requests while the link to the server is down: kept and sent when it "
    "is back, or refused at once.",
)
@click.option("--log-level", default="info", show_default=True)
def robot(
    name: str,
    server: str | None,
    token: str | None,
    can_spec: str | None,
    no_can: bool,
    simulate: bool,
    time_scale: float,
    gui_port: int | None,
    start_node: str | None,
    site: Path | None,
    battery_level: float | None,
    state_period: float,
    visitor: VisitorAnswer | None,  # click.Choice(["yes", "no"])
    offline_requests: str,
    log_level: str,
) -> None:
    """Run one robot agent (on-board bus, RoboCAN, RG dispatch, navigation, speech, link, GUI)."""
    logging.basicConfig(
        level=log_level.upper(), format=f"%(asctime)s {name} %(levelname)s %(name)s: %(message)s"
    )
    if no_can and can_spec:
        raise click.UsageError("--no-can and --can exclude each other")
    if not no_can and can_spec is None:
        if not simulate:
            raise click.UsageError("without --simulate, say which bus: --can socketcan:can0")
        can_spec = f"virtual:{name}"
    if server and not token:
        raise click.UsageError("--server needs --token (or GUIDEBOT_ROBOT_TOKEN)")
    robot_params: dict[str, float] = {}
    if site is not None:
        from guidebot.site.yamlio import load_site_file

        known = load_site_file(site).robot(name)
        if known is not None:
            start_node = start_node or known.start_node
            robot_params = {
                "max_speed": known.max_speed_mps,
                "battery_low": known.battery_low,
                "battery_panic": known.battery_panic,
            }
    config = AgentConfig(
        name=name,
        server=server,
        token=token,
        can=None if no_can else can_spec,
        simulate=simulate or no_can,
        time_scale=time_scale,
        gui_port=gui_port,
        start_node=start_node,
        site=site,
        battery_level=battery_level,
        state_period_s=state_period,
        auto_answer=visitor,
        offline_requests="refuse" if offline_requests == "refuse" else "queue",
        **robot_params,  # type: ignore[arg-type]
    )
    try:
        asyncio.run(run_agent(config))
    except KeyboardInterrupt:
        pass
