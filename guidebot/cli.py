"""The ``guidebot`` command: one subcommand per process, each loaded only when used.

A subcommand is listed here as ``name -> "module:attribute"``; the module defines a click
command or group. Loading lazily keeps ``guidebot --help`` fast and lets each package own its
command-line code.
"""

from __future__ import annotations

import importlib
from typing import Any

import click

from guidebot.heap import no_final_collection, quiet_imports

COMMANDS: dict[str, str] = {
    "robot": "robot_agent.cli:robot",
    "demo": "guidebot.demo:demo",
    "petri": "petri_nets.cli:petri",
    "server": "backend.server_cli:server",
    "site": "backend.site.cli:site",
    "robocan": "robot_agent.robocan.cli:robocan",
    "building-sim": "building_sim.cli:building_sim",
    "vda5050-sim": "guidebot.vda5050.cli:vda5050_sim",
    "replay": "backend.reports.cli:replay_command",
    "plan": "backend.planning.cli:plan_command",
    "users": "backend.accounts.cli:users",
    "bookings": "backend.bookings.cli:bookings",
    "webtypes": "guidebot.webtypes:webtypes",
}

BENCHMARKS: dict[str, str] = {
    "robot": "bench.robot:main",
    "hub": "bench.hub:hub",
    "reclaim": "bench.hub_reclaim:main",
    "petri": "bench.petri:main",
    "robocan": "bench.robocan:main",
    "traffic": "bench.traffic:main",
    "tasks": "bench.tasks:main",
    "modbus": "bench.modbus:main",
    "reconfigure": "bench.reconfigure:main",
    "console": "bench.console:main",
    "captions": "bench.captions:main",
    "nets": "bench.nets:main",
    "reaction": "bench.reaction:main",
    "emergency": "bench.emergency:main",
    "soak": "bench.soak:main",
    "failover": "bench.failover:main",
    "vda5050": "bench.vda5050:main",
    "reports": "bench.reports:main",
    "plan": "bench.plan:main",
    "plan-check": "bench.plan_check:main",
    "eta": "bench.eta:main",
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def __init__(self, *args: Any, lazy: dict[str, str], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy = lazy

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.lazy:
            module_name, attribute = self.lazy[cmd_name].split(":")
            with quiet_imports():
                command = getattr(importlib.import_module(module_name), attribute)
            if not isinstance(command, click.Command):
                raise TypeError(f"{self.lazy[cmd_name]} is not a click command")
            return command
        return super().get_command(ctx, cmd_name)


@click.group(cls=LazyGroup, lazy=COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="guidebot")
def main() -> None:
    """GuideBot: run the central server, robots, building simulator, tools and benchmarks."""
    no_final_collection()  # guidebot/heap.py: no collection of the whole heap at exit


@main.group(cls=LazyGroup, lazy=BENCHMARKS)
def bench() -> None:
    """Benchmarks; each prints one JSON object as its last line."""


if __name__ == "__main__":
    main()
