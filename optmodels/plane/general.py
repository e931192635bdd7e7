r"""The ML plane for general (non-proportional) covariances :math:`D_i`, fast and warm-startable.

:func:`fit_general` minimises the reduced problem (1.12)-(1.13) of paper 000 -- equivalent
to the original (1.2)-(1.3) for any SPD :math:`D_i` (1.11) -- by Newton's method on the
unit sphere for the *profile*

.. math::
    \Phi(n) = \min_a \sum_i \frac{(\langle n, x_i\rangle - a)^2}{\langle D_i n, n\rangle}
            = \sum_i w_i r_i^2,\qquad w_i = \frac1{\langle D_i n, n\rangle},\quad
              r_i = \langle n, x_i\rangle - a(n),\quad a(n) = \frac{\sum w_i \langle n,
              x_i\rangle}{\sum w_i},

with the analytic gradient and Hessian (below) and a backtracking line search, then a
re-check of the result (the Newton step with round-off floors, as
:func:`optmodels.plane.verify._profile_check` does for the generic
:func:`optmodels.plane.solve`, which :meth:`GeneralFit.to_solution` runs too). It needs no
CasADi and costs O(N) per iteration: a warm-started step of a sliding window of 100 points
takes about 3 iterations, 0.6 ms (``solvers_cmp/plane_sequential.py``). Under (1.4) its
minimiser is the closed form's (1.5)-(1.8).

Stationarity (the fixed point of the reweighted closed form). :math:`\Phi` is homogeneous
of degree 0 in ``n``; by the envelope theorem (``a`` optimal, :math:`\sum_i w_i r_i = 0`)

.. math::
    \nabla\Phi = 2\,(Q_w - M_w)\,n,\qquad Q_w = \sum_i w_i (x_i - \bar x_w)(x_i - \bar
    x_w)^T,\quad M_w = \sum_i w_i^2 r_i^2 D_i ,

and :math:`n^TQ_wn = n^TM_wn = \Phi`, so :math:`n^T\nabla\Phi = 0` (Euler). A unit ``n`` is
stationary for (1.12)-(1.13) iff :math:`Q_w n = M_w n`: ``n`` is a generalized eigenvector
of the reweighted scatter :math:`Q_w` in the metric :math:`M_w`, with eigenvalue 1. Under
(1.4), :math:`D_i = \alpha_i^2 D`, :math:`M_w = (\Phi / n^TDn)\,D` and the condition is
:math:`Q n = \rho D n` (1.14)-(1.15): the paper's closed form is the case where the metric
does not depend on ``n``. For general :math:`D_i` the fixed-point iteration on that
eigenproblem (weights and metric from the last ``n``) converges at best linearly, hence
Newton (``tests/test_plane_general.py`` checks :math:`Q_wn = M_wn` at the result).

Hessian of the profile (``a`` eliminated, :math:`u_i = D_i n`):

.. math::
    \varphi_{nn} &= \sum_i 2w_i x_ix_i^T - 4w_i^2r_i(x_iu_i^T + u_ix_i^T) + 8w_i^3r_i^2u_iu_i^T
                   - 2w_i^2r_i^2 D_i,\\
    \varphi_{na} &= \sum_i -2w_ix_i + 4w_i^2 r_i u_i,\qquad \varphi_{aa} = 2\sum_i w_i,\\
    \nabla^2\Phi &= \varphi_{nn} - \varphi_{na}\varphi_{na}^T/\varphi_{aa},

and, since :math:`n^T\nabla\Phi = 0`, the Riemannian Hessian on the sphere is
:math:`P\,\nabla^2\Phi\,P` (``P`` the tangent projector; no curvature term).

Resolved or not (the analogue of the two-smallest-eigenvalue test Λ₁ + Λ₂ of
:func:`optmodels.plane.planarity_test` under (1.4)): the minimum of (1.2) over *lines*,
:math:`L = \min_{p,d,t_i} \sum_i (x_i - p - t_id)^TD_i^{-1}(x_i - p - t_id)`, is χ² with
2N − 4 degrees of freedom if the points are on a line; the plane is ``resolved`` when
``L > chi2.ppf(level, 2N - 4)`` and the normal passes its numerical re-check
(:mod:`optmodels.plane.lines`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    REJECT_TOL,
    VERIFY_TOL,
    FloatArray,
    ProblemError,
    Status,
    as_count,
    as_finite_array,
    as_instance,
    as_number,
    as_probability,
    check_spd_stack,
    verified_status,
)
from optmodels.plane.data import PlaneData, _canonical_sign
from optmodels.plane.lines import (
    LineTest,
    _chi2_ppf,
    _eig2,
    _line_fit,
    _line_lower_bound,
    _tangent,
    line_test,
)
from optmodels.plane.solution import PlaneSolution, _failure
from optmodels.plane.verify import _finish, _profile_check

__all__ = ["GeneralFit", "LineTest", "fit_general", "line_test"]

_WHERE = "plane.fit_general"
_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class GeneralFit:
    """The ML plane (1.12)-(1.13) for general :math:`D_i` (:func:`fit_general`).

    Attributes
    ----------
    normal : ndarray (3,)
        Unit normal; sign convention of :func:`optmodels.plane.closed_form` (``offset >=
        0``; if 0, first non-zero component positive). Not determined by the data where
        ``resolved`` is False (every plane through ``line_direction`` fits about equally).
    offset : float
        ``a`` of (1.1), m.
    objective : float
        Minimum of (1.12) = minimum of (1.2) (dimensionless), χ²(N − 3) for planar motion.
    iterations : int
        Newton iterations (all starts).
    converged : bool
        The last Newton step was below ``tol`` (rad) with a positive definite tangent
        Hessian (a strict local minimum of the profile).
    resolved : bool
        The data determine the plane at ``level``: ``line_statistic > line_threshold`` and
        ``numerical_error <= 1e-3`` rad.
    line_statistic : float
        Minimum of (1.2) over lines, χ²(2N − 4) if the points are on a line -- computed
        exactly whenever it could be below ``line_threshold``; where a lower bound of it
        already exceeds the threshold (a clearly curved track) that lower bound is
        reported instead (then ``resolved`` is certain and the exact value not needed).
    line_direction : ndarray (3,)
        Unit direction of that best line (what the data determine when not ``resolved``:
        the planes containing it all fit about equally); sign: largest component > 0.
    numerical_error : float
        Estimated error (rad) of ``normal``: the Newton step of the package's re-check
        :func:`optmodels.plane.verify._profile_check` with its round-off floor (inf if
        the curvature does not clear it).
    status : Status
        OPTIMAL if converged and ``numerical_error <= 1e-6``; OPTIMAL_INACCURATE up to
        1e-3; ITERATION_LIMIT if not converged (never OK); ERROR above 1e-3 or at a saddle.
    level, line_dof, line_threshold : float, int, float
        Level of the line test, ``2N − 4`` and ``chi2.ppf(level, 2N − 4)``.
    curvature : float
        Smallest tangent curvature of the profile over the largest (> 0 at a minimum).
    message : str
    """

    normal: FloatArray
    offset: float
    objective: float
    iterations: int
    converged: bool
    resolved: bool
    line_statistic: float
    line_direction: FloatArray
    numerical_error: float
    status: Status = Status.OPTIMAL
    level: float = 0.997
    line_dof: int = 0
    line_threshold: float = float("nan")
    curvature: float = float("nan")
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.status.ok

    def to_solution(self, data: PlaneData) -> PlaneSolution:
        """This fit as a :class:`PlaneSolution` of ``data`` (the same points and
        covariances), through the package's own re-check: the finite-difference Newton
        step of :func:`optmodels.plane.verify._profile_check` (independent of the analytic
        Hessian used here; the larger of the two estimates is the ``stationarity``), then
        :func:`optmodels.plane.verify._finish` (projection (1.8), residuals of (1.3), the
        gate :func:`optmodels.core.finish`). A fit that is not converged or not OK is
        returned in the failure form (NaN normal; the numbers in ``info["rejected"]``), and
        so is a fit that is not ``resolved`` (status ERROR, "unresolved: ...", with
        ``resolved=False`` and the ``line_direction``)."""
        as_instance(f"{_WHERE} data", data, PlaneData)
        status = self.status if self.converged else Status.ITERATION_LIMIT
        step = self.numerical_error
        if np.all(np.isfinite(self.normal)):
            centre = data.points.mean(axis=0)
            y = data.points - centre
            sc = float(np.sqrt(np.mean(np.sum(y * y, axis=1))))
            chk = _profile_check(y / sc, data.covs / sc**2, self.normal)
            step = max(step, float(chk.step[0]))
        sol = _finish(
            data,
            self.normal,
            self.offset,
            status=status,
            method="general",
            stationarity=step,
            iterations=self.iterations,
            message=self.message,
            info={
                "resolved": self.resolved,
                "line_statistic": self.line_statistic,
                "line_direction": self.line_direction,
                "min_curvature": self.curvature,
                "numerical_error": self.numerical_error,
            },
        )
        if sol.ok:  # the fit's own (exact where it matters) line test: its verdict
            sol.resolved = bool(self.resolved)
            sol.line_direction = np.asarray(self.line_direction, dtype=float)
            if not self.resolved:
                sol = _failure(sol)
                sol.status = Status.ERROR
                sol.message = (
                    f"unresolved: the points lie on a line at level "
                    f"{self.level:g} (line statistic {self.line_statistic:.6g} <= "
                    f"{self.line_threshold:.6g}): the plane is not determined; "
                    "line_direction is the maximum-likelihood line"
                )
        return sol


# --------------------------------------------------------------------------- profile
def _profile(y: FloatArray, c: FloatArray, n: FloatArray) -> float:
    u = np.einsum("ijk,k->ij", c, n)
    w = 1.0 / (u @ n)
    p = y @ n
    a = float(w @ p) / float(np.sum(w))
    r = p - a
    return float(w @ (r * r))


def _derivatives(
    y: FloatArray, c: FloatArray, n: FloatArray
) -> tuple[float, float, FloatArray, FloatArray]:
    """``(Φ, a, ∇Φ, ∇²Φ)`` at ``n`` (see the module docstring)."""
    u = np.einsum("ijk,k->ij", c, n)
    w = 1.0 / (u @ n)
    p = y @ n
    sw = float(np.sum(w))
    a = float(w @ p) / sw
    r = p - a
    wr = w * r
    w2r = w * wr
    w2r2 = w2r * r
    phi = float(wr @ r)
    g = 2.0 * (wr @ y) - 2.0 * (w2r2 @ u)
    yu = (y * w2r[:, None]).T @ u
    hnn = (
        2.0 * (y * w[:, None]).T @ y
        - 4.0 * (yu + yu.T)
        + 8.0 * (u * (w2r2 * w)[:, None]).T @ u
        - 2.0 * np.einsum("i,ijk->jk", w2r2, c)
    )
    hna = -2.0 * (w @ y) + 4.0 * (w2r @ u)
    h = hnn - np.outer(hna, hna) / (2.0 * sw)
    return phi, a, g, 0.5 * (h + h.T)


def _check(y: FloatArray, c: FloatArray, n: FloatArray) -> tuple[float, float, float]:
    r"""Re-check of a final normal: ``(numerical_error, curvature, a)``.

    ``numerical_error`` is the estimated angle (rad) to the exact stationary point of
    (1.12)-(1.13): the Newton step :math:`\|H^{-1}g\|` of the analytic tangent gradient
    and Hessian plus what the round-off of ``g`` could hide, ``g_floor / (h_min -
    h_floor)`` (inf when the smallest curvature does not clear its floor: the normal is
    not determined to working precision) -- the estimate of
    :func:`optmodels.plane.verify._profile_check` with an analytic instead of a
    finite-difference Hessian. ``curvature``: smallest tangent curvature over the
    largest.
    """
    _, a, g, h = _derivatives(y, c, n)
    t = _tangent(n)
    gt = t @ g
    ht = t @ h @ t.T
    hl = _eig2(ht)
    u = np.einsum("ijk,k->ij", c, n)
    w = 1.0 / (u @ n)
    absy = np.abs(y)
    r = y @ n - a
    err = 2.0 * (w * (absy @ np.abs(n) + abs(a) + np.abs(r))) @ absy + 2.0 * (
        w * w * r * r
    ) @ np.abs(u)
    fl = 8.0 * np.finfo(float).eps * np.sqrt(len(y))
    gfloor = 2.0 * fl * float(np.linalg.norm(err))
    hfloor = fl * max(abs(hl[0]), abs(hl[1])) + gfloor
    hmin = hl[0] - hfloor
    curv = hl[0] / max(abs(hl[1]), np.finfo(float).tiny)
    if not hmin > 0:
        return float("inf"), curv, a
    step = float(np.linalg.norm(np.linalg.solve(ht, gt))) + gfloor / hmin
    return step, curv, a


def _newton(
    y: FloatArray, c: FloatArray, n0: FloatArray, tol: float, max_iter: int
) -> tuple[FloatArray, int, bool, float]:
    """Newton on the sphere with backtracking; ``(n, iterations, converged, curvature)``."""
    n = n0 / np.linalg.norm(n0)
    phi, _, g, h = _derivatives(y, c, n)
    curv = float("nan")
    tiny = np.finfo(float).tiny
    stalls = 0
    for it in range(1, max_iter + 1):
        t = _tangent(n)
        gt = t @ g
        ht = t @ h @ t.T
        hl = _eig2(ht)
        curv = hl[0] / max(abs(hl[1]), tiny)
        convex = bool(hl[0] > 1e-12 * max(abs(hl[1]), tiny))
        if convex:
            delta = -np.linalg.solve(ht, gt)
        else:  # not locally convex: saddle-free Newton (|curvatures|, floored at 1e-8
            # of the largest: big steps along a flat direction), then the cap and the
            # line search below
            lam, vec = np.linalg.eigh(ht)
            lam_abs = np.maximum(np.abs(lam), 1e-8 * max(float(np.max(np.abs(lam))), tiny))
            delta = -vec @ ((vec.T @ gt) / lam_abs)
            if lam[0] < 0:  # near a saddle or maximum the gradient vanishes: leave it
                # along the direction of negative curvature (0.5 rad, downhill sign)
                v0 = vec[:, 0]
                delta = delta + (0.5 if float(gt @ v0) <= 0 else -0.5) * v0
        size = float(np.linalg.norm(delta))
        if size > 0.5:  # at most ~30° per step
            delta *= 0.5 / size
            size = 0.5
        if size < tol and convex:  # the last (tiny) step taken: error ~ size²
            cand = n + delta @ t
            return cand / np.linalg.norm(cand), it, True, curv
        step = 1.0
        while True:
            cand = n + step * (delta @ t)
            cand = cand / np.linalg.norm(cand)
            phi_c = _profile(y, c, cand)
            if phi_c <= phi + 1e-14 * abs(phi) or step < 1e-8:
                break
            step *= 0.5
        if step < 1e-8:  # no descent at round-off: stationary to working precision
            return n + 0.0, it, convex, curv
        # a flat, non-convex profile (points on a line to round-off): steps that change
        # Φ only at round-off lead nowhere; give up after 5 of them (not converged)
        stalls = stalls + 1 if (not convex and phi - phi_c <= 8 * _EPS * abs(phi)) else 0
        if stalls >= 5:
            return cand, it, False, curv
        n = cand
        phi, _, g, h = _derivatives(y, c, n)
    return n, max_iter, False, curv


# --------------------------------------------------------------------------- entry
def fit_general(
    points: ArrayLike,
    cov: ArrayLike,
    *,
    normal0: ArrayLike | None = None,
    tol: float = 1e-10,
    max_iter: int = 100,
    level: float = 0.997,
) -> GeneralFit:
    r"""The ML plane (1.12)-(1.13) = (1.2)-(1.3) for general SPD :math:`D_i`, by Newton's
    method on the sphere for the profile of (1.12) (see the module docstring).

    Parameters
    ----------
    points : array_like (N, 3)
        Measured positions :math:`x_i^*` (m), N >= 3, any Cartesian frame.
    cov : array_like (N, 3, 3) or (3, 3)
        Error covariances :math:`D_i` (m², same frame), SPD; a (3, 3) is used for every
        point.
    normal0 : array_like (3,), optional
        Warm start (e.g. the previous step's normal in a sliding window): one Newton run
        from it. Default (cold): runs from the closed form with the mean covariance and
        from the three principal axes of the scatter; the lowest converged (1.12) is kept.
    tol : float
        Convergence: Newton step (rad) below ``tol``, in (0, 1e-3].
    max_iter : int
        Newton iterations per start, >= 1.
    level : float
        Level of the line test behind ``resolved``, in (0, 1).

    Returns
    -------
    GeneralFit
        ``status`` from the re-check: never OK unless ``converged`` and the independent
        Newton-step estimate ``numerical_error`` is ≤ 1e-3 rad (OPTIMAL ≤ 1e-6).
        :meth:`GeneralFit.to_solution` gives the :class:`PlaneSolution` of the package's
        gate.

    Raises
    ------
    ProblemError
        Naming the argument: shapes, non-finite values, covariances not SPD, identical or
        collinear-to-round-off points, ``tol``/``max_iter``/``level`` out of range.
    """
    pts, cv, tol, max_iter, lv, start = _validate(
        points, cov, normal0=normal0, tol=tol, max_iter=max_iter, level=level
    )
    sc = _scaled(pts, cv, start)
    starts = [start / np.linalg.norm(start)] if start is not None else _cold_starts(sc)
    phi, n, converged, curv, iters = _best_start(sc, starts, tol, max_iter)
    return _package(sc, lv, n, phi, converged, curv, iters, max_iter)


def _validate(
    points: ArrayLike,
    cov: ArrayLike,
    *,
    normal0: ArrayLike | None,
    tol: float,
    max_iter: int,
    level: float,
) -> tuple[FloatArray, FloatArray, float, int, float, FloatArray | None]:
    """The arguments of :func:`fit_general` checked: points (N, 3), covariances (N, 3, 3)
    SPD (a (3, 3) broadcast), ``tol``, ``max_iter``, ``level`` and the warm start."""
    pts = as_finite_array(f"{_WHERE} points", points, shape=(None, 3), max_abs=MAX_MAGNITUDE)
    npts = pts.shape[0]
    if npts < 3:
        raise ProblemError(f"{_WHERE} points: a plane needs at least 3 points, got {npts}")
    cv = as_finite_array(f"{_WHERE} cov", cov, ndim=(2, 3), max_abs=MAX_MAGNITUDE)
    if cv.shape == (3, 3):
        cv = np.broadcast_to(cv, (npts, 3, 3))
    elif cv.shape != (npts, 3, 3):
        raise ProblemError(f"{_WHERE} cov: expected shape ({npts}, 3, 3) or (3, 3), got {cv.shape}")
    check_spd_stack(f"{_WHERE} cov", cv)
    tol = as_number(f"{_WHERE} tol", tol, low=0.0, low_open=True, high=REJECT_TOL)
    max_iter = as_count(f"{_WHERE} max_iter", max_iter, minimum=1, maximum=10**6)
    lv = as_probability(f"{_WHERE} level", level, low_open=True, high_open=True)
    start: FloatArray | None = None
    if normal0 is not None:
        start = as_finite_array(f"{_WHERE} normal0", normal0, shape=(3,), max_abs=MAX_MAGNITUDE)
        if not float(np.linalg.norm(start)) > 0:
            raise ProblemError(f"{_WHERE} normal0: must be non-zero")
    return pts, cv, tol, max_iter, lv, start


@dataclass(frozen=True)
class _ScaledFit:
    """The data of :func:`fit_general` centred and scaled to unit RMS spread (translation
    and scaling map planes to planes; (1.2) is unchanged when the covariances are scaled
    with the points): ``y`` (N, 3), ``c`` (N, 3, 3) symmetrised, their traces ``tr``."""

    y: FloatArray
    c: FloatArray
    tr: FloatArray
    centre: FloatArray
    scale: float

    @property
    def n_points(self) -> int:
        return int(self.y.shape[0])


def _scaled(pts: FloatArray, cv: FloatArray, start: FloatArray | None) -> _ScaledFit:
    """Centre and scale the data; refuse identical points, points collinear to round-off
    (on a cold start only: a warm start skips that SVD) and covariances
    that float64 cannot weight."""
    npts = pts.shape[0]
    centre = pts.mean(axis=0)
    y = pts - centre
    scale = float(np.sqrt(np.mean(np.sum(y * y, axis=1))))
    spread = np.linalg.svd(y, compute_uv=False) if start is None else None
    big = float(np.max(np.abs(pts)))
    floor = 64.0 * np.finfo(float).eps * np.sqrt(npts) * big
    if not scale > floor / np.sqrt(npts):
        raise ProblemError(f"{_WHERE} points: all points are identical; no plane is defined")
    if spread is not None and spread[1] <= floor:
        raise ProblemError(
            f"{_WHERE} points: the points are collinear to round-off; every "
            "plane through the line fits, the plane is not unique"
        )
    y = y / scale
    c = 0.5 * (cv + cv.transpose(0, 2, 1)) / scale**2
    tr = np.trace(c, axis1=1, axis2=2)  # SPD: λ_max ≤ tr ≤ 3 λ_max
    if float(tr.min()) < 1e-100 or float(tr.max()) > 1e100:
        raise ProblemError(
            f"{_WHERE} cov: variances outside 1e±100 of the spread² of the "
            "points (float64 cannot hold the weights); check units"
        )
    return _ScaledFit(y=y, c=c, tr=tr, centre=centre, scale=scale)


def _cold_starts(sc: _ScaledFit) -> list[FloatArray]:
    """The cold starts: the closed form (1.14)-(1.15) with the mean covariance, then the
    three principal axes of the scatter."""
    y, c = sc.y, sc.c
    _, axes = np.linalg.eigh(y.T @ y)
    dm = np.mean(c, axis=0)
    m, h = np.linalg.eigh(dm)
    tw = h / np.sqrt(m)
    _, gv = np.linalg.eigh(tw.T @ (y.T @ y) @ tw)
    n_cf = tw @ gv[:, 0]
    return [n_cf / np.linalg.norm(n_cf), axes[:, 0], axes[:, 1], axes[:, 2]]


def _best_start(
    sc: _ScaledFit, starts: list[FloatArray], tol: float, max_iter: int
) -> tuple[float, FloatArray, bool, float, int]:
    """Newton from every start; the lowest converged (1.12) is kept (a converged run
    before any that did not): ``(Φ, n, converged, curvature, iterations of all runs)``."""
    best: tuple[float, FloatArray, bool, float] | None = None
    iters = 0
    for s in starts:
        n, it, conv, curv = _newton(sc.y, sc.c, s, tol, max_iter)
        iters += it
        val = _profile(sc.y, sc.c, n)
        key = (not conv, val)
        if best is None or key < (not best[2], best[0]):
            best = (val, n, conv, curv)
    assert best is not None
    return (*best, iters)


def _package(
    sc: _ScaledFit,
    lv: float,
    n: FloatArray,
    phi: float,
    converged: bool,
    curv: float,
    iters: int,
    max_iter: int,
) -> GeneralFit:
    """The re-check of the kept normal (:func:`_check`), its status, the line test behind
    ``resolved`` (:mod:`optmodels.plane.lines`), the plane in the data's frame."""
    y, c, npts = sc.y, sc.c, sc.n_points
    num_err, curv_chk, a_scaled = _check(y, c, n)
    curv = curv_chk if np.isfinite(curv_chk) else curv
    normal, offset = _canonical_sign(n, sc.scale * a_scaled + float(n @ sc.centre))

    status = verified_status(Status.OPTIMAL, num_err)
    message = ""
    if not converged:
        status = Status.ITERATION_LIMIT
        message = (
            f"Newton did not converge ({iters} iterations, at most {max_iter} per "
            "start; a flat profile: points on a line?)"
        )
    elif curv < -1e-6:
        status = Status.ERROR
        message = f"not a minimum of (1.12)-(1.13): profile curvature {curv:.2g}"
    elif not status.ok:
        message = f"normal not determined to working precision (estimated error {num_err:.2g} rad)"
    elif num_err > VERIFY_TOL:
        message = f"estimated error of the normal {num_err:.2g} rad (NumPy re-check)"

    line_dof = 2 * npts - 4
    line_thr = _chi2_ppf(lv, line_dof)
    lower, lower_dir = _line_lower_bound(y, sc.tr)
    if lower > line_thr:  # resolved beyond doubt: no need for the exact line fit
        line_stat, line_dir, above = lower, lower_dir, True
    else:
        line_stat, line_dir, line_conv = _line_fit(y, c, lower_dir)
        above = bool(line_stat > line_thr) if line_conv else False
    line_dir = line_dir / np.linalg.norm(line_dir)
    line_dir = line_dir if line_dir[np.argmax(np.abs(line_dir))] > 0 else -line_dir
    # undecided (iterations ran out near the threshold): not resolved, the safe side
    resolved = bool(above is True and num_err <= REJECT_TOL and converged)
    return GeneralFit(
        normal=normal,
        offset=float(offset),
        objective=phi,
        iterations=iters,
        converged=bool(converged),
        resolved=resolved,
        line_statistic=line_stat,
        line_direction=line_dir,
        numerical_error=num_err,
        status=status,
        level=lv,
        line_dof=line_dof,
        line_threshold=line_thr,
        curvature=curv,
        message=message,
    )
