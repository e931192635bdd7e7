"""The comparison harness: cases × formulations × solvers × settings profile.

A *case* is (problem, instance, size, seed); a *run* is a case × formulation × solver ×
profile. Every run goes to a worker process (``isolate=True``, the default) with the
profile's time limit: a run that exceeds it, or crashes the interpreter (a solver
segfault), is recorded as a failed row (``time_limit`` / ``crashed``) and the worker is
restarted, so one bad run never stops a sweep. Rows are appended to ``results.csv`` as they
finish (whole lines, flush + fsync); a rerun skips rows already there (same problem,
instance, size, seed, formulation, solver, settings), so an interrupted sweep resumes where
it stopped.

Faults are handled as in :mod:`optmodels.montecarlo` (same helpers): the worker exits with
its parent, even after a SIGKILL, and ignores SIGINT; Ctrl-C kills the worker, keeps the
finished rows and raises :class:`optmodels.montecarlo.Interrupted`; a second sweep on the
same folder gets a ``ProblemError`` (``results.csv.lock``); unreadable rows of
``results.csv`` (a last row cut short by a kill, garbage) are moved to
``results.csv.skipped``, logged, and run again.

The worker builds each case's instance and its reference once (the closed form where the
paper has one, else the best known solution, see :mod:`solvers_cmp.cases`), then each run
is measured against it: ``solution_error`` (adapter-defined, relative), ``objective_gap``
(relative), ``max_violation`` (the package's NumPy re-check of the original problem), and
``success`` = status OK and error ≤ the profile's tolerance and violation ≤ tolerance
(qpbenchmark's definition), with ``reason`` saying why not.
"""

from __future__ import annotations

import csv
import io
import multiprocessing as mp
import os
import platform
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels.core import ProblemError, as_choice, as_count, as_positive
from optmodels.io import csv_cell
from optmodels.montecarlo import Interrupted, LineLog, guard_worker, sigint_ignored
from solvers_cmp import cases as cs
from solvers_cmp.report import cpu_name

#: Fixed columns of ``results.csv`` (DESIGN.md, "Solver comparison"), in order.
COLUMNS = ("problem", "instance", "size", "seed", "formulation", "solver", "settings",
           "status", "success", "reason", "objective", "objective_gap", "solution_error",
           "max_violation", "build_time", "solve_time", "iterations", "message",
           "solver_version", "cpu")
KEY = ("problem", "instance", "size", "seed", "formulation", "solver", "settings")


@dataclass(frozen=True)
class Profile:
    """A settings profile: solver options and the success tolerances.

    ``error_tol`` bounds ``solution_error`` (relative, or radians for the plane normal;
    assignment errors are 0/1), ``violation_tol`` the re-computed residuals of the
    original problem; ``time_limit`` (s) is per run, and is what a failure is charged in
    the shifted geometric means.
    """

    name: str
    error_tol: float
    violation_tol: float
    time_limit: float
    high_accuracy: bool

    def options(self, solver: str) -> dict[str, Any]:
        """Solver options for this profile: none (the package's defaults) or
        :data:`solvers_cmp.cases.HIGH_OPTIONS`."""
        return dict(cs.HIGH_OPTIONS.get(solver, {})) if self.high_accuracy else {}


PROFILES: dict[str, Profile] = {
    # optmodels' own solver defaults (already tighter than several solvers' own); success
    # at 1e-5: what a tracking engineer needs (sub-metre on 100 km, sub-μrad on angles).
    "default": Profile("default", 1e-5, 1e-6, 60.0, False),
    # every solver pushed to ~1e-10: who reaches 1e-8 at all, and at what cost.
    "high": Profile("high", 1e-8, 1e-8, 120.0, True),
}


@dataclass(frozen=True)
class Case:
    problem: str
    instance: str
    size: int
    seed: int


# ------------------------------------------------------------------------ the worker
class _State:
    """Worker-side cache: the last case's adapter, data and reference."""

    key: tuple[Any, ...] | None = None
    adapter: cs.Adapter | None = None
    data: Any = None
    ref: cs.Outcome | None = None


