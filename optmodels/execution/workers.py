"""Worker processes that exit with their parent and leave Ctrl-C to it.

Shared fault handling of the process engines: the pool of :func:`optmodels.execution.execute`
(Monte Carlo studies, track fits) and the comparison harness's worker
(``solvers_cmp.harness``): :func:`guard_worker` (the workers' initializer),
:func:`sigint_ignored` (around starting children) and :func:`kill_pool` (no orphans after
Ctrl-C or an error).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor

__all__ = ["guard_worker", "kill_pool", "sigint_ignored"]


def guard_worker(parent_pid: int) -> None:
    """Make a worker process exit with its parent and leave Ctrl-C to the parent.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, so the kernel kills the worker when its
    parent dies, even by SIGKILL; everywhere: a daemon thread polling ``os.getppid()``
    every 0.5 s (the portable fallback). SIGINT is ignored: a terminal's Ctrl-C reaches
    the whole process group, and the parent alone saves and reports."""
    with contextlib.suppress(ValueError, OSError):  # not the main thread / no signals
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(Exception):  # not Linux, or no libc: the watchdog remains
        import ctypes
        import sys

        if sys.platform.startswith("linux"):
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent_pid:  # the parent died before the guard was set
        os._exit(1)

    def watchdog() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watchdog, name="optmodels-parent-watchdog", daemon=True).start()


@contextlib.contextmanager
def sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while child processes are started (in the main thread): a spawned
    child inherits the ignored disposition, so a Ctrl-C during its start-up, before
    :func:`guard_worker` runs, cannot print a traceback from it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def kill_pool(ex: ProcessPoolExecutor) -> None:
    """Kill a pool's workers now (Ctrl-C, or leaving with an error): no orphans, no wait
    for running trials."""
    procs = list(getattr(ex, "_processes", {}).values())  # no public API for this
    for p in procs:
        with contextlib.suppress(Exception):
            p.kill()
    for p in procs:
        with contextlib.suppress(Exception):
            p.join(1.0)
    # the workers are dead: the manager thread sees a broken pool and stops at once;
    # waiting for it lets the queues' semaphores be released (no resource_tracker noise)
    ex.shutdown(wait=True, cancel_futures=True)
