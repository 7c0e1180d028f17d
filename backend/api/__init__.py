"""REST API of the server brain (site, robots, tasks, tours, points of interest, locks,
events) and the component that runs the services behind it."""

from backend.api import (
    events,
    locks,
    nets_editor,
    robots,
    site,
    site_editor,
    tasks,
    tours,
    translations,
    visitor,
    web,
)

ROUTERS = [
    site.router,
    site_editor.router,
    tours.router,
    tasks.router,
    robots.router,
    locks.router,
    events.router,
    web.router,
    visitor.router,
    nets_editor.router,
    translations.router,
]

__all__ = ["ROUTERS"]