def _prepare(state: _State, path: str, case: Case) -> dict[str, Any]:
    key = (path, case)
    if state.key != key:
        state.key, state.ref = None, None
        state.adapter = cs.adapter(case.problem, path)
        state.data = state.adapter.make(case.instance, case.size, case.seed)
        state.ref = state.adapter.reference(case.instance, state.data)
        state.key = key
    assert state.ref is not None
    return {"ok": state.ref.ok, "status": state.ref.status, "message": state.ref.message}


def _execute(state: _State, path: str, case: Case, run: cs.Run,
             options: dict[str, Any]) -> dict[str, Any]:
    _prepare(state, path, case)
    ad, ref = state.adapter, state.ref
    assert ad is not None and ref is not None
    out = ad.solve(case.instance, state.data, run, options)
    row: dict[str, Any] = {
        "status": out.status, "objective": out.objective, "max_violation": out.max_violation,
        "build_time": out.build_time, "solve_time": out.solve_time,
        "iterations": out.iterations, "message": out.message, "ok": out.ok,
        "solution_error": float("nan"), "objective_gap": float("nan"),
    }
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
    if log is not None:  # solver libraries print from C/C++: send fds 1 and 2 to the log
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


class Worker:
    """A child process running :func:`_worker_loop`, restarted after a crash/time-out."""

    def __init__(self, log: Path | None = None) -> None:
        self._log = str(log) if log is not None else None
        self._ctx = mp.get_context("spawn")
        self._proc: Any = None
        self._conn: Any = None

    def _start(self) -> None:
        parent, child = self._ctx.Pipe()
        self._proc = self._ctx.Process(target=_worker_loop,
                                       args=(child, self._log, os.getpid()), daemon=True)
        with sigint_ignored():  # the child starts with SIGINT ignored
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


# ------------------------------------------------------------------------ versions
#: Non-CVXPY solver names of the adapters → package (CVXPY's come from
#: :data:`optmodels.backends.cvxpy_backend.PIP_NAMES`; the rest are CasADi plugins).
_OTHER_PACKAGES = {"numpy": "numpy", "scipy": "scipy", "SCIPY": "scipy"}


def solver_version(solver: str) -> str:
    """Package and version behind a solver name (CasADi plugins: the casadi version)."""
    if solver == "python":
        return f"python {platform.python_version()}"
    from optmodels.backends.cvxpy_backend import PIP_NAMES

    pkg = PIP_NAMES.get(solver) or _OTHER_PACKAGES.get(solver, "casadi")
    try:
        return f"{pkg} {metadata.version(pkg)}"
    except metadata.PackageNotFoundError:
        return pkg


# ------------------------------------------------------------------------ the sweep
def _header_line() -> str:
    return _csv_line(dict(zip(COLUMNS, COLUMNS, strict=True)))


def _csv_line(row: Mapping[str, Any]) -> str:
    """One CSV line, newlines in cells replaced by spaces (a row is always one line)."""
    buf = io.StringIO()
    cells = [csv_cell(row.get(c)) for c in COLUMNS]
    cells = [" ".join(str(v).splitlines()) if isinstance(v, str) else v for v in cells]
    csv.writer(buf, lineterminator="").writerow(cells)
    return buf.getvalue()


def _parse_line(raw: bytes) -> dict[str, Any] | None:
    """A row of ``results.csv``, or None if the line is not a complete, readable row."""
    try:
        cells = next(csv.reader([raw.decode()]))
        if len(cells) != len(COLUMNS):
            return None
        return {k: _parse(k, v) for k, v in zip(COLUMNS, cells, strict=True)}
    except (UnicodeDecodeError, ValueError, csv.Error, StopIteration):
        return None


