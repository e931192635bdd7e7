"""Fusion (paper 003): :class:`FusionWeight`, vec Ŵ from sample covariances of two
independent estimators, its Monte Carlo covariance compared with the linearised (10).

The study imports :mod:`optmodels.fusion` inside the trial, so that a worker process
loads only what it runs; it is found by :data:`optmodels.montecarlo.studies.STUDIES`
through this module's name (the problem's).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from optmodels.core import ProblemError, as_count, check_spd
from optmodels.montecarlo.studies._common import _set

__all__ = ["FusionWeight"]


@dataclass(frozen=True)
class FusionWeight:
    """Fusion (paper 003): Ŵ from n snapshots of two independent estimators (sample
    covariances about the sample mean), vec Ŵ per trial; the summary compares its sample
    covariance with the linearised (10)."""

    name: ClassVar[str] = "fusion-weight"
    problem: ClassVar[str] = "fusion"
    #: The unit of each per-trial value and summary entry (``optmodels montecarlo`` prints
    #: it); ``w#`` stands for ``w0``, ``w1``, ...
    units: ClassVar[dict[str, str]] = {
        "w#": "dimensionless (an entry of vec Ŵ)",
        "max_rel_diff_diag": "relative (largest |MC − (10)| / (10) on the diagonal)",
        "var_mc_mean": "dimensionless (mean variance of vec Ŵ's entries, Monte Carlo)",
        "var_linear_mean": "dimensionless (mean variance of vec Ŵ's entries, (10))",
    }

    n: int = 30
    s1: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 3.0))
    s2: tuple[tuple[float, ...], ...] = ((2.0, 0.5, 0.0), (0.5, 1.0, 0.2), (0.0, 0.2, 1.5))

    def __post_init__(self) -> None:
        from optmodels.core import as_finite_array

        mats = []
        for key in ("s1", "s2"):
            m = as_finite_array(f"montecarlo.FusionWeight {key}", getattr(self, key), ndim=2)
            if m.shape[0] != m.shape[1] or m.shape[0] < 1:
                raise ProblemError(
                    f"montecarlo.FusionWeight {key}: expected a square matrix, got shape {m.shape}"
                )
            check_spd(f"montecarlo.FusionWeight {key}", m)
            mats.append(m)
            _set(self, key, tuple(tuple(float(x) for x in row) for row in m))
        if mats[0].shape != mats[1].shape:
            raise ProblemError(
                f"montecarlo.FusionWeight s2: shape {mats[1].shape} differs "
                f"from s1's {mats[0].shape}"
            )
        # sample covariances about the sample mean need n > m snapshots
        _set(self, "n", as_count("montecarlo.FusionWeight n", self.n, minimum=mats[0].shape[0] + 1))

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
        return {
            "max_rel_diff_diag": float(np.max(np.abs(emp - lin) / lin)),
            "var_mc_mean": float(np.mean(emp)),
            "var_linear_mean": float(np.mean(lin)),
        }
