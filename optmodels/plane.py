r"""Plane of maneuver by maximum likelihood (paper 000, Korobochkin).

Paper: ``shared/papers/000_9c0f4a5f1246cc76.txt``, equations (1.1)-(1.17).

Problem as posed
----------------
Measured positions :math:`x_i^* = x_i + \xi_i`, :math:`\xi_i \sim N(0, D_i)` independent,
:math:`i = 1..N`. The plane is :math:`\langle n, x\rangle = a`, :math:`\|n\| = 1` (1.1).
Maximum likelihood gives the non-convex program in :math:`3N + 4` unknowns

.. math::
    F = \sum_i (x_i - x_i^*)^T D_i^{-1} (x_i - x_i^*) \to \min_{x_i, n, a}      (1.2)

    \langle n, x_i\rangle - a = 0,\ i = 1..N, \qquad n_1^2 + n_2^2 + n_3^2 = 1     (1.3)

Reductions
----------
* Fixing ``(n, a)`` the problem splits into N projections; the minimum of each is
  :math:`\varphi_i = (a - \langle n, x_i^*\rangle)^2 / \langle D_i n, n\rangle` (1.11),
  reached at the oblique projection (1.8). So (1.2)-(1.3) is equivalent to the
  4-variable problem :math:`\sum_i \varphi_i(a, n) \to \min`, :math:`\|n\|=1`
  (1.12)-(1.13), for **any** SPD :math:`D_i`.
* If :math:`D_i = \alpha_i^2 D` (1.4), minimising over ``a`` gives (1.7) and the Rayleigh
  quotient :math:`n^T Q n / n^T D n` (1.14)-(1.15) with the weighted scatter ``Q`` (1.5):
  the plane normal is the generalized eigenvector of ``(Q, D)`` of the smallest
  eigenvalue, found along the paper's route ``D = h M h^T``, ``R = M^{-1/2} h^T Q h
  M^{-1/2} = g \Lambda g^T``, ``n \propto h M^{-1/2} g_k`` (1.6), and
  :math:`\min F = \Lambda_{\min}` (1.16).

Entry points
------------
:func:`solve` (``formulation="full"`` (1.2)-(1.3) or ``"reduced"`` (1.12)-(1.13), CasADi +
IPOPT), :func:`closed_form` (1.5)-(1.8), :func:`svd_fit` (unweighted total least squares,
the baseline), :func:`planarity_test` (χ² test, with the paper's rule (1.17) beside it),
:func:`identify_sequence` (running estimate as in the paper's example),
:func:`cramer_rao_bound`.

Errata (details and the tests that show them in ``docs/errata.md``)
--------------------------------------------------------------------
* (1.17): the statistic :math:`\Lambda_{\min}` is :math:`\chi^2` with ``N - 3`` degrees
  of freedom, not ``N`` (three plane parameters are fitted), and the Fisher approximation
  gives :math:`\sqrt{2\chi^2} \approx N(\sqrt{2k-1}, 1)`: the margin ``+2`` is the
  0.977 quantile, not 0.997 (which needs 2.75). The printed rule raises false alarms
  about 2% of the time (at N = 1000), not 0.3%. Valid only when the plane is resolved
  (a short, nearly straight arc gives a statistic below :math:`\chi^2_{N-3}`).
* The change of basis after (1.15) is :math:`B = g^T M^{1/2} h^T`, not :math:`M^{-1/2}`.
* The number (1.7) is used twice (for ``R`` and for ``a``); the reference before (1.16)
  is broken in the source ("Ошибка! Источник ссылки не найден").
* ``a`` is called "the distance to the origin"; it is a signed distance (``n`` and ``a``
  are defined up to a common sign). optmodels reports ``offset >= 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from optmodels.backends.casadi_backend import BuiltNlp, build_nlpsol, run_nlpsol
from optmodels.core import (
    MAX_MAGNITUDE,
    REJECT_TOL,
    VERIFY_TOL,
    FloatArray,
    ProblemError,
    Solution,
    SolverNotAvailable,
    Status,
    as_choice,
    as_count,
    as_finite_array,
    as_number,
    as_probability,
    check_spd,
    check_spd_stack,
    timed,
    verified_status,
)

__all__ = [
    "CramerRao",
    "PlanarityTest",
    "PlaneData",
    "PlaneSequence",
    "PlaneSolution",
    "angle_error",
    "clear_nlp_cache",
    "closed_form",
    "constraint_residuals",
    "cramer_rao_bound",
    "identify_sequence",
    "objective",
    "optimal_offset",
    "planarity_test",
    "plane_errors",
    "project",
    "reduced_objective",
    "solve",
    "svd_fit",
]

Formulation = Literal["full", "reduced"]

#: Upper-triangle index pairs of a symmetric 3x3 matrix, the order used for parameters.
_IU = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))

#: Relative tolerance to declare D_i proportional (1.4): round-off of a product α²·D.
_PROPORTIONAL_RTOL = 1e-10
_EPS = float(np.finfo(float).eps)


def _roundoff(count: int | FloatArray) -> FloatArray | float:
    """Relative round-off allowed for a sum of ``count`` terms: 8 ulps x sqrt(N) (the
    statistical growth of BLAS/cumsum summation error, with a margin of 8)."""
    return 8.0 * _EPS * np.sqrt(np.asarray(count, dtype=float))


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
        pts = as_finite_array("plane.PlaneData points", self.points, shape=(None, 3),
                              max_abs=MAX_MAGNITUDE)
        n = pts.shape[0]
        if n < 3:
            raise ProblemError(f"plane.PlaneData points: a plane needs at least 3 points, got {n}")
        cov = as_finite_array("plane.PlaneData cov", self.cov, ndim=(2, 3), max_abs=MAX_MAGNITUDE)
        alpha2: FloatArray | None
        if cov.ndim == 2:
            if cov.shape != (3, 3):
                raise ProblemError(f"plane.PlaneData cov: expected shape (3, 3) or ({n}, 3, 3), "
                                   f"got {cov.shape}")
            check_spd("plane.PlaneData cov", cov)
            if self.alpha2 is None:
                alpha2 = np.ones(n)
            else:
                alpha2 = as_finite_array("plane.PlaneData alpha2", self.alpha2, shape=(n,),
                                         max_abs=MAX_MAGNITUDE)
                if np.any(alpha2 < 1 / MAX_MAGNITUDE):
                    raise ProblemError(
                        f"plane.PlaneData alpha2: the factors of (1.4) must be ≥ 1e-100; "
                        f"{int(np.sum(alpha2 < 1 / MAX_MAGNITUDE))} are not"
                    )
            base = 0.5 * (cov + cov.T)
            covs = alpha2[:, None, None] * base
        else:
            if cov.shape != (n, 3, 3):
                raise ProblemError(f"plane.PlaneData cov: expected shape (3, 3) or ({n}, 3, 3), "
                                   f"got {cov.shape}")
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
            raise ProblemError("plane.PlaneData points: all points are identical; no plane is "
                              "defined")
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
                "outside 1e±100 of the spread² (float64 cannot hold the weights); check units")
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


# =========================================================================== solution
@dataclass
class PlaneSolution(Solution):
    """A plane estimate with the projected points.

    Attributes
    ----------
    normal : ndarray (3,)
        Unit normal ``n``; sign convention: ``offset >= 0``, and if ``offset == 0`` the
        first non-zero component of ``normal`` is positive.
    offset : float
        ``a`` in :math:`\\langle n, x\\rangle = a` (1.1).
    projected : ndarray (N, 3)
        The estimated positions :math:`x_i` on the plane (1.8).
    """

    normal: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    offset: float = float("nan")
    projected: FloatArray = field(default_factory=lambda: np.empty((0, 3)))


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
    x = as_finite_array("plane.constraint_residuals projected", projected,
                        shape=(data.n_points, 3))
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
    if not isinstance(data, PlaneData):
        raise ProblemError(f"{where} data: expected a PlaneData, got {type(data).__name__}")


def _check_plane(where: str, data: Any, normal: ArrayLike, offset: Any) -> tuple[FloatArray,
                                                                                   float]:
    """Validated ``(normal, offset)``: a finite non-zero (3,) vector (not renormalised:
    the functions are evaluated at the plane exactly as given) and a finite number."""
    _check_data(where, data)
    n = as_finite_array(f"{where} normal", normal, shape=(3,), max_abs=MAX_MAGNITUDE)
    if not float(np.linalg.norm(n)) > 0:
        raise ProblemError(f"{where} normal: must be non-zero")
    return n, as_number(f"{where} offset", offset)


def _tangent_basis(normal: FloatArray) -> FloatArray:
    """Orthonormal bases (..., 2, 3) of the planes orthogonal to unit ``normal`` (..., 3)."""
    e = np.zeros_like(normal)
    np.put_along_axis(e, np.argmin(np.abs(normal), axis=-1)[..., None], 1.0, axis=-1)
    t1 = np.cross(normal, e)
    t1 = t1 / np.linalg.norm(t1, axis=-1, keepdims=True)
    return np.stack([t1, np.cross(normal, t1)], axis=-2)


@dataclass(frozen=True)
class _Check:
    """Newton-step re-check of a normal, vectorised over a leading dimension K.

    ``step``: estimated angle (rad) between the given normal and the exact stationary
    point, :math:`\\|H^{-1} g\\| + g_{floor} / (h_{min} - h_{floor})` with ``g``, ``H`` the
    tangent gradient and Hessian on the unit sphere and the floors the round-off of their
    computation (inf if the curvature does not clear its
    floor: the normal is not determined to working precision). ``curvature``: smallest
    tangent curvature relative to the largest (< 0: not a minimum). ``rho``: the value.
    """

    step: FloatArray
    curvature: FloatArray
    rho: FloatArray
    newton: FloatArray  # (K, 3) the Newton step in the ambient space (0 where undefined)


def _rayleigh_check(
    q: FloatArray, qabs: FloatArray, d: FloatArray, normal: FloatArray, count: FloatArray
) -> _Check:
    """Re-check of normals of the pencil ``(Q, D)`` in the original coordinates.

    :math:`f(n) = n^TQn / n^TDn` (1.14)-(1.15); on the sphere its gradient is
    :math:`g = 2(Qn - fDn)/n^TDn` and, at a stationary point, its Hessian is
    :math:`2 P(Q - fD)P / n^TDn` (``P`` the tangent projector; ``f`` is homogeneous of
    degree 0, so no curvature term of the sphere). ``qabs`` bounds the magnitudes of the
    terms summed into ``Q`` (for its round-off). Working in ``n``-space (not the whitened
    coordinates) makes the estimate insensitive to an anisotropic ``D``: whitening by
    ``diag(1, 1, 1e-13)`` multiplies the largest eigenvalue of ``R`` by 1e13 without
    changing how well ``n`` is determined.
    """
    dn = normal @ d
    nd = np.sum(normal * dn, axis=-1)
    qn = np.einsum("kij,kj->ki", q, normal)
    rho = np.sum(normal * qn, axis=-1) / nd
    g = 2.0 * (qn - rho[:, None] * dn) / nd[:, None]
    t = _tangent_basis(normal)
    gt = np.einsum("kaj,kj->ka", t, g)
    h = 2.0 * np.einsum("kai,kij,kbj->kab", t, q - rho[:, None, None] * d, t) / nd[:, None, None]
    h = 0.5 * (h + np.swapaxes(h, -1, -2))
    fl = _roundoff(count)
    absn = np.abs(normal)
    term = np.einsum("kij,kj->ki", qabs, absn) + np.abs(rho)[:, None] * (absn @ np.abs(d))
    gfloor = 2.0 * fl * np.linalg.norm(term, axis=-1) / nd
    hfloor = 2.0 * fl * (np.linalg.norm(qabs, axis=(-2, -1))
                         + np.abs(rho) * np.linalg.norm(d)) / nd
    return _newton(gt, h, gfloor, hfloor, t, rho)


def _newton(gt: FloatArray, h: FloatArray, gfloor: FloatArray, hfloor: FloatArray,
            t: FloatArray, rho: FloatArray) -> _Check:
    hl = np.linalg.eigvalsh(h)
    hmin = hl[:, 0] - hfloor
    good = hmin > 0
    hh = np.where(good[:, None, None], h, np.eye(2))
    delta = np.where(good[:, None], np.linalg.solve(hh, gt[..., None])[..., 0], 0.0)
    # the Newton step itself, plus what the round-off of g could hide (bounded by the
    # smallest curvature)
    step = np.where(good, np.linalg.norm(delta, axis=-1)
                    + gfloor / np.where(good, hmin, 1.0), np.inf)
    newton = -np.einsum("ka,kaj->kj", delta, t)
    curv = hl[:, 0] / np.maximum(np.abs(hl[:, 1]), np.finfo(float).tiny)
    return _Check(step=step, curvature=curv, rho=rho, newton=newton)


def _profile_check(points: FloatArray, covs: FloatArray, normal: FloatArray) -> _Check:
    """Re-check of a normal for general :math:`D_i`: the profile
    :math:`\\Phi(n) = \\min_a \\varphi(a, n)` of (1.12) on the unit sphere.

    Analytic gradient (envelope theorem, ``a`` optimal):
    :math:`\nabla\\Phi = \\sum_i 2 r_i x_i / q_i - 2 r_i^2 D_i n / q_i^2` with
    :math:`r_i = \\langle n, x_i\\rangle - a`, :math:`q_i = \\langle D_i n, n\\rangle`;
    tangent Hessian by central differences of that gradient (step 1e-5 rad: truncation
    ~1e-10 and round-off ~1e-11 of the curvature). ``Φ`` is homogeneous of degree 0, so
    that is the Riemannian Hessian. Use on scaled data (:class:`_Scaled`).
    """
    absx = np.abs(points)

    def grad(n: FloatArray) -> tuple[FloatArray, FloatArray]:
        dn = covs @ n
        w = 1.0 / (dn @ n)
        p = points @ n
        a = float(np.sum(w * p) / np.sum(w))
        r = p - a
        g = 2.0 * (w * r) @ points - 2.0 * (w * w * r * r) @ dn
        # round-off: r_i is a difference of terms of size |x_i| + |a|
        err = 2.0 * (w * (absx @ np.abs(n) + abs(a) + np.abs(r))) @ absx \
            + 2.0 * (w * w * r * r) @ np.abs(dn)
        return g, err

    n0 = normal / np.linalg.norm(normal)
    t = _tangent_basis(n0[None, :])[0]
    g0, err = grad(n0)
    fl = float(_roundoff(len(points)))
    gfloor = 2.0 * fl * float(np.linalg.norm(err))
    hstep = 1e-5
    cols = []
    for tj in t:
        gp, _ = grad((n0 + hstep * tj) / np.linalg.norm(n0 + hstep * tj))
        gm, _ = grad((n0 - hstep * tj) / np.linalg.norm(n0 - hstep * tj))
        cols.append(t @ (gp - gm) / (2 * hstep))
    h = np.array(cols).T
    h = 0.5 * (h + h.T)
    hmax = float(np.max(np.abs(np.linalg.eigvalsh(h))))
    hfloor = 1e-8 * hmax + gfloor / hstep
    wd, proj, a0 = _weighted_offset(points, covs, n0)
    rho = np.array([float(np.sum(wd * (proj - a0) ** 2))])
    return _newton((t @ g0)[None, :], h[None], np.array([gfloor]), np.array([hfloor]),
                   t[None], rho)


def _finish(
    data: PlaneData, normal: FloatArray, offset: float, *, status: Status, method: str,
    stationarity: float, build_time: float = 0.0, solve_time: float = 0.0,
    iterations: int | None = None, message: str = "", info: dict[str, Any] | None = None,
    projected: FloatArray | None = None,
) -> PlaneSolution:
    """Canonical sign, projection (1.8) if not given, re-check against the original form.

    The re-check (``info["verification"]``, all dimensionless) is passed to
    :func:`optmodels.core.verified_status`: ``unit_normal`` = :math:`|\\|n\\|^2 - 1|`,
    ``plane`` = :math:`\\max_i |\\langle n, x_i\\rangle - a|` over the largest coordinate,
    ``stationarity`` = the caller's estimated angle (rad) to the exact stationary point
    (Newton step, conditioning included), and for solver-supplied ``projected`` points
    ``projection`` = the largest distance, in noise standard deviations
    :math:`\\sqrt{e^T D_i^{-1} e}`, between them and the optimal points (1.8) of the
    returned plane (the stationarity of (1.2)-(1.3) in the :math:`x_i`).
    """
    info = dict(info or {})
    if not np.all(np.isfinite(normal)) or not np.isfinite(offset) \
            or float(np.linalg.norm(normal)) == 0.0:
        return PlaneSolution(
            status=status if not status.ok else Status.ERROR, objective=float("nan"),
            method=method, build_time=build_time, solve_time=solve_time,
            iterations=iterations, message=message or "non-finite iterate", info=info,
        )
    normal, offset = _canonical_sign(normal, offset)
    checks: dict[str, float] = {}
    if projected is None:
        projected = project(data, normal, offset)
    else:
        unit = normal / np.linalg.norm(normal)
        opt = _oblique_projection(data.points, data.covs, unit, offset / np.linalg.norm(normal))
        e = projected - opt
        dist2 = np.sum(e * np.linalg.solve(data.covs, e[..., None])[..., 0], axis=1)
        checks["projection"] = float(np.sqrt(np.max(np.abs(dist2))))
    residuals = constraint_residuals(data, projected, normal, offset)
    scale = float(np.max(np.abs(data.points)))
    checks.update(unit_normal=residuals["unit_normal"], plane=residuals["plane"] / scale,
                  stationarity=float(stationarity))
    worst = max(checks.values())
    new_status = verified_status(status, worst)
    if new_status != status:
        message = (message + "; " if message else "") + \
            f"re-check of (1.2)-(1.3): worst {worst:.2g} ({max(checks, key=checks.__getitem__)})"
    info["verification"] = checks
    return PlaneSolution(
        status=new_status,
        objective=objective(data, projected),
        method=method,
        build_time=build_time,
        solve_time=solve_time,
        iterations=iterations,
        residuals=residuals,
        message=message,
        info=info,
        normal=normal,
        offset=offset,
        projected=projected,
    )


# =========================================================================== generic solve
@dataclass(frozen=True)
class _Scaled:
    r"""Data moved to the unweighted centroid and scaled to unit RMS spread.

    Translation and scaling map planes to planes and leave (1.2) unchanged when the
    covariances are scaled with the points, so IPOPT sees well-scaled numbers whatever the
    units or the distance from the origin; the plane is mapped back exactly:
    :math:`\langle n, y\rangle = b` with :math:`y = (x - c)/s` is
    :math:`\langle n, x\rangle = s b + \langle n, c\rangle`.
    """

    center: FloatArray
    scale: float
    points: FloatArray  # (N, 3) scaled
    covs: FloatArray  # (N, 3, 3) scaled

    @classmethod
    def of(cls, data: PlaneData) -> _Scaled:
        c = data.points.mean(axis=0)
        y = data.points - c
        s = float(np.sqrt(np.mean(np.sum(y * y, axis=1))))
        return cls(center=c, scale=s, points=y / s, covs=data.covs / s**2)


def _upper(mats: FloatArray) -> FloatArray:
    """(N, 3, 3) symmetric → (6, N) upper-triangle entries in :data:`_IU` order."""
    return np.stack([mats[:, j, k] for j, k in _IU])


def _full_problem(n: int) -> dict[str, Any]:
    """(1.2)-(1.3) as a CasADi NLP with the data as parameters.

    Unknowns: ``vec(X)`` (3N, columns x_i), ``n`` (3), ``a``. Parameters: ``vec(X*)``
    (3N) and the upper triangles of :math:`D_i^{-1}` (6N).
    """
    x = ca.MX.sym("x", 3, n)
    nv = ca.MX.sym("n", 3)
    a = ca.MX.sym("a")
    p_pts = ca.MX.sym("xs", 3, n)
    p_w = ca.MX.sym("Dinv", 6, n)
    e = x - p_pts
    f = 0
    for r, (j, k) in enumerate(_IU):
        f = f + (1.0 if j == k else 2.0) * ca.dot(p_w[r, :], e[j, :] * e[k, :])
    g = ca.vertcat((ca.mtimes(nv.T, x) - a).T, ca.dot(nv, nv) - 1.0)
    return {
        "x": ca.vertcat(ca.vec(x), nv, a),
        "f": f / n,  # (1.2) / N: an O(1) objective, so IPOPT's tolerances are meaningful
        "g": g,
        "p": ca.vertcat(ca.vec(p_pts), ca.vec(p_w)),
    }


def _reduced_problem(n: int) -> dict[str, Any]:
    """(1.12)-(1.13) as a CasADi NLP in (n, a) with the data as parameters.

    Parameters: ``vec(X*)`` (3N) and the upper triangles of :math:`D_i` (6N).
    """
    nv = ca.MX.sym("n", 3)
    a = ca.MX.sym("a")
    p_pts = ca.MX.sym("xs", 3, n)
    p_d = ca.MX.sym("D", 6, n)
    resid = a - ca.mtimes(nv.T, p_pts)
    den = 0
    for r, (j, k) in enumerate(_IU):
        den = den + (1.0 if j == k else 2.0) * nv[j] * nv[k] * p_d[r, :]
    return {
        "x": ca.vertcat(nv, a),
        "f": ca.sum2(resid * resid / den) / n,  # (1.12) / N, O(1) as above
        "g": ca.dot(nv, nv) - 1.0,
        "p": ca.vertcat(ca.vec(p_pts), ca.vec(p_d)),
    }


_NLP_CACHE: dict[tuple[Any, ...], BuiltNlp] = {}
_NLP_CACHE_SIZE = 8


def _get_nlp(
    formulation: Formulation, n: int, options: dict[str, Any] | None, plugin: str = "ipopt"
) -> tuple[BuiltNlp, bool]:
    """Built NLP for this structure, and whether it was built by this call.

    The symbolic construction does not depend on the data values, so Monte Carlo and
    sequential runs pay it once per (formulation, N, options).
    """
    key = (formulation, n, plugin, repr(sorted((options or {}).items())))
    if key in _NLP_CACHE:
        return _NLP_CACHE[key], False
    problem = _full_problem(n) if formulation == "full" else _reduced_problem(n)
    built = build_nlpsol(problem, plugin=plugin, options=options)
    if len(_NLP_CACHE) >= _NLP_CACHE_SIZE:
        _NLP_CACHE.pop(next(iter(_NLP_CACHE)))
    _NLP_CACHE[key] = built
    return built, True


#: A stationary point whose smallest profile curvature is below -1e-6 of the largest is a
#: saddle or a maximum of (1.12)-(1.13), not a solution (finite-difference accuracy of the
#: relative curvature is ~1e-8).
_SADDLE_RTOL = 1e-6


def clear_nlp_cache() -> None:
    """Forget the built CasADi NLPs (the next solve pays the construction again; used by
    benchmarks that measure cold build + solve)."""
    _NLP_CACHE.clear()


def _principal_axes(points: FloatArray) -> FloatArray:
    """Rows: unit axes of the unweighted scatter, smallest variance first."""
    y = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(y.T @ y)
    return vecs.T


def solve(
    data: PlaneData,
    formulation: Formulation = "full",
    *,
    starts: int | Literal["auto"] = "auto",
    initial_normal: ArrayLike | None = None,
    ipopt_options: dict[str, Any] | None = None,
    plugin: str = "ipopt",
    plugin_options: dict[str, Any] | None = None,
) -> PlaneSolution:
    """Solve the ML plane problem generically with CasADi + IPOPT (or another NLP plugin).

    Parameters
    ----------
    data : PlaneData
    formulation : {"full", "reduced"}
        ``"full"``: the original problem (1.2)-(1.3) in all 3N + 4 unknowns.
        ``"reduced"``: (1.12)-(1.13) in (n, a), valid for general :math:`D_i`.
    starts : "auto" or int 1..3
        Starts along the principal axes of the *unweighted* scatter (smallest variance
        first); the best KKT point is kept. Never started from the closed form.
        ``"auto"`` (default): under (1.4), the first axis, then the other two only if it
        failed or fails the second-order check (``info["min_curvature"] <= 0``: not a
        local minimum of the profile :math:`\\Phi(n) = \\min_a \\varphi(a, n)` on the
        sphere); for general :math:`D_i` all three.
    initial_normal : array_like (3,), optional
        Start from this normal instead (a single start, e.g. a warm start in a sequence).
    ipopt_options : dict, optional
        Extra IPOPT options (defaults: ``tol = constr_viol_tol = 1e-10``).
    plugin : str
        CasADi ``nlpsol`` plugin: ``"ipopt"`` (default) or another that loads here, e.g.
        ``"sqpmethod"``, ``"blocksqp"``, ``"feasiblesqpmethod"`` (see
        :data:`optmodels.backends.casadi_backend.NLP_PLUGINS`). Every result is re-checked
        against (1.3) in NumPy whatever the plugin.
    plugin_options : dict, optional
        Options for a plugin other than IPOPT (CasADi's option dictionary).

    Returns
    -------
    PlaneSolution
        The best successful start. If no start succeeded, the status is not OK (and
        ``require_ok()`` raises). ``build_time`` is the CasADi construction when it
        happened in this call (``info["cached_build"]`` says whether it was reused);
        ``info["start_objectives"]`` lists each start's value of (1.2).

    Notes
    -----
    What is guaranteed: each successful run is a KKT point of the chosen formulation to
    IPOPT's tolerance, re-checked against (1.3) in ``residuals``. Under (1.4) every local
    minimum of the Rayleigh quotient (1.15) is global (its other stationary points, the
    other generalized eigenvectors, are a saddle and a maximum), so any run that reaches a
    local minimum is the global ML plane. A run that stops on a saddle or maximum (a start
    exactly on one, e.g. a principal axis when ``D`` is isotropic) is caught by the
    second-order check, and the remaining starts are tried. For general :math:`D_i`
    (1.12) can have spurious local minima (seen in tests: a strict local minimum with
    (1.2) four orders of magnitude above the global one), so all three starts are run;
    this is a heuristic, not a global guarantee -- compare ``info["start_objectives"]``.

    Every run ends in a NumPy re-check against (1.2)-(1.3) (``info["verification"]``):
    the residuals of (1.3), the Newton step of the profile :math:`\\Phi` on the sphere
    (analytic gradient, finite-difference Hessian; an estimate in rad of the normal's
    error, inf when the curvature does not clear its round-off floor, e.g. nearly collinear
    points) and, for ``"full"``, the distance of the solver's :math:`x_i` from (1.8) in
    noise standard deviations; then :func:`optmodels.core.verified_status`. A stationary
    point with negative curvature (saddle or maximum) is reported as ERROR.
    """
    if not isinstance(data, PlaneData):
        raise ProblemError(f"plane.solve data: expected a PlaneData, got {type(data).__name__}")
    formulation = as_choice("plane.solve formulation", formulation,  # type: ignore[assignment]
                            ("full", "reduced"))
    auto = isinstance(starts, str) and starts == "auto"
    if not auto:
        if isinstance(starts, str):
            raise ProblemError(f"plane.solve starts: expected 'auto', 1, 2 or 3, got {starts!r}")
        starts = as_count("plane.solve starts", starts, minimum=1, maximum=3)
    if not isinstance(plugin, str) or not plugin:
        raise ProblemError(f"plane.solve plugin: expected a CasADi nlpsol name, got {plugin!r}")
    for name, opts in (("ipopt_options", ipopt_options), ("plugin_options", plugin_options)):
        if opts is not None and (not isinstance(opts, dict)
                                 or not all(isinstance(k, str) for k in opts)):
            raise ProblemError(f"plane.solve {name}: expected a dict with str keys or None, "
                               f"got {type(opts).__name__}")
    sc = _Scaled.of(data)
    n_pts = data.n_points
    if initial_normal is not None:
        n0 = as_finite_array("plane.solve initial_normal", initial_normal, shape=(3,))
        if not np.linalg.norm(n0) > 0:
            raise ProblemError("plane.solve initial_normal: must be non-zero")
        start_normals = [n0 / np.linalg.norm(n0)]
    else:
        start_normals = list(_principal_axes(sc.points)[: 3 if auto else int(starts)])

    with timed() as t_prep:
        try:
            if plugin == "ipopt":
                built, fresh = _get_nlp(formulation, n_pts, ipopt_options)
            else:
                built, fresh = _get_nlp(formulation, n_pts, plugin_options, plugin)
        except RuntimeError as exc:  # CasADi: unknown plugin/option, missing library
            raise SolverNotAvailable(
                f"plugin: CasADi nlpsol {plugin!r} could not be built for the plane NLP: "
                f"{str(exc).splitlines()[0][:200]}") from exc
        if formulation == "full":
            params = np.concatenate(
                [sc.points.T.ravel(order="F"), _upper(np.linalg.inv(sc.covs)).ravel(order="F")]
            )
        else:
            params = np.concatenate(
                [sc.points.T.ravel(order="F"), _upper(sc.covs).ravel(order="F")]
            )
    build_time = t_prep.elapsed  # includes the construction when it happened here

    best: PlaneSolution | None = None
    first_fail: PlaneSolution | None = None
    start_objs: list[float] = []
    start_status: list[str] = []
    total_solve = 0.0
    total_iter = 0
    method = f"casadi:{plugin}:{formulation}"
    curvature = float("nan")
    for nv0 in start_normals:
        if auto and data.proportional and len(start_objs) == 1 and best is not None \
                and curvature > 0:
            # Under (1.4) a local minimum of Φ on the sphere is the global one.
            break
        # Start plane (nv0, b0): b0 and the x_i are the best ones *for that plane* --
        # the weighted offset and the oblique projections (1.8), not orthogonal ones,
        # which under anisotropic D_i start far from optimal and cost IPOPT dozens of
        # iterations. This uses only the start plane, never the closed-form solution.
        b0 = _weighted_offset(sc.points, sc.covs, nv0)[2]
        if formulation == "full":
            x_start = _oblique_projection(sc.points, sc.covs, nv0, b0)
            x0 = np.concatenate([x_start.T.ravel(order="F"), nv0, [b0]])
        else:
            x0 = np.concatenate([nv0, [b0]])
        res, xopt = run_nlpsol(built, x0=x0, p=params)
        total_solve += res.solve_time
        total_iter += res.iterations or 0
        k = 3 * n_pts if formulation == "full" else 0
        normal, b = xopt[k : k + 3], float(xopt[k + 3])
        # The solver's own normal (not renormalised), so that a violated ‖n‖ = 1 shows in
        # the residuals; "full" reports its own x_i, "reduced" projects by (1.8).
        offset = b * sc.scale + float(normal @ sc.center)
        x_scaled = xopt[:k].reshape(n_pts, 3) if formulation == "full" else None
        proj = None
        if x_scaled is not None and np.all(np.isfinite(xopt)):
            proj = x_scaled * sc.scale + sc.center
        status = res.status
        message = res.message
        curv_i, step_i = float("nan"), float("inf")
        if np.all(np.isfinite(normal)) and np.linalg.norm(normal) > 0:
            chk = _profile_check(sc.points, sc.covs, normal / np.linalg.norm(normal))
            curv_i, step_i = float(chk.curvature[0]), float(chk.step[0])
            if res.message == "Search_Direction_Becomes_Too_Small" and step_i <= VERIFY_TOL:
                # IPOPT's precision limit: accept only a point verified independently
                # (the re-check in _finish then applies to it like to any other).
                status = Status.OPTIMAL_INACCURATE
                message += f" (KKT point verified: Newton step {step_i:.1e} rad, " \
                    f"curvature {curv_i:.2f})"
            if status.ok and curv_i < -_SADDLE_RTOL:
                status = Status.ERROR
                message += f"; not a minimum of (1.12)-(1.13): profile curvature {curv_i:.2g}" \
                    " (a saddle or maximum)"
        sol = _finish(data, normal, offset, status=status, method=method,
                      stationarity=step_i, message=message, projected=proj,
                      info={"min_curvature": curv_i})
        start_objs.append(sol.objective)
        start_status.append(res.message)
        if sol.ok and (best is None or sol.objective < best.objective):
            best = sol
            curvature = curv_i
        elif not sol.ok and first_fail is None:
            first_fail = sol
    out = best if best is not None else first_fail
    assert out is not None
    verification = out.info.get("verification", {})
    curvature = float(out.info.get("min_curvature", float("nan")))
    out.build_time = build_time
    out.solve_time = total_solve
    out.iterations = total_iter
    out.info = {
        "start_objectives": start_objs,
        "start_status": start_status,
        "starts": len(start_objs),
        "min_curvature": curvature,
        "cached_build": not fresh,
        "verification": verification,
    }
    return out


# =========================================================================== closed form
@dataclass(frozen=True)
class _Eig:
    """Closed-form pieces for a stack of problems (leading dimension K)."""

    normal: FloatArray  # (K, 3), unit, un-signed, Newton-refined
    lam: FloatArray  # (K, 3) eigenvalues of R, ascending
    mean: FloatArray  # (K, 3) weighted mean Σ w y / Σ w (in the coordinates of the sums)
    line: FloatArray  # (K, 3) unit direction of the best line (largest eigenvalue)
    check: _Check  # re-check of ``normal`` against the pencil (Q, D)
    refined: np.ndarray  # (K,) whether a Newton step replaced the eigenvector


def _closed_form_from_sums(
    s0: FloatArray, s1: FloatArray, s2: FloatArray, s2abs: FloatArray, count: FloatArray,
    base_cov: FloatArray,
) -> _Eig:
    """The paper's route (1.5)-(1.7) from running sums, vectorised over a stack, then the
    re-check of the normal against the pencil (and up to two Newton refinements of it).

    ``s0 = Σ w_i``, ``s1 = Σ w_i y_i``, ``s2 = Σ w_i y_i y_i^T``, ``s2abs = Σ w_i |y_i||y_i|^T``
    with :math:`w_i = \alpha_i^{-2}` and :math:`y_i` the points about a data point and
    divided by their spread (``base_cov`` divided by the spread² too): ``Q`` (1.5) is shift
    invariant and the normal scale invariant, and sums about a data point avoid the
    cancellation of the printed form far from the origin.
    """
    q = s2 - s1[..., :, None] * s1[..., None, :] / s0[..., None, None]  # (1.5)
    qabs = s2abs + np.abs(s1)[..., :, None] * np.abs(s1)[..., None, :] / s0[..., None, None]
    m, h = np.linalg.eigh(base_cov)  # D = h M h^T
    t = h / np.sqrt(m)  # h M^{-1/2}
    r = t.T @ q @ t  # (1.7), first use of the number: R = M^{-1/2} h^T Q h M^{-1/2}
    r = 0.5 * (r + np.swapaxes(r, -1, -2))
    lam, g = np.linalg.eigh(r)  # R = g Λ g^T, ascending
    nvec = g[..., :, 0] @ t.T  # (1.6): h M^{-1/2} g_k (row-vector form)
    nvec = nvec / np.linalg.norm(nvec, axis=-1, keepdims=True)
    line = g[..., :, 2] @ (h * np.sqrt(m)).T  # directions map by h M^{1/2}, normals by T
    line = line / np.linalg.norm(line, axis=-1, keepdims=True)
    chk = _rayleigh_check(q, qabs, base_cov, nvec, count)
    refined = np.zeros(len(nvec), dtype=bool)
    for _ in range(2):  # Newton on the Rayleigh quotient; kept only where it helps
        if not np.any(chk.step > 1e-12):
            break
        cand = nvec + chk.newton
        cand = cand / np.linalg.norm(cand, axis=-1, keepdims=True)
        c2 = _rayleigh_check(q, qabs, base_cov, cand, count)
        take = np.isfinite(c2.step) & (c2.step < 0.5 * chk.step) & (chk.step > 1e-12)
        if not np.any(take):
            break
        nvec = np.where(take[:, None], cand, nvec)
        chk = _Check(*(np.where(take[(...,) + (None,) * (a.ndim - 1)], b, a)
                       for a, b in zip((chk.step, chk.curvature, chk.rho, chk.newton),
                                       (c2.step, c2.curvature, c2.rho, c2.newton),
                                       strict=True)))
        refined |= take
    mean = s1 / s0[..., None]
    return _Eig(normal=nvec, lam=lam, mean=mean, line=line, check=chk, refined=refined)


def _scaled_sums(
    points: FloatArray, alpha2: FloatArray, *, cumulative: bool
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, float]:
    """``(s0, s1, s2, s2abs, ref, spread)`` of :func:`_closed_form_from_sums` (totals, or
    running sums over the first 1..N points with ``cumulative``)."""
    ref = points[0]
    y = points - ref
    spread = float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    y = y / spread
    w = 1.0 / alpha2
    ay = np.abs(y)
    if cumulative:
        terms = (w, w[:, None] * y, w[:, None, None] * (y[:, :, None] * y[:, None, :]),
                 w[:, None, None] * (ay[:, :, None] * ay[:, None, :]))
        s0, s1, s2, s2abs = (np.cumsum(a, axis=0) for a in terms)
    else:
        s0 = np.array([np.sum(w)])
        s1 = (w @ y)[None]
        s2 = ((y * w[:, None]).T @ y)[None]
        s2abs = ((ay * w[:, None]).T @ ay)[None]
    return s0, s1, s2, s2abs, ref, spread


def closed_form(data: PlaneData) -> PlaneSolution:
    """The paper's closed form (1.5)-(1.8), valid under (1.4) :math:`D_i = \alpha_i^2 D`.

    Route: ``Q`` (1.5); ``D = h M h^T``; ``R = M^{-1/2} h^T Q h M^{-1/2} = g Λ g^T`` (1.7);
    ``n = h M^{-1/2} g_k / ‖·‖`` (1.6) for the smallest ``Λ_kk``; ``a`` (1.7); projected
    points (1.8). ``objective`` is (1.2) re-evaluated at the projected points and equals
    ``Λ_min`` (``info["lambda_min"]``, (1.16)).

    Re-check (then :func:`optmodels.core.verified_status`): the normal is checked against
    the pencil ``(Q, D)`` in the original coordinates -- the Newton step of the Rayleigh
    quotient (1.14) on the sphere, :math:`\\|H^{-1}g\\|`, with the round-off floors of
    ``g`` and ``H`` (``info["verification"]["stationarity"]``, an estimate in rad of the
    normal's error). Where that step is not at round-off level the eigenvector is refined
    by up to two Newton steps (``info["refined"]``). Together with the residuals of (1.3)
    (``unit_normal``; ``plane`` over the largest coordinate): above 1e-6 the status is
    OPTIMAL_INACCURATE, above 1e-3 the plane is refused.

    ``info["line_statistic"]``: the two smallest eigenvalues Λ₁ + Λ₂, the minimum of (1.2)
    over *lines*, χ² with ``info["line_dof"]`` = 2N − 4 degrees of freedom if the points
    are on a line (see :func:`planarity_test`, ``resolved``).

    Raises
    ------
    ProblemError
        If the covariances are not proportional (use :func:`solve`), or if the normal is
        not determined to working precision (the estimated error above 1e-3 rad or no
        positive curvature: the two smallest generalized eigenvalues of ``(Q, D)``
        coincide to round-off, e.g. collinear points).
    """
    if not isinstance(data, PlaneData):
        raise ProblemError(
            f"plane.closed_form data: expected a PlaneData, got {type(data).__name__}")
    if data.base_cov is None or data.alpha2 is None:
        raise ProblemError(
            "cov: the closed form needs proportional covariances D_i = alpha_i^2 D (1.4); "
            "these are not -- use plane.solve(data) (full or reduced formulation)"
        )
    with timed() as t:
        s0, s1, s2, s2abs, ref, spread = _scaled_sums(data.points, data.alpha2,
                                                       cumulative=False)
        eig = _closed_form_from_sums(s0, s1, s2, s2abs, np.array([float(data.n_points)]),
                                     data.base_cov / spread**2)
        normal = eig.normal[0]
        offset = spread * float(normal @ eig.mean[0]) + float(normal @ ref)  # (1.7)
    lam = eig.lam[0]
    step = float(eig.check.step[0])
    if not step <= REJECT_TOL:
        raise ProblemError(
            "points: the plane is not determined to working precision (estimated error of "
            f"the normal {step:.3g} rad > {REJECT_TOL:g}; generalized eigenvalues of (Q, D) "
            f"{lam[0]:.6g}, {lam[1]:.6g}, {lam[2]:.6g}: the two smallest coincide to "
            "round-off -- collinear points?)"
        )
    return _finish(
        data, normal, offset, status=Status.OPTIMAL, method="closed_form",
        stationarity=step, solve_time=t.elapsed, iterations=None,
        info={"lambda_min": float(eig.check.rho[0]), "eigenvalues": lam.copy(),
              "line_statistic": float(lam[0] + lam[1]), "line_dof": 2 * data.n_points - 4,
              "refined": bool(eig.refined[0])},
    )


def change_of_basis(base_cov: ArrayLike, q: ArrayLike, *, printed: bool = False) -> FloatArray:
    """The matrix ``B`` after (1.15) with :math:`\\eta = B n` diagonalising both forms.

    Correct: :math:`B = g^T M^{1/2} h^T` (then :math:`n^T D n = \\|\\eta\\|^2` and
    :math:`n^T Q n = \\sum \\lambda_k \\eta_k^2`). ``printed=True`` returns the paper's
    :math:`g^T M^{-1/2} h^T`, which does not (see errata).
    """
    d = as_finite_array("plane.change_of_basis base_cov", base_cov, shape=(3, 3))
    check_spd("plane.change_of_basis base_cov", d)
    qm = as_finite_array("plane.change_of_basis q", q, shape=(3, 3), max_abs=MAX_MAGNITUDE)
    if float(np.max(np.abs(qm - qm.T))) > 1e-10 * max(float(np.max(np.abs(qm))), 1e-300):
        raise ProblemError("plane.change_of_basis q: must be symmetric (Q of (1.5))")
    if not isinstance(printed, bool | np.bool_):
        raise ProblemError(f"plane.change_of_basis printed: expected a bool, got {printed!r}")
    m, h = np.linalg.eigh(d)
    t = h / np.sqrt(m)
    _, g = np.linalg.eigh(t.T @ qm @ t)
    power = -0.5 if printed else 0.5
    return g.T @ np.diag(m**power) @ h.T


def scatter_matrix(data: PlaneData) -> FloatArray:
    """``Q`` of (1.5) under (1.4), computed about a data point (shift invariant)."""
    _check_data("plane.scatter_matrix", data)
    if data.alpha2 is None:
        raise ProblemError("cov: Q of (1.5) is defined under (1.4) only")
    w = 1.0 / data.alpha2
    y = data.points - data.points[0]
    s1 = w @ y
    return (y * w[:, None]).T @ y - np.outer(s1, s1) / np.sum(w)


# =========================================================================== baseline
def svd_fit(data: PlaneData) -> PlaneSolution:
    """Unweighted total-least-squares plane (centroid + smallest singular vector), as a
    NumPy or scikit-spatial user would fit it; ignores the :math:`D_i`.

    The points are then projected onto that plane by (1.8) so that ``objective`` is (1.2)
    under the data's covariances, comparable with the ML solutions.
    """
    if not isinstance(data, PlaneData):
        raise ProblemError(f"plane.svd_fit data: expected a PlaneData, got {type(data).__name__}")
    with timed() as t:
        c = data.points.mean(axis=0)
        _, _, vt = np.linalg.svd(data.points - c, full_matrices=False)
        normal = vt[-1]
        offset = float(normal @ c)
    # re-check: the TLS normal is the pencil (scatter, I) eigenvector -- same Newton test
    y = data.points - c
    y = y / float(np.max(np.abs(y)))
    chk = _rayleigh_check((y.T @ y)[None], (np.abs(y).T @ np.abs(y))[None], np.eye(3),
                          normal[None], np.array([float(data.n_points)]))
    return _finish(data, normal, offset, status=Status.OPTIMAL, method="svd",
                   stationarity=float(chk.step[0]), solve_time=t.elapsed)


# =========================================================================== statistics
@dataclass(frozen=True)
class PlanarityTest:
    """χ² test of the hypothesis "the target moves in a plane".

    Attributes
    ----------
    statistic : float
        :math:`\\Lambda_{\\min}` = minimum of (1.2), (1.16).
    dof : int
        ``N - 3``: N residuals, three fitted plane parameters (two for the direction of
        ``n``, one for ``a``).
    level : float
        Probability of accepting a planar motion (1 - false-alarm rate).
    threshold : float
        ``chi2.ppf(level, dof)``: reject when ``statistic > threshold``.
    p_value : float
        ``chi2.sf(statistic, dof)``.
    planar : bool
        ``statistic <= threshold``.
    paper_statistic, paper_threshold : float
        The printed rule (1.17): :math:`\\sqrt{2\\Lambda}` against :math:`\\sqrt{2N} + 2`.
    paper_planar : bool
        :math:`\\sqrt{2\\Lambda} \\le \\sqrt{2N} + 2`.
    paper_false_alarm : float
        The rule's actual false-alarm probability under χ²(N − 3) (the paper claims
        0.003).
    resolved : bool
        Whether the data determine the plane: the hypothesis "the points are on a line"
        is rejected at ``level`` (``line_statistic > line_threshold``). Only then does
        :math:`\\Lambda_{\\min}` follow χ²(N − 3) (a nearly straight track gives a
        statistic far below it, and every plane through the line fits about equally).
        When not resolved, ``planar`` and ``paper_planar`` are False.
    line_statistic : float
        Under (1.4): Λ₁ + Λ₂, the two smallest eigenvalues of (Q, D) = the minimum of
        (1.2) over lines, χ²(2N − 4) for points on a line (scale invariant: whitened).
        For general :math:`D_i`: a lower bound of that minimum, the two smallest
        eigenvalues of the scatter weighted by :math:`1/\\lambda_{max}(D_i)` (so
        ``resolved`` errs towards "not resolved" when the :math:`D_i` are anisotropic).
    line_dof, line_threshold : int, float
        ``2N − 4`` and ``chi2.ppf(level, 2N − 4)``.
    """

    statistic: float
    dof: int
    level: float
    threshold: float
    p_value: float
    planar: bool
    paper_statistic: float
    paper_threshold: float
    paper_planar: bool
    paper_false_alarm: float
    resolved: bool = True
    line_statistic: float = float("nan")
    line_dof: int = 0
    line_threshold: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {k: (bool(v) if isinstance(v, np.bool_) else v) for k, v in self.__dict__.items()}


def _planarity_arrays(
    stat: FloatArray, n: FloatArray, level: float, line_stat: FloatArray,
    determined: FloatArray | bool = True,
) -> dict[str, FloatArray]:
    """The χ²(N − 3) test, the rule (1.17) and the line test, vectorised.

    ``determined``: the normal passed its numerical re-check; ``resolved`` needs it and
    the rejection of the line hypothesis at ``level``.
    """
    dof = n - 3
    thr = stats.chi2.ppf(level, dof)
    paper_thr = np.sqrt(2.0 * n) + 2.0
    line_dof = 2 * n - 4
    line_thr = stats.chi2.ppf(level, line_dof)
    resolved = np.asarray(determined) & (line_stat > line_thr)
    paper_stat = np.sqrt(2.0 * np.maximum(stat, 0.0))
    return {
        "dof": dof,
        "threshold": thr,
        "p_value": np.where(resolved, stats.chi2.sf(stat, dof), np.nan),
        "planar": resolved & (stat <= thr),
        "paper_statistic": paper_stat,
        "paper_threshold": paper_thr,
        "paper_planar": resolved & (paper_stat <= paper_thr),
        "paper_false_alarm": stats.chi2.sf(paper_thr**2 / 2.0, dof),
        "resolved": resolved,
        "line_dof": line_dof,
        "line_threshold": line_thr,
    }


def _line_statistic(data: PlaneData) -> float:
    """Minimum of (1.2) over lines (under (1.4)) or its lower bound (general D_i); see
    :class:`PlanarityTest` ``line_statistic``."""
    if data.alpha2 is not None and data.base_cov is not None:
        s0, s1, s2, _, _, spread = _scaled_sums(data.points, data.alpha2, cumulative=False)
        q = (s2 - s1[..., :, None] * s1[..., None, :] / s0[..., None, None])[0]
        m, h = np.linalg.eigh(data.base_cov / spread**2)
        t = h / np.sqrt(m)
        lam = np.linalg.eigvalsh(0.5 * (t.T @ q @ t + (t.T @ q @ t).T))
    else:
        w = 1.0 / np.linalg.eigvalsh(data.covs)[:, -1]
        c = w @ data.points / np.sum(w)
        y = data.points - c
        lam = np.linalg.eigvalsh((y * w[:, None]).T @ y)
    return float(lam[0] + lam[1])


def planarity_test(
    data: PlaneData, solution: PlaneSolution | None = None, level: float = 0.997
) -> PlanarityTest:
    """χ² test of planar motion, with the paper's rule (1.17) beside it.

    Parameters
    ----------
    data : PlaneData
        Needs N >= 4 (with N = 3 the plane fits exactly and the test has no degrees of
        freedom).
    solution : PlaneSolution, optional
        A plane estimate; default :func:`closed_form` under (1.4), else :func:`solve`.
        The statistic is (1.12) at its ``normal`` and ``offset``.
    level : float
        Acceptance probability for a planar motion, in (0, 1), default 0.997 as in the
        paper; also the level of the line test behind ``resolved``.

    Returns
    -------
    PlanarityTest
        ``planar`` is True only if the plane is ``resolved`` (the points are not on a
        line, at ``level``) and :math:`\\Lambda_{\\min}` is below the χ²(N − 3) threshold.
    """
    lv = as_probability("plane.planarity_test level", level, low_open=True, high_open=True)
    if not isinstance(data, PlaneData):
        raise ProblemError(
            f"plane.planarity_test data: expected a PlaneData, got {type(data).__name__}")
    if data.n_points < 4:
        raise ProblemError("points: the planarity test needs N >= 4 (dof = N - 3)")
    if solution is None:
        solution = closed_form(data) if data.proportional else solve(data).require_ok()
    if not isinstance(solution, PlaneSolution):
        raise ProblemError("plane.planarity_test solution: expected a PlaneSolution, got "
                           f"{type(solution).__name__}")
    solution.require_ok()
    stat = reduced_objective(data, solution.normal, solution.offset)
    line = _line_statistic(data)
    arr = _planarity_arrays(np.asarray(stat), np.asarray(float(data.n_points)), lv,
                            np.asarray(line))
    return PlanarityTest(
        statistic=stat, dof=int(arr["dof"]), level=lv, threshold=float(arr["threshold"]),
        p_value=float(arr["p_value"]), planar=bool(arr["planar"]),
        paper_statistic=float(arr["paper_statistic"]),
        paper_threshold=float(arr["paper_threshold"]),
        paper_planar=bool(arr["paper_planar"]),
        paper_false_alarm=float(arr["paper_false_alarm"]),
        resolved=bool(arr["resolved"]), line_statistic=line,
        line_dof=int(arr["line_dof"]), line_threshold=float(arr["line_threshold"]),
    )


@dataclass(frozen=True)
class CramerRao:
    """Cramér–Rao bound for (tilt_1, tilt_2, a) at a true plane.

    Attributes
    ----------
    cov : ndarray (3, 3)
        Bound on the covariance of (tilt about ``tangent[0]``... in radians: the small
        rotations of ``n`` towards ``tangent[0]`` and ``tangent[1]``, and ``a`` in metres).
    tangent : ndarray (2, 3)
        Orthonormal basis of the plane used for the tilts.
    angle_rms : float
        :math:`\\sqrt{\\mathrm{tr}\\, cov_{tilt}}`: bound on the RMS angle between the
        estimated and true normals (rad).
    offset_std : float
        :math:`\\sqrt{cov_{aa}}` (m).
    """

    cov: FloatArray
    tangent: FloatArray
    angle_rms: float
    offset_std: float


def cramer_rao_bound(data: PlaneData, normal: ArrayLike, offset: float) -> CramerRao:
    """Cramér–Rao bound of the plane parameters, ``data.points`` being the *true* points.

    Derivation: with :math:`x_i = a n + T u_i` (``T`` a basis of the plane, :math:`u_i`
    nuisance), eliminating :math:`u_i` from the Fisher information of
    :math:`x_i^* \\sim N(x_i, D_i)` leaves
    :math:`D_i^{-1} - D_i^{-1}T(T^TD_i^{-1}T)^{-1}T^TD_i^{-1} = n n^T / (n^T D_i n)`, so
    only the normal component of each point informs the plane, and
    :math:`J = \\sum_i h_i h_i^T / (n^T D_i n)` with
    :math:`h_i = (\\langle t_1, x_i\\rangle, \\langle t_2, x_i\\rangle, -1)`, the gradient
    of :math:`\\langle n(\\delta), x_i\\rangle - a` in (tilts δ, a). The bound is
    :math:`J^{-1}`.
    """
    n, offset = _check_plane("plane.cramer_rao_bound", data, normal, offset)
    n = n / np.linalg.norm(n)
    # tangent basis: complete n to an orthonormal frame
    _, _, vt = np.linalg.svd(n[None, :])
    tangent = vt[1:]
    x = data.points
    h = np.column_stack([x @ tangent[0], x @ tangent[1], -np.ones(len(x))])
    w = 1.0 / _quad_forms(data.covs, n)
    fisher = (h * w[:, None]).T @ h
    ev = np.linalg.eigvalsh(fisher)
    if not ev[0] > 1e-13 * ev[-1]:
        raise ProblemError(
            "plane.cramer_rao_bound data: the Fisher information is singular (eigenvalues "
            f"{ev[0]:.3g} ... {ev[-1]:.3g}): the true points do not determine the plane "
            "(collinear?), the bound is infinite")
    cov = np.linalg.inv(fisher)
    return CramerRao(cov=cov, tangent=tangent, angle_rms=float(np.sqrt(cov[0, 0] + cov[1, 1])),
                     offset_std=float(np.sqrt(cov[2, 2])))


def _direction_stack(name: str, value: ArrayLike) -> FloatArray:
    if np.iscomplexobj(value):
        raise ProblemError(f"{name}: complex values are not accepted (give real numbers)")
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"{name}: not a numeric array ({exc})") from exc
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ProblemError(f"{name}: expected shape (..., 3), got {a.shape}")
    if np.any(np.isinf(a)) or np.any(np.abs(a[np.isfinite(a)]) > MAX_MAGNITUDE):
        raise ProblemError(f"{name}: infinite or huge entries")
    nrm = np.linalg.norm(a, axis=-1)
    if np.any(nrm == 0):
        raise ProblemError(f"{name}: zero vectors have no direction")
    return a


def angle_error(normal: ArrayLike, true_normal: ArrayLike) -> FloatArray:
    """Angle (rad) between estimated and true normals, ignoring the common sign of (n, a).

    Works on stacks (..., 3). Uses ``atan2(‖n × m‖, |n·m|)``, accurate for tiny angles.
    NaN rows (e.g. the unresolved steps of :class:`PlaneSequence`) give NaN; infinite,
    complex or zero vectors are refused.
    """
    a = _direction_stack("plane.angle_error normal", normal)
    b = _direction_stack("plane.angle_error true_normal", true_normal)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.arctan2(cross, np.abs(np.sum(a * b, axis=-1)))


def plane_errors(
    normal: ArrayLike, offset: ArrayLike, true_normal: ArrayLike, true_offset: float
) -> tuple[FloatArray, FloatArray]:
    """(angle error in rad, offset error in m) with (n, a) sign-aligned to the truth.
    Stacks (..., 3) and (...,) work; NaN rows give NaN (see :func:`angle_error`)."""
    n = _direction_stack("plane.plane_errors normal", normal)
    if np.iscomplexobj(offset):
        raise ProblemError("plane.plane_errors offset: complex values are not accepted")
    try:
        a = np.asarray(offset, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"plane.plane_errors offset: not numeric ({exc})") from exc
    if a.shape != n.shape[:-1] or np.any(np.isinf(a)):
        raise ProblemError(f"plane.plane_errors offset: expected finite values (NaN allowed) "
                           f"of shape {n.shape[:-1]}, got shape {a.shape}")
    true_offset = as_number("plane.plane_errors true_offset", true_offset)
    _direction_stack("plane.plane_errors true_normal", true_normal)
    sign = np.sign(np.sum(n * np.asarray(true_normal, dtype=float), axis=-1))
    sign = np.where(sign == 0, 1.0, sign)
    return angle_error(n, true_normal), sign * a - true_offset


# =========================================================================== sequence
@dataclass
class PlaneSequence:
    """Running plane identification, one row per step (a new measurement).

    Attributes
    ----------
    times : (K,) time of each step; n_points : (K,) measurements used so far.
    normal : (K, 3), offset : (K,) -- closed form (1.5)-(1.7); NaN where not ``resolved``.
    statistic : (K,) Λ_min (1.16), the minimum of (1.2) (defined at every step).
    dof, threshold, p_value, planar : (K,) the χ² test at ``level``; ``p_value`` is NaN
        and ``planar`` False where not ``resolved``.
    paper_statistic, paper_threshold, paper_planar : (K,) the paper's rule (1.17);
        ``paper_planar`` False where not ``resolved``.
    resolved : (K,) bool
        The data so far determine the plane: the line hypothesis is rejected at ``level``
        (``line_statistic > line_threshold``, see :class:`PlanarityTest`) **and** the
        normal passes its numerical re-check (estimated error ``numerical_error`` ≤ 1e-3
        rad, :func:`closed_form`). Scale invariant (whitened eigenvalues) and
        conditioning-aware. Where False no plane is reported.
    line_statistic, line_threshold : (K,) Λ₁ + Λ₂ (χ²(2N − 4) on a line) and its
        threshold at ``level``.
    line_direction : (K, 3) unit direction of the best-fitting line where not
        ``resolved`` (what the data do determine), NaN where resolved.
    numerical_error : (K,) estimated error (rad) of the closed-form normal, the Newton
        step of the re-check (inf: not determined to working precision).
    solve_time : float, seconds for the whole closed-form track.
    generic : dict or None
        With ``resolve_every``: ``index`` (J,) into the steps, ``normal`` (J, 3),
        ``offset`` (J,), ``objective`` (J,), ``status`` (J,) and ``solve_time`` of the
        warm-started generic re-solves (on resolved steps only; an unresolved step has
        status ``"unresolved"`` and NaN values).
    """

    times: FloatArray
    n_points: FloatArray
    normal: FloatArray
    offset: FloatArray
    statistic: FloatArray
    dof: FloatArray
    threshold: FloatArray
    p_value: FloatArray
    planar: np.ndarray
    paper_statistic: FloatArray
    paper_threshold: FloatArray
    paper_planar: np.ndarray
    level: float
    solve_time: float
    resolved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    line_statistic: FloatArray = field(default_factory=lambda: np.zeros(0))
    line_threshold: FloatArray = field(default_factory=lambda: np.zeros(0))
    line_direction: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    numerical_error: FloatArray = field(default_factory=lambda: np.zeros(0))
    generic: dict[str, Any] | None = None


def identify_sequence(
    times: ArrayLike,
    points: ArrayLike,
    cov: ArrayLike,
    alpha2: ArrayLike | None = None,
    start: float | None = None,
    *,
    level: float = 0.997,
    resolve_every: int | None = None,
    formulation: Formulation = "reduced",
) -> PlaneSequence:
    """Re-estimate the plane after every measurement from time ``start`` on.

    The closed form is updated in O(1) per measurement: running sums of
    :math:`\alpha_i^{-2}`, :math:`\alpha_i^{-2} x_i` and :math:`\alpha_i^{-2} x_i x_i^T`
    (about the first point, divided by the spread) give ``Q`` (1.5) at every step,
    followed by one 3x3 eigenproblem per step (done for all steps at once) and the
    re-check of :func:`closed_form`.

    A step is ``resolved`` when the points so far are not on a line at ``level`` -- the
    two smallest generalized eigenvalues of (Q, D), Λ₁ + Λ₂ (the minimum of (1.2) over
    lines, χ²(2N − 4) under the line hypothesis), exceed ``chi2.ppf(level, 2N − 4)`` --
    and the normal's estimated numerical error is ≤ 1e-3 rad. Unresolved steps report
    no plane (NaN normal and offset, ``planar`` False) and the line direction instead.

    Parameters
    ----------
    times : (N,) strictly increasing measurement times (s).
    points, cov, alpha2 : as :class:`PlaneData` (m, m²); the covariances must satisfy
        (1.4).
    start : float, optional
        First time (s) at which to identify (the paper: 2 s after the first measurement).
        Default: as soon as 4 points are in (the test needs N >= 4).
    level : float
        Level of the χ² test and of the line test, in (0, 1).
    resolve_every : int, optional
        Also re-solve the generic problem every ``resolve_every`` (≥ 1) steps,
        warm-started from the previous generic solution (one start).
    formulation : {"reduced", "full"}
        Formulation of those generic re-solves.
    """
    data = PlaneData(points, cov, alpha2)
    t = as_finite_array("plane.identify_sequence times", times, shape=(data.n_points,))
    if np.any(np.diff(t) <= 0):
        raise ProblemError("plane.identify_sequence times: must be strictly increasing")
    if data.base_cov is None or data.alpha2 is None:
        raise ProblemError(
            "cov: the sequential closed form needs proportional covariances (1.4); for "
            "general D_i call plane.solve on each window"
        )
    lv = as_probability("plane.identify_sequence level", level, low_open=True, high_open=True)
    formulation = as_choice("plane.identify_sequence formulation",  # type: ignore[assignment]
                            formulation, ("full", "reduced"))
    every = None if resolve_every is None else as_count(
        "plane.identify_sequence resolve_every", resolve_every, minimum=1)
    if start is None:
        first = 3
    else:
        t0 = as_number("plane.identify_sequence start", start)
        first = max(int(np.searchsorted(t, t0, side="left")), 3)  # at least 4 points
    if first >= data.n_points:
        raise ProblemError(
            f"plane.identify_sequence start: no step with at least 4 measurements at or "
            f"after t = {start}"
        )

    with timed() as tm:
        s0, s1, s2, s2abs, ref, spread = _scaled_sums(data.points, data.alpha2,
                                                       cumulative=True)
        count = np.arange(first + 1, data.n_points + 1, dtype=float)
        eig = _closed_form_from_sums(s0[first:], s1[first:], s2[first:], s2abs[first:],
                                     count, data.base_cov / spread**2)
        normal = eig.normal
        offset = spread * np.sum(normal * eig.mean, axis=-1) + normal @ ref  # (1.7)
        lead = np.take_along_axis(normal, np.argmax(normal != 0, axis=-1)[:, None], -1)[:, 0]
        flip = (offset < 0) | ((offset == 0) & (lead < 0))  # the sign of _canonical_sign
        normal = np.where(flip[:, None], -normal, normal)
        offset = np.abs(offset)
        stat = eig.check.rho
        line_stat = eig.lam[:, 0] + eig.lam[:, 1]
        err = eig.check.step
        arr = _planarity_arrays(stat, count, lv, line_stat, err <= REJECT_TOL)
        resolved = arr["resolved"]
        normal = np.where(resolved[:, None], normal, np.nan)
        offset = np.where(resolved, offset, np.nan)
        line_dir = np.where(resolved[:, None], np.nan, eig.line)

    generic = None
    if every is not None:
        generic = _sequence_generic(data, first, every, formulation, resolved)
    return PlaneSequence(
        times=t[first:], n_points=count, normal=normal, offset=offset, statistic=stat,
        dof=arr["dof"], threshold=arr["threshold"], p_value=arr["p_value"],
        planar=arr["planar"], paper_statistic=arr["paper_statistic"],
        paper_threshold=arr["paper_threshold"], paper_planar=arr["paper_planar"],
        level=lv, solve_time=tm.elapsed, resolved=resolved, line_statistic=line_stat,
        line_threshold=arr["line_threshold"], line_direction=line_dir,
        numerical_error=err, generic=generic,
    )


def _sequence_generic(
    data: PlaneData, first: int, every: int, formulation: Formulation, resolved: np.ndarray
) -> dict[str, Any]:
    assert data.base_cov is not None and data.alpha2 is not None
    steps = np.arange(first, data.n_points, every)
    normals = np.full((len(steps), 3), np.nan)
    offsets = np.full(len(steps), np.nan)
    objs = np.full(len(steps), np.nan)
    status: list[str] = []
    total = 0.0
    prev: FloatArray | None = None
    for j, i in enumerate(steps):
        if not resolved[i - first]:
            status.append("unresolved")
            continue
        sub = PlaneData(data.points[: i + 1], data.base_cov, data.alpha2[: i + 1])
        sol = solve(sub, formulation, starts=3 if prev is None else 1, initial_normal=prev)
        total += sol.build_time + sol.solve_time
        status.append(sol.status.value)
        if sol.ok:
            normals[j], offsets[j], objs[j] = sol.normal, sol.offset, sol.objective
            prev = sol.normal
    return {"index": steps - first, "normal": normals, "offset": offsets,
            "objective": objs, "status": status, "solve_time": total}
