"""The execution engine: :func:`execute` (tasks on serial / a local process pool / Dask
distributed, results handed back in the parent as they finish), shared by the Monte Carlo
trials (:func:`run`) and the comparison harness (``solvers_cmp.harness``, ``optmodels
compare --scheduler``). Trial ``i`` draws from ``default_rng([seed, i])`` whatever the
engine, the chunking or a resume (see :mod:`optmodels.montecarlo`).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels.core import (
    ProblemError,
    SolverNotAvailable,
    as_count,
    as_positive,
)
from optmodels.montecarlo.checkpoint import _load_checkpoint
from optmodels.montecarlo.files import LineLog
from optmodels.montecarlo.results import Interrupted, MonteCarloResult, _result
from optmodels.montecarlo.studies import Study, _builtin
from optmodels.montecarlo.workers import _kill_pool, guard_worker, sigint_ignored

__all__ = ["CONNECT_TIMEOUT", "MAX_TRIALS", "MAX_WORKERS", "execute", "run"]


#: Size guards: trials per run (the trial indices are held in memory; split a larger
#: study over seeds) and local worker processes.
MAX_TRIALS = 10_000_000
MAX_WORKERS = 256


#: Seconds to wait for a Dask scheduler to answer (``run(connect_timeout=...)``).
CONNECT_TIMEOUT = 10.0


def _describe(study: Any) -> str:
    if is_dataclass(study) and not isinstance(study, type):
        return f"{type(study).__name__}{json.dumps(asdict(study), sort_keys=True)}"
    return getattr(study, "__qualname__", type(study).__name__)


Chunk = tuple[list[tuple[int, dict[str, float]]], list[tuple[int, str]]]


def _chunk_task(study: Study, seed: int, indices: list[int]) -> Chunk:
    """Run trials ``indices`` of ``study``; each gets ``default_rng([seed, i])``. A trial
    that raises (or returns no mapping of names to numbers) is a failure, not an abort."""
    ok, failed = [], []
    for i in indices:
        try:
            res = study(np.random.default_rng([seed, i]))
            if not isinstance(res, Mapping) or not res:
                raise TypeError(f"the study returned {type(res).__name__}, expected a "
                                f"non-empty dict of name -> number")
            vals = {str(k): float(v) for k, v in res.items()}
        except Exception as exc:
            failed.append((i, f"{type(exc).__name__}: {exc}"[:300]))
        else:
            ok.append((i, vals))
    return ok, failed


def _chunks(todo: list[int], size: int) -> list[list[int]]:
    return [todo[k:k + size] for k in range(0, len(todo), size)]


def _dask_client(scheduler: Any, timeout: float, what: str = "montecarlo.run") -> Any:
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise SolverNotAvailable("scheduler: Dask distributed is not installed; "
                                 "pip install 'optmodels[distributed]'") from exc
    if isinstance(scheduler, Client):
        return scheduler, False
    try:
        return Client(scheduler, timeout=timeout), True
    except (OSError, TimeoutError, ValueError) as exc:
        raise ProblemError(f"{what} scheduler: cannot reach the Dask scheduler at "
                           f"{scheduler} within {timeout:g} s "
                           f"({type(exc).__name__}: {str(exc)[:200]})") from None


def _check_scheduler(scheduler: Any, what: str = "montecarlo.run") -> None:
    if scheduler is None or scheduler in ("processes", "serial"):
        return
    if isinstance(scheduler, str):
        if "://" not in scheduler or scheduler.endswith("://"):
            raise ProblemError(f"{what} scheduler: expected None, 'processes', "
                               f"'serial' or a Dask address like tcp://host:8786, got "
                               f"{scheduler!r}")
        return
    if not hasattr(scheduler, "submit") or not hasattr(scheduler, "map"):
        raise ProblemError(f"{what} scheduler: expected None, 'processes', "
                           f"'serial', a Dask address or a distributed.Client, got "
                           f"{type(scheduler).__name__}")


def execute(fn: Callable[..., Any], tasks: Sequence[tuple[Any, ...]], *,
            on_result: Callable[[int, Any], None], scheduler: Any = None,
            workers: int | None = None, on_lost: Callable[[int, str], None] | None = None,
            connect_timeout: float = CONNECT_TIMEOUT, what: str = "montecarlo.run") -> str:
    """Run ``fn(*tasks[k])`` for every ``k`` and call ``on_result(k, result)`` in this
    process as each one finishes (in completion order); return the engine's description.

    ``scheduler``: ``"serial"`` (here, in order), ``None``/``"processes"`` (a local spawn
    pool of ``workers`` processes, each exiting with its parent and ignoring SIGINT; at
    most 2 tasks per worker in flight), a Dask address (``tcp://host:8786``) or a
    ``distributed.Client``. ``fn`` and the tasks must pickle for the last two. A task
    whose worker died (a crashed pool process, Dask's ``KilledWorker``) goes to
    ``on_lost(k, message)``; without ``on_lost`` the error is raised. An exception of
    ``fn`` itself is raised: tasks that may fail record their failures in their result.
    Ctrl-C kills the local workers (cancels the Dask futures) and raises
    ``KeyboardInterrupt``: what was handed to ``on_result`` is all that finished.
    ``what`` prefixes the ``ProblemError`` of an unreachable scheduler.
    """
    _check_scheduler(scheduler, what)
    if scheduler == "serial" or not tasks:
        for k, args in enumerate(tasks):
            on_result(k, fn(*args))
        return "serial"
    if scheduler is None or scheduler == "processes":
        nworkers = workers or os.cpu_count() or 1
        _run_pool(fn, list(tasks), nworkers, on_result, on_lost)
        return f"processes ({nworkers})"
    from distributed import KilledWorker, as_completed

    client, own = _dask_client(scheduler, connect_timeout, what)
    engine = f"dask ({client.scheduler.address})"
    futs: list[Any] = []
    try:
        futs = [client.submit(fn, *args, pure=False) for args in tasks]
        index = {f.key: k for k, f in enumerate(futs)}
        for f in as_completed(futs):
            try:
                res = f.result()
            except KilledWorker as exc:
                if on_lost is None:
                    raise
                on_lost(index[f.key], f"Dask worker died while running this task ({exc})"
                        [:300])
            else:
                on_result(index[f.key], res)
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            client.cancel(futs)
        raise
    finally:
        if own:
            client.close()
    return engine


def run(study: Study | str, trials: int, seed: int = 0, *, scheduler: Any = None,
        checkpoint: str | Path | None = None, workers: int | None = None,
        chunk: int | None = None, progress: bool = False,
        params: Mapping[str, Any] | None = None, retry_failed: bool = False,
        connect_timeout: float = CONNECT_TIMEOUT) -> MonteCarloResult:
    """Run ``trials`` seeded trials of ``study`` and summarise the successful ones.

    Parameters
    ----------
    study : callable or str
        ``study(rng) -> {name: value}``, picklable (a module-level function or a dataclass
        instance such as :class:`PlaneAngle`), or the name of a built-in study in
        :data:`STUDIES` (``params`` then go to its constructor, which checks them).
    trials : int
        Number of trials (1 ≤ trials ≤ :data:`MAX_TRIALS` = 10⁷).
    seed : int
        Trial ``i`` uses ``numpy.random.default_rng([seed, i])`` (≥ 0).
    scheduler : None, "processes", "serial", Dask address or ``distributed.Client``
        The engine (module docstring).
    checkpoint : path, optional
        JSON-lines file; trials recorded there (finished or failed) are not run again.
        Locked for the run: a second process on the same path gets a ``ProblemError``.
    workers : int, optional
        Local processes (default: all cores; at most :data:`MAX_WORKERS` = 256).
    chunk : int, optional
        Trials per task (default: about 8 tasks per worker, at most 1000 trials).
    progress : bool
        Show a progress bar (tqdm).
    retry_failed : bool
        Run the trials recorded as failed in the checkpoint again (default: keep them
        as failures).
    connect_timeout : float
        Seconds to wait for a Dask scheduler given by address (default 10).

    Returns
    -------
    MonteCarloResult
        Values and ``summary`` (the study's ``summarise(values)`` when it has one) over
        the successful trials; ``failures`` the others.

    Raises
    ------
    ProblemError
        Bad arguments, a checkpoint of another study or in use by another process, an
        unreachable Dask scheduler.
    Interrupted
        Ctrl-C; what finished is in the checkpoint and in ``exc.partial``.
    """
    if isinstance(study, str):
        study = _builtin(study, params if params is not None else {})
    elif params:
        raise ProblemError("montecarlo.run params: only for a built-in study given by name")
    if not callable(study):
        raise ProblemError(f"montecarlo.run study: expected a callable rng -> dict, got "
                           f"{type(study).__name__}")
    trials = as_count("montecarlo.run trials", trials, minimum=1, maximum=MAX_TRIALS)
    seed = as_count("montecarlo.run seed", seed, minimum=0)
    if workers is not None:
        workers = as_count("montecarlo.run workers", workers, minimum=1, maximum=MAX_WORKERS)
    if chunk is not None:
        chunk = as_count("montecarlo.run chunk", chunk, minimum=1)
    connect_timeout = as_positive("montecarlo.run connect_timeout", connect_timeout)
    _check_scheduler(scheduler)
    name = _describe(study)
    header = {"study": name, "seed": seed}
    ck = (LineLog(checkpoint, "montecarlo.run checkpoint") if checkpoint is not None
          else None)
    try:
        return _run(study, trials, seed, name, header, ck, scheduler, workers, chunk,
                    progress, retry_failed, connect_timeout)
    finally:
        if ck is not None:
            ck.close()


def _run(study: Study, trials: int, seed: int, name: str, header: dict[str, Any],
         ck: LineLog | None, scheduler: Any, workers: int | None, chunk: int | None,
         progress: bool, retry_failed: bool, connect_timeout: float) -> MonteCarloResult:
    done, failed, skipped = _load_checkpoint(ck, header) if ck is not None else ({}, {}, 0)
    done = {i: v for i, v in done.items() if i < trials}
    failed = {i: m for i, m in failed.items() if i < trials}
    if retry_failed:
        failed = {}
    resumed = len(done) + len(failed)
    todo = [i for i in range(trials) if i not in done and i not in failed]
    nworkers = workers or os.cpu_count() or 1
    size = chunk or max(1, min(1000, -(-len(todo) // (8 * nworkers)) if todo else 1))
    parts = _chunks(todo, size)
    bar = tqdm(total=trials, initial=resumed, desc=name[:40], disable=not progress)

    def collect(res: Chunk) -> None:
        ok, bad = res
        for i, vals in ok:
            done[i] = vals
            failed.pop(i, None)
        for i, msg in bad:
            failed[i] = msg
        if ck is not None:
            ck.append(([json.dumps(ok)] if ok else [])
                      + ([json.dumps({"failed": bad})] if bad else []))
        bar.update(len(ok) + len(bad))

    def lost(k: int) -> None:
        collect(([], [(i, "worker process died while running this chunk "
                          "(a trial crashed the interpreter?)") for i in parts[k]]))

    engine = "serial" if scheduler == "serial" or not parts else (
        f"processes ({nworkers})" if scheduler in (None, "processes") else
        f"dask ({getattr(getattr(scheduler, 'scheduler', None), 'address', scheduler)})")
    try:
        engine = execute(_chunk_task, [(study, seed, p) for p in parts],
                         on_result=lambda _k, res: collect(res), scheduler=scheduler,
                         workers=nworkers, on_lost=lambda k, _msg: lost(k),
                         connect_timeout=connect_timeout)
    except KeyboardInterrupt:
        partial = _result(study, name, seed, trials, done, failed, resumed, engine,
                          skipped, interrupted=True)
        where = (f"saved in {ck.path}; rerun the same command to resume" if ck is not None
                 else "no checkpoint, kept in the exception's .partial")
        raise Interrupted(f"montecarlo: interrupted after {len(done) + len(failed)} of "
                          f"{trials} trials ({where})", partial) from None
    finally:
        bar.close()
    return _result(study, name, seed, trials, done, failed, resumed, engine, skipped)


def _run_pool(fn: Callable[..., Any], tasks: list[tuple[Any, ...]], nworkers: int,
              on_result: Callable[[int, Any], None],
              on_lost: Callable[[int, str], None] | None) -> None:
    """The local process pool; at most 2 tasks per worker in flight, so that Ctrl-C and
    a dead worker lose little. A dead worker breaks the pool: every task in flight goes
    to ``on_lost`` and a new pool runs the rest."""
    import multiprocessing as mp

    queue = list(reversed(range(len(tasks))))
    msg = "worker process died while running this task"
    while queue:
        ex = ProcessPoolExecutor(nworkers, mp_context=mp.get_context("spawn"),
                                 initializer=guard_worker, initargs=(os.getpid(),))
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
            _kill_pool(ex)
            raise
        ex.shutdown(wait=True)
