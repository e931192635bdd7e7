"""The solution of paper 002's problem (:class:`TrajectorySolution`: θ, each object's line,
Ψ (14), the re-check's residuals), the packing of a fit -- or of a failure, with NaN
estimates -- into it (:func:`_package`, :func:`_failure`), and the end of every
solve and closed form: :func:`_finish` (the one gate :func:`optmodels.core.finish` on the
NumPy residuals of :mod:`.verify`, then the coarse-time / far-epoch downgrade) and
:func:`_finish_solve` (a generic solve's point: re-check, line residuals, gate).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from optmodels.core import VERIFY_TOL, FloatArray, Solution, Status, Verdict, finish
from optmodels.trajectories.data import Family, TrajectoryData
from optmodels.trajectories.fits import _Fit
from optmodels.trajectories.moments import _stats
from optmodels.trajectories.original import design_matrix
from optmodels.trajectories.verify import _downgrade, _line_residuals, _recheck


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


# --------------------------------------------------------------------------- the gate
def _finish(
    data: TrajectoryData,
    fam: Family,
    fit: _Fit,
    theta: FloatArray,
    residuals: dict[str, float],
    objective: float,
    diag: dict[str, Any],
    common: dict[str, Any],
    *,
    strict: bool,
    note: Any,
    keep: _Fit | None = None,
) -> TrajectorySolution:
    """Pack θ and pass it through the one gate (:func:`optmodels.core.finish`, ``strict``
    for a solver's claim, see :func:`optmodels.core.gate`). Refused: the failure form
    (:func:`_failure`, θ kept in ``info["rejected_theta"]``), or with ``keep`` (the
    misprinted (13)) the numbers under status ERROR, packed with the fit ``keep``.
    Accepted: :func:`~.verify._downgrade` (coarse times, far epoch). ``diag`` goes to
    ``info`` except for a refused solver point."""
    sol = _package(data, fam, fit, theta, residuals, objective, common)

    def reject(s: TrajectorySolution) -> TrajectorySolution:
        failed = dict(common, status=s.status, message=s.message)
        if keep is not None:
            out = _package(data, fam, keep, theta, residuals, objective, failed)
        else:
            out = _failure(data, fam, fit, residuals, failed, theta)
        if not strict:
            out.info.update(diag)
        return out

    sol = finish(sol, strict=strict, note=note, reject=reject)
    if sol.ok:
        sol.status, text = _downgrade(data, sol.status, diag)
        if text:
            sol.message += "; " + text
        sol.info.update(diag)
    return sol


def _solve_note(v: Verdict) -> str:
    return f"verification failed: {v.key} = {v.worst:.2e} > {VERIFY_TOL:g}"


def _finish_solve(
    data: TrajectoryData,
    fam: Family,
    fit: _Fit,
    theta: FloatArray,
    lines: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None,
    common: dict[str, Any],
) -> TrajectorySolution:
    """End of :func:`~.generic.solve` for a finite solver point θ (and the solver's own
    lines, constrained formulation): the re-check against the original problem
    (stationarity; the equalities of the family by the lines), the one gate in its strict
    form (a claimed optimum above VERIFY_TOL is OPTIMAL_INACCURATE if it was OPTIMAL and
    stays within REJECT_TOL, else refused), then the downgrades of :func:`_finish`."""
    obj, stat, diag = _recheck(data, fam, fit, theta)
    std = np.sqrt(np.diagonal(fit.cov, axis1=1, axis2=2)).T
    residuals = (
        {"shared_start": 0.0, "shared_velocity": 0.0}
        if lines is None
        else _line_residuals(_stats(data), fam, *lines, std)
    )
    residuals["stationarity"] = stat
    sol = _finish(
        data, fam, fit, theta, residuals, obj, diag, common, strict=True, note=_solve_note
    )
    if lines is not None and sol.ok:
        sol.info["lines"] = {
            "position": lines[0],
            "velocity": lines[1],
            "at_time": (lines[2][:, 0] + data.epoch),
        }
    return sol
