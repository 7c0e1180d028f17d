"""RGM: the server's RoboGraph dispatch (GuideBot paper, section 5.1), a server component.

The same engine as on every robot, on hub endpoint "rgm": a `run_petri_net` published on the
hub (by staff tools, GUIs or external modules) starts a net of the library in
`petri_nets/library` on the server; its actions publish on the hub, so a server net can open
doors, call elevators or talk to robots, and its end is published as `petri_net_ended`.
Robots never see these requests: the link forwards no `run_petri_net` either way.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

from fastapi import FastAPI

from petri_nets.clock import AsyncioClock
from petri_nets.dispatch import Dispatch
from petri_nets.library import NetLibrary

__all__ = ["rgm"]


@contextlib.asynccontextmanager
async def rgm(app: FastAPI) -> AsyncIterator[None]:
    """Run the dispatch while the server runs; `app.state.rgm` is the `Dispatch`."""
    library = await asyncio.to_thread(NetLibrary)  # parse off the loop; re-read when edited
    dispatch = Dispatch(
        app.state.hub.endpoint("rgm"), library, AsyncioClock(), idle_net=None, monitor=True
    )
    dispatch.open()
    app.state.rgm = dispatch
    try:
        yield
    finally:
        dispatch.close()
