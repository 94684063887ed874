"""Where the draws of a basin and the runs of a sweep execute: a pool of local processes, or a
Dask distributed cluster (``--cluster tcp://host:port``) when one machine is not enough.

Both are ``concurrent.futures`` executors: Dask's ``Client.get_executor()`` submits each task
to the cluster's scheduler, which places it on a worker, moves it to another worker when
its worker is lost (the scheduler's own retry: a task is given up after
``distributed.scheduler.allowed-failures`` lost workers, 3 by default) and retries a task
that raised RETRIES more times.  A task's arguments travel to the worker (pickled), so a
scenario goes as its text; the workers need zswarm installed (the same version: a task
names functions of the worker's zswarm).  The README shows how to start a scheduler and
workers on several hosts, and on SLURM with dask-jobqueue.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

CONNECT_TIMEOUT_S = 10.0
RETRIES = 1  # a task that raised is tried once more (a lost worker is the scheduler's: allowed-failures)


class ClusterError(RuntimeError):
    """The cluster cannot be used (no dask installed, the scheduler not reachable, no workers)."""


@dataclass
class Runner:
    """An executor, how many tasks it runs at once, and how to drop what runs when interrupted."""

    pool: Executor
    slots: int
    abort: Callable[[], None]
    where: str  # "3 local processes", "the cluster at tcp://...: 4 worker threads"


def worker_init(parent: int | None = None) -> None:
    """Local workers leave signals to the parent: Ctrl-C reaches the whole process group, and
    the parent, not each worker, decides what is kept (it kills them)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    # A parent killed with SIGKILL cannot kill them, and a spawned worker waiting for its next
    # task never learns (it holds its own end of the task queue): it would wait for ever.
    # ``parent``: the pool owner's PID, given by it: read here, the parent could already be gone
    # (a kill while the worker was still starting) and its adopter taken for it.
    threading.Thread(target=_exit_with_parent, args=(os.getppid() if parent is None else parent,), name="zswarm-parent-watch", daemon=True).start()


def _exit_with_parent(ppid: int) -> None:
    while os.getppid() == ppid:
        time.sleep(0.5)
    os._exit(1)


@contextmanager
def executor(jobs: int, cluster: str | None = None) -> Iterator[Runner]:
    """A local pool of ``jobs`` processes, or the Dask cluster whose scheduler is at ``cluster``."""
    if cluster is None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        pool = ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"), initializer=worker_init, initargs=(os.getpid(),))

        def kill() -> None:
            for proc in list((getattr(pool, "_processes", None) or {}).values()):  # the executor's own workers
                proc.kill()
            pool.shutdown(wait=True, cancel_futures=True)

        with pool:
            try:
                yield Runner(pool, jobs, kill, f"{jobs} local processes")
            except BaseException:
                kill()  # leaving the pool waits for its runs: a hung one would be waited for ever
                raise
        return
    try:
        import distributed
    except ImportError:
        raise ClusterError("--cluster needs Dask distributed: pip install 'zswarm[cluster]' (or distributed)") from None
    try:
        client: Any = distributed.Client(cluster, timeout=CONNECT_TIMEOUT_S, set_as_default=False)  # type: ignore[no-untyped-call]  # distributed has no types
    except (OSError, TimeoutError) as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {cluster} ({type(exc).__name__}: {exc})") from None
    try:
        deadline = time.monotonic() + CONNECT_TIMEOUT_S
        while not client.nthreads() and time.monotonic() < deadline:
            time.sleep(0.2)
        slots = sum(client.nthreads().values())
        if not slots:
            raise ClusterError(f"the Dask scheduler at {cluster} has no workers (start some: dask worker {cluster})")
        ex = client.get_executor(pure=False, retries=RETRIES)
        yield Runner(ex, slots, lambda: ex.shutdown(wait=False), f"the cluster at {cluster}: {slots} worker threads on {len(client.nthreads())} workers")
    finally:
        client.close()
