"""robot_connected / robot_disconnected: a robot's hub link coming up or going, announced on the
hub from the hub's connection events (no polling). The Task Manager and the console follow
robots by these messages (docs/messages.md)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from backend.auth import Role
from backend.site.service import SiteService
from guidebot.payloads.tasks import RobotLink

__all__ = ["announce_links", "announce_robot_links"]


def announce_links(
    hub: Any, accept: Callable[[Any], bool], *, name: str = "link_watcher"
) -> Callable[[], None]:
    """Publish robot_connected / robot_disconnected when the hub link of a robot that ``accept``
    takes comes up or goes (a hub connection event, no polling). Returns the unsubscribe
    function."""
    endpoint = hub.endpoint(name)

    def changed(client: Any, connected: bool) -> None:
        if client.role is not Role.ROBOT or not accept(client):
            return
        kind = "robot_connected" if connected else "robot_disconnected"
        endpoint.publish(kind, RobotLink(robot=client.name))

    unsubscribe = hub.on_connection(changed)

    def stop() -> None:
        unsubscribe()
        endpoint.close()

    return stop


def announce_robot_links(hub: Any, sites: SiteService) -> Callable[[], None]:
    """The links of the robots the site names (a robot the site does not know is refused)."""
    return announce_links(hub, lambda client: sites.site.robot(client.name) is not None)
