"""A local worker ends when the process that started it is killed without clean-up (review 33a M3: after a SIGKILL
of ``tritools solve`` its two workers kept solving, orphaned, for 14 minutes)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and parent ids")

_PARENT = textwrap.dedent("""
    import concurrent.futures as cf, multiprocessing, os, time
    from tritools.solve.batch import worker_init
    ex = cf.ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                                initializer=worker_init, initargs=(os.getpid(),))
    pid = ex.submit(os.getpid).result()          # the worker has started (and run its initializer)
    ex.submit(time.sleep, 60)
    print(pid, flush=True)
    time.sleep(120)
""")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:                                     # a zombie (exited, not yet reaped by its new parent) counts as gone
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return True


def test_workers_exit_when_their_parent_is_killed():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    proc = subprocess.Popen([sys.executable, "-c", _PARENT], stdout=subprocess.PIPE, text=True, cwd=root,
                            env={**os.environ, "PYTHONPATH": root})
    try:
        line = proc.stdout.readline()
        workers = [int(p) for p in line.split()]
        assert len(workers) == 1 and all(_alive(p) for p in workers)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        t0 = time.monotonic()
        while any(_alive(p) for p in workers) and time.monotonic() - t0 < 20:
            time.sleep(0.1)
        assert not any(_alive(p) for p in workers)        # before: they slept on, orphaned, for the whole minute
    finally:
        proc.kill()
        for p in workers if "workers" in locals() else []:
            try:
                os.kill(p, signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_a_forkserver_pools_workers_live_while_their_creator_does():
    """Review 33c L2: a worker of a ``forkserver`` pool is the server's child, not its creator's: a watch of the
    parent id alone ended every such worker after a second (BrokenProcessPool)."""
    import concurrent.futures as cf
    import multiprocessing

    from tritools.solve.batch import PARENT_POLL_SECONDS, worker_init

    ctx = multiprocessing.get_context("forkserver")
    with cf.ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=worker_init,
                                initargs=(os.getpid(),)) as ex:
        first = ex.submit(os.getpid).result(timeout=60)
        time.sleep(2.5 * PARENT_POLL_SECONDS)
        assert ex.submit(os.getpid).result(timeout=60) == first       # the same worker, alive
