"""The fused estimate's solution and its failure form (paper 003 (1)-(2)).

:class:`FusionSolution` is what :func:`optmodels.fusion.fuse` returns, closed form or CVXPY;
:func:`_failure` is the form of a result the gate refused
(:func:`optmodels.fusion.verify._finish`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optmodels.core import REJECT_TOL, FloatArray, Solution

__all__ = ["FusionSolution"]


@dataclass
class FusionSolution(Solution):
    """Fused estimate (1): ``estimate`` (m,), ``covariance`` (C1 + C2)⁻¹, ``W``."""

    estimate: FloatArray = field(default_factory=lambda: np.empty(0))
    covariance: FloatArray = field(default_factory=lambda: np.empty(0))
    W: FloatArray = field(default_factory=lambda: np.empty(0))


def _failure(sol: Solution) -> None:
    """Fusion's failure form: no estimate (NaN), and no W/covariance if W itself failed."""
    sol.estimate = np.full_like(sol.estimate, np.nan)  # type: ignore[attr-defined]
    if not sol.residuals["weight_error"] <= REJECT_TOL:
        sol.W = np.full_like(sol.W, np.nan)  # type: ignore[attr-defined]
        sol.covariance = np.full_like(sol.covariance, np.nan)  # type: ignore[attr-defined]
