import os
import signal
import time

from sr3d_cli.cli import workers
from sr3d_cli.cli.workers import Workers


def _job(index):
    if index == 2:
        os.kill(os.getpid(), signal.SIGKILL)  # what the out-of-memory killer does
    return index, index * 10


def _failed(index, why):
    return index, why


def test_a_killed_worker_fails_its_job_and_the_others_run():
    with Workers(2, _job, _failed) as pool:
        results = dict(pool.map(6))
    assert sorted(results) == [0, 1, 2, 3, 4, 5]
    assert [results[i] for i in (0, 1, 3, 4, 5)] == [0, 10, 30, 40, 50]
    assert results[2] == "the worker process was killed by SIGKILL (out of memory?)"


def _stubborn(index):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if index == 1:
        time.sleep(600)
    return index, index


def test_stop_kills_a_worker_that_ignores_sigterm(monkeypatch):
    monkeypatch.setattr(workers, "STOP_SECONDS", 0.5)
    pool = Workers(2, _stubborn, _failed)
    procs = list(pool._procs.values())
    results = pool.map(3)
    assert next(results) == (0, 0)
    pool.stop()
    assert all(not p.is_alive() for p in procs)
    # the one asleep in its job is killed; the other, idle, ends when its pipe closes
    assert sorted(p.exitcode for p in procs)[0] == -signal.SIGKILL
