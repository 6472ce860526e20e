"""Forked worker processes for a batch of independent jobs, one pipe per worker.

Each worker has its own pipe to the parent and nothing else shared (no queue locks), so a
worker that dies, is killed by the kernel's out-of-memory killer or ignores a stop request
cannot block the parent: its job comes back as a failure and a fresh worker takes its place.
Ctrl-C reaches the whole process group; the workers ignore it and the parent stops them with
SIGTERM (which unwinds the job in progress, so its temporary files are removed), then SIGKILL
for any that has not ended after :data:`STOP_SECONDS`.
"""

from __future__ import annotations

import multiprocessing
import signal
import time
from multiprocessing.connection import Connection, wait
from typing import Any, Callable, Iterator

STOP_SECONDS = 10.0  # how long stopped workers get to unwind before they are killed


def _stop_worker(signum, frame):
    raise SystemExit(1)


def _serve(conn: Connection, others: list[Connection], job: Callable[[int], Any]) -> None:
    """A worker's loop: job indices in, ``job(index)`` out, until None or the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop_worker)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    for other in others:  # the parent's ends of the other workers' pipes
        other.close()
    while True:
        try:
            index = conn.recv()
        except EOFError:
            return
        if index is None:
            return
        conn.send(job(index))


def _ended(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        name = signal.Signals(-exitcode).name
        why = " (out of memory?)" if -exitcode == signal.SIGKILL else ""
        return f"the worker process was killed by {name}{why}"
    return f"the worker process ended (exit code {exitcode})"


class Workers:
    """``count`` forked processes running ``job(index)``; :meth:`map` yields results in order
    of completion. ``failed(index, message)`` makes the result of a job whose worker ended
    without one. Use as a context manager: leaving it normally ends the workers, leaving it by
    an exception (Ctrl-C) stops them (:meth:`stop`)."""

    def __init__(self, count: int, job: Callable[[int], Any],
                 failed: Callable[[int, str], Any]):
        self._context = multiprocessing.get_context("fork")
        self._job, self._failed = job, failed
        self._procs: dict[Connection, multiprocessing.process.BaseProcess] = {}
        for _ in range(count):
            self._start()

    def _start(self) -> Connection:
        mine, theirs = self._context.Pipe(duplex=True)
        others = list(self._procs)
        proc = self._context.Process(target=_serve, args=(theirs, others, self._job),
                                     daemon=True)
        # Ctrl-C between the fork and the worker's own handlers must not reach it
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:
            proc.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        theirs.close()
        self._procs[mine] = proc
        return mine

    def map(self, count: int) -> Iterator[Any]:
        """Run jobs 0..count-1; yield each result as it comes."""
        todo = iter(range(count))
        busy: dict[Connection, int] = {}

        def give(conn: Connection) -> None:
            index = next(todo, None)
            if index is not None:
                conn.send(index)
                busy[conn] = index

        for conn in list(self._procs):
            give(conn)
        while busy:
            for conn in wait(list(busy)):
                index = busy.pop(conn)
                try:
                    result = conn.recv()
                except (EOFError, OSError):
                    proc = self._procs.pop(conn)
                    proc.join()
                    conn.close()
                    result = self._failed(index, _ended(proc.exitcode))
                    conn = self._start()
                give(conn)
                yield result

    def close(self) -> None:
        """End idle workers and wait for them."""
        for conn in self._procs:
            try:
                conn.send(None)
            except OSError:  # a worker that died while idle
                pass
        for conn, proc in self._procs.items():
            proc.join()
            conn.close()
        self._procs.clear()

    def stop(self) -> None:
        """SIGTERM every worker (its job unwinds), SIGKILL those alive after STOP_SECONDS."""
        for conn, proc in self._procs.items():
            proc.terminate()
            conn.close()  # a worker that carries on past SIGTERM ends at its next recv
        deadline = time.monotonic() + STOP_SECONDS
        for proc in self._procs.values():
            proc.join(max(0.0, deadline - time.monotonic()))
        for proc in self._procs.values():
            if proc.exitcode is None:
                proc.kill()
                proc.join()
        self._procs.clear()

    def __enter__(self) -> "Workers":
        return self

    def __exit__(self, kind, value, tb) -> None:
        if kind is None:
            self.close()
        else:
            self.stop()
