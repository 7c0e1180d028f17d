"""What the hub's modules send a client as it connects leaves in the welcome's own frame: the
hub queues the welcome, then tells its modules the client is there (robot_connected), and the
closures in force, today's booked tours or the fleet's service go out to a robot at once. The
client took such a frame for no welcome and reconnected for ever."""

from __future__ import annotations

from backend.testing import RunningServer
from guidebot.client import HubClient
from guidebot.payloads.bookings import NextTours

from .conftest import TOKENS
from .test_routing import Inbox


async def test_news_in_the_welcomes_frame_is_taken_and_the_session_stays(
    server: RunningServer,
) -> None:
    hub = server.app.state.hub
    greeter = hub.endpoint("greeter")

    def greet(client: object, connected: bool) -> None:
        if connected and getattr(client, "name", None) == "R1":
            greeter.publish(NextTours(tz="UTC", tours=[]), destination="R1")

    hub.on_connection(greet)
    inbox = Inbox()
    client = HubClient(server.hub_url, TOKENS["R1"].token)
    client.subscribe("next_tours", inbox)
    await client.start()
    try:
        told = await inbox.next()
        assert told.type == "next_tours" and told.destination == "R1"
        assert client.connected.is_set() and client.connections == 1
    finally:
        await client.close()
        greeter.close()
