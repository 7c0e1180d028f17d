"""``guidebot site``: check a site file (every error with its line) and print it normalised."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from backend.site.translations import stale_translations
from guidebot.site.access import step_free_warnings
from guidebot.site.i18n import missing_translations
from guidebot.site.schema import Site
from guidebot.site.validate import SiteInvalid
from guidebot.site.yamlio import dump_site, load_site_file

__all__ = ["site"]


@click.group()
def site() -> None:
    """Site files: check them before loading them into a server."""


@site.command("check")
@click.argument("path", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--deadlock-robots",
    type=click.IntRange(min=0),
    default=None,
    help="Robots in the deadlock search (default: the site's robots, at least 2; 0: skip it).",
)
@click.option(
    "--deadlock-states",
    type=click.IntRange(min=1),
    default=200_000,
    show_default=True,
    help="States the deadlock search explores before it gives up (a warning, exit 0).",
)
def check(path: Path, deadlock_robots: int | None, deadlock_states: int) -> None:
    """Validate PATH; exit 1 listing every problem with its line. Texts missing in a
    declared language or older than their source, and tour stops a step-free tour skips, are
    warnings (exit 0). Then search the lock table for a deadlock of the robots
    (guidebot/site/deadlock.py): a cycle found is a problem (exit 1), a search that gave up a
    warning."""
    try:
        loaded = load_site_file(path)
    except SiteInvalid as exc:
        for line in exc.file_lines(path):
            click.echo(line, err=True)
        click.echo(f"{len(exc.issues)} problem(s): site refused", err=True)
        sys.exit(1)
    warnings = (
        missing_translations(loaded)
        + stale_translations(loaded.model_dump(mode="json"))
        + step_free_warnings(loaded)
    )
    for issue in warnings:
        click.echo(f"{path}: warning: {issue.loc}: {issue.message}", err=True)
    click.echo(
        f"{path}: ok: {len(loaded.floors)} floors, {len(loaded.nodes)} nodes, "
        f"{len(loaded.pois)} points of interest, {len(loaded.tours)} tours, "
        f"{len(loaded.areas)} restricted areas, {len(loaded.robots)} robots"
        + (f", {len(warnings)} warning(s)" if warnings else "")
    )
    robots = max(2, len(loaded.robots)) if deadlock_robots is None else deadlock_robots
    if robots and not _deadlock_free(path, loaded, robots, deadlock_states):
        sys.exit(1)


def _deadlock_free(path: Path, loaded: Site, robots: int, max_states: int) -> bool:
    """Report the deadlock search; False when a cycle was found (each lock with its line)."""
    import yaml

    from guidebot.site.deadlock import find_deadlock, lock_loc
    from guidebot.site.yamlio import _line_finder

    result = find_deadlock(loaded, robots, max_states=max_states)
    if not result.deadlock:
        prefix = "" if result.complete else "warning: "
        click.echo(f"{path}: {prefix}{result.describe()}", err=not result.complete)
        return True
    line_of = _line_finder(yaml.compose(path.read_text(encoding="utf-8")))
    for held, wanted in result.cycle:
        loc = lock_loc(loaded, held)
        where = ".".join(str(p) for p in loc[:1]) + "".join(f"[{p}]" for p in loc[1:])
        click.echo(
            f"{path}:{line_of(loc) or 0}: {where}: a robot stopped in {held} waits for {wanted}",
            err=True,
        )
    click.echo(f"{path}: {result.describe()}; reached by: " + "; ".join(result.trace), err=True)
    return False


@site.command("format")
@click.argument("path", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def format_(path: Path) -> None:
    """Print PATH as the server would export it (defaults left out)."""
    try:
        click.echo(dump_site(load_site_file(path)), nl=False)
    except SiteInvalid as exc:
        raise click.ClickException(str(exc)) from None
