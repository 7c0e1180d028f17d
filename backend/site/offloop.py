"""Heavy site work (validation, dumps, the route graph) in a thread, so that the server's event
loop keeps serving while a 10 000-node site is loaded or published.

A thread alone is not enough: the work allocates a few hundred thousand objects, and the cyclic
garbage collector's passes over them run in one piece while holding the GIL (up to 100 ms on a
10 000-node site), stopping the loop as surely as running on it. So the collector is paused
while such work runs and what it built is then frozen (``gc.freeze()``): a site lives until the
next publish, and rescanning it finds nothing. Reference counting still frees the replaced site;
only reference cycles made meanwhile would wait until the hub stops (no pass over everything
frozen runs while it serves, backend/hub/memory.py): loading a 10 000-node site and building
its graph twice, then dropping both, left none (measured, 28 Nov 2026).

Nor is a thread enough for single native calls that hold the GIL throughout: freeing a whole
site at once is one (``release`` takes it apart in a thread, guidebot/site/dispose.py), and so
are libyaml's composer and orjson on megabytes (guidebot/site/yamlio.py, jsonio.py).

Work that is seconds of plain Python and whose answer is small to send back (the route
tables, a large YAML file read as JSON) runs in worker processes instead (``in_processes``):
there it takes no GIL from the loop at all.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from typing import Any, ParamSpec, TypeVar

from guidebot.site.dispose import dispose

__all__ = ["gc_paused", "in_processes", "off_loop", "release"]

P = ParamSpec("P")
T = TypeVar("T")
A = TypeVar("A")

WORKER_NICE = 10
"""How much lower the scheduling priority of a worker process is than the server's (the
``nice`` value added; POSIX only). The workers use every CPU they are given, the server's
event loop a millisecond now and then: with equal priority the kernel lets a waking loop wait
behind a busy worker for a few milliseconds (ticks late p99 3.5 ms while two workers compute,
0.5-1.1 ms at nice 10; the workers' time is unchanged on an otherwise idle machine)."""

SWITCH_INTERVAL_S = 0.001
"""The GIL's switch interval while site work runs in a thread (Python's default is 5 ms): the
loop thread, woken by I/O, waits at most this long for the worker to hand the GIL over."""

_paused = 0
_was_enabled = False
_interval = 0.005


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """No cyclic collection and a short GIL switch interval inside the block (nested and
    overlapping blocks allowed); what was allocated is frozen when the last block ends."""
    global _paused, _was_enabled, _interval
    if _paused == 0:
        _was_enabled = gc.isenabled()
        gc.disable()
        _interval = sys.getswitchinterval()
        sys.setswitchinterval(min(_interval, SWITCH_INTERVAL_S))
    _paused += 1
    try:
        yield
    finally:
        _paused -= 1
        if _paused == 0:
            sys.setswitchinterval(_interval)
            gc.freeze()
            if _was_enabled:
                gc.enable()


async def off_loop(fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """``fn(*args, **kwargs)`` in a thread with the collector paused."""
    with gc_paused():
        return await asyncio.to_thread(fn, *args, **kwargs)


async def release(box: list[Any]) -> None:
    """Free the objects in ``box`` in a thread, a piece at a time (the caller keeps no other
    reference to them: dropping the last one on the loop would free them there in one go)."""
    if box:
        await off_loop(dispose, box)


def _lower_priority() -> None:
    """A worker's first step: yield the CPU to the server's loop whenever it wakes."""
    if hasattr(os, "nice"):
        os.nice(WORKER_NICE)


async def in_processes(fn: Callable[[A], T], args: Sequence[A], workers: int) -> list[T]:
    """``[fn(a) for a in args]`` in ``workers`` new processes, which end with the call.

    They are spawned, not forked (the server's threads are not copied), and import ``fn``'s
    module and the main module again: a program that embeds the server must guard its main
    module with ``if __name__ == "__main__":``. Worker ``i`` computes ``args[i::workers]``,
    given and answered through a pipe of its own. Starting them and waiting for them is
    done in a thread (a few milliseconds of forking and pickling; the wait). A worker that dies
    raises ``BrokenProcessPool``; one that cannot start, ``OSError``; ``fn``'s own exception is
    raised as it is. They run at a lower priority than the server (``WORKER_NICE``). The call
    returns once every worker has exited: none outlives it.

    Our own processes, not a ``ProcessPoolExecutor``: when one of its workers died, CPython
    3.11 left a worker started by a racing submit running, blocked sending its answer, and
    ``shutdown`` waited for ever (a CI run hung 17 min in the killed-worker test); killing them
    took the pool's private ``_broken`` and ``_processes``. Here every process is ours to kill,
    with ``Process.kill``."""
    if not args:
        return []
    context = multiprocessing.get_context("spawn")
    count = max(1, min(workers, len(args)))
    chunks = [list(args[i::count]) for i in range(count)]
    processes: list[BaseProcess] = []
    pipes: list[Connection] = []

    def start() -> None:
        for _ in chunks:
            pipe, theirs = context.Pipe()
            process = context.Process(target=_work, args=(theirs,), daemon=True)
            processes.append(process)
            pipes.append(pipe)
            process.start()
            theirs.close()  # EOF here once the worker is gone
        # The work goes through the pipe once every worker runs, not as the process's
        # arguments: those are written to the new process while this one still holds the
        # other end of that pipe, so a worker killed before it read them left the write
        # blocked for ever (a large chunk is more than the pipe holds).
        for index, (pipe, chunk) in enumerate(zip(pipes, chunks, strict=True)):
            try:
                pipe.send((fn, chunk))
            except OSError:
                raise _broken(processes[index]) from None

    try:
        await asyncio.to_thread(start)
        answers = await asyncio.to_thread(_collect, pipes, processes)
    finally:
        # Waited for (in a thread): a worker still exiting (seconds on a loaded machine, being
        # niced) must not outlive the call.
        await asyncio.to_thread(_end, processes, pipes)
    results: list[T] = [None] * len(args)  # type: ignore[list-item]
    for i, answer in enumerate(answers):
        results[i::count] = answer
    return results


def _work(pipe: Connection) -> None:
    """A worker: reads ``fn`` and its arguments from ``pipe`` and sends back the answers, or
    the exception ``fn`` raised."""
    _lower_priority()
    fn, chunk = pipe.recv()
    try:
        answer: tuple[bool, object] = (True, [fn(a) for a in chunk])
    except BaseException as exc:  # sent back to the caller, raised there
        answer = (False, exc)
    pipe.send(answer)
    pipe.close()


def _broken(process: BaseProcess) -> BrokenProcessPool:
    process.join()
    return BrokenProcessPool(f"a worker process died (exit code {process.exitcode})")


def _collect(pipes: list[Connection], processes: list[BaseProcess]) -> list[list[Any]]:
    """Every worker's answers, in order; ``BrokenProcessPool`` once one dies without them."""
    answers: dict[int, list[Any]] = {}
    index_of = {id(pipe): i for i, pipe in enumerate(pipes)}
    waiting = list(pipes)
    while waiting:
        for ready in wait(waiting):
            index = index_of[id(ready)]
            waiting.remove(pipes[index])
            try:
                received: Any = pipes[index].recv()
            except (EOFError, OSError):
                raise _broken(processes[index]) from None
            ok, answer = received
            if not ok:
                raise answer
            answers[index] = answer
    return [answers[i] for i in range(len(pipes))]


def _end(processes: list[BaseProcess], pipes: list[Connection]) -> None:
    """Kill what still runs (the others answered or died), then reap every worker."""
    for pipe in pipes:
        pipe.close()
    for process in processes:
        if process.is_alive():
            process.kill()
    for process in processes:
        process.join()
