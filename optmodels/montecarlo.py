"""Seeded Monte Carlo studies on local processes or a Dask cluster, with checkpoints.

A *study* is a picklable callable ``study(rng) -> dict[str, float]``: one trial, drawing
everything from the :class:`numpy.random.Generator` it is given. :func:`run` gives trial
``i`` the generator ``default_rng([seed, i])``, so a trial's result depends only on
``(seed, i)`` -- not on the engine, the number of workers, the chunking, or whether the
study was interrupted and resumed. That is what makes the engines interchangeable and the
checkpoints safe.

Engines (``scheduler``):

* ``None`` or ``"processes"`` (default): a local process pool (``concurrent.futures``,
  spawn start method, ``workers`` processes, all cores by default). Workers exit with
  their parent, even after a SIGKILL (Linux ``PR_SET_PDEATHSIG``, plus a watchdog thread
  polling ``os.getppid()`` every 0.5 s elsewhere), and ignore SIGINT (the parent handles
  Ctrl-C);
* ``"serial"``: in this process (debugging, tiny studies);
* ``"tcp://host:8786"`` (any Dask address, ``inproc://`` included), or a
  ``distributed.Client``: Dask distributed (``pip install 'optmodels[distributed]'``).
  The study and optmodels must be importable on the workers. An address that does not
  answer within ``connect_timeout`` (10 s) is a :class:`~optmodels.core.ProblemError`.

Faults:

* a trial that raises is a *failure*, recorded with its index and message
  (:attr:`MonteCarloResult.failures`, and in the checkpoint); the study goes on and the
  summary is computed over the successful trials (:attr:`MonteCarloResult.n_ok`). A rerun
  does not retry recorded failures unless ``retry_failed=True``. A worker process that
  dies (a trial crashed the interpreter) fails the chunks it had in flight; the pool is
  restarted for the rest;
* Ctrl-C (KeyboardInterrupt): the finished chunks are already in the checkpoint, the
  workers are killed, and :class:`Interrupted` (a ``KeyboardInterrupt``, one-line message,
  the partial result in ``.partial``) is raised; rerunning resumes;
* two processes on one checkpoint: the second gets a ``ProblemError`` (an ``fcntl.flock``
  on ``PATH.lock``, held for the run; the kernel drops it when the holder dies, so a
  killed run never blocks the next one).

Checkpoint (``checkpoint=PATH``): JSON lines, a header naming the study and seed, then one
line per finished chunk of trials (``[[i, {name: value}], ...]``) and one per chunk with
failures (``{"failed": [[i, message], ...]}``), appended as whole lines with flush + fsync.
Rerunning with the same path skips the recorded trials; a header that does not match
(another study or seed) or a file that is not a checkpoint is refused rather than mixed in
or overwritten. An empty file, or a header cut short by a crash, starts afresh; lines that
cannot be read (a last line cut short by a kill, garbage) are moved to ``PATH.skipped``,
logged (logger ``optmodels``) and counted (:attr:`MonteCarloResult.skipped_lines`).

Built-in studies (:data:`STUDIES`): plane angle error vs the CRB, trajectories η vs Monte
Carlo, Cov(vec Ŵ) vs (10), bias-field recovery error, association rate vs separation.
Their parameters are checked when the study is built (``ProblemError``).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels.core import (
    ProblemError,
    SolverNotAvailable,
    as_count,
    as_positive,
    check_spd,
)

__all__ = ["STUDIES", "AssignmentSeparation", "BiasfieldRecovery", "FusionWeight",
           "Interrupted", "LineLog", "MonteCarloResult", "PlaneAngle", "TrajectoriesEta",
           "guard_worker", "run", "study"]

Study = Callable[[np.random.Generator], Mapping[str, float]]
log = logging.getLogger("optmodels")

#: Size guards: trials per run (the trial indices are held in memory; split a larger
#: study over seeds) and local worker processes.
MAX_TRIALS = 10_000_000
MAX_WORKERS = 256

#: Seconds to wait for a Dask scheduler to answer (``run(connect_timeout=...)``).
CONNECT_TIMEOUT = 10.0


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a study or a comparison sweep, after what had finished was saved.

    A ``KeyboardInterrupt`` (so ``except Exception`` does not swallow it) whose message
    is one line saying what was kept; ``partial`` is the partial result
    (:class:`MonteCarloResult` with ``interrupted=True``, or the sweep's rows)."""

    def __init__(self, message: str, partial: Any = None) -> None:
        super().__init__(message)
        self.partial = partial

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "interrupted"


