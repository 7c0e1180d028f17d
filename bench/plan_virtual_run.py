"""The virtual run's process (``backend.planning.virtual`` starts it):

    python -m bench.plan_virtual_run JOB.json OUTCOME.json

It switches ``time.time`` and ``time.monotonic`` to the virtual clock's switches
(``backend.planning.vtime.install``) before it imports any of the product: a module that took a
reference to them at import (``clock=time.time``) then follows the run's clock too. Then it
reads the job, plays it (``bench.plan_virtual.play``) and writes the outcome."""

from __future__ import annotations

import sys

from backend.planning.vtime import install

install()

from bench.plan_virtual import main  # noqa: E402  (after install: see the docstring)

if __name__ == "__main__":
    sys.exit(main())
