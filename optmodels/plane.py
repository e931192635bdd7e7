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
    FloatArray,
    ProblemError,
    Solution,
    SolverNotAvailable,
    Status,
    as_finite_array,
    check_spd,
    check_spd_stack,
    timed,
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
#: Relative gap between the two smallest generalized eigenvalues below which the plane is
#: not unique (collinear data): a few hundred ulps of the largest eigenvalue.
_UNIQUE_RTOL = 1e-12


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
        pts = as_finite_array("points", self.points, shape=(None, 3), max_abs=MAX_MAGNITUDE)
        n = pts.shape[0]
        if n < 3:
            raise ProblemError(f"points: a plane needs at least 3 points, got {n}")
        cov = as_finite_array("cov", self.cov, ndim=(2, 3), max_abs=MAX_MAGNITUDE)
        alpha2: FloatArray | None
        if cov.ndim == 2:
            if cov.shape != (3, 3):
                raise ProblemError(f"cov: expected shape (3, 3) or ({n}, 3, 3), got {cov.shape}")
            check_spd("cov", cov)
            if self.alpha2 is None:
                alpha2 = np.ones(n)
            else:
                alpha2 = as_finite_array("alpha2", self.alpha2, shape=(n,),
                                         max_abs=MAX_MAGNITUDE)
                if np.any(alpha2 < 1 / MAX_MAGNITUDE):
                    raise ProblemError(
                        f"alpha2: the factors of (1.4) must be ≥ 1e-100; "
                        f"{int(np.sum(alpha2 < 1 / MAX_MAGNITUDE))} are not"
                    )
            base = 0.5 * (cov + cov.T)
            covs = alpha2[:, None, None] * base
        else:
            if cov.shape != (n, 3, 3):
                raise ProblemError(f"cov: expected shape (3, 3) or ({n}, 3, 3), got {cov.shape}")
            if self.alpha2 is not None:
                raise ProblemError(
                    "alpha2: only meaningful with a common (3, 3) cov (1.4); with per-point "
                    "covariances put the factors into cov"
                )
            check_spd_stack("cov", cov)
            covs = 0.5 * (cov + cov.transpose(0, 2, 1))
            base, alpha2 = _detect_proportional(covs)
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        scale = max(1.0, float(np.max(np.abs(pts))))
        if spread[0] <= 1e-12 * scale * np.sqrt(n):
            raise ProblemError("points: all points are identical; no plane is defined")
        if spread[1] <= 1e-9 * spread[0]:
            raise ProblemError(
                "points: the points are collinear; every plane through their line fits "
                "(the two smallest generalized eigenvalues coincide), the plane is not unique"
            )
        # Found by the robustness sweep: covariances at 1e±150 relative to the points made
        # the scaled problem's inverses and quadratic forms overflow. The plane problem is
        # invariant to x → s·x, D → s²·D; what must stay in range is the noise relative to
        # the extent of the data.
        eig = np.linalg.eigvalsh(covs)
        ext2 = max(float(spread[0]) ** 2 / n, 1e-300)
        if float(eig.min()) < 1e-100 * ext2 or float(eig.max()) > 1e100 * ext2:
            raise ProblemError(
                f"cov: variances from {float(eig.min()):.3g} to {float(eig.max()):.3g} for "
                f"points spread over {np.sqrt(ext2):.3g}; outside 1e±100 of the spread² "
                "(float64 cannot hold the weights); check units")
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
    """Objective (1.2): :math:`\\sum_i (x_i - x_i^*)^T D_i^{-1} (x_i - x_i^*)`."""
    x = as_finite_array("projected", projected, shape=(data.n_points, 3))
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
    x = np.asarray(projected, dtype=float)
    n = np.asarray(normal, dtype=float)
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
    n = np.asarray(normal, dtype=float)
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
    return _weighted_offset(data.points, data.covs, np.asarray(normal, dtype=float))[2]