# ============================================================ shared fault handling
# (used by the Monte Carlo engine here and by the comparison harness, solvers_cmp.harness)
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


class LineLog:
    """A line-oriented file (JSON lines, CSV) that one process at a time appends to.

    Opening takes an exclusive ``fcntl.flock`` on ``PATH.lock`` for the object's life
    (:class:`~optmodels.core.ProblemError` if another process holds it; the kernel
    releases it when the holder dies, so a stale lock never blocks). :meth:`read` returns
    the complete lines and the bytes after the last newline (a write cut short by a kill);
    :meth:`rewrite` atomically replaces the file by the valid lines, moving the others to
    ``PATH.skipped``; :meth:`append` writes whole lines with flush + fsync.

    ``what`` names the argument in messages, e.g. ``"montecarlo.run checkpoint"``.
    """

    def __init__(self, path: str | os.PathLike[str], what: str) -> None:
        try:
            self.path = Path(path)
        except TypeError:
            raise ProblemError(f"{what}: expected a file path, got {type(path).__name__}"
                               ) from None
        self.what = what
        self._fh: Any = None
        self._lock_fd: int | None = None
        if self.path.is_dir():
            raise ProblemError(f"{what}: {self.path} is a directory, expected a file")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ProblemError(f"{what}: cannot create the folder of {self.path} ({exc})"
                               ) from None
        self._lock()

    def _lock(self) -> None:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no locking
            return
        lock = Path(str(self.path) + ".lock")
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise ProblemError(f"{self.what}: cannot create the lock file {lock} ({exc})"
                               ) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
            os.close(fd)
            raise ProblemError(
                f"{self.what}: {self.path} is in use by another process"
                + (f" (pid {holder})" if holder else "")
                + f"; wait for it to finish or use another path (lock: {lock})") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._lock_fd = fd

    def read(self) -> tuple[list[bytes], bytes]:
        """Complete lines (without their newline) and the incomplete tail."""
        try:
            data = self.path.read_bytes() if self.path.exists() else b""
        except OSError as exc:
            raise ProblemError(f"{self.what}: cannot read {self.path} ({exc})") from None
        cut = data.rfind(b"\n") + 1
        return data[:cut].split(b"\n")[:-1], data[cut:]

    def open_with_header(self, head: str, foreign: str) -> tuple[list[bytes], bytes]:
        """The file's lines after ensuring it starts with a header: a new or empty file,
        or one whose header a crash cut short, is (re)started with ``head`` and gives
        ``([], b"")``; a file with no header line is refused with ``foreign`` (what it is
        not, e.g. "a Monte Carlo checkpoint"). Otherwise :meth:`read`'s lines and tail."""
        lines, tail = self.read()
        if lines:
            return lines, tail
        if tail and not (head + "\n").encode().startswith(tail):
            raise ProblemError(f"{self.what}: {self.path} is not {foreign} (no header "
                               "line); use another path or delete it")
        if tail:
            self.rewrite([], [])  # a header cut short by a crash: start afresh
        self.append([head])
        return [], b""

    def keep(self, keep: list[str], dropped: list[bytes], tail: bytes) -> int:
        """After parsing: if any line was unreadable (or the last cut short), rewrite the
        file with the ``keep`` lines, move the rest to ``PATH.skipped`` and say so
        (:func:`report_skipped`). Returns the number of lines skipped."""
        if dropped or tail:
            moved = self.rewrite(keep, dropped + ([tail] if tail else []))
            report_skipped(self.what, self.path, len(dropped), len(tail), moved)
        return len(dropped) + bool(tail)

    def rewrite(self, lines: list[str], dropped: list[bytes]) -> Path:
        """Replace the file by ``lines`` (atomically: a temporary file, fsync, rename);
        append ``dropped`` to ``PATH.skipped``, which is returned."""
        skipped = Path(str(self.path) + ".skipped")
        with skipped.open("ab") as fh:
            fh.write(b"".join(d + b"\n" for d in dropped))
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        with tmp.open("wb") as fh:
            fh.write("".join(line + "\n" for line in lines).encode())
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        return skipped

    def append(self, lines: list[str]) -> None:
        """Append whole lines (one write), then flush and fsync."""
        if self._fh is None:
            try:
                self._fh = self.path.open("ab")
            except OSError as exc:
                raise ProblemError(f"{self.what}: cannot write {self.path} ({exc})") from None
        if lines:
            self._fh.write("".join(line + "\n" for line in lines).encode())
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Close the file and release the lock."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    def __enter__(self) -> LineLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def report_skipped(what: str, path: Path, bad: int, tail: int, moved: Path) -> None:
    """One warning line (logger ``optmodels``) for lines that could not be read."""
    parts = ([f"{bad} unreadable line{'s' * (bad != 1)}"] if bad else []) + (
        [f"a last line cut short ({tail} bytes)"] if tail else [])
    log.warning("%s: %s: skipped %s (moved to %s)", what, path, " and ".join(parts), moved)


