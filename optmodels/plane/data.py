r"""Data and the original problem (1.2)-(1.3) of the plane of maneuver, in NumPy.

:class:`PlaneData` (measurements :math:`x_i^*` and covariances :math:`D_i`, with the
proportional case (1.4) detected) and the functions of the
original form at a candidate: :func:`objective` (1.2), :func:`constraint_residuals` (1.3),
:func:`reduced_objective` (1.11)-(1.12), :func:`optimal_offset` (the ``a`` of (1.12), (1.7)
under (1.4)) and :func:`project`, the oblique projection (1.8). Imports only
:mod:`optmodels.core`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_finite_array,
    as_instance,
    as_number,
    check_spd,
    check_spd_stack,
)

#: Relative tolerance to declare D_i proportional (1.4): round-off of a product α²·D.
_PROPORTIONAL_RTOL = 1e-10
_EPS = float(np.finfo(float).eps)


# =========================================================================== data
@dataclass(frozen=True)
class PlaneData:
    """Measurements of a target that may move in a plane.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Measured positions :math:`x_i^*`, N >= 3.
    cov : array_like, shape (3, 3) or (N, 3, 3)
        Either the common matrix ``D`` of (1.4), then :math:`D_i = \\alpha_i^2 D`, or one
        error covariance :math:`D_i` per point. Each must be symmetric positive definite.
    alpha2 : array_like, shape (N,), optional
        The known factors :math:`\\alpha_i^2 > 0` of (1.4); only with a (3, 3) ``cov``.
        Default: ones (a single source).

    Attributes
    ----------
    covs : ndarray, shape (N, 3, 3)
        The :math:`D_i` actually used.
    base_cov, alpha2 : ndarray or None
        ``D`` and :math:`\\alpha_i^2` when the :math:`D_i` are proportional (1.4) --
        given so, or detected in a per-point stack -- else ``None``.
    """

    points: FloatArray
    cov: FloatArray
    alpha2: FloatArray | None = None
    covs: FloatArray = field(init=False, repr=False)
    base_cov: FloatArray | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pts = as_finite_array(
            "plane.PlaneData points", self.points, shape=(None, 3), max_abs=MAX_MAGNITUDE
        )
        n = pts.shape[0]
        if n < 3:
            raise ProblemError(f"plane.PlaneData points: a plane needs at least 3 points, got {n}")
        cov = as_finite_array("plane.PlaneData cov", self.cov, ndim=(2, 3), max_abs=MAX_MAGNITUDE)
        alpha2: FloatArray | None
        if cov.ndim == 2:
            if cov.shape != (3, 3):
                raise ProblemError(
                    f"plane.PlaneData cov: expected shape (3, 3) or ({n}, 3, 3), got {cov.shape}"
                )
            check_spd("plane.PlaneData cov", cov)
            if self.alpha2 is None:
                alpha2 = np.ones(n)
            else:
                alpha2 = as_finite_array(
                    "plane.PlaneData alpha2", self.alpha2, shape=(n,), max_abs=MAX_MAGNITUDE
                )
                if np.any(alpha2 < 1 / MAX_MAGNITUDE):
                    raise ProblemError(
                        f"plane.PlaneData alpha2: the factors of (1.4) must be ≥ 1e-100; "
                        f"{int(np.sum(alpha2 < 1 / MAX_MAGNITUDE))} are not"
                    )
            common = 0.5 * (cov + cov.T)
            covs = alpha2[:, None, None] * common
            base: FloatArray | None = common
        else:
            if cov.shape != (n, 3, 3):
                raise ProblemError(
                    f"plane.PlaneData cov: expected shape (3, 3) or ({n}, 3, 3), got {cov.shape}"
                )
            if self.alpha2 is not None:
                raise ProblemError(
                    "plane.PlaneData alpha2: only meaningful with a common (3, 3) cov (1.4); "
                    "with per-point "
                    "covariances put the factors into cov"
                )
            check_spd_stack("plane.PlaneData cov", cov)
            covs = 0.5 * (cov + cov.transpose(0, 2, 1))
            base, alpha2 = _detect_proportional(covs)
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        # Scale-invariant and independent of the covariances: refuse only what no D_i can
        # rescue -- a spread at the round-off level of the coordinates themselves. Data
        # that are collinear to within the noise, or ill-conditioned for a given D, are
        # judged by the solvers' re-checks (closed_form refuses, solve downgrades) and
        # by the "resolved" line test of planarity_test / identify_sequence.
        scale = float(np.max(np.abs(pts)))
        floor = 64.0 * _EPS * np.sqrt(n) * scale
        if spread[0] <= max(floor, 1e-12 * scale * np.sqrt(n)) or scale == 0.0:
            raise ProblemError(
                "plane.PlaneData points: all points are identical; no plane is defined"
            )
        if spread[1] <= floor:
            raise ProblemError(
                "plane.PlaneData points: the points are collinear (spread across their line "
                f"{float(spread[1]):.3g} is at the round-off level of coordinates up to "
                f"{scale:.3g}); every plane through the line fits, the plane is not unique"
            )
        # Found by the robustness sweep: covariances at 1e±150 relative to the points made
        # the scaled problem's inverses and quadratic forms overflow. The plane problem is
        # invariant to x → s·x, D → s²·D; what must stay in range is the noise relative to
        # the extent of the data.
        eig = np.linalg.eigvalsh(covs)
        ext2 = max(float(spread[0]) ** 2 / n, 1e-300)
        if float(eig.min()) < 1e-100 * ext2 or float(eig.max()) > 1e100 * ext2:
            raise ProblemError(
                f"plane.PlaneData cov: variances from {float(eig.min()):.3g} to "
                f"{float(eig.max()):.3g} for points spread over {np.sqrt(ext2):.3g}; "
                "outside 1e±100 of the spread² (float64 cannot hold the weights); check units"
            )
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "alpha2", alpha2)
        object.__setattr__(self, "covs", covs)
        object.__setattr__(self, "base_cov", base)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def proportional(self) -> bool:
        """Whether the covariances satisfy (1.4), so that :func:`closed_form` applies."""
        return self.base_cov is not None


def _detect_proportional(covs: FloatArray) -> tuple[FloatArray | None, FloatArray | None]:
    """Return ``(D, alpha2)`` if every ``covs[i] = alpha2[i] * D`` to round-off, else Nones."""
    ref = covs[0] / np.trace(covs[0])
    alpha2 = np.trace(covs, axis1=1, axis2=2)
    dev = np.max(np.abs(covs - alpha2[:, None, None] * ref), axis=(1, 2))
    if np.all(dev <= _PROPORTIONAL_RTOL * np.max(np.abs(covs), axis=(1, 2))):
        return ref, alpha2
    return None, None


def _canonical_sign(normal: FloatArray, offset: float) -> tuple[FloatArray, float]:
    nrm = np.asarray(normal, dtype=float)
    if offset < 0 or (offset == 0 and nrm[np.flatnonzero(nrm)[0]] < 0):
        return -nrm, -offset
    return nrm, float(offset)


# =========================================================================== original form
def objective(data: PlaneData, projected: ArrayLike) -> float:
    """Objective (1.2): :math:`\\sum_i (x_i - x_i^*)^T D_i^{-1} (x_i - x_i^*)`
    (dimensionless; ``projected`` in the units of the points)."""
    _check_data("plane.objective", data)
    x = as_finite_array("plane.objective projected", projected, shape=(data.n_points, 3))
    e = x - data.points
    sol = np.linalg.solve(data.covs, e[..., None])[..., 0]
    return float(np.sum(e * sol))


def constraint_residuals(
    data: PlaneData, projected: ArrayLike, normal: ArrayLike, offset: float
) -> dict[str, float]:
    """Maximum violation of each constraint of (1.3) at a candidate solution.

    Returns ``{"plane": max_i |<n, x_i> - a|, "unit_normal": |‖n‖² - 1|}`` (metres and
    dimensionless).
    """
    _check_data("plane.constraint_residuals", data)
    x = as_finite_array("plane.constraint_residuals projected", projected, shape=(data.n_points, 3))
    n = as_finite_array("plane.constraint_residuals normal", normal, shape=(3,))
    offset = as_number("plane.constraint_residuals offset", offset)
    return {
        "plane": float(np.max(np.abs(x @ n - offset))) if x.size else float("nan"),
        "unit_normal": float(abs(n @ n - 1.0)),
    }


def _quad_forms(covs: FloatArray, normal: FloatArray) -> FloatArray:
    """:math:`\\langle D_i n, n\\rangle` for every i."""
    return np.einsum("j,ijk,k->i", normal, covs, normal)


def reduced_objective(data: PlaneData, normal: ArrayLike, offset: float) -> float:
    """Objective (1.12): :math:`\\sum_i (a - \\langle n, x_i^*\\rangle)^2 / \\langle D_i n,
    n\\rangle` -- the minimum of (1.2) over the :math:`x_i` for a fixed plane (1.11)."""
    n, offset = _check_plane("plane.reduced_objective", data, normal, offset)
    r = offset - data.points @ n
    return float(np.sum(r * r / _quad_forms(data.covs, n)))


def _weighted_offset(
    points: FloatArray, covs: FloatArray, normal: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Weights :math:`w_i = 1/\\langle D_i n, n\\rangle`, projections
    :math:`\\langle n, x_i^*\\rangle` and the offset minimising (1.12) for this normal."""
    w = 1.0 / _quad_forms(covs, normal)
    proj = points @ normal
    return w, proj, float(np.sum(w * proj) / np.sum(w))