def _load_results(rl: LineLog) -> list[dict[str, Any]]:
    """The readable rows of ``results.csv`` (held by ``rl``); writes the header of a new
    or empty file and moves unreadable lines to ``results.csv.skipped`` (logged)."""
    head = _header_line()
    lines, tail = rl.open_with_header(head, "a results file of this harness")
    if not lines:
        return []
    if lines[0].decode(errors="replace").strip() != head:
        raise ProblemError(f"{rl.what}: {rl.path} has other columns than this harness "
                           f"writes ({', '.join(COLUMNS)}); use another --out or delete it")
    rows, keep, dropped = [], [head], []
    for raw in lines[1:]:
        if not raw.strip():
            continue
        row = _parse_line(raw)
        if row is None:
            dropped.append(raw)
        else:
            rows.append(row)
            keep.append(raw.decode())
    rl.keep(keep, dropped, tail)
    return rows


def read_results(path: Path) -> list[dict[str, Any]]:
    """Rows of an existing ``results.csv`` (numbers parsed), or [] if there is none.
    Read-only: unreadable lines (a row cut short, garbage) are left out, not repaired."""
    path = Path(path)
    if not path.exists():
        return []
    if path.is_dir():
        raise ProblemError(f"compare results: {path} is a directory, expected a file")
    data = path.read_bytes()
    lines = data[:data.rfind(b"\n") + 1].split(b"\n")[:-1]  # without a cut-short tail
    rows = [_parse_line(raw) for raw in lines[1:] if raw.strip()]
    return [r for r in rows if r is not None]


def _parse(key: str, v: str) -> Any:
    if key in ("size", "seed"):
        return int(v)
    if key == "iterations":
        return int(float(v)) if v not in ("", "None") else None
    if key == "success":
        if v not in ("True", "False"):
            raise ValueError(f"success: {v!r}")
        return v == "True"
    if key in ("objective", "objective_gap", "solution_error", "max_violation",
               "build_time", "solve_time"):
        return float(v) if v not in ("", "None") else float("nan")
    return v


def _key(row: dict[str, Any]) -> tuple[Any, ...]:
    return tuple(str(row[k]) for k in KEY)


def _judge(row: dict[str, Any], prof: Profile) -> None:
    ok = row.pop("ok", False)
    err, viol = row["solution_error"], row["max_violation"]
    reasons = []
    if not ok:
        reasons.append(f"status {row['status']}")
    elif not np.isfinite(err):
        reasons.append("no solution error (reference failed)")
    else:
        if err > prof.error_tol:
            reasons.append(f"solution error {err:.1e} > {prof.error_tol:.0e}")
        if not np.isfinite(viol) or viol > prof.violation_tol:
            reasons.append(f"violation {viol:.1e} > {prof.violation_tol:.0e}")
    row["success"] = not reasons
    row["reason"] = "; ".join(reasons)


Sizes = Sequence[int] | Mapping[str, Sequence[int]] | None


def _names(what: str, v: Any) -> list[str] | None:
    """A list of names from a list (or one string); None stays None."""
    if v is None:
        return None
    items = [v] if isinstance(v, str) else v
    if not isinstance(items, Sequence | set | frozenset) or not all(
            isinstance(x, str) for x in items):
        raise ProblemError(f"{what}: expected a list of names, got {v!r}"[:200])
    items = [x.strip() for x in items if x.strip()]
    if not items:
        raise ProblemError(f"{what}: expected at least one name, got {v!r}")
    return items


def _counts(what: str, v: Any, minimum: int) -> list[int]:
    if isinstance(v, str) or not isinstance(v, Sequence | range):
        raise ProblemError(f"{what}: expected a list of whole numbers, got {v!r}"[:200])
    out = [as_count(what, x, minimum=minimum) for x in v]
    if not out:
        raise ProblemError(f"{what}: expected at least one value, got {v!r}")
    return out


