"""The catalogue of message types: one module per domain, each owning its payload models.

Importing this package registers every known type (see guidebot.messages.register_payload).
"""

from guidebot.payloads import (  # noqa: F401
    alerts,
    bookings,
    building,
    console,
    emergency,
    hub,
    nets,
    petri,
    robot,
    site,
    tasks,
    traffic,
)