def _oblique_projection(
    points: FloatArray, covs: FloatArray, normal: FloatArray, offset: float
) -> FloatArray:
    """(1.8) on raw arrays: :math:`x_i^* + (a - \\langle n, x_i^*\\rangle) D_i n /
    \\langle D_i n, n\\rangle`."""
    dn = covs @ normal
    coef = (offset - points @ normal) / (dn @ normal)
    return points + coef[:, None] * dn


def optimal_offset(data: PlaneData, normal: ArrayLike) -> float:
    """The ``a`` minimising (1.12) for a fixed normal: a weighted mean of
    :math:`\\langle n, x_i^*\\rangle` with weights :math:`1/\\langle D_i n, n\\rangle`
    (under (1.4) this is (1.7))."""
    n, _ = _check_plane("plane.optimal_offset", data, normal, 0.0)
    return _weighted_offset(data.points, data.covs, n)[2]


def project(data: PlaneData, normal: ArrayLike, offset: float) -> FloatArray:
    """Most likely true positions on a given plane, (1.8):
    :math:`x_i = x_i^* + \\frac{a - \\langle n, x_i^*\\rangle}{\\langle D_i n, n\\rangle} D_i n`."""
    n, offset = _check_plane("plane.project", data, normal, offset)
    return _oblique_projection(data.points, data.covs, n, offset)


def _check_data(where: str, data: Any) -> None:
    as_instance(f"{where} data", data, PlaneData)


def _check_plane(where: str, data: Any, normal: ArrayLike, offset: Any) -> tuple[FloatArray, float]:
    """Validated ``(normal, offset)``: a finite non-zero (3,) vector (not renormalised:
    the functions are evaluated at the plane exactly as given) and a finite number."""
    _check_data(where, data)
    n = as_finite_array(f"{where} normal", normal, shape=(3,), max_abs=MAX_MAGNITUDE)
    if not float(np.linalg.norm(n)) > 0:
        raise ProblemError(f"{where} normal: must be non-zero")
    return n, as_number(f"{where} offset", offset)
