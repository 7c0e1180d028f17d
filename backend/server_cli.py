"""``guidebot server``: run the central server (FastAPI + uvicorn) in the foreground."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click
from pydantic import ValidationError


def refuse_broken_site(path: Path) -> None:
    """A broken site file stops the start with every problem and its line (no traceback)."""
    from guidebot.site.validate import SiteInvalid
    from guidebot.site.yamlio import load_site_file

    try:
        load_site_file(path)
    except OSError as exc:
        click.echo(f"{path}: cannot read the site file: {exc.strerror}", err=True)
        sys.exit(2)
    except SiteInvalid as exc:
        for line in exc.file_lines(path):
            click.echo(line, err=True)
        click.echo(
            f"{path}: {len(exc.issues)} problem(s): site refused, server not started", err=True
        )
        sys.exit(2)


@click.command()
@click.option("--host", default=None, help="Bind address (default 127.0.0.1, GUIDEBOT_HOST).")
@click.option("--port", type=int, default=None, help="Port (default 8000, GUIDEBOT_PORT).")
@click.option("--db", "db_url", default=None, help="Database URL (GUIDEBOT_DB_URL).")
@click.option(
    "--site",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Site YAML file (GUIDEBOT_SITE).",
)
@click.option(
    "--site-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Site folder: plans, media and uploads (GUIDEBOT_SITE_DIR; default the site file's "
    "folder, else ./guidebot-site).",
)
@click.option(
    "--broker",
    "broker_url",
    default=None,
    help="redis://host:port: run as one of several processes (GUIDEBOT_BROKER_URL; needs a "
    "PostgreSQL --db; docs/scaling.md).",
)
@click.option(
    "--hub-ws-port",
    type=int,
    default=None,
    help="Also serve the hub on this port without ASGI, for robots and modules "
    "(GUIDEBOT_HUB_WS_PORT; docs/protocol.md).",
)
@click.option(
    "--mqtt",
    "mqtt_url",
    default=None,
    help="mqtt://[user:password@]host:1883 (mqtts:// for TLS): the broker of the site's VDA 5050 "
    "robots (GUIDEBOT_MQTT_URL; docs/vda5050.md).",
)
@click.option(
    "--mqtt-user", "mqtt_username", default=None, help="MQTT user (GUIDEBOT_MQTT_USERNAME)."
)
@click.option(
    "--mqtt-cafile",
    default=None,
    help="CA certificates of an mqtts:// broker (GUIDEBOT_MQTT_CAFILE; password: "
    "GUIDEBOT_MQTT_PASSWORD).",
)
@click.option("--log-level", default=None, help="uvicorn log level (default info).")
@click.option(
    "--access-log/--no-access-log",
    default=None,
    help="A log line per HTTP request (default on, GUIDEBOT_ACCESS_LOG).",
)
def server(
    host: str | None,
    port: int | None,
    db_url: str | None,
    site: Path | None,
    site_dir: Path | None,
    broker_url: str | None,
    hub_ws_port: int | None,
    mqtt_url: str | None,
    mqtt_username: str | None,
    mqtt_cafile: str | None,
    log_level: str | None,
    access_log: bool | None,
) -> None:
    """Run the central server: hub at /ws, REST API at /api, docs at /docs, web pages at /."""
    from guidebot.heap import quiet_imports

    with quiet_imports():  # long-lived objects only: nothing to collect (guidebot/heap.py)
        import uvicorn

        from backend.app import create_app, uvicorn_config
        from backend.settings import Settings, describe_errors

    overrides: dict[str, Any] = {
        key: value
        for key, value in {
            "host": host,
            "port": port,
            "db_url": db_url,
            "site": site,
            "site_dir": site_dir,
            "broker_url": broker_url,
            "hub_ws_port": hub_ws_port,
            "mqtt_url": mqtt_url,
            "mqtt_username": mqtt_username,
            "mqtt_cafile": mqtt_cafile,
            "log_level": log_level,
            "access_log": access_log,
        }.items()
        if value is not None
    }
    try:
        settings = Settings(**overrides)
    except ValidationError as exc:
        raise click.UsageError(describe_errors(exc)) from None
    if settings.site is not None:
        refuse_broken_site(settings.site)
    app = create_app(settings)
    listener = {
        None: "",
        0: ", its own listener on a free port: /api/health",
    }.get(settings.hub_ws_port, f", ws://{settings.host}:{settings.hub_ws_port}/ws")
    click.echo(
        f"GuideBot server on http://{settings.host}:{settings.port} "
        f"(docs /docs, hub ws://{settings.host}:{settings.port}/ws{listener})"
    )
    config = uvicorn_config(
        app, settings.host, settings.port, settings.log_level, settings.access_log
    )
    try:
        uvicorn.Server(config).run()
    except KeyboardInterrupt:
        pass  # uvicorn re-raises the Ctrl-C it already handled with a clean shutdown