def project(data: PlaneData, normal: ArrayLike, offset: float) -> FloatArray:
    """Most likely true positions on a given plane, (1.8):
    :math:`x_i = x_i^* + \\frac{a - \\langle n, x_i^*\\rangle}{\\langle D_i n, n\\rangle} D_i n`."""
    return _oblique_projection(data.points, data.covs, np.asarray(normal, dtype=float), offset)


def _finish(
    data: PlaneData, normal: FloatArray, offset: float, *, status: Status, method: str,
    build_time: float = 0.0, solve_time: float = 0.0, iterations: int | None = None,
    message: str = "", info: dict[str, Any] | None = None, projected: FloatArray | None = None,
) -> PlaneSolution:
    """Canonical sign, projection (1.8) if not given, re-check against the original form."""
    if not np.all(np.isfinite(normal)) or not np.isfinite(offset):
        return PlaneSolution(
            status=status if not status.ok else Status.ERROR, objective=float("nan"),
            method=method, build_time=build_time, solve_time=solve_time,
            iterations=iterations, message=message or "non-finite iterate", info=info or {},
        )
    normal, offset = _canonical_sign(normal, offset)
    if projected is None:
        projected = project(data, normal, offset)
    return PlaneSolution(
        status=status,
        objective=objective(data, projected),
        method=method,
        build_time=build_time,
        solve_time=solve_time,
        iterations=iterations,
        residuals=constraint_residuals(data, projected, normal, offset),
        message=message,
        info=info or {},
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


def _profile_derivatives(sc: _Scaled, normal: FloatArray) -> tuple[float, float]:
    """Gradient norm and smallest Hessian eigenvalue of
    :math:`\\Phi(n) = \\min_a \\varphi(a, n)` on the unit sphere at ``normal``
    (tangent coordinates, scaled data), both relative to the largest curvature.

    Central differences with step ``h = 1e-4`` rad: truncation O(h²) relative, round-off
    ~1e-16/h² = 1e-8 relative, both far below the O(1) curvature of a real minimum.
    A positive curvature means a strict local minimum of (1.12)-(1.13); the gradient is
    an independent first-order check.
    """
    _, _, vt = np.linalg.svd(normal[None, :])
    t1, t2 = vt[1], vt[2]
    h = 1e-4

    def phi(d1: float, d2: float) -> float:
        n = normal + d1 * t1 + d2 * t2
        n = n / np.linalg.norm(n)
        wd, proj, a = _weighted_offset(sc.points, sc.covs, n)
        return float(np.sum(wd * (proj - a) ** 2))

    f0 = phi(0.0, 0.0)
    fp1, fm1, fp2, fm2 = phi(h, 0), phi(-h, 0), phi(0, h), phi(0, -h)
    grad = np.array([fp1 - fm1, fp2 - fm2]) / (2 * h)
    h11 = (fp1 - 2 * f0 + fm1) / h**2
    h22 = (fp2 - 2 * f0 + fm2) / h**2
    h12 = (phi(h, h) - phi(h, -h) - phi(-h, h) + phi(-h, -h)) / (4 * h**2)
    lam = np.linalg.eigvalsh(np.array([[h11, h12], [h12, h22]]))
    scale = max(abs(lam[1]), np.finfo(float).tiny)
    return float(np.linalg.norm(grad) / scale), float(lam[0] / scale)


#: Independent acceptance of a point where IPOPT stopped at its precision limit: tangent
#: gradient of Φ below 1e-6 of its curvature (an angle error of ~1e-6 rad at most, and the
#: finite-difference gradient is accurate to ~1e-8) and feasibility of (1.3) to 1e-8.
_VERIFY_GRAD = 1e-6


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
    """
    if formulation not in ("full", "reduced"):
        raise ProblemError(f"formulation: expected 'full' or 'reduced', got {formulation!r}")
    auto = starts == "auto"
    if not auto and (not isinstance(starts, int | np.integer) or not 1 <= int(starts) <= 3):
        raise ProblemError(f"starts: expected 'auto', 1, 2 or 3, got {starts!r}")
    sc = _Scaled.of(data)
    n_pts = data.n_points
    if initial_normal is not None:
        n0 = as_finite_array("initial_normal", initial_normal, shape=(3,))
        if np.linalg.norm(n0) == 0:
            raise ProblemError("initial_normal: must be non-zero")
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
        curv_i = float("nan")
        if np.all(np.isfinite(normal)) and np.linalg.norm(normal) > 0:
            grad_i, curv_i = _profile_derivatives(sc, normal / np.linalg.norm(normal))
            if res.message == "Search_Direction_Becomes_Too_Small":
                # IPOPT's precision limit: accept only a point verified independently.
                ok = grad_i <= _VERIFY_GRAD and curv_i > 0 and abs(normal @ normal - 1) <= 1e-8
                if ok and x_scaled is not None:
                    ok = float(np.max(np.abs(x_scaled @ normal - b))) <= 1e-8
                if ok:
                    status = Status.OPTIMAL_INACCURATE
                    message += " (KKT point verified: tangent gradient " \
                        f"{grad_i:.1e}, curvature {curv_i:.2f})"
        sol = _finish(data, normal, offset, status=status, method=method,
                      message=message, projected=proj)
        start_objs.append(sol.objective)
        start_status.append(res.message)
        if sol.ok and (best is None or sol.objective < best.objective):
            best = sol
            curvature = curv_i
        elif not sol.ok and first_fail is None:
            first_fail = sol
    out = best if best is not None else first_fail
    assert out is not None
    out.build_time = build_time
    out.solve_time = total_solve
    out.iterations = total_iter
    out.info = {
        "start_objectives": start_objs,
        "start_status": start_status,
        "starts": len(start_objs),
        "min_curvature": curvature,
        "cached_build": not fresh,
    }
    return out


# =========================================================================== closed form
@dataclass(frozen=True)
class _Eig:
    """Closed-form pieces for a stack of problems (leading dimension K)."""

    normal: FloatArray  # (K, 3), unit, un-signed
    lam: FloatArray  # (K, 3) eigenvalues of R, ascending
    offset: FloatArray  # (K,)


def _closed_form_from_sums(
    s0: FloatArray, s1: FloatArray, s2: FloatArray, ref: FloatArray, base_cov: FloatArray
) -> _Eig:
    """The paper's route (1.5)-(1.7) from running sums, vectorised over a stack.

    ``s0 = Σ w_i``, ``s1 = Σ w_i (x_i - ref)``, ``s2 = Σ w_i (x_i - ref)(x_i - ref)^T`` with
    :math:`w_i = \\alpha_i^{-2}`. ``Q`` (1.5) is shift invariant; sums about ``ref`` (a
    data point) avoid the cancellation of the printed form far from the origin.
    """
    q = s2 - s1[..., :, None] * s1[..., None, :] / s0[..., None, None]  # (1.5)
    m, h = np.linalg.eigh(base_cov)  # D = h M h^T
    t = h / np.sqrt(m)  # h M^{-1/2}
    r = t.T @ q @ t  # (1.7), first use of the number: R = M^{-1/2} h^T Q h M^{-1/2}
    r = 0.5 * (r + np.swapaxes(r, -1, -2))
    lam, g = np.linalg.eigh(r)  # R = g Λ g^T, ascending
    nvec = g[..., :, 0] @ t.T  # (1.6): h M^{-1/2} g_k (row-vector form)
    nvec = nvec / np.linalg.norm(nvec, axis=-1, keepdims=True)
    mean = ref + s1 / s0[..., None]
    offset = np.sum(nvec * mean, axis=-1)  # (1.7), second use: a = <n, Σ w x> / Σ w
    return _Eig(normal=nvec, lam=lam, offset=offset)


def closed_form(data: PlaneData) -> PlaneSolution:
    """The paper's closed form (1.5)-(1.8), valid under (1.4) :math:`D_i = \\alpha_i^2 D`.

    Route: ``Q`` (1.5); ``D = h M h^T``; ``R = M^{-1/2} h^T Q h M^{-1/2} = g Λ g^T`` (1.7);
    ``n = h M^{-1/2} g_k / ‖·‖`` (1.6) for the smallest ``Λ_kk``; ``a`` (1.7); projected
    points (1.8). ``objective`` is (1.2) re-evaluated at the projected points and equals
    ``Λ_min`` (``info["lambda_min"]``, (1.16)).

    Raises
    ------
    ProblemError
        If the covariances are not proportional (use :func:`solve`), or if the two
        smallest eigenvalues of ``R`` coincide (plane not unique).
    """
    if data.base_cov is None or data.alpha2 is None:
        raise ProblemError(
            "cov: the closed form needs proportional covariances D_i = alpha_i^2 D (1.4); "
            "these are not -- use plane.solve(data) (full or reduced formulation)"
        )
    with timed() as t:
        w = 1.0 / data.alpha2
        ref = data.points[0]
        y = data.points - ref
        s0 = np.asarray(np.sum(w))
        s1 = w @ y
        s2 = (y * w[:, None]).T @ y
        eig = _closed_form_from_sums(s0, s1, s2, ref, data.base_cov)
    lam = eig.lam
    if lam[1] - lam[0] <= _UNIQUE_RTOL * max(lam[2], np.finfo(float).tiny):
        raise ProblemError(
            "points: the two smallest generalized eigenvalues of (Q, D) coincide "
            f"({lam[0]:.6g}, {lam[1]:.6g}); the plane is not unique (collinear data?)"
        )
    return _finish(
        data, eig.normal, float(eig.offset), status=Status.OPTIMAL, method="closed_form",
        solve_time=t.elapsed, iterations=None,
        info={"lambda_min": float(lam[0]), "eigenvalues": lam.copy()},
    )


def change_of_basis(base_cov: ArrayLike, q: ArrayLike, *, printed: bool = False) -> FloatArray:
    """The matrix ``B`` after (1.15) with :math:`\\eta = B n` diagonalising both forms.

    Correct: :math:`B = g^T M^{1/2} h^T` (then :math:`n^T D n = \\|\\eta\\|^2` and
    :math:`n^T Q n = \\sum \\lambda_k \\eta_k^2`). ``printed=True`` returns the paper's
    :math:`g^T M^{-1/2} h^T`, which does not (see errata).
    """
    d = as_finite_array("base_cov", base_cov, shape=(3, 3))
    qm = as_finite_array("q", q, shape=(3, 3))
    m, h = np.linalg.eigh(d)
    t = h / np.sqrt(m)
    _, g = np.linalg.eigh(t.T @ qm @ t)
    power = -0.5 if printed else 0.5
    return g.T @ np.diag(m**power) @ h.T


def scatter_matrix(data: PlaneData) -> FloatArray:
    """``Q`` of (1.5) under (1.4), computed about a data point (shift invariant)."""
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
    with timed() as t:
        c = data.points.mean(axis=0)
        _, _, vt = np.linalg.svd(data.points - c, full_matrices=False)
        normal = vt[-1]
        offset = float(normal @ c)
    return _finish(data, normal, offset, status=Status.OPTIMAL, method="svd",
                   solve_time=t.elapsed)


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

    def to_dict(self) -> dict[str, Any]:
        return {k: (bool(v) if isinstance(v, np.bool_) else v) for k, v in self.__dict__.items()}


def _check_level(level: float) -> float:
    lv = float(level)
    if not 0.0 < lv < 1.0:
        raise ProblemError(f"level: must be in (0, 1), got {level}")
    return lv


def _planarity_arrays(
    stat: FloatArray, n: FloatArray, level: float
) -> dict[str, FloatArray]:
    dof = n - 3
    thr = stats.chi2.ppf(level, dof)
    paper_thr = np.sqrt(2.0 * n) + 2.0
    return {
        "dof": dof,
        "threshold": thr,
        "p_value": stats.chi2.sf(stat, dof),
        "planar": stat <= thr,
        "paper_statistic": np.sqrt(2.0 * np.maximum(stat, 0.0)),
        "paper_threshold": paper_thr,
        "paper_planar": np.sqrt(2.0 * np.maximum(stat, 0.0)) <= paper_thr,
        "paper_false_alarm": stats.chi2.sf(paper_thr**2 / 2.0, dof),
    }


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
        Acceptance probability for a planar motion, default 0.997 as in the paper.
    """
    lv = _check_level(level)
    if data.n_points < 4:
        raise ProblemError("points: the planarity test needs N >= 4 (dof = N - 3)")
    if solution is None:
        solution = closed_form(data) if data.proportional else solve(data).require_ok()
    solution.require_ok()
    stat = reduced_objective(data, solution.normal, solution.offset)
    arr = _planarity_arrays(np.asarray(stat), np.asarray(float(data.n_points)), lv)
    return PlanarityTest(
        statistic=stat, dof=int(arr["dof"]), level=lv, threshold=float(arr["threshold"]),
        p_value=float(arr["p_value"]), planar=bool(arr["planar"]),
        paper_statistic=float(arr["paper_statistic"]),
        paper_threshold=float(arr["paper_threshold"]),
        paper_planar=bool(arr["paper_planar"]),
        paper_false_alarm=float(arr["paper_false_alarm"]),
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
    n = as_finite_array("normal", normal, shape=(3,))
    n = n / np.linalg.norm(n)
    # tangent basis: complete n to an orthonormal frame
    _, _, vt = np.linalg.svd(n[None, :])
    tangent = vt[1:]
    x = data.points
    h = np.column_stack([x @ tangent[0], x @ tangent[1], -np.ones(len(x))])
    w = 1.0 / _quad_forms(data.covs, n)
    fisher = (h * w[:, None]).T @ h
    cov = np.linalg.inv(fisher)
    return CramerRao(cov=cov, tangent=tangent, angle_rms=float(np.sqrt(cov[0, 0] + cov[1, 1])),
                     offset_std=float(np.sqrt(cov[2, 2])))


def angle_error(normal: ArrayLike, true_normal: ArrayLike) -> FloatArray:
    """Angle (rad) between estimated and true normals, ignoring the common sign of (n, a).

    Works on stacks (..., 3). Uses ``atan2(‖n × m‖, |n·m|)``, accurate for tiny angles.
    """
    a = np.asarray(normal, dtype=float)
    b = np.asarray(true_normal, dtype=float)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.arctan2(cross, np.abs(np.sum(a * b, axis=-1)))


def plane_errors(
    normal: ArrayLike, offset: ArrayLike, true_normal: ArrayLike, true_offset: float
) -> tuple[FloatArray, FloatArray]:
    """(angle error in rad, offset error in m) with (n, a) sign-aligned to the truth."""
    n = np.asarray(normal, dtype=float)
    a = np.asarray(offset, dtype=float)
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
    normal : (K, 3), offset : (K,), statistic : (K,) Λ_min -- closed form (1.5)-(1.7).
    dof, threshold, p_value, planar : (K,) the χ² test at ``level``.
    paper_statistic, paper_threshold, paper_planar : (K,) the paper's rule (1.17).
    solve_time : float, seconds for the whole closed-form track.
    generic : dict or None
        With ``resolve_every``: ``index`` (J,) into the steps, ``normal`` (J, 3),
        ``offset`` (J,), ``objective`` (J,), ``status`` (J,) and ``solve_time`` of the
        warm-started generic re-solves.
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
    :math:`\\alpha_i^{-2}`, :math:`\\alpha_i^{-2} x_i` and :math:`\\alpha_i^{-2} x_i x_i^T`
    (about the first point) give ``Q`` (1.5) at every step, followed by one 3x3
    eigenproblem per step (done for all steps at once).

    Parameters
    ----------
    times : (N,) strictly increasing measurement times (s).
    points, cov, alpha2 : as :class:`PlaneData`; the covariances must satisfy (1.4).
    start : float, optional
        First time at which to identify (the paper: 2 s after the first measurement).
        Default: as soon as 4 points are in (the test needs N >= 4).
    level : float
        Level of the χ² test.
    resolve_every : int, optional
        Also re-solve the generic problem every ``resolve_every`` steps, warm-started
        from the previous generic solution (one start).
    formulation : {"reduced", "full"}
        Formulation of those generic re-solves.
    """
    data = PlaneData(points, cov, alpha2)
    t = as_finite_array("times", times, shape=(data.n_points,))
    if np.any(np.diff(t) <= 0):
        raise ProblemError("times: must be strictly increasing")
    if data.base_cov is None or data.alpha2 is None:
        raise ProblemError(
            "cov: the sequential closed form needs proportional covariances (1.4); for "
            "general D_i call plane.solve on each window"
        )
    lv = _check_level(level)
    first = 3 if start is None else int(np.searchsorted(t, float(start), side="left"))
    first = max(first, 3)  # at least 4 points
    if first >= data.n_points:
        raise ProblemError(
            f"start: no step with at least 4 measurements at or after t = {start}"
        )
    if resolve_every is not None and int(resolve_every) < 1:
        raise ProblemError(f"resolve_every: must be >= 1, got {resolve_every}")

    with timed() as tm:
        w = 1.0 / data.alpha2
        ref = data.points[0]
        y = data.points - ref
        s0 = np.cumsum(w)[first:]
        s1 = np.cumsum(w[:, None] * y, axis=0)[first:]
        s2 = np.cumsum(w[:, None, None] * (y[:, :, None] * y[:, None, :]), axis=0)[first:]
        eig = _closed_form_from_sums(s0, s1, s2, ref, data.base_cov)
        normal, offset = eig.normal, eig.offset
        flip = offset < 0
        normal = np.where(flip[:, None], -normal, normal)
        offset = np.abs(offset)
        stat = eig.lam[:, 0]
    count = np.arange(first + 1, data.n_points + 1, dtype=float)
    arr = _planarity_arrays(stat, count, lv)

    generic = None
    if resolve_every is not None:
        generic = _sequence_generic(data, first, int(resolve_every), formulation)
    return PlaneSequence(
        times=t[first:], n_points=count, normal=normal, offset=offset, statistic=stat,
        dof=arr["dof"], threshold=arr["threshold"], p_value=arr["p_value"],
        planar=arr["planar"], paper_statistic=arr["paper_statistic"],
        paper_threshold=arr["paper_threshold"], paper_planar=arr["paper_planar"],
        level=lv, solve_time=tm.elapsed, generic=generic,
    )


def _sequence_generic(
    data: PlaneData, first: int, every: int, formulation: Formulation
) -> dict[str, Any]:
    steps = np.arange(first, data.n_points, every)
    normals = np.full((len(steps), 3), np.nan)
    offsets = np.full(len(steps), np.nan)
    objs = np.full(len(steps), np.nan)
    status: list[str] = []
    total = 0.0
    prev: FloatArray | None = None
    for j, i in enumerate(steps):
        sub = PlaneData(data.points[: i + 1], data.base_cov, data.alpha2[: i + 1])
        sol = solve(sub, formulation, starts=3 if prev is None else 1, initial_normal=prev)
        total += sol.build_time + sol.solve_time
        status.append(sol.status.value)
        if sol.ok:
            normals[j], offsets[j], objs[j] = sol.normal, sol.offset, sol.objective
            prev = sol.normal
    return {"index": steps - first, "normal": normals, "offset": offsets,
            "objective": objs, "status": status, "solve_time": total}


