"""Where steps run: in this process, a local process pool (``--workers N``), or a Dask cluster.

All three are ``concurrent.futures`` executors, so :func:`~doorbatch.pipeline.batch.scheduler.run_steps`
drives them the same way. Pool workers ignore SIGINT (Ctrl-C reaches the whole process group; the main
process decides) and are terminated by :func:`open_executor` on an interruption, after which the caller
removes the staged folders they left.
"""

from __future__ import annotations

import ctypes
import importlib
import logging
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any, ParamSpec, TypeVar

from doorbatch.errors import OptionalDependencyError, UsageError
from doorbatch.progress import set_progress_enabled

log = logging.getLogger(__name__)
P = ParamSpec("P")
T = TypeVar("T")
SCHEDULER_TIMEOUT_S = 10.0  # how long --scheduler ADDRESS may take to answer


class InlineExecutor(Executor):
    """Runs each submitted call at once in this process (``--workers 1``): no pickling, plain tracebacks."""

    def submit(self, fn: Callable[P, T], /, *args: P.args, **kwargs: P.kwargs) -> Future[T]:
        """Call ``fn`` now; the future holds its result or exception (an interruption propagates)."""
        future: Future[T] = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as err:
            future.set_exception(err)
        return future


def _worker_init(parent_pid: int) -> None:
    """A pool worker: Ctrl-C goes to the main process alone; and the worker dies with the main process (Linux's
    PR_SET_PDEATHSIG), which a SIGKILL (the OOM killer, ``kill -9`` of the cron job) would otherwise leave
    orphaned, writing into OUT without the lock's holder and then idle for good. It draws no progress bars of its
    own (the em stage's): the main process shows one per kind of step."""
    set_progress_enabled(False)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    # only a worker the main process forked itself (a forkserver's children have the server as parent)
    if not sys.platform.startswith("linux") or os.getppid() != parent_pid:
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # no prctl to call: the worker outlives a killed parent, as before
        return
    if os.getppid() != parent_pid:  # the parent died between the two looks
        os._exit(1)


_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def resolve_workers(workers: int) -> int:
    """``workers``, or the CPU count when 0."""
    return workers if workers > 0 else (os.cpu_count() or 1)


@contextmanager
def _process_pool(workers: int) -> Iterator[Executor]:
    pool = ProcessPoolExecutor(workers, initializer=_worker_init, initargs=(os.getpid(),))
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        for child in multiprocessing.active_children():  # the pool's workers: stop their steps now
            child.terminate()
        for child in multiprocessing.active_children():
            child.join(5)
        raise
    pool.shutdown(wait=True)


@contextmanager
def _dask(workers: int, scheduler: str | None) -> Iterator[Executor]:
    try:
        distributed: Any = importlib.import_module("distributed")  # untyped calls: keep mypy strict elsewhere
    except ImportError as err:
        raise OptionalDependencyError("dask.distributed", "dask") from err
    cluster: Any = None
    if scheduler is None:
        # threads in this process: light, and the steps release the GIL in NumPy and numba
        cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=workers, processes=False,
                                           dashboard_address=None)
        client = distributed.Client(cluster)
    else:
        try:
            client = distributed.Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as err:  # unreachable, refused, or not an address
            raise UsageError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({err})") from err
    try:
        yield client.get_executor(pure=False)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@contextmanager
def open_executor(kind: str, workers: int, scheduler: str | None = None) -> Iterator[Executor]:
    """The executor for ``--executor`` (``local`` or ``dask``) and ``--workers``.

    Raises:
        OptionalDependencyError: ``dask`` without the ``dask`` extra installed.
        UsageError: a ``scheduler`` address that answers nothing within ``SCHEDULER_TIMEOUT_S``.
    """
    if kind == "dask":
        with _dask(resolve_workers(workers), scheduler) as executor:
            yield executor
    elif resolve_workers(workers) == 1:
        yield InlineExecutor()
    else:
        with _process_pool(resolve_workers(workers)) as executor:
            yield executor
