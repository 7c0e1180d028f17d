"""``guidebot plan --live --virtual``: the live run on virtual time. The building simulator, the
server and bare simulated robots run in one child process (``bench.plan_virtual_run``) on an event
loop whose clock jumps to the next timer whenever every task waits (``backend.planning.vtime``):
exact simulated seconds, as fast as the CPU allows. This side writes the job, starts the child
and reads its outcome. docs/planning.md, "The virtual run"."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

from backend.planning.live import LiveOptions
from backend.planning.profile import PlanError, Request
from backend.planning.sim import Outcome
from guidebot.site.schema import Site

__all__ = ["run_virtual"]


def run_virtual(
    site_path: Path,
    site: Site,
    requests: Sequence[Request],
    *,
    robots: int,
    day_s: float,
    patience_s: float | None = None,
    queue_limit: int | None = None,
    options: LiveOptions | None = None,
) -> Outcome:
    """Play ``requests`` on a fleet of ``robots`` in virtual time; the outcome in simulated
    seconds, with the live run's ``extra`` (``mode`` "virtual", ``cpu_s``)."""
    opts = options or LiveOptions(virtual=True)
    workdir = opts.workdir or Path(tempfile.mkdtemp(prefix="guidebot-plan-"))
    workdir.mkdir(parents=True, exist_ok=True)
    job_file, out_file = workdir / f"virtual-{robots}.job.json", workdir / f"virtual-{robots}.json"
    job = {
        "site": str(site_path.resolve()),
        "requests": [dataclasses.asdict(r) for r in requests],
        "robots": robots,
        "day_s": day_s,
        "patience_s": patience_s,
        "queue_limit": queue_limit,
        "workdir": str(workdir),
    }
    job_file.write_text(json.dumps(job), encoding="utf-8")
    out_file.unlink(missing_ok=True)
    opts.log(f"a fleet of {robots} in virtual time (log: {workdir / f'virtual-{robots}'})")
    done = subprocess.run(
        [sys.executable, "-m", "bench.plan_virtual_run", str(job_file), str(out_file)],
        stdin=subprocess.DEVNULL,
        check=False,
    )
    if not out_file.exists():
        raise PlanError(f"virtual run: the child exited {done.returncode} without an outcome")
    result = json.loads(out_file.read_text(encoding="utf-8"))
    if "error" in result:
        raise PlanError(str(result["error"]))
    result["wait_of"] = {int(k): float(v) for k, v in result["wait_of"].items()}
    return Outcome(**result)
