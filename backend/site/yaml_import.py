"""A YAML site file read off the event loop.

Reading a large file is seconds of plain Python in a thread (PyYAML's composer, kept so that
no single native call holds the GIL long, guidebot/site/yamlio.py), all that time sharing the
GIL with the loop. A worker process instead reads it with libyaml's one-call composer and
hands back JSON, which the thread then decodes and validates (a fraction of the time). A file
the worker does not vouch for (an error to report with its line, data JSON would not carry)
is read the usual way, so answers and errors are the same either way.
"""

from __future__ import annotations

import logging
from concurrent.futures.process import BrokenProcessPool

from backend.site.offloop import in_processes, off_loop
from guidebot.site.jsonio import LARGE
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_text, yaml_as_json

__all__ = ["read_site_yaml"]

log = logging.getLogger(__name__)


async def read_site_yaml(text: str, workers: int) -> Site:
    """``load_site_text(text)`` off the loop; a file above ``LARGE`` characters is read in a
    worker process when ``workers`` allows one (raises SiteInvalid like load_site_text)."""
    parsed = None
    if workers >= 1 and len(text) > LARGE:
        try:
            (parsed,) = await in_processes(yaml_as_json, [text], 1)
        except (BrokenProcessPool, OSError) as exc:
            log.warning("site import: worker process failed (%s); reading in a thread", exc)
    return await off_loop(load_site_text, text, parsed)