def plan(problems: Sequence[str], sizes: Sizes = None,
         solvers: Sequence[str] | None = None, seeds: Sequence[int] = (0,),
         instances: Sequence[str] | None = None) -> list[tuple[str, Case, list[cs.Run]]]:
    """The sweep: (adapter path, case, runs) for every problem × instance × size × seed.
    ``sizes``: one list for every problem, or a list per problem name (missing names and
    ``None``: the adapter's default sizes). ``solvers`` filters runs by solver name
    (case-insensitive); the closed-form rows are always kept (they are the floor of every
    plot).

    Raises
    ------
    ProblemError
        An unknown problem, or a solver or instance name that none of the problems has
        (the message lists the known ones), sizes < 1, seeds < 0.
    """
    problems = _names("compare problems", problems) or []
    solvers = _names("compare solvers", solvers)
    instances = _names("compare instances", instances)
    seeds = _counts("compare seeds", seeds, 0)
    if isinstance(sizes, Mapping):
        sizes = {str(k): _counts(f"compare sizes[{k!r}]", v, 1) for k, v in sizes.items()
                 if v is not None}
    elif sizes is not None:
        sizes = _counts("compare sizes", sizes, 1)
    ads = {p: cs.adapter(p) for p in problems}  # ProblemError for an unknown problem
    if instances:
        known_inst = {i for ad in ads.values() for i in ad.instances}
        bad = [i for i in instances if i not in known_inst]
        if bad:
            raise ProblemError(f"compare instances: unknown instance(s) {bad} of "
                               f"{', '.join(problems)} (known: {sorted(known_inst)})")
    want = {x.lower() for x in solvers} if solvers else None
    if want is not None:
        known = {r.solver for ad in ads.values() for inst in ad.instances
                 if not instances or inst in instances for r in ad.runs(inst)}
        bad = [x for x in solvers or () if x.lower() not in {k.lower() for k in known}]
        if bad:
            raise ProblemError(f"compare solvers: unknown solver(s) {bad} for "
                               f"{', '.join(problems)} (available here: {sorted(known)})")
    out = []
    for p, ad in ads.items():
        path = cs.REGISTRY.get(p)
        assert path is not None
        for inst in ad.instances:
            if instances and inst not in instances:
                continue
            runs = [r for r in ad.runs(inst) if want is None or r.formulation == "closed_form"
                    or r.solver.lower() in want]
            own = sizes.get(p) if isinstance(sizes, Mapping) else sizes
            for size in (own or ad.sizes):
                for seed in seeds:
                    out.append((path, Case(p, inst, int(size), int(seed)), runs))
    return out


def run_sweep(problems: Sequence[str], out: Path, *, sizes: Sizes = None,
              solvers: Sequence[str] | None = None, profile: str = "default",
              seeds: Sequence[int] = (0,), instances: Sequence[str] | None = None,
              time_limit: float | None = None, isolate: bool = True,
              progress: bool = False) -> list[dict[str, Any]]:
    """Run (or resume) a sweep; append rows to ``out/results.csv`` and return all rows of
    this sweep (the finished ones read back included).

    ``time_limit`` (s, > 0 and finite; default the profile's) bounds each run. The folder
    is locked for the sweep: a second sweep on it gets a ``ProblemError``.

    Raises
    ------
    ProblemError
        Bad arguments (see :func:`plan`), ``out`` not a folder, ``results.csv`` of
        another format, or in use by another sweep.
    optmodels.montecarlo.Interrupted
        Ctrl-C: the finished rows are in ``results.csv`` (rerun to resume) and in
        ``exc.partial``.
    """
    profile = as_choice("compare profile", profile, sorted(PROFILES))
    prof = PROFILES[profile]
    limit = (prof.time_limit if time_limit is None
             else as_positive("compare time_limit", time_limit))
    sweep = plan(problems, sizes, solvers, seeds, instances)
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
        return _sweep(rl, done, sweep, out, profile, prof, limit, isolate, progress)
    finally:
        rl.close()


