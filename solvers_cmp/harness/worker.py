"""The isolated local worker of the comparison harness.

:class:`Worker`: a spawned child process running :func:`_worker_loop` (it exits with its
parent, even a SIGKILLed one, and ignores SIGINT: :func:`optmodels.montecarlo.guard_worker`),
restarted after a crash or a time-out; :meth:`Worker.call` enforces the time limit of a
task. The child keeps the last case's adapter, instance and reference (:class:`_State`,
:func:`_prepare`) and measures each run against it (:func:`_execute`). :class:`_InProcess`
is the same interface in this process, without isolation or time limit.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.execution import guard_worker, sigint_ignored
from solvers_cmp import cases as cs
from solvers_cmp.harness.planning import Case


class _State:
    """Worker-side cache: the last case's adapter, data and reference."""

    key: tuple[Any, ...] | None = None
    adapter: cs.Adapter | None = None
    data: Any = None
    ref: cs.Outcome | None = None
    truth: tuple[Any, float] | None = None


def _prepare(state: _State, path: str, case: Case) -> dict[str, Any]:
    key = (path, case)
    if state.key != key:
        state.key, state.ref = None, None
        state.adapter = cs.adapter(case.problem, path)
        state.data = state.adapter.make(case.instance, case.size, case.seed)
        state.ref = state.adapter.reference(case.instance, state.data)
        state.truth = state.adapter.truth(case.instance, case.size, case.seed, state.data)
        state.key = key
    assert state.ref is not None
    return {"ok": state.ref.ok, "status": state.ref.status, "message": state.ref.message}


#: A run's repetitions stop once they have taken this many seconds (the first always runs).
REPEAT_BUDGET = 1.0


def _execute(
    state: _State, path: str, case: Case, run: cs.Run, options: dict[str, Any], repeats: int = 1
) -> dict[str, Any]:
    """One run: ``ad.solve`` up to ``repeats`` times (stopping once the repetitions have
    taken :data:`REPEAT_BUDGET` s), the last result judged. Times (issue 27, item 5):
    ``build_time`` is the *first* call's build -- its wall time minus the solver's time,
    measured here for every row, the closed forms' included (their set-up, not 0) -- and
    ``solve_time`` the median of the calls' solver times; ``build_again`` the median
    build of the later calls (a compiled model reused: CVXPY parameters, cached CasADi
    functions) and ``repeats_done`` how many calls ran."""
    _prepare(state, path, case)
    ad, ref = state.adapter, state.ref
    assert ad is not None and ref is not None
    walls, solves, out = [], [], None
    t_all = time.perf_counter()
    for _ in range(max(int(repeats), 1)):
        t0 = time.perf_counter()
        out = ad.solve(case.instance, state.data, run, options)
        wall = time.perf_counter() - t0
        solves.append(min(float(out.solve_time), wall))
        walls.append(wall)
        if time.perf_counter() - t_all > REPEAT_BUDGET:
            break
    assert out is not None
    builds = [max(w - s, 0.0) for w, s in zip(walls, solves, strict=True)]
    row: dict[str, Any] = {
        "status": out.status,
        "objective": out.objective,
        "max_violation": out.max_violation,
        "build_time": builds[0],
        "solve_time": float(np.median(solves)),
        "iterations": out.iterations,
        "message": out.message,
        "ok": out.ok,
        "solution_error": float("nan"),
        "objective_gap": float("nan"),
        "build_again": float(np.median(builds[1:])) if len(builds) > 1 else float("nan"),
        "repeats_done": len(walls),
        "estimate_sq_error": float("nan"),
        "crb": float("nan"),
    }
    if out.ok and out.x is not None and state.truth is not None:
        # the estimate against the truth of the draw (any estimate the solver calls
        # optimal, also one above the success bar: what an early stop costs)
        row["estimate_sq_error"] = ad.sq_error(out.x, state.truth[0])
        row["crb"] = float(state.truth[1])
    if out.ok and ref.ok:
        row["solution_error"] = ad.error(out.x, ref.x)
        denom = abs(ref.objective) if ref.objective != 0 else 1.0
        row["objective_gap"] = (out.objective - ref.objective) / denom
    elif not ref.ok:
        row["message"] = f"no reference ({ref.status}: {ref.message}); " + row["message"]
    return row


def _worker_loop(conn: Any, log: str | None = None, parent_pid: int | None = None) -> None:
    if parent_pid is not None:  # exit with the parent (even a SIGKILLed one); no Ctrl-C
        guard_worker(parent_pid)
    if log == "-":  # on a Dask worker: C/C++ solver output to its stderr, never stdout
        os.dup2(2, 1)
    elif log is not None:  # solver libraries print from C/C++: send fds 1 and 2 to the log
        fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
    state = _State()
    conn.send(("ready", None))  # start-up (imports) is not charged to the first run
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        kind, args = msg
        try:
            res = _prepare(state, *args) if kind == "prepare" else _execute(state, *args)
            conn.send(("ok", res))
        except Exception as exc:  # reported as the run's failure
            tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
            conn.send(("error", tb[:400]))


