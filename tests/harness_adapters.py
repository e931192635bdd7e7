"""A deliberately troublesome problem for the harness tests: one run sleeps past the time
limit, one kills its interpreter, one raises; the others solve a 2-vector least-squares
problem exactly (reference = the exact solution)."""

from __future__ import annotations

import os
import signal
import time
from typing import Any

import numpy as np

from solvers_cmp.cases import Adapter, Outcome, Run


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
        return [Run("closed_form", "numpy"), Run("f", "crash"), Run("f", "ok"),
                Run("f", "sleep"), Run("f", "raise"), Run("f", "sloppy")]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        if run.solver == "crash":
            os.kill(os.getpid(), signal.SIGSEGV)
        if run.solver == "sleep":
            time.sleep(60)
        if run.solver == "raise":
            raise RuntimeError("solver library exploded")
        x = data + (1e-3 if run.solver == "sloppy" else 0.0)
        return Outcome(True, "optimal", 0.0, x, 0.0, 0.001, 0.002, 3)