def _sweep(rl: LineLog, done: dict[tuple[Any, ...], dict[str, Any]],
           sweep: list[tuple[str, Case, list[cs.Run]]], out: Path, profile: str,
           prof: Profile, limit: float, isolate: bool, progress: bool
           ) -> list[dict[str, Any]]:
    total = sum(len(runs) for _, _, runs in sweep)
    cpu = cpu_name()
    worker: Worker | _InProcess = Worker(out / "worker.log") if isolate else _InProcess()
    rows: list[dict[str, Any]] = []
    new = 0
    bar = tqdm(total=total, desc=f"compare ({profile})", disable=not progress)
    try:
        for ad_path, case, runs in sweep:
            base = {"problem": case.problem, "instance": case.instance, "size": case.size,
                    "seed": case.seed, "settings": profile, "cpu": cpu}
            todo = []
            for run in runs:
                k = _key({**base, "formulation": run.formulation, "solver": run.solver})
                if k in done:
                    rows.append(done[k])
                    bar.update()
                else:
                    todo.append(run)
            if not todo:
                continue
            # the instance and its reference get their own (longer) time limit
            kind, res = worker.call("prepare", (ad_path, case), 4 * limit)
            prep_fail = None if kind == "ok" else f"instance/reference {kind}: {res}"
            for run in todo:
                row: dict[str, Any] = {**base, "formulation": run.formulation,
                                       "solver": run.solver,
                                       "solver_version": solver_version(run.solver)}
                if prep_fail is None:
                    t0 = time.perf_counter()
                    kind, res = worker.call(
                        "run", (ad_path, case, run, prof.options(run.solver)), limit)
                    wall = time.perf_counter() - t0
                else:
                    kind, res, wall = "error", prep_fail, 0.0
                if kind == "ok":
                    row.update(res)
                else:
                    row.update({"status": kind, "ok": False, "objective": float("nan"),
                                "objective_gap": float("nan"),
                                "solution_error": float("nan"),
                                "max_violation": float("nan"),
                                "build_time": float("nan"),
                                "solve_time": wall if kind != "error" else float("nan"),
                                "iterations": None,
                                "message": (f"killed after the {limit:g} s time limit"
                                            if kind == "time_limit" else
                                            f"worker died (exit code {res})"
                                            if kind == "crashed" else str(res))})
                _judge(row, prof)
                rl.append([_csv_line(row)])
                new += 1
                rows.append({c: row.get(c) for c in COLUMNS})
                bar.update()
    except KeyboardInterrupt:
        worker.stop(kill=True)
        raise Interrupted(f"compare: interrupted after {new} new run(s) of {total} "
                          f"({len(rows)} rows of this sweep saved in {rl.path}); rerun the "
                          f"same command to resume", rows) from None
    finally:
        bar.close()
        worker.stop()
    return rows


# ------------------------------------------------------------------------ metrics
def shifted_geometric_mean(times: Iterable[float], shift: float = 0.01) -> float:
    """exp(mean log(t + shift)) − shift (qpbenchmark; shift 10 ms keeps sub-millisecond
    times from dominating)."""
    t = np.asarray(list(times), dtype=float)
    if t.size == 0:
        return float("nan")
    return float(np.exp(np.mean(np.log(t + shift))) - shift)


def summarise(rows: Sequence[dict[str, Any]], time_limit: float) -> list[dict[str, Any]]:
    """Per (problem, formulation, solver): runs, success rate, shifted geometric means of
    solve and build time (failures charged ``time_limit``), each also normalised to the
    best of its problem, worst error and violation among successes."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["problem"], r["formulation"], r["solver"]), []).append(r)
    out = []
    for (problem, form, solver), rs in groups.items():
        succ = [r for r in rs if r["success"]]
        solve = [r["solve_time"] if r["success"] else time_limit for r in rs]
        build = [r["build_time"] if r["success"] else time_limit for r in rs]
        out.append({
            "problem": problem, "formulation": form, "solver": solver, "runs": len(rs),
            "success_rate": len(succ) / len(rs),
            "sgm_solve_time": shifted_geometric_mean(solve),
            "sgm_build_time": shifted_geometric_mean(build),
            "max_error": max((r["solution_error"] for r in succ), default=float("nan")),
            "max_violation": max((r["max_violation"] for r in succ), default=float("nan")),
        })
    for problem in {o["problem"] for o in out}:
        mine = [o for o in out if o["problem"] == problem]
        for key in ("sgm_solve_time", "sgm_build_time"):
            best = min(o[key] for o in mine) + 0.01
            for o in mine:
                o[key.replace("sgm", "rel")] = (o[key] + 0.01) / best
    out.sort(key=lambda o: (o["problem"], -o["success_rate"], o["sgm_solve_time"]))
    return out
