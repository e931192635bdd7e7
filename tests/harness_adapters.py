"""A deliberately troublesome problem for the harness tests: one run sleeps past the time
limit, one kills its interpreter, one raises; the others solve a 2-vector least-squares
problem exactly (reference = the exact solution). Also the small Monte Carlo studies of
tests/test_montecarlo.py (here, so that worker processes import nothing heavy) and /proc
helpers for the process tests."""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from solvers_cmp.cases import Adapter, Outcome, Run


@dataclass(frozen=True)
class Slow:
    """A study whose trials take ``pause`` seconds (to be killed midway)."""

    pause: float = 0.02

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        time.sleep(self.pause)
        x = rng.normal(size=3)
        return {"a": float(x[0]), "b": float(x @ x)}


@dataclass(frozen=True)
class Flaky:
    """Raises when the trial's first uniform draw is below ``p``; else like :class:`Slow`."""

    p: float = 0.1
    pause: float = 0.0

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        time.sleep(self.pause)
        if rng.uniform() < self.p:
            raise RuntimeError("trial exploded")
        x = rng.normal(size=3)
        return {"a": float(x[0]), "b": float(x @ x)}

    @staticmethod
    def summarise(v: dict[str, np.ndarray]) -> dict[str, float]:
        return {"mean_b": float(np.mean(v["b"]))}


class Trouble(Adapter):
    name = "trouble"
    instances = ("only",)
    sizes = (2,)
    size_meaning = "n"

    def make(self, instance: str, size: int, seed: int) -> Any:
        return np.arange(1.0, size + 1.0)

    def reference(self, instance: str, data: Any) -> Outcome:
        return Outcome(True, "optimal", 0.0, data, 0.0, 0.0, 0.0)

    def runs(self, instance: str) -> list[Run]:
        return [
            Run("closed_form", "numpy"),
            Run("f", "crash"),
            Run("f", "ok"),
            Run("f", "sleep"),
            Run("f", "raise"),
            Run("f", "sloppy"),
        ]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        if run.solver == "crash":
            os.kill(os.getpid(), signal.SIGSEGV)
        if run.solver == "sleep":
            time.sleep(60)
        if run.solver == "raise":
            raise RuntimeError("solver library exploded")
        x = data + (1e-3 if run.solver == "sloppy" else 0.0)
        return Outcome(True, "optimal", 0.0, x, 0.0, 0.001, 0.002, 3)


class GaussMean(Adapter):
    """The analytic case of the statistical-efficiency column: ``size`` draws of
    N(μ, I₃), estimate μ. The sample mean is efficient (E‖x̄ − μ‖² = 3/size, the
    Cramér–Rao bound); ``biased`` adds a fixed δ with ‖δ‖² = 3/size, so that its
    E‖x̂ − μ‖² = 6/size and its efficiency is exactly 1/2."""

    name = "gaussmean"
    instances = ("only",)
    sizes = (10,)
    size_meaning = "draws"

    def make(self, instance: str, size: int, seed: int) -> Any:
        rng = np.random.default_rng([seed, size])
        mu = rng.uniform(-5, 5, 3)
        return {"mu": mu, "z": mu + rng.normal(size=(size, 3))}

    def truth(self, instance: str, size: int, seed: int, data: Any) -> tuple[Any, float]:
        return data["mu"], 3.0 / size

    def reference(self, instance: str, data: Any) -> Outcome:
        return Outcome(True, "optimal", 0.0, data["z"].mean(axis=0), 0.0, 0.0, 0.0)

    def runs(self, instance: str) -> list[Run]:
        return [Run("closed_form", "numpy"), Run("f", "biased")]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        x = data["z"].mean(axis=0)
        if run.solver == "biased":
            x = x + np.sqrt(1.0 / len(data["z"]))  # ‖δ‖² = 3/size
        return Outcome(True, "optimal", 0.0, x, 0.0, 0.0, 1e-4)

    def error(self, x: Any, ref: Any) -> float:
        return 0.0  # judged on success only; the efficiency is what is tested


# ---------------------------------------------------------------- process helpers (Linux /proc)
def children(pid: int) -> list[int]:
    """PIDs whose parent is ``pid`` (from /proc/*/stat)."""
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                stat = open(f"/proc/{d}/stat").read()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d))
    return out


def alive(pids: list[int]) -> list[int]:
    """Those of ``pids`` still running (a zombie nobody reaped counts as dead)."""
    out = []
    for p in pids:
        try:
            state = open(f"/proc/{p}/stat").read().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            out.append(p)
    return out


def wait_gone(pids: list[int], timeout: float) -> list[int]:
    """Poll until none of ``pids`` runs, or ``timeout`` s; the survivors."""
    deadline = time.monotonic() + timeout
    while alive(pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return alive(pids)


def interrupt(proc: Any) -> tuple[str, str, float]:
    """Ctrl-C as a terminal sends it (SIGINT to the whole process group of ``proc``, a
    ``subprocess.Popen`` started with ``start_new_session=True``); waits up to 10 s and
    SIGKILLs a process that did not stop. Returns stdout, stderr and the seconds it took."""
    import signal

    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return out or "", err or "", time.monotonic() - t0
