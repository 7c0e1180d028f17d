"""The load of ``guidebot bench vda5050``, in a process of its own: ``--robots`` VDA 5050
vehicles on one MQTT connection that only report (``connection`` ONLINE, then ``state`` at
``--rate`` Hz each, spread evenly, the state's timestamp the moment it is sent), and ``--movers``
full simulated vehicles (guidebot/vda5050/sim.py) that take orders. Prints ``ready`` once
everything is connected, runs until killed."""

from __future__ import annotations

import asyncio
import json
import sys

import aiomqtt
import click

from guidebot.vda5050.mqtt import NO_DELAY
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import Vehicle, parse_broker

MANUFACTURER = "Bench"


def serial(i: int) -> str:
    return f"V{i:04d}"


@click.command()
@click.option("--broker", required=True)
@click.option("--robots", type=int, required=True, help="Vehicles that only report.")
@click.option("--movers", type=int, default=0, help="Simulated vehicles that drive (after).")
@click.option("--rate", type=float, default=1.0, help="States per second per vehicle.")
@click.option("--time-scale", type=float, default=10.0)
def main(broker: str, robots: int, movers: int, rate: float, time_scale: float) -> None:
    asyncio.run(_run(broker, robots, movers, rate, time_scale))


async def _run(broker: str, robots: int, movers: int, rate: float, time_scale: float) -> None:
    address = parse_broker(broker)
    reporters = [
        SimVehicle(address, Vehicle(MANUFACTURER, serial(i)), map_id="F0", node="n0")
        for i in range(robots)
    ]
    drivers = [
        SimVehicle(
            address,
            Vehicle(MANUFACTURER, serial(robots + i)),
            x=0.0,
            map_id="F0",
            node="n0",
            speed=1.0,
            time_scale=time_scale,
        )
        for i in range(movers)
    ]
    for driver in drivers:
        await driver.start()
    async with aiomqtt.Client(
        address.host, address.port, identifier="bench-load", socket_options=NO_DELAY
    ) as client:
        for sim in reporters:
            online = {**sim.vehicle.header(0), "connectionState": "ONLINE"}
            await client.publish(sim.vehicle.topic("connection"), json.dumps(online), qos=1)
        for driver in drivers:
            await driver.session.connected.wait()
        print("ready", flush=True)
        period = 1.0 / rate
        loop = asyncio.get_running_loop()
        start = loop.time()
        n = 0
        while True:
            for k, sim in enumerate(reporters):
                due = start + n * period + k * period / max(1, len(reporters))
                delay = due - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
                await client.publish(sim.vehicle.topic("state"), json.dumps(sim.state()), qos=0)
            n += 1


if __name__ == "__main__":
    sys.exit(main())
