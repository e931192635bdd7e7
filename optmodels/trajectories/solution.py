"""The solution of paper 002's problem (:class:`TrajectorySolution`: θ, each object's line,
Ψ (14), the re-check's residuals) and the packing of a fit -- or of a failure, with NaN
estimates -- into it (:func:`_package`, :func:`_failure`). The gate that decides between
the two is :func:`optmodels.trajectories.verify._finish`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from optmodels.core import FloatArray, Solution, Status
from optmodels.trajectories.data import Family, TrajectoryData
from optmodels.trajectories.fits import _Fit
from optmodels.trajectories.original import design_matrix


# --------------------------------------------------------------------------- solution
@dataclass
class TrajectorySolution(Solution):
    """Estimated family of lines.

    Attributes
    ----------
    family : Family
    theta : (R,) or (R, d)
        Parameters in the paper's ordering (see :class:`Family`).
    start, velocity : (Q,) or (Q, d)
        Each object's start (at ``epoch``, m) and velocity (m/s).
    covariance : (R, R) or (d, R, R)
        Ψ (14): σ²(AᵀA)⁻¹, or (AᵀWA)⁻¹ with per-measurement variances; one per coordinate
        for vector values. With an epoch far from the data the start's variance is that
        of the extrapolation, σ²(start) ≈ (T_j − epoch)²·σ²(velocity).
    objective : float
        Σ w (y − ŷ)², the χ² statistic of the fit (with σ² known), on ``dof`` degrees of
        freedom, evaluated at the returned lines in centred times.
    dof : int
        (Σ N_j − R)·d.
    residuals : dict
        ``shared_start``, ``shared_velocity`` (relative violation of the family's
        equalities by the lines found) and ``stationarity`` (relative distance to the exact
        least-squares optimum, see the module notes).
    info : dict
        ``time_resolution`` (largest ``eps·|t|/std(t)`` of an object) and
        ``extrapolation`` (rounding of the reported starts in standard deviations of the
        lines at the data), the quantities behind a downgraded status.
    """

    family: Family | None = None
    theta: FloatArray = field(default_factory=lambda: np.empty(0))
    start: FloatArray = field(default_factory=lambda: np.empty(0))
    velocity: FloatArray = field(default_factory=lambda: np.empty(0))
    covariance: FloatArray = field(default_factory=lambda: np.empty(0))
    dof: int = 0
    _data: TrajectoryData | None = field(default=None, repr=False)

    @property
    def design_matrix(self) -> sp.csr_matrix:
        """A ((5), (11)) of this family for this data (sparse, Σ N_j × R)."""
        assert self._data is not None and self.family is not None
        return design_matrix(self._data, self.family)

    @property
    def std(self) -> FloatArray:
        """Standard deviations of θ (square roots of Ψ's diagonal), shaped like θ."""
        diag = np.diagonal(self.covariance, axis1=-2, axis2=-1)
        with np.errstate(invalid="ignore"):
            return np.sqrt(diag.T if diag.ndim == 2 else diag)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out.pop("_data", None)
        fam = self.family
        out["family"] = (
            None
            if fam is None
            else {
                "name": fam.name,
                "start_groups": fam.start_groups,
                "velocity_groups": fam.velocity_groups,
            }
        )
        return out


def _shape(data: TrajectoryData, arr: FloatArray) -> FloatArray:
    """(k, d) → (k,) for scalar values."""
    return arr if data.vector else arr[:, 0]


def _package(
    data: TrajectoryData,
    fam: Family,
    fit: _Fit,
    theta: FloatArray,
    residuals: dict[str, float],
    objective: float,
    common: dict[str, Any],
) -> TrajectorySolution:
    cov = fit.cov
    return TrajectorySolution(
        objective=objective,
        residuals=residuals,
        family=fam,
        theta=_shape(data, theta),
        start=_shape(data, theta[fam.start_index]),
        velocity=_shape(data, theta[fam.velocity_index]),
        covariance=cov if data.vector else cov[0],
        dof=(data.n_measurements - fam.n_params) * data.dim,
        _data=data,
        **common,
    )


def _failure(
    data: TrajectoryData,
    fam: Family,
    fit: _Fit,
    residuals: dict[str, float],
    common: dict[str, Any],
    rejected: FloatArray | None,
) -> TrajectorySolution:
    nan = np.full((fam.n_params, data.dim), np.nan)
    sol = _package(data, fam, fit, nan, residuals, float("nan"), common)
    sol.status = Status.ERROR if common["status"].ok else common["status"]
    if rejected is not None:
        sol.info["rejected_theta"] = rejected
    return sol
