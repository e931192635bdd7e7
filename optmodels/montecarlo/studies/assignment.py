"""Assignment (paper 004): :class:`AssignmentSeparation`, the rate at which the MAP
hypothesis resolves (merged or not) and pairs two objects ``separation`` σ apart.

The study imports :mod:`optmodels.assignment` inside the trial, so that a worker process
loads only what it runs; it is found by :data:`optmodels.montecarlo.studies.STUDIES`
through this module's name (the problem's).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from optmodels.core import as_positive
from optmodels.montecarlo.studies._common import _set

__all__ = ["AssignmentSeparation"]


@dataclass(frozen=True)
class AssignmentSeparation:
    """Assignment (paper 004): two objects ``separation`` measurement-σ apart; below
    ``resolution`` σ the sensor returns one merged mark at the centroid, else one each
    (detection probability 1, no clutter in the truth, ρ = 0.05 in the model). A trial
    scores 1 when the MAP hypothesis gets the resolution right (merged vs not) and
    pairs every mark with its source."""

    name: ClassVar[str] = "assignment-separation"
    problem: ClassVar[str] = "assignment"
    #: The unit of each per-trial value and summary entry (``optmodels montecarlo`` prints it).
    units: ClassVar[dict[str, str]] = {
        "correct": "0 or 1 (1: the MAP hypothesis is right)",
        "rate": "fraction of trials",
        "se": "fraction of trials (standard error of the rate)",
    }

    separation: float = 1.0
    resolution: float = 1.5
    prior_sigma: float = 0.5

    def __post_init__(self) -> None:
        for key in ("separation", "resolution"):
            _set(
                self,
                key,
                as_positive(
                    f"montecarlo.AssignmentSeparation {key}", getattr(self, key), allow_zero=True
                ),
            )
        _set(
            self,
            "prior_sigma",
            as_positive("montecarlo.AssignmentSeparation prior_sigma", self.prior_sigma),
        )

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import assignment as asg

        truth = np.array([[0.0, 0.0], [self.separation, 0.0]])
        means = truth + rng.normal(0, self.prior_sigma, (2, 2))
        covs = np.stack([np.eye(2) * self.prior_sigma**2] * 2)
        merged = self.separation < self.resolution
        marks = truth.mean(axis=0, keepdims=True) if merged else truth
        meas = marks + rng.normal(0, 1.0, marks.shape)
        side = 20.0
        data = asg.AssignmentData(means, covs, meas, np.eye(2), side**2, 0.95, 0.05)
        sol = asg.solve(data).require_ok()
        blocks = [tuple(sorted(b)) for b in sol.partition]
        if merged:
            ok = blocks == [(0, 1)] and int(sol.assignment[0]) == 0
        else:
            ok = sorted(blocks) == [(0,), (1,)] and all(
                int(sol.assignment[k]) == b[0] for k, b in enumerate(sol.partition)
            )
        return {"correct": float(ok)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        p = float(np.mean(v["correct"]))
        return {"rate": p, "se": float(np.sqrt(p * (1 - p) / v["correct"].size))}
