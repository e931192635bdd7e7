"""The execution engine: :func:`execute` runs tasks serially, on a local process pool or
on Dask distributed, and hands the results back in this process as they finish. Used by
the Monte Carlo studies (:func:`optmodels.montecarlo.run`), the track fits
(``biasfield.fit_tracks``) and the comparison harness (``solvers_cmp.harness``).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from optmodels.execution.scheduler import CONNECT_TIMEOUT, as_scheduler, dask_client
from optmodels.execution.workers import guard_worker, kill_pool, sigint_ignored

__all__ = ["MAX_WORKERS", "describe", "execute", "run_pool"]

#: Size guard: local worker processes.
MAX_WORKERS = 256

#: Tasks in flight per Dask worker thread (:func:`execute`).
DASK_IN_FLIGHT = 4


def describe(scheduler: Any, workers: int) -> str:
    """The engine's description before it runs (``serial``, ``processes (N)``,
    ``dask (ADDRESS)``); ``scheduler`` as :func:`~optmodels.execution.as_scheduler`
    returns it."""
    if scheduler == "serial":
        return "serial"
    if scheduler == "processes":
        return f"processes ({workers})"
    address = getattr(getattr(scheduler, "scheduler", None), "address", scheduler)
    return f"dask ({address})"


def execute(
    fn: Callable[..., Any],
    tasks: Sequence[tuple[Any, ...]],
    *,
    on_result: Callable[[int, Any], None],
    scheduler: Any = None,
    workers: int | None = None,
    on_lost: Callable[[int, str], None] | None = None,
    connect_timeout: float = CONNECT_TIMEOUT,
    what: str = "execute",
) -> str:
    """Run ``fn(*tasks[k])`` for every ``k`` and call ``on_result(k, result)`` in this
    process as each one finishes (in completion order); return the engine's description.

    ``scheduler`` (:func:`~optmodels.execution.as_scheduler`; ``None`` is
    ``"processes"``): ``"serial"`` (here, in order), ``"processes"`` (a local spawn pool
    of ``workers`` processes, each exiting with its parent and ignoring SIGINT; at most 2
    tasks per worker in flight), a Dask address (``tcp://host:8786``) or a
    ``distributed.Client`` (at most :data:`DASK_IN_FLIGHT` tasks per worker thread in
    flight, each result released on the worker once handed over). ``fn`` and the tasks
    must pickle for the last three. A task whose worker died (a crashed pool process,
    Dask's ``KilledWorker``) goes to ``on_lost(k, message)``; without ``on_lost`` the
    error is raised. An exception of
    ``fn`` itself is raised: tasks that may fail record their failures in their result.
    Ctrl-C kills the local workers (cancels the Dask futures) and raises
    ``KeyboardInterrupt``: what was handed to ``on_result`` is all that finished.
    ``what`` names the caller in the ``ProblemError`` of a bad or unreachable scheduler
    (``"<what> scheduler: ..."``); ``connect_timeout`` (s) bounds the connection and the
    handshake with a Dask address.
    """
    scheduler = as_scheduler(f"{what} scheduler", scheduler, default="processes")
    if scheduler == "serial" or not tasks:
        for k, args in enumerate(tasks):
            on_result(k, fn(*args))
        return "serial"
    if scheduler == "processes":
        nworkers = workers or os.cpu_count() or 1
        run_pool(fn, list(tasks), nworkers, on_result, on_lost)
        return f"processes ({nworkers})"
    from distributed import KilledWorker, as_completed

    client, own = dask_client(f"{what} scheduler", scheduler, connect_timeout)
    engine = f"dask ({client.scheduler.address})"
    # at most DASK_IN_FLIGHT tasks per worker thread submitted at a time, each future
    # dropped once its result is handed over: the scheduler holds the arguments of those
    # tasks only and the workers their results only (all submitted at once, a day of
    # track fits kept its arguments on the scheduler and its results on the workers
    # until the last task finished: +145 B a plot at the country scale)
    limit = DASK_IN_FLIGHT * max(1, sum(client.nthreads().values()))
    running = as_completed()
    index: dict[Any, int] = {}
    queue = list(reversed(range(len(tasks))))

    def submit() -> None:
        k = queue.pop()
        fut = client.submit(fn, *tasks[k], pure=False)
        index[fut.key] = k
        running.add(fut)

    try:
        while queue and len(index) < limit:
            submit()
        for f in running:
            k = index.pop(f.key)
            try:
                res = f.result()
            except KilledWorker as exc:
                if on_lost is None:
                    raise
                on_lost(k, f"Dask worker died while running this task ({exc})"[:300])
            else:
                on_result(k, res)
            del f  # the last reference: the worker drops the result
            if queue:
                submit()
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            client.cancel(list(running.futures))
        raise
    finally:
        if own:
            client.close()
    return engine


def run_pool(
    fn: Callable[..., Any],
    tasks: list[tuple[Any, ...]],
    nworkers: int,
    on_result: Callable[[int, Any], None],
    on_lost: Callable[[int, str], None] | None,
) -> None:
    """The local process pool; at most 2 tasks per worker in flight, so that Ctrl-C and
    a dead worker lose little. A dead worker breaks the pool: every task in flight goes
    to ``on_lost`` and a new pool runs the rest."""
    import multiprocessing as mp

    queue = list(reversed(range(len(tasks))))
    msg = "worker process died while running this task"
    while queue:
        ex = ProcessPoolExecutor(
            nworkers,
            mp_context=mp.get_context("spawn"),
            initializer=guard_worker,
            initargs=(os.getpid(),),
        )
        pending: dict[Future[Any], int] = {}
        try:
            while queue or pending:
                with sigint_ignored():  # workers start inside submit
                    while queue and len(pending) < 2 * nworkers:
                        k = queue.pop()
                        pending[ex.submit(fn, *tasks[k])] = k
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                broken = False
                for f in finished:
                    k = pending.pop(f)
                    try:
                        res = f.result()
                    except BrokenProcessPool:
                        if on_lost is None:
                            raise
                        broken = True
                        on_lost(k, msg)
                    else:
                        on_result(k, res)
                if broken:  # every other task in flight died with the pool
                    assert on_lost is not None
                    for k in pending.values():
                        on_lost(k, msg)
                    pending.clear()
                    break
        except BaseException:
            kill_pool(ex)
            raise
        ex.shutdown(wait=True)
