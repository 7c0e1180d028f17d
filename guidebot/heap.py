"""The cyclic garbage collector's work at the start and the end of a ``guidebot`` process.

A process that imports the server holds about 230 000 objects the collector tracks, almost
all of them modules, classes and functions that live as long as the process. Collecting them
does nothing useful and costs CPU that short-lived processes (a test's server, a demo's robot
agents and building simulator) pay every time (measured on the 2-core VM, medians of 5):
- while the modules are imported, the collector's automatic passes walk the growing heap
  again and again: about 0.4 CPU-s (558 passes) of the 1.9 of ``import backend.app``;
- when the interpreter exits, its last collections break up every cycle and free the objects
  one by one (memory the operating system takes back at once anyway): about 0.65 CPU-s.

``quiet_imports()`` keeps the collector off while a command's modules are imported and then
freezes what they made (``gc.freeze()``: the collector's later passes skip it; the server's hub
does the same with what start-up made, backend/hub/memory.py); ``no_final_collection()``
freezes whatever is left at exit, after every other exit handler: the interpreter then exits
without collecting it. At-exit handlers, buffered files and the exit status are as before;
only cycles of objects still alive at exit are no longer finalized, which CPython does not
promise anyway.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
from collections.abc import Iterator

__all__ = ["no_final_collection", "quiet_imports"]

_registered = False


@contextlib.contextmanager
def quiet_imports() -> Iterator[None]:
    """No automatic collection inside the block (modules being imported: long-lived objects,
    nothing to collect); what is alive after it is frozen. The collector is then as it was
    (still off if it was off)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        if was_enabled:
            gc.enable()


def no_final_collection() -> None:
    """Let this process exit without the collector's last pass over every live object: freeze
    them at exit. Registered once; call it before other at-exit handlers are registered (handlers
    run last-registered first, so this one runs after them)."""
    global _registered
    if not _registered:
        _registered = True
        atexit.register(gc.freeze)
