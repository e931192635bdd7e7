"""The sweep of the comparison harness: :func:`run_sweep` and its loop :func:`_sweep`.

Checks the arguments, locks and repairs ``results.csv``, skips the rows already there and
sends the other runs through :func:`optmodels.execution.execute`: in order to the
one local :class:`~solvers_cmp.harness.worker.Worker` (or :class:`_InProcess`), or as Dask
tasks (:func:`~solvers_cmp.harness.remote._remote_run`); each outcome becomes a judged row
appended to ``results.csv`` by this process alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from optmodels.core import ProblemError, as_choice, as_count, as_positive
from optmodels.execution import CONNECT_TIMEOUT, Interrupted, LineLog, as_scheduler, execute
from solvers_cmp import cases as cs
from solvers_cmp.common import cpu_name
from solvers_cmp.harness.planning import Case, Sizes, plan
from solvers_cmp.harness.profiles import PROFILES, Profile, _judge, options_key, too_slow
from solvers_cmp.harness.remote import _remote_run
from solvers_cmp.harness.results import COLUMNS, _csv_line, _key, _load_results
from solvers_cmp.harness.versions import solver_version
from solvers_cmp.harness.worker import Worker, _InProcess, run_prepared


def run_sweep(
    problems: Sequence[str],
    out: Path,
    *,
    sizes: Sizes = None,
    solvers: Sequence[str] | None = None,
    profile: str = "default",
    seeds: Sequence[int] = (0,),
    instances: Sequence[str] | None = None,
    time_limit: float | None = None,
    isolate: bool = True,
    progress: bool = False,
    scheduler: Any = None,
    connect_timeout: float = CONNECT_TIMEOUT,
    repeats: int = 3,
    skip_slow: bool = False,
) -> list[dict[str, Any]]:
    """Run (or resume) a sweep; append rows to ``out/results.csv`` and return all rows of
    this sweep (the finished ones read back included), in the sweep's order.

    ``time_limit`` (s, > 0 and finite; default the profile's) bounds each run. The folder
    is locked for the sweep: a second sweep on it gets a ``ProblemError``.
    ``scheduler`` (:func:`optmodels.execution.as_scheduler`): ``None``/``"processes"``
    (one worker process here, or in this process with ``isolate=False``), ``"serial"``
    (in this process), or a Dask address (``tcp://host:8786``) / ``distributed.Client``:
    each run is then one Dask task, isolated in a child process of its Dask worker with
    the same time limit (:func:`_remote_run`; ``isolate`` is not used). Both go through
    :func:`optmodels.execution.execute`; this process alone writes
    ``results.csv``, so resume, locks and repairs are the same. ``connect_timeout``: s to
    reach the scheduler (an unreachable one is a ``ProblemError``). ``repeats``: calls
    per run (median solve time; stopped after 1 s of calls), ``skip_slow``: leave out the
    runs :data:`solvers_cmp.harness.profiles.TOO_SLOW` marks as too slow for their size
    (the quick sweep; they are listed in the report, not run).

    A row is reused on a rerun only when its whole key matches (:data:`KEY`: the case,
    formulation, solver, profile, time limit, options, solver version and repeats);
    any other row is computed again.

    Raises
    ------
    ProblemError
        Bad arguments (see :func:`plan`), ``out`` not a folder, ``results.csv`` of
        another format, or in use by another sweep.
    optmodels.execution.Interrupted
        Ctrl-C: the finished rows are in ``results.csv`` (rerun to resume) and in
        ``exc.partial``.
    """
    profile = as_choice("compare profile", profile, sorted(PROFILES))
    prof = PROFILES[profile]
    limit = prof.time_limit if time_limit is None else as_positive("compare time_limit", time_limit)
    scheduler = as_scheduler("compare scheduler", scheduler, default="processes")
    connect_timeout = as_positive("compare connect_timeout", connect_timeout)
    repeats = as_count("compare repeats", repeats, minimum=1)
    sweep = plan(problems, sizes, solvers, seeds, instances)
    if skip_slow:
        sweep = [(a, c, [r for r in runs if too_slow(c, r) is None]) for a, c, runs in sweep]
    try:
        out = Path(out)
    except TypeError:
        raise ProblemError(f"compare out: expected a folder path, got {out!r}") from None
    if out.exists() and not out.is_dir():
        raise ProblemError(f"compare out: {out} is a file, expected a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProblemError(f"compare out: cannot create {out} ({exc})") from None
    path = out / "results.csv"
    rl = LineLog(path, "compare results")
    try:
        done = {_key(r): r for r in _load_results(rl)}
        return _sweep(
            rl,
            done,
            sweep,
            out,
            profile,
            prof,
            limit,
            isolate,
            progress,
            scheduler,
            connect_timeout,
            repeats,
        )
    finally:
        rl.close()


def _sweep(
    rl: LineLog,
    done: dict[tuple[Any, ...], dict[str, Any]],
    sweep: list[tuple[str, Case, list[cs.Run]]],
    out: Path,
    profile: str,
    prof: Profile,
    limit: float,
    isolate: bool,
    progress: bool,
    scheduler: Any = None,
    connect_timeout: float = CONNECT_TIMEOUT,
    repeats: int = 1,
) -> list[dict[str, Any]]:
    total = sum(len(runs) for _, _, runs in sweep)
    cpu = cpu_name()
    slots: list[dict[str, Any] | None] = []  # the sweep's rows, in order
    tasks: list[tuple[int, dict[str, Any], str, Case, cs.Run]] = []
    for ad_path, case, runs in sweep:
        base = {
            "problem": case.problem,
            "instance": case.instance,
            "size": case.size,
            "seed": case.seed,
            "settings": profile,
            "cpu": cpu,
            "time_limit": float(limit),
            "repeats": repeats,
        }
        for run in runs:
            mine = {
                **base,
                "formulation": run.formulation,
                "solver": run.solver,
                "options": options_key(prof, run.solver),
                "solver_version": solver_version(run.solver),
            }
            k = _key(mine)
            if k in done:
                slots.append(done[k])
            else:
                tasks.append((len(slots), mine, ad_path, case, run))
                slots.append(None)
    new = 0
    bar = tqdm(
        total=total, initial=total - len(tasks), desc=f"compare ({profile})", disable=not progress
    )

    def record(t: int, outcome: tuple[str, Any, float, str, str]) -> None:
        nonlocal new
        slot, base, _, _, _ = tasks[t]
        kind, res, wall, version, where = outcome
        row: dict[str, Any] = {**base, "cpu": where, "solver_version": version}
        if kind == "ok":
            row.update(res)
        else:
            row.update(
                {
                    "status": kind,
                    "ok": False,
                    "objective": float("nan"),
                    "objective_gap": float("nan"),
                    "solution_error": float("nan"),
                    "max_violation": float("nan"),
                    "build_time": float("nan"),
                    "solve_time": wall if kind != "error" else float("nan"),
                    "iterations": None,
                    "estimate_sq_error": float("nan"),
                    "crb": float("nan"),
                    "message": (
                        f"killed after the {limit:g} s time limit"
                        if kind == "time_limit"
                        else (
                            f"worker died ({res})"
                            if isinstance(res, str)
                            else f"worker died (exit code {res})"
                        )
                        if kind == "crashed"
                        else str(res)
                    ),
                }
            )
        _judge(row, prof)
        rl.append([_csv_line(row)])
        new += 1
        slots[slot] = {c: row.get(c) for c in COLUMNS}
        bar.update()

    worker: Worker | _InProcess | None = None
    prepared: list[Any] = [None, None]  # (path, case) last prepared, its failure

    def local_run(
        ad_path: str,
        case: Case,
        run: cs.Run,
        options: dict[str, Any],
        limit: float,
        repeats: int = 1,
    ) -> tuple[str, Any, float, str, str]:
        """One run on this machine: the instance and its reference once per case (their
        own, longer, time limit), then the run in the worker with the time limit."""
        assert worker is not None
        return (
            *run_prepared(worker, prepared, ad_path, case, run, options, limit, repeats),
            solver_version(run.solver),
            cpu,
        )

    def lost(t: int, msg: str) -> None:
        record(t, ("crashed", msg, float("nan"), solver_version(tasks[t][4].solver), "unknown"))

    args = [
        (ad_path, case, run, prof.options(run.solver), limit, repeats)
        for _, _, ad_path, case, run in tasks
    ]
    try:
        if scheduler in ("serial", "processes"):
            worker = (
                Worker(out / "worker.log") if isolate and scheduler == "processes" else _InProcess()
            )
            execute(local_run, args, on_result=record, scheduler="serial")
        else:
            execute(
                _remote_run,
                args,
                on_result=record,
                on_lost=lost,
                scheduler=scheduler,
                connect_timeout=connect_timeout,
                what="compare",
            )
    except KeyboardInterrupt:
        if worker is not None:
            worker.stop(kill=True)
        rows = [r for r in slots if r is not None]
        raise Interrupted(
            f"compare: interrupted after {new} new run(s) of {total} "
            f"({len(rows)} rows of this sweep saved in {rl.path}); rerun the "
            f"same command to resume",
            rows,
        ) from None
    finally:
        bar.close()
        if worker is not None:
            worker.stop()
    return [r for r in slots if r is not None]