#: Seconds a new worker may take to start (spawn + imports) before its first run.
_STARTUP_TIMEOUT = 120.0


@contextlib.contextmanager
def _children_allowed() -> Iterator[None]:
    """Let a daemonic process (a Dask worker started by its nanny) start the run's child:
    multiprocessing refuses children of daemons, but :func:`guard_worker` already ties
    the child's life to its parent."""
    cfg = getattr(mp.current_process(), "_config", {})
    daemon = cfg.pop("daemon", None)
    try:
        yield
    finally:
        if daemon is not None:
            cfg["daemon"] = daemon


class Worker:
    """A child process running :func:`_worker_loop`, restarted after a crash/time-out.
    ``log``: the file for the child's fds 1 and 2 (``"-"``: fd 1 to fd 2)."""

    def __init__(self, log: Path | str | None = None) -> None:
        self._log = str(log) if log is not None else None
        self._ctx = mp.get_context("spawn")
        self._proc: Any = None
        self._conn: Any = None

    def _start(self) -> None:
        parent, child = self._ctx.Pipe()
        self._proc = self._ctx.Process(
            target=_worker_loop, args=(child, self._log, os.getpid()), daemon=True
        )
        with sigint_ignored(), _children_allowed():  # the child starts with SIGINT ignored
            self._proc.start()
        child.close()
        self._conn = parent
        try:  # wait for the child's start-up, so that it is not charged to a run
            if parent.poll(_STARTUP_TIMEOUT):
                parent.recv()
        except (EOFError, OSError):
            pass  # died at start-up: the call that follows reports it as crashed

    def call(self, kind: str, args: tuple[Any, ...], timeout: float) -> tuple[str, Any]:
        """Send one task; ``("ok", result)``, ``("error", message)``, ``("time_limit",
        seconds)`` or ``("crashed", exit code)``."""
        if self._proc is None or not self._proc.is_alive():
            self._start()
        self._conn.send((kind, args))
        try:
            ready = self._conn.poll(timeout)
        except (EOFError, OSError):
            ready = True
        if not ready:
            self.stop(kill=True)
            return "time_limit", timeout
        try:
            msg = self._conn.recv()
            if msg[0] == "ready":  # a start-up slower than _STARTUP_TIMEOUT
                msg = self._conn.recv() if self._conn.poll(timeout) else ("time_limit", timeout)
                if msg[0] == "time_limit":
                    self.stop(kill=True)
            return msg
        except (EOFError, OSError):
            self._proc.join(5)
            code = self._proc.exitcode
            self._proc = None
            return "crashed", code

    def stop(self, kill: bool = False) -> None:
        """Ask the worker to exit (``kill``: kill it now); a worker still busy after 2 s
        is killed, so none outlives the sweep."""
        if self._proc is None:
            return
        if not kill:
            try:
                self._conn.send(None)
            except (OSError, BrokenPipeError):
                pass
            self._proc.join(2)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(2)
        self._proc = None


class _InProcess:
    """Same interface, no isolation (for debugging and quick tests): no time limit."""

    def __init__(self) -> None:
        self.state = _State()

    def call(self, kind: str, args: tuple[Any, ...], timeout: float) -> tuple[str, Any]:
        try:
            fn: Callable[..., dict[str, Any]] = _prepare if kind == "prepare" else _execute
            return "ok", fn(self.state, *args)
        except Exception as exc:
            return "error", f"{type(exc).__name__}: {exc}"[:400]

    def stop(self, kill: bool = False) -> None:
        pass


def run_prepared(
    worker: Worker | _InProcess,
    prepared: list[Any],
    ad_path: str,
    case: Case,
    run: cs.Run,
    options: dict[str, Any],
    limit: float,
    repeats: int = 1,
) -> tuple[str, Any, float]:
    """One run in ``worker``, the local and the Dask engine alike: the case's instance and
    reference first (their own, longer, time limit ``4 * limit``; once per case, remembered
    in ``prepared`` = [(path, case), failure message or None], a failure kept for the case's
    other runs), then the run (``repeats`` calls, :func:`_execute`) within ``limit``.
    Returns ``(kind, result, wall seconds)``."""
    if prepared[0] != (ad_path, case):
        kind, res = worker.call("prepare", (ad_path, case), 4 * limit)
        prepared[:] = [
            (ad_path, case),
            None if kind == "ok" else f"instance/reference {kind}: {res}",
        ]
    if prepared[1] is not None:
        return "error", prepared[1], 0.0
    t0 = time.perf_counter()
    kind, res = worker.call("run", (ad_path, case, run, options, repeats), limit)
    return kind, res, time.perf_counter() - t0
