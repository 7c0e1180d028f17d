"""``guidebot vda5050-sim``: run one simulated VDA 5050 vehicle until Ctrl-C (docs/vda5050.md)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
from pathlib import Path

import click

__all__ = ["vda5050_sim"]


@click.command("vda5050-sim")
@click.option("--broker", required=True, help="mqtt://[user:password@]host:1883 (mqtts:// TLS).")
@click.option(
    "--site",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="Take the vehicle's names, maps and start node from this site's --robot entry.",
)
@click.option("--robot", default=None, help="The robot of --site (interface: vda5050).")
@click.option("--manufacturer", default=None, help="Without --site: the manufacturer.")
@click.option("--serial-number", default=None, help="Without --site: the serial number.")
@click.option("--interface", default="uagv", show_default=True, help="The topics' first level.")
@click.option(
    "--vda-version",
    type=click.Choice(["2.1.0", "3.0.0"]),
    default=None,
    help="The version it speaks (default: its site entry's, else 2.1.0).",
)
@click.option("--x", type=float, default=0.0, help="Without --site: start x (m).")
@click.option("--y", type=float, default=0.0, help="Without --site: start y (m).")
@click.option("--map-id", default="map", help="Without --site: the start map.")
@click.option("--node", default="", help="Without --site: the node it stands on.")
@click.option("--speed", type=float, default=1.0, show_default=True, help="m/s.")
@click.option("--time-scale", type=float, default=1.0, show_default=True)
@click.option("--state-period", type=float, default=1.0, show_default=True, help="s (wall).")
def vda5050_sim(
    broker: str,
    site: Path | None,
    robot: str | None,
    manufacturer: str | None,
    serial_number: str | None,
    interface: str,
    vda_version: str | None,
    x: float,
    y: float,
    map_id: str,
    node: str,
    speed: float,
    time_scale: float,
    state_period: float,
) -> None:
    """A simulated VDA 5050 vehicle (2.1.0 or 3.0.0): follows orders, reports state
    (docs/vda5050.md)."""
    from guidebot.vda5050.sim import SimVehicle
    from guidebot.vda5050.topics import Vehicle, parse_broker

    try:
        address = parse_broker(broker)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    if site is not None:
        from guidebot.site.yamlio import load_site_file

        loaded = load_site_file(site)
        entry = loaded.robot(robot or "")
        if entry is None or entry.interface != "vda5050":
            raise click.UsageError(f"{site}: no VDA 5050 robot named {robot!r} (--robot)")
        assert entry.manufacturer is not None and entry.serial_number is not None
        vehicle = Vehicle(
            entry.manufacturer,
            entry.serial_number,
            entry.mqtt_interface,
            vda_version or entry.vda_version,
        )
        start = next((n for n in loaded.nodes if n.id == entry.start_node), loaded.nodes[0])
        x, y, node = start.x, start.y, start.id
        map_id = entry.map_ids.get(start.floor, start.floor)
    elif manufacturer and serial_number:
        vehicle = Vehicle(manufacturer, serial_number, interface, vda_version or "2.1.0")
    else:
        raise click.UsageError("give --site and --robot, or --manufacturer and --serial-number")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    sim = SimVehicle(
        address,
        vehicle,
        x=x,
        y=y,
        map_id=map_id,
        node=node,
        speed=speed,
        time_scale=time_scale,
        state_period_s=state_period,
    )

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(signum, stop.set)
        async with sim:
            click.echo(
                f"vda5050-sim: {vehicle.manufacturer}/{vehicle.serial_number} on {address}, "
                f"topics {vehicle.topic('#')}, at {node or (x, y)} on map {map_id}"
            )
            await stop.wait()  # then OFFLINE on its connection topic: a clean goodbye

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run())
