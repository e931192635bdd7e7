r"""The paper's closed form (1.5)-(1.8) under (1.4), and the SVD baseline.

:func:`closed_form`: ``Q`` (1.5), ``D = h M h^T``, ``R = g Λ g^T`` (1.7), the normal
(1.6), ``a`` (1.7), the projections (1.8), from weighted sums that
:mod:`optmodels.plane.sequence` also accumulates step by step
(:func:`_scaled_sums`, :func:`_closed_form_from_sums`); :func:`change_of_basis` (after
(1.15), with the printed erratum), :func:`scatter_matrix` (``Q`` of (1.5)) and
:func:`svd_fit`, the unweighted total-least-squares plane.

(Named ``closedform`` so that the module does not shadow the function
:func:`optmodels.plane.closed_form` re-exported by the package.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    REJECT_TOL,
    FloatArray,
    ProblemError,
    Status,
    as_finite_array,
    as_flag,
    as_instance,
    check_spd,
    timed,
)
from optmodels.plane.data import PlaneData, _check_data
from optmodels.plane.solution import PlaneSolution
from optmodels.plane.verify import _Check, _finish, _rayleigh_check, _resolve


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
    s0: FloatArray,
    s1: FloatArray,
    s2: FloatArray,
    s2abs: FloatArray,
    count: FloatArray,
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
        chk = _Check(
            *(
                np.where(take[(...,) + (None,) * (a.ndim - 1)], b, a)
                for a, b in zip(
                    (chk.step, chk.curvature, chk.rho, chk.newton),
                    (c2.step, c2.curvature, c2.rho, c2.newton),
                    strict=True,
                )
            )
        )
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
        terms = (
            w,
            w[:, None] * y,
            w[:, None, None] * (y[:, :, None] * y[:, None, :]),
            w[:, None, None] * (ay[:, :, None] * ay[:, None, :]),
        )
        s0, s1, s2, s2abs = (np.cumsum(a, axis=0) for a in terms)
    else:
        s0 = np.array([np.sum(w)])
        s1 = (w @ y)[None]
        s2 = ((y * w[:, None]).T @ y)[None]
        s2abs = ((ay * w[:, None]).T @ ay)[None]
    return s0, s1, s2, s2abs, ref, spread


def closed_form(data: PlaneData, *, level: float | None = 0.997) -> PlaneSolution:
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
    are on a line (see :func:`planarity_test`, ``resolved``). At ``level`` (default
    0.997; ``None``: no test) points on a line give the unresolved form: status ERROR,
    ``resolved=False``, NaN normal and offset, the ML ``line_direction`` (never an
    arbitrary normal with an OK status; ``info["lambda_min"]`` is kept).

    Raises
    ------
    ProblemError
        If the covariances are not proportional (use :func:`solve`), or if the normal is
        not determined to working precision (the estimated error above 1e-3 rad or no
        positive curvature: the two smallest generalized eigenvalues of ``(Q, D)``
        coincide to round-off, e.g. collinear points).
    """
    as_instance("plane.closed_form data", data, PlaneData)
    if data.base_cov is None or data.alpha2 is None:
        raise ProblemError(
            "cov: the closed form needs proportional covariances D_i = alpha_i^2 D (1.4); "
            "these are not -- use plane.solve(data) (full or reduced formulation)"
        )
    with timed() as t:
        s0, s1, s2, s2abs, ref, spread = _scaled_sums(data.points, data.alpha2, cumulative=False)
        eig = _closed_form_from_sums(
            s0, s1, s2, s2abs, np.array([float(data.n_points)]), data.base_cov / spread**2
        )
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
    sol = _finish(
        data,
        normal,
        offset,
        status=Status.OPTIMAL,
        method="closed_form",
        stationarity=step,
        solve_time=t.elapsed,
        iterations=None,
        info={
            "lambda_min": float(eig.check.rho[0]),
            "eigenvalues": lam.copy(),
            "line_statistic": float(lam[0] + lam[1]),
            "line_dof": 2 * data.n_points - 4,
            "refined": bool(eig.refined[0]),
        },
    )
    return _resolve(sol, data, level)


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
    as_flag("plane.change_of_basis printed", printed)
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
    as_instance("plane.svd_fit data", data, PlaneData)
    with timed() as t:
        c = data.points.mean(axis=0)
        _, _, vt = np.linalg.svd(data.points - c, full_matrices=False)
        normal = vt[-1]
        offset = float(normal @ c)
    # re-check: the TLS normal is the pencil (scatter, I) eigenvector -- same Newton test
    y = data.points - c
    y = y / float(np.max(np.abs(y)))
    chk = _rayleigh_check(
        (y.T @ y)[None],
        (np.abs(y).T @ np.abs(y))[None],
        np.eye(3),
        normal[None],
        np.array([float(data.n_points)]),
    )
    return _finish(
        data,
        normal,
        offset,
        status=Status.OPTIMAL,
        method="svd",
        stationarity=float(chk.step[0]),
        solve_time=t.elapsed,
    )
