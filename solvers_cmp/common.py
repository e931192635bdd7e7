"""Pieces every comparison case uses."""

from __future__ import annotations

import functools
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Repeated:
    """Results and wall times (s) of repeated calls; ``last`` is the final result."""

    results: list[Any]
    walls: list[float]

    @property
    def last(self) -> Any:
        return self.results[-1]

    @property
    def median(self) -> float:
        return float(np.median(self.walls))

    @property
    def best(self) -> float:
        return float(np.min(self.walls))


def repeat(
    fn: Callable[[], Any], repeats: int, setup: Callable[[], None] | None = None
) -> Repeated:
    """Call ``fn`` ``repeats`` times, timing each call (``setup``, if given, runs before
    each call, outside the timed region: e.g. clearing a build cache for cold timings)."""
    results, walls = [], []
    for _ in range(repeats):
        if setup is not None:
            setup()
        t0 = time.perf_counter()
        results.append(fn())
        walls.append(time.perf_counter() - t0)
    return Repeated(results, walls)


@functools.cache
def cpu_name() -> str:
    """The CPU's model name (/proc/cpuinfo), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()
