"""The study runner: :func:`run` splits the trials into chunks, runs them through the
execution engine (:func:`optmodels.execution.execute`), records them in the checkpoint
and summarises them. Trial ``i`` draws from ``default_rng([seed, i])`` whatever the
engine, the chunking or a resume (see :mod:`optmodels.montecarlo`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels.core import ProblemError, as_count, as_positive
from optmodels.execution import (
    CONNECT_TIMEOUT,
    MAX_WORKERS,
    Interrupted,
    LineLog,
    as_scheduler,
    describe,
    execute,
)
from optmodels.montecarlo.checkpoint import _load_checkpoint
from optmodels.montecarlo.results import MonteCarloResult, _result
from optmodels.montecarlo.studies import Study, _builtin

__all__ = ["MAX_TRIALS", "run"]


#: Size guard: trials per run (the trial indices are held in memory; split a larger
#: study over seeds).
MAX_TRIALS = 10_000_000


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
                raise TypeError(
                    f"the study returned {type(res).__name__}, expected a "
                    f"non-empty dict of name -> number"
                )
            vals = {str(k): float(v) for k, v in res.items()}
        except Exception as exc:
            failed.append((i, f"{type(exc).__name__}: {exc}"[:300]))
        else:
            ok.append((i, vals))
    return ok, failed


def _chunks(todo: list[int], size: int) -> list[list[int]]:
    return [todo[k : k + size] for k in range(0, len(todo), size)]


def run(
    study: Study | str,
    trials: int,
    seed: int = 0,
    *,
    scheduler: Any = None,
    checkpoint: str | Path | None = None,
    workers: int | None = None,
    chunk: int | None = None,
    progress: bool = False,
    params: Mapping[str, Any] | None = None,
    retry_failed: bool = False,
    connect_timeout: float = CONNECT_TIMEOUT,
) -> MonteCarloResult:
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
        raise ProblemError(
            f"montecarlo.run study: expected a callable rng -> dict, got {type(study).__name__}"
        )
    trials = as_count("montecarlo.run trials", trials, minimum=1, maximum=MAX_TRIALS)
    seed = as_count("montecarlo.run seed", seed, minimum=0)
    if workers is not None:
        workers = as_count("montecarlo.run workers", workers, minimum=1, maximum=MAX_WORKERS)
    if chunk is not None:
        chunk = as_count("montecarlo.run chunk", chunk, minimum=1)
    connect_timeout = as_positive("montecarlo.run connect_timeout", connect_timeout)
    scheduler = as_scheduler("montecarlo.run scheduler", scheduler, default="processes")
    name = _describe(study)
    header = {"study": name, "seed": seed}
    ck = LineLog(checkpoint, "montecarlo.run checkpoint") if checkpoint is not None else None
    try:
        return _run(
            study,
            trials,
            seed,
            name,
            header,
            ck,
            scheduler,
            workers,
            chunk,
            progress,
            retry_failed,
            connect_timeout,
        )
    finally:
        if ck is not None:
            ck.close()


def _run(
    study: Study,
    trials: int,
    seed: int,
    name: str,
    header: dict[str, Any],
    ck: LineLog | None,
    scheduler: Any,
    workers: int | None,
    chunk: int | None,
    progress: bool,
    retry_failed: bool,
    connect_timeout: float,
) -> MonteCarloResult:
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
            ck.append(
                ([json.dumps(ok)] if ok else []) + ([json.dumps({"failed": bad})] if bad else [])
            )
        bar.update(len(ok) + len(bad))

    def lost(k: int) -> None:
        collect(
            (
                [],
                [
                    (
                        i,
                        "worker process died while running this chunk "
                        "(a trial crashed the interpreter?)",
                    )
                    for i in parts[k]
                ],
            )
        )

    engine = "serial" if not parts else describe(scheduler, nworkers)
    try:
        engine = execute(
            _chunk_task,
            [(study, seed, p) for p in parts],
            on_result=lambda _k, res: collect(res),
            scheduler=scheduler,
            workers=nworkers,
            on_lost=lambda k, _msg: lost(k),
            connect_timeout=connect_timeout,
            what="montecarlo.run",
        )
    except KeyboardInterrupt:
        partial = _result(
            study, name, seed, trials, done, failed, resumed, engine, skipped, interrupted=True
        )
        where = (
            f"saved in {ck.path}; rerun the same command to resume"
            if ck is not None
            else "no checkpoint, kept in the exception's .partial"
        )
        raise Interrupted(
            f"montecarlo: interrupted after {len(done) + len(failed)} of {trials} trials ({where})",
            partial,
        ) from None
    finally:
        bar.close()
    return _result(study, name, seed, trials, done, failed, resumed, engine, skipped)
