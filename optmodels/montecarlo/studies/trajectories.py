"""Dependent linear trajectories (paper 002): :class:`TrajectoriesEta`, the velocity
error of the dependent (diverging) fit against the independent lines, whose ratio of means
is compared with the formula for η.

The study imports :mod:`optmodels.trajectories` inside the trial, so that a worker process
loads only what it runs; it is found by :data:`optmodels.montecarlo.studies.STUDIES`
through this module's name (the problem's).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from optmodels.core import as_count
from optmodels.montecarlo.studies._common import _set

__all__ = ["TrajectoriesEta"]


@dataclass(frozen=True)
class TrajectoriesEta:
    """Dependent linear trajectories (paper 002): squared errors of object 0's velocity
    (the unique parameter of a diverging family) from the dependent fit and from its own
    independent line; Q objects at t = 0..N−1, σ = 1. The ratio of the means is η."""

    name: ClassVar[str] = "trajectories-eta"
    problem: ClassVar[str] = "trajectories"
    #: The unit of each per-trial value and summary entry (``optmodels montecarlo`` prints it).
    units: ClassVar[dict[str, str]] = {
        "dep": "(unit of y per s)², σ = 1 (squared velocity error, dependent fit)",
        "ind": "(unit of y per s)², σ = 1 (squared velocity error, independent line)",
        "eta_mc": "ratio (mean dep / mean ind)",
        "eta_formula": "ratio (η of paper 002)",
    }

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
        return {
            "dep": float((dep.velocity[0] - v[0]) ** 2),
            "ind": float((ind.velocity[0] - v[0]) ** 2),
        }

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import trajectories as tr

        return {
            "eta_mc": float(np.mean(v["dep"]) / np.mean(v["ind"])),
            "eta_formula": tr.eta(self.n, self.q),
        }