# ============================================================ results
@dataclass
class MonteCarloResult:
    """Per-trial values of the successful trials and the study's summary.

    ``trials`` are the indices of the successful trials (ascending) and ``values[key][j]``
    is trial ``trials[j]``'s value; ``summary`` is computed over them alone (``n_ok``
    trials). ``failures`` lists ``(index, message)`` of the trials that raised (recorded
    ones from the checkpoint included); ``requested`` the number of trials asked for;
    ``resumed`` how many results came from the checkpoint; ``skipped_lines`` the
    checkpoint lines that could not be read; ``interrupted`` marks a partial result
    (:class:`Interrupted`)."""

    study: str
    seed: int
    trials: np.ndarray
    values: dict[str, np.ndarray]
    summary: dict[str, Any] = field(default_factory=dict)
    resumed: int = 0
    engine: str = ""
    failures: list[tuple[int, str]] = field(default_factory=list)
    requested: int = 0
    skipped_lines: int = 0
    interrupted: bool = False
    summary_error: str = ""

    @property
    def n_ok(self) -> int:
        """Number of successful trials (those the values and the summary are over)."""
        return int(self.trials.size)

    def mean(self, key: str) -> float:
        v = self.values[key]
        return float(np.mean(v)) if v.size else float("nan")

    def se(self, key: str) -> float:
        """Standard error of the mean of ``values[key]`` (NaN below two trials)."""
        v = self.values[key]
        return float(np.std(v, ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")


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


def _pair_ok(p: Any) -> bool:
    return (isinstance(p, list) and len(p) == 2 and isinstance(p[0], int)
            and not isinstance(p[0], bool) and p[0] >= 0)


def _load_checkpoint(ck: LineLog, header: dict[str, Any]
                     ) -> tuple[dict[int, dict[str, float]], dict[int, str], int]:
    """Finished and failed trials recorded in the checkpoint, and the number of lines
    skipped. Writes the header of a new (or empty) file; repairs a damaged one."""
    head_line = json.dumps(header)
    lines, tail = ck.open_with_header(head_line, "a Monte Carlo checkpoint")
    if not lines:
        return {}, {}, 0
    try:
        head = json.loads(lines[0])
    except (json.JSONDecodeError, UnicodeDecodeError):
        head = None
    if head != header:
        what = ("is not a Monte Carlo checkpoint (its first line is not a header)"
                if not isinstance(head, dict) or "study" not in head else
                f"belongs to another study or seed ({head})")
        raise ProblemError(f"{ck.what}: {ck.path} {what}; expected {header}. "
                           f"Use another path or delete it.")
    done: dict[int, dict[str, float]] = {}
    failed: dict[int, str] = {}
    keep, dropped = [head_line], []
    for raw in lines[1:]:
        if not raw.strip():
            continue  # blank lines (older versions started each resume with one)
        try:
            rec = json.loads(raw)
            if isinstance(rec, list) and all(
                    _pair_ok(p) and isinstance(p[1], dict) and p[1] and all(
                        isinstance(v, int | float) and not isinstance(v, bool)
                        for v in p[1].values()) for p in rec):
                for i, vals in rec:
                    done[i] = {str(k): float(v) for k, v in vals.items()}
            elif (isinstance(rec, dict) and set(rec) == {"failed"}
                  and isinstance(rec["failed"], list)
                  and all(_pair_ok(p) and isinstance(p[1], str) for p in rec["failed"])):
                for i, msg in rec["failed"]:
                    failed[i] = msg
            else:
                raise ValueError("not a record")
        except (ValueError, UnicodeDecodeError):  # JSONDecodeError is a ValueError
            dropped.append(raw)
            continue
        keep.append(raw.decode())
    skipped = ck.keep(keep, dropped, tail)
    failed = {i: m for i, m in failed.items() if i not in done}
    return done, failed, skipped


def _chunks(todo: list[int], size: int) -> list[list[int]]:
    return [todo[k:k + size] for k in range(0, len(todo), size)]


def _dask_client(scheduler: Any, timeout: float) -> Any:
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
        raise ProblemError(f"montecarlo.run scheduler: cannot reach the Dask scheduler at "
                           f"{scheduler} within {timeout:g} s "
                           f"({type(exc).__name__}: {str(exc)[:200]})") from None


def _check_scheduler(scheduler: Any) -> None:
    if scheduler is None or scheduler in ("processes", "serial"):
        return
    if isinstance(scheduler, str):
        if "://" not in scheduler or scheduler.endswith("://"):
            raise ProblemError(f"montecarlo.run scheduler: expected None, 'processes', "
                               f"'serial' or a Dask address like tcp://host:8786, got "
                               f"{scheduler!r}")
        return
    if not hasattr(scheduler, "submit") or not hasattr(scheduler, "map"):
        raise ProblemError(f"montecarlo.run scheduler: expected None, 'processes', "
                           f"'serial', a Dask address or a distributed.Client, got "
                           f"{type(scheduler).__name__}")


def _kill_pool(ex: ProcessPoolExecutor) -> None:
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

    engine = "serial"
    try:
        if scheduler == "serial" or not parts:
            for p in parts:
                collect(_chunk_task(study, seed, p))
        elif scheduler is None or scheduler == "processes":
            engine = f"processes ({nworkers})"
            _run_pool(study, seed, parts, nworkers, collect)
        else:
            from distributed import as_completed

            client, own = _dask_client(scheduler, connect_timeout)
            engine = f"dask ({client.scheduler.address})"
            futs: list[Any] = []
            try:
                futs = client.map(_chunk_task, [study] * len(parts), [seed] * len(parts),
                                  parts, pure=False)
                for f in as_completed(futs):
                    collect(f.result())
            except KeyboardInterrupt:
                with contextlib.suppress(Exception):
                    client.cancel(futs)
                raise
            finally:
                if own:
                    client.close()
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


def _run_pool(study: Study, seed: int, parts: list[list[int]], nworkers: int,
              collect: Callable[[Chunk], None]) -> None:
    """The local process pool; at most 2 chunks per worker in flight, so that Ctrl-C and
    a dead worker lose little."""
    import multiprocessing as mp

    queue = list(reversed(parts))
    while queue:
        ex = ProcessPoolExecutor(nworkers, mp_context=mp.get_context("spawn"),
                                 initializer=guard_worker, initargs=(os.getpid(),))
        pending: dict[Future[Chunk], list[int]] = {}
        try:
            while queue or pending:
                with sigint_ignored():  # workers start inside submit
                    while queue and len(pending) < 2 * nworkers:
                        p = queue.pop()
                        pending[ex.submit(_chunk_task, study, seed, p)] = p
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                broken = False
                for f in finished:
                    p = pending.pop(f)
                    try:
                        res = f.result()
                    except BrokenProcessPool:
                        broken = True
                        res = ([], [(i, "worker process died while running this chunk "
                                        "(a trial crashed the interpreter?)") for i in p])
                    collect(res)
                if broken:  # every other chunk in flight died with the pool
                    for p in pending.values():
                        collect(([], [(i, "worker process died while running this chunk "
                                          "(a trial crashed the interpreter?)")
                                      for i in p]))
                    pending.clear()
                    break
        except BaseException:
            _kill_pool(ex)
            raise
        ex.shutdown(wait=True)


def _result(study: Study, name: str, seed: int, trials: int,
            done: dict[int, dict[str, float]], failed: dict[int, str], resumed: int,
            engine: str, skipped: int, interrupted: bool = False) -> MonteCarloResult:
    ok = sorted(done)
    fails = dict(failed)
    keys = list(done[ok[0]]) if ok else []
    for i in ok[1:]:
        if set(done[i]) != set(keys):
            fails[i] = f"returned keys {sorted(done[i])}, expected {sorted(keys)}"
    ok = [i for i in ok if i not in fails]
    values = {k: np.array([done[i][k] for i in ok], dtype=float) for k in keys}
    summary: dict[str, Any] = {}
    summary_error = ""
    if ok and hasattr(study, "summarise"):
        try:
            with np.errstate(all="ignore"):
                summary = dict(study.summarise(values))
        except Exception as exc:  # e.g. a covariance from a single trial
            summary_error = f"{type(exc).__name__}: {exc}"[:300]
    return MonteCarloResult(name, seed, np.array(ok, dtype=int), values, summary, resumed,
                            engine, sorted(fails.items()), trials, skipped, interrupted,
                            summary_error)


# ============================================================================ studies
@dataclass(frozen=True)
class PlaneAngle:
    """Plane of maneuver (paper 000): angle error (rad) of the ML plane and of the
    unweighted SVD plane, and the Cramér–Rao bound of the angle for the trial's truth.
    ``setting``: "two-source" (D_i = α_i² D, closed form) or "radar" (general D_i,
    reduced NLP)."""

    n: int = 50
    setting: str = "radar"

    def __post_init__(self) -> None:
        _set(self, "n", as_count("montecarlo.PlaneAngle n", self.n, minimum=3))
        if self.setting not in ("radar", "two-source"):
            raise ProblemError(f"montecarlo.PlaneAngle setting: expected 'radar' or "
                               f"'two-source', got {self.setting!r}")

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import plane, scenarios

        sc = (scenarios.two_source_plane(self.n, rng) if self.setting == "two-source"
              else scenarios.radar_plane(self.n, rng, geometry="broadside"))
        data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
        ml = (plane.closed_form(data) if data.proportional
              else plane.solve(data, "reduced")).require_ok()
        crb = plane.cramer_rao_bound(plane.PlaneData(sc.truth, sc.cov, sc.alpha2),
                                     sc.normal, sc.offset)
        return {"ml": float(plane.angle_error(ml.normal, sc.normal)),
                "svd": float(plane.angle_error(plane.svd_fit(data).normal, sc.normal)),
                "crb2": float(crb.angle_rms ** 2)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        crb = float(np.sqrt(np.mean(v["crb2"])))
        return {"rmse_ml": float(np.sqrt(np.mean(v["ml"] ** 2))),
                "rmse_svd": float(np.sqrt(np.mean(v["svd"] ** 2))), "crb": crb,
                "ml_over_crb": float(np.sqrt(np.mean(v["ml"] ** 2))) / crb}


@dataclass(frozen=True)
class TrajectoriesEta:
    """Dependent linear trajectories (paper 002): squared errors of object 0's velocity
    (the unique parameter of a diverging family) from the dependent fit and from its own
    independent line; Q objects at t = 0..N−1, σ = 1. The ratio of the means is η."""

    q: int = 2
    n: int = 10

    def __post_init__(self) -> None:
        _set(self, "q", as_count("montecarlo.TrajectoriesEta q", self.q, minimum=1))
        _set(self, "n", as_count("montecarlo.TrajectoriesEta n", self.n, minimum=2))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import trajectories as tr

        t = np.arange(self.n, dtype=float)
        v = rng.uniform(-2, 2, self.q)
        vals = [5.0 + v[j] * t + rng.normal(0, 1, self.n) for j in range(self.q)]
        data = tr.TrajectoryData([t] * self.q, vals, 1.0)
        dep = tr.closed_form(data, "diverging")
        ind = tr.closed_form(data, "independent")
        return {"dep": float((dep.velocity[0] - v[0]) ** 2),
                "ind": float((ind.velocity[0] - v[0]) ** 2)}

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import trajectories as tr

        return {"eta_mc": float(np.mean(v["dep"]) / np.mean(v["ind"])),
                "eta_formula": tr.eta(self.n, self.q)}


@dataclass(frozen=True)
class FusionWeight:
    """Fusion (paper 003): Ŵ from n snapshots of two independent estimators (sample
    covariances about the sample mean), vec Ŵ per trial; the summary compares its sample
    covariance with the linearised (10)."""

    n: int = 30
    s1: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 3.0))
    s2: tuple[tuple[float, ...], ...] = ((2.0, 0.5, 0.0), (0.5, 1.0, 0.2), (0.0, 0.2, 1.5))

    def __post_init__(self) -> None:
        from optmodels.core import as_finite_array

        mats = []
        for key in ("s1", "s2"):
            m = as_finite_array(f"montecarlo.FusionWeight {key}", getattr(self, key), ndim=2)
            if m.shape[0] != m.shape[1] or m.shape[0] < 1:
                raise ProblemError(f"montecarlo.FusionWeight {key}: expected a square "
                                   f"matrix, got shape {m.shape}")
            check_spd(f"montecarlo.FusionWeight {key}", m)
            mats.append(m)
            _set(self, key, tuple(tuple(float(x) for x in row) for row in m))
        if mats[0].shape != mats[1].shape:
            raise ProblemError(f"montecarlo.FusionWeight s2: shape {mats[1].shape} differs "
                               f"from s1's {mats[0].shape}")
        # sample covariances about the sample mean need n > m snapshots
        _set(self, "n", as_count("montecarlo.FusionWeight n", self.n,
                                 minimum=mats[0].shape[0] + 1))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import fusion as fu

        s1, s2 = np.array(self.s1), np.array(self.s2)
        m = s1.shape[0]
        a1 = rng.multivariate_normal(np.zeros(m), s1, self.n)
        a2 = rng.multivariate_normal(np.zeros(m), s2, self.n)
        w = fu.weight_from_samples(a1, a2).ravel(order="F")
        return {f"w{k}": float(x) for k, x in enumerate(w)}

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import fusion as fu

        s1, s2 = np.array(self.s1), np.array(self.s2)
        w = np.column_stack([v[f"w{k}"] for k in range(s1.size)])
        emp = np.diag(np.cov(w, rowvar=False))
        lin = np.diag(fu.weight_covariance(s1, s2, self.n, self.n, mean="sample"))
        return {"max_rel_diff_diag": float(np.max(np.abs(emp - lin) / lin)),
                "var_mc_mean": float(np.mean(emp)), "var_linear_mean": float(np.mean(lin))}


@dataclass(frozen=True)
class BiasfieldRecovery:
    """Bias field (paper 001): RMS error of the closed-form smoothest field (11) against
    the true smooth field, range (m) and azimuth (mrad), on synthetic uncertainty sets with
    ``noise`` metres of position noise."""

    cells: int = 200
    noise: float = 20.0

    def __post_init__(self) -> None:
        _set(self, "cells", as_count("montecarlo.BiasfieldRecovery cells", self.cells,
                                     minimum=3))
        _set(self, "noise", as_positive("montecarlo.BiasfieldRecovery noise", self.noise,
                                        allow_zero=True))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import biasfield as bf

        data, truth = bf.synthetic_field_data(rng, cells=self.cells, noise=self.noise)
        f = bf.closed_form(data).require_ok().field
        err = f - truth
        return {"range_rms_m": float(np.sqrt(np.mean(err[..., 0] ** 2))),
                "azimuth_rms_mrad": float(np.sqrt(np.mean(err[..., 1] ** 2)) * 1e3)}


@dataclass(frozen=True)
class AssignmentSeparation:
    """Assignment (paper 004): two objects ``separation`` measurement-σ apart; below
    ``resolution`` σ the sensor returns one merged mark at the centroid, else one each
    (detection probability 1, no clutter in the truth, ρ = 0.05 in the model). A trial
    scores 1 when the MAP hypothesis gets the resolution right (merged vs not) and
    pairs every mark with its source."""

    separation: float = 1.0
    resolution: float = 1.5
    prior_sigma: float = 0.5

    def __post_init__(self) -> None:
        for key in ("separation", "resolution"):
            _set(self, key, as_positive(f"montecarlo.AssignmentSeparation {key}",
                                        getattr(self, key), allow_zero=True))
        _set(self, "prior_sigma", as_positive("montecarlo.AssignmentSeparation prior_sigma",
                                              self.prior_sigma))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import assignment as asg

        truth = np.array([[0.0, 0.0], [self.separation, 0.0]])
        means = truth + rng.normal(0, self.prior_sigma, (2, 2))
        covs = np.stack([np.eye(2) * self.prior_sigma**2] * 2)
        merged = self.separation < self.resolution
        marks = (truth.mean(axis=0, keepdims=True) if merged else truth)
        meas = marks + rng.normal(0, 1.0, marks.shape)
        side = 20.0
        data = asg.AssignmentData(means, covs, meas, np.eye(2), side**2, 0.95, 0.05)
        sol = asg.solve(data).require_ok()
        blocks = [tuple(sorted(b)) for b in sol.partition]
        if merged:
            ok = blocks == [(0, 1)] and int(sol.assignment[0]) == 0
        else:
            ok = sorted(blocks) == [(0,), (1,)] and all(
                int(sol.assignment[k]) == b[0] for k, b in enumerate(sol.partition))
        return {"correct": float(ok)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        p = float(np.mean(v["correct"]))
        return {"rate": p, "se": float(np.sqrt(p * (1 - p) / v["correct"].size))}


#: Built-in studies by name (the CLI's ``optmodels montecarlo NAME``).
STUDIES: dict[str, Callable[..., Study]] = {
    "plane-angle": PlaneAngle,
    "trajectories-eta": TrajectoriesEta,
    "fusion-weight": FusionWeight,
    "biasfield-recovery": BiasfieldRecovery,
    "assignment-separation": AssignmentSeparation,
}


def study(name: str, **params: Any) -> Study:
    """A built-in study by name, e.g. ``study("plane-angle", n=100)``."""
    return _builtin(name, params)


def _set(obj: Any, key: str, value: Any) -> None:
    object.__setattr__(obj, key, value)  # the studies are frozen dataclasses


def _builtin(name: str, params: Any) -> Study:
    if not isinstance(name, str) or name not in STUDIES:
        raise ProblemError(f"montecarlo.run study: unknown study {name!r} "
                           f"(built-in: {sorted(STUDIES)})")
    if not isinstance(params, Mapping) or not all(isinstance(k, str) for k in params):
        raise ProblemError(f"montecarlo.run params: expected a mapping of parameter "
                           f"names to values, got {type(params).__name__}")
    cls = STUDIES[name]
    known = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ProblemError(f"montecarlo.run params: unknown parameter(s) {unknown} of "
                           f"study {name!r} (it takes {known})")
    return cls(**params)
