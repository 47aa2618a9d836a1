"""``--workers N`` and ``--scheduler ADDRESS``: the executor of the per-point SDPs of a command, as a context
manager that shuts it down afterwards.

* neither flag: None (the library's default: a local process pool for large batches, else this process);
* ``--workers 1``: this process (:class:`InlineExecutor`);
* ``--workers N``: a :class:`concurrent.futures.ProcessPoolExecutor` of N spawned processes (fork deadlocks
  Clarabel's thread pool);
* ``--scheduler ADDRESS``: a ``dask.distributed.Client`` connected to a running scheduler (the optional
  ``distributed`` extra), e.g. ``tcp://10.0.0.5:8786``.

A bad value, a missing extra or a scheduler that does not answer within :data:`SCHEDULER_TIMEOUT_S` is a
:class:`~tritools.cli.app.CLIError` naming the flag (exit 2).
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib

from .app import CLIError

__all__ = ["InlineExecutor", "add_worker_options", "executor_from_args", "SCHEDULER_TIMEOUT_S"]

#: seconds to wait for ``--scheduler`` to answer.
SCHEDULER_TIMEOUT_S = 10


class InlineExecutor(cf.Executor):
    """Runs each task at ``submit`` in this process (``--workers 1``)."""

    def submit(self, fn, /, *args, **kwargs):
        fut: cf.Future = cf.Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future
            fut.set_exception(exc)
        return fut


def add_worker_options(p) -> None:
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="solve the per-point SDPs in N local processes (1: this process; default: a local pool "
                        "for large batches)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="solve the per-point SDPs on a running Dask scheduler, e.g. tcp://host:8786 (needs the "
                        "'distributed' extra)")


@contextlib.contextmanager
def executor_from_args(args):
    """The executor the flags ask for (None: the default), shut down on exit."""
    workers, address = getattr(args, "workers", None), getattr(args, "scheduler", None)
    if workers is not None and address is not None:
        raise CLIError("--workers and --scheduler exclude each other")
    if workers is not None and workers < 1:
        raise CLIError(f"--workers: must be a positive integer, got {workers}")
    if address is not None:
        try:
            from dask.distributed import Client
        except ImportError:
            raise CLIError("--scheduler needs dask.distributed (pip install 'sospoly-tritools[distributed]')") \
                from None
        try:
            client = Client(address, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise CLIError(f"--scheduler {address}: cannot connect ({type(exc).__name__}: {exc})") from None
        with client:
            yield client
        return
    if workers is None:
        yield None
    elif workers == 1:
        yield InlineExecutor()
    else:
        import multiprocessing
        import os

        from ..solve.batch import stop_pool, worker_init

        ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                    initializer=worker_init, initargs=(os.getpid(),))
        try:
            yield ex
        except BaseException:               # Ctrl-C, SIGTERM, an error: the workers stop now (stop_pool)
            stop_pool(ex)
            raise
        finally:
            ex.shutdown(wait=True, cancel_futures=True)
