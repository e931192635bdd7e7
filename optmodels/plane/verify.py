r"""Re-check of a plane estimate against the original problem (1.2)-(1.3), in NumPy.

The Newton step on the unit sphere of the Rayleigh quotient (1.14)-(1.15) of the pencil
``(Q, D)`` (:func:`_rayleigh_check`: closed form, SVD baseline) or of the profile of
(1.12) (:func:`_profile_check`: generic solve), with the round-off floors of gradient and
Hessian; and :func:`_finish`, which every estimate goes through: canonical sign,
projection (1.8), residuals of (1.3), then the one gate :func:`optmodels.core.finish`
(:func:`optmodels.core.verified_status` of the dimensionless checks); a non-finite
estimate is the failure form :func:`optmodels.core.failure`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from optmodels.core import FloatArray, Status, failure, finish
from optmodels.plane.data import (
    _EPS,
    PlaneData,
    _canonical_sign,
    _oblique_projection,
    _weighted_offset,
    constraint_residuals,
    objective,
    project,
)
from optmodels.plane.solution import PlaneSolution, _failure


def _roundoff(count: int | FloatArray) -> FloatArray | float:
    """Relative round-off allowed for a sum of ``count`` terms: 8 ulps x sqrt(N) (the
    statistical growth of BLAS/cumsum summation error, with a margin of 8)."""
    return 8.0 * _EPS * np.sqrt(np.asarray(count, dtype=float))


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
    hfloor = 2.0 * fl * (np.linalg.norm(qabs, axis=(-2, -1)) + np.abs(rho) * np.linalg.norm(d)) / nd
    return _newton(gt, h, gfloor, hfloor, t, rho)


def _newton(
    gt: FloatArray,
    h: FloatArray,
    gfloor: FloatArray,
    hfloor: FloatArray,
    t: FloatArray,
    rho: FloatArray,
) -> _Check:
    hl = np.linalg.eigvalsh(h)
    hmin = hl[:, 0] - hfloor
    good = hmin > 0
    hh = np.where(good[:, None, None], h, np.eye(2))
    delta = np.where(good[:, None], np.linalg.solve(hh, gt[..., None])[..., 0], 0.0)
    # the Newton step itself, plus what the round-off of g could hide (bounded by the
    # smallest curvature)
    step = np.where(
        good, np.linalg.norm(delta, axis=-1) + gfloor / np.where(good, hmin, 1.0), np.inf
    )
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
        err = 2.0 * (w * (absx @ np.abs(n) + abs(a) + np.abs(r))) @ absx + 2.0 * (
            w * w * r * r
        ) @ np.abs(dn)
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
    return _newton((t @ g0)[None, :], h[None], np.array([gfloor]), np.array([hfloor]), t[None], rho)


def _finish(
    data: PlaneData,
    normal: FloatArray,
    offset: float,
    *,
    status: Status,
    method: str,
    stationarity: float,
    build_time: float = 0.0,
    solve_time: float = 0.0,
    iterations: int | None = None,
    message: str = "",
    info: dict[str, Any] | None = None,
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
    if (
        not np.all(np.isfinite(normal))
        or not np.isfinite(offset)
        or float(np.linalg.norm(normal)) == 0.0
    ):
        return failure(
            PlaneSolution,
            method,
            message or "non-finite iterate",
            status=status,
            build_time=build_time,
            solve_time=solve_time,
            iterations=iterations,
            info=info,
        )
    normal, offset = _canonical_sign(normal, offset)
    checks: dict[str, float] = {}
    if projected is None:
        projected = project(data, normal, offset)
    else:
        unit = normal / np.linalg.norm(normal)
        opt = _oblique_projection(
            data.points, data.covs, unit, float(offset / np.linalg.norm(normal))
        )
        e = projected - opt
        dist2 = np.sum(e * np.linalg.solve(data.covs, e[..., None])[..., 0], axis=1)
        checks["projection"] = float(np.sqrt(np.max(np.abs(dist2))))
    residuals = constraint_residuals(data, projected, normal, offset)
    scale = float(np.max(np.abs(data.points)))
    checks.update(
        unit_normal=residuals["unit_normal"],
        plane=residuals["plane"] / scale,
        stationarity=float(stationarity),
    )
    info["verification"] = checks
    sol = PlaneSolution(
        status=status,
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
    # the one gate (core.finish) on the dimensionless checks; a refused plane is returned
    # without an estimate (its numbers stay in info["rejected"] for diagnosis)
    return finish(
        sol,
        checks,
        reject=_failure,
        note=lambda v: f"re-check of (1.2)-(1.3): worst {v.worst:.2g} ({v.key})",
    )


def _resolve(sol: PlaneSolution, data: PlaneData, level: float | None) -> PlaneSolution:
    """The verdict of the line test on a single fit (issue 26): an OK plane whose points
    are on a line at ``level`` is not a plane -- it becomes the unresolved form (status
    ERROR, message "unresolved: ...", NaN normal and offset, the plane that was fitted in
    ``info["rejected"]``), with ``resolved=False`` and the ML ``line_direction``. A fit
    that is not OK, or ``level=None``, is returned untested (``resolved=None``)."""
    if level is None or not sol.ok:
        return sol
    from optmodels.plane.general import line_test

    lt = line_test(data, level)
    sol.resolved = lt.resolved
    sol.line_direction = lt.direction
    sol.info["line_test"] = {
        "statistic": lt.statistic,
        "dof": lt.dof,
        "threshold": lt.threshold,
        "level": lt.level,
        "exact": lt.exact,
    }
    if lt.resolved:
        return sol
    sol = _failure(sol)
    sol.status = Status.ERROR
    sol.message = (
        f"unresolved: the points lie on a line at level {lt.level:g} (line "
        f"statistic {lt.statistic:.6g} <= {lt.threshold:.6g}, chi2({lt.dof})): "
        "the plane is not determined; line_direction is the maximum-likelihood "
        "line"
    )
    return sol
