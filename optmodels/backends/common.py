"""What every back-end returns: the common fields of :class:`optmodels.core.Solution`."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from optmodels.core import Status


@dataclass
class BackendResult:
    """Outcome of one back-end solve, before the problem module adds its own fields."""

    status: Status
    method: str
    build_time: float
    solve_time: float
    iterations: int | None
    message: str
    objective: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)

    def common(self) -> dict[str, Any]:
        """Keyword arguments for a :class:`~optmodels.core.Solution` subclass."""
        return {
            "status": self.status,
            "method": self.method,
            "build_time": self.build_time,
            "solve_time": self.solve_time,
            "iterations": self.iterations,
            "message": self.message,
        }


def probe_in_child(script: str, names: Sequence[str], timeout: float = 120.0) -> dict[str, str]:
    """Run ``script`` (Python source that takes plugin names as ``sys.argv[1:]`` and prints
    ``"<name> <verdict>"`` per name, flushing each line) in a child interpreter.

    A plugin that crashes the interpreter (seen here: a segfault inside a solver library)
    costs only the child: the verdict is ``"crashed ..."`` and the probe resumes with the
    next name. Solver noise on the child's stdout/stderr is discarded.
    """
    import subprocess
    import sys

    todo = list(names)
    res: dict[str, str] = {}
    while todo:
        try:
            proc = subprocess.run(
                [sys.executable, "-c", script, *todo],
                capture_output=True,
                text=True,
                timeout=timeout,
                check=False,
            )
        except subprocess.TimeoutExpired:
            res[todo.pop(0)] = f"probe timed out after {timeout:g} s"
            continue
        for line in proc.stdout.splitlines():
            name, _, verdict = line.partition(" ")
            if name in todo and verdict:
                res[name] = verdict
                todo.remove(name)
        if todo:  # the child died on the first name left
            res[todo.pop(0)] = f"crashed the interpreter (exit code {proc.returncode})"
    return res


@contextmanager
def quiet_fds(fds: Sequence[int] = (1, 2)) -> Iterator[bool]:
    """Point the process's file descriptors ``fds`` (C-level stdout/stderr, where IPOPT and
    HiGHS print) at /dev/null for the block, then restore them. Yields False, silencing
    nothing, where there are no real file descriptors."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(fd) for fd in fds]
    except (OSError, ValueError, AttributeError):  # no real file descriptors
        yield False
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(devnull, fd)
        yield True
    finally:
        for fd, old in zip(fds, saved, strict=True):
            os.dup2(old, fd)
        for fd in (*saved, devnull):
            os.close(fd)


def last_line(text: object, limit: int = 200) -> str:
    """The last non-blank line of a solver's message (CasADi's errors end with the reason),
    cut to ``limit`` characters."""
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    return (lines[-1] if lines else str(text))[:limit]
