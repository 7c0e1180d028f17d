"""``guidebot site``: check a site file (every error with its line) and print it normalised."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from guidebot.site.i18n import missing_translations
from guidebot.site.validate import SiteInvalid
from guidebot.site.yamlio import dump_site, load_site_file

__all__ = ["site"]


@click.group()
def site() -> None:
    """Site files: check them before loading them into a server."""


@site.command("check")
@click.argument("path", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def check(path: Path) -> None:
    """Validate PATH; exit 1 listing every problem with its line. Texts missing in a
    declared language are warnings (exit 0)."""
    try:
        loaded = load_site_file(path)
    except SiteInvalid as exc:
        for line in exc.file_lines(path):
            click.echo(line, err=True)
        click.echo(f"{len(exc.issues)} problem(s): site refused", err=True)
        sys.exit(1)
    warnings = missing_translations(loaded)
    for issue in warnings:
        click.echo(f"{path}: warning: {issue.loc}: {issue.message}", err=True)
    click.echo(
        f"{path}: ok: {len(loaded.floors)} floors, {len(loaded.nodes)} nodes, "
        f"{len(loaded.pois)} points of interest, {len(loaded.tours)} tours, "
        f"{len(loaded.areas)} restricted areas, {len(loaded.robots)} robots"
        + (f", {len(warnings)} warning(s)" if warnings else "")
    )


@site.command("format")
@click.argument("path", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def format_(path: Path) -> None:
    """Print PATH as the server would export it (defaults left out)."""
    try:
        click.echo(dump_site(load_site_file(path)), nl=False)
    except SiteInvalid as exc:
        raise click.ClickException(str(exc)) from None
