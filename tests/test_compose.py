"""docker-compose.yml: every service's command is a valid `guidebot` command line with existing
site files and the site's robot tokens; tests/test_compose_engine.py runs the fleet on a
Docker engine."""

from __future__ import annotations

import re
import shlex
from pathlib import Path
from typing import Any

import click
import pytest
import yaml

from guidebot.cli import main
from guidebot.site import load_site_file

ROOT = Path(__file__).resolve().parent.parent
COMPOSE = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
SERVICES: dict[str, Any] = {  # the services that run GuideBot's image (not redis, postgres)
    name: service
    for name, service in COMPOSE["services"].items()
    if "command" in service and service.get("image") == "guidebot:demo"
}
VARIABLE = re.compile(r"\$\{[A-Z_0-9]+:?-([^}]*)\}")


def _argv(service: dict[str, Any]) -> list[str]:
    command = service["command"]
    argv = shlex.split(command) if isinstance(command, str) else list(command)
    # Compose variables with defaults (${TIME_SCALE:-1}) resolve to their defaults; the image's
    # /app is this checkout.
    return [VARIABLE.sub(r"\1", a).replace("/app/", f"{ROOT}/") for a in argv]


def _parse(argv: list[str]) -> click.Context:
    """Resolve the subcommand and parse its options exactly as `guidebot` would."""
    parent = click.Context(main, info_name="guidebot")
    command = main.get_command(parent, argv[0])
    assert command is not None, f"no guidebot command {argv[0]!r}"
    return command.make_context(argv[0], argv[1:], parent=parent)


@pytest.mark.parametrize("name", sorted(SERVICES))
def test_every_service_runs_a_valid_guidebot_command(name: str) -> None:
    argv = _argv(SERVICES[name])
    sub = _parse(argv)
    site = sub.params.get("site")
    if site is not None:
        assert Path(site).is_file(), site


def test_robot_services_use_the_tokens_of_the_site() -> None:
    site = load_site_file(ROOT / "sites" / "demo_museum.yaml")
    tokens = {robot.name: robot.token for robot in site.robots}
    robots = [_parse(_argv(s)).params for n, s in SERVICES.items() if n.startswith("robot")]
    assert robots, "the fleet has robots"
    for params in robots:
        assert tokens[params["name"]] == params["token"]


def test_a_broken_command_line_would_be_caught() -> None:
    with pytest.raises(click.UsageError):
        _parse(["robot", "--name", "R1", "--no-such-flag"])
