r"""The line test of paper 000's plane: is the track a line (the plane not determined)?

Resolved or not, the analogue of the two-smallest-eigenvalue test Λ₁ + Λ₂ of
:func:`optmodels.plane.planarity_test` under (1.4)): the minimum of (1.2) over *lines*,
:math:`L = \min_{p,d,t_i} \sum_i (x_i - p - t_id)^TD_i^{-1}(x_i - p - t_id)`, is χ² with
2N − 4 degrees of freedom if the points are on a line; the plane is ``resolved`` when
``L > chi2.ppf(level, 2N - 4)`` and the normal passes its numerical re-check. Decided in
two stages: a lower bound (:math:`D_i \preceq \mathrm{tr}(D_i) I`: the isotropic weighted
line fit, two eigenvalues) settles clearly curved tracks at once; otherwise ``L`` itself
is computed (the point of the line eliminated in closed form, Newton on the sphere for
the direction). Under (1.4) ``L`` is exactly Λ₁ + Λ₂.

Used by :func:`optmodels.plane.general.fit_general` (each window of
:func:`optmodels.plane.track`) and on its own by :func:`line_test`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import special

from optmodels.core import FloatArray, as_instance, as_probability
from optmodels.plane.data import PlaneData

__all__ = ["LineTest", "line_test"]


def _eig2(h: FloatArray) -> tuple[float, float]:
    """Eigenvalues (ascending) of a symmetric 2x2 matrix (``eigvalsh`` costs ~20x more)."""
    m = 0.5 * (float(h[0, 0]) + float(h[1, 1]))
    d = 0.5 * (float(h[0, 0]) - float(h[1, 1]))
    rad = (d * d + float(h[0, 1]) ** 2) ** 0.5
    return m - rad, m + rad


def _tangent(n: FloatArray) -> FloatArray:
    """Orthonormal basis (2, 3) of the plane orthogonal to unit ``n`` (the basis of
    :func:`optmodels.plane.verify._tangent_basis`, without its stack overhead)."""
    x, y, z = (float(v) for v in n)
    k = int(np.argmin(np.abs(n)))
    # n x e_k (np.cross costs ~40 us per call on 3-vectors)
    a = (0.0, z, -y) if k == 0 else (-z, 0.0, x) if k == 1 else (y, -x, 0.0)
    s = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]) ** 0.5
    u = (a[0] / s, a[1] / s, a[2] / s)
    v = (y * u[2] - z * u[1], z * u[0] - x * u[2], x * u[1] - y * u[0])
    return np.array([u, v])


def _line_lower_bound(y: FloatArray, trace: FloatArray) -> tuple[float, FloatArray]:
    r"""A lower bound of the minimum of (1.2) over lines, and its line's direction:
    :math:`D_i \preceq \mathrm{tr}(D_i)\, I`, so each point's distance to a line is at
    least its Euclidean one over :math:`\mathrm{tr}\,D_i`, and the best line of that
    isotropic weighted problem is given by the weighted scatter's eigenvalues (the two
    smallest sum to its minimum)."""
    w = 1.0 / trace
    yc = y - (w @ y) / np.sum(w)
    lam, vec = np.linalg.eigh((yc * w[:, None]).T @ yc)
    return float(lam[0] + lam[1]), vec[:, 2]


def _line_value(y: FloatArray, c: FloatArray, d: FloatArray) -> float:
    r"""Minimum of (1.2) over the lines of direction ``d`` (unit).

    The minimum over ``t`` of :math:`(e - td)^TD^{-1}(e - td)` is :math:`z^TS^{-1}z` with
    :math:`z = B^Te`, :math:`S = B^TDB` (``B`` an orthonormal basis of :math:`d^\perp`:
    the marginal of the noise across the line), and the best point of the line is the
    :math:`S_i^{-1}`-weighted mean of the :math:`B^Ty_i`. Invariant to the choice of ``B``.
    """
    b = _tangent(d)
    s = np.einsum("aj,ijk,bk->iab", b, c, b)
    det = s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] ** 2
    i00, i11, i01 = s[:, 1, 1] / det, s[:, 0, 0] / det, -s[:, 0, 1] / det
    z = y @ b.T
    a = np.array([[np.sum(i00), np.sum(i01)], [np.sum(i01), np.sum(i11)]])
    rhs = np.array([i00 @ z[:, 0] + i01 @ z[:, 1], i01 @ z[:, 0] + i11 @ z[:, 1]])
    q = np.linalg.solve(a, rhs)
    r0, r1 = z[:, 0] - q[0], z[:, 1] - q[1]
    return float(np.sum(i00 * r0 * r0 + 2.0 * i01 * r0 * r1 + i11 * r1 * r1))


def _line_fit(
    y: FloatArray, c: FloatArray, d0: FloatArray, *, max_iter: int = 50, tol: float = 1e-8
) -> tuple[float, FloatArray, bool]:
    """Minimum of (1.2) over lines: Newton on the sphere for :func:`_line_value` (the
    point of the line eliminated), with central-difference gradient and Hessian (step
    1e-4 rad: relative truncation ~1e-8 of the derivatives, so the value is exact to
    round-off at the minimum) and backtracking, from ``d0``. ``(L, direction,
    converged)``."""
    d = d0 / np.linalg.norm(d0)
    hs = 1e-4
    val = _line_value(y, c, d)
    for _ in range(max_iter):
        t = _tangent(d)

        def f(u: float, v: float, d: FloatArray = d, t: FloatArray = t) -> float:
            m = d + u * t[0] + v * t[1]
            return _line_value(y, c, m / np.linalg.norm(m))

        fp0, fm0, f0p, f0m = f(hs, 0.0), f(-hs, 0.0), f(0.0, hs), f(0.0, -hs)
        fpp, fmm = f(hs, hs), f(-hs, -hs)
        g = np.array([fp0 - fm0, f0p - f0m]) / (2 * hs)
        h00 = (fp0 - 2 * val + fm0) / hs**2
        h11 = (f0p - 2 * val + f0m) / hs**2
        h01 = (fpp + fmm + 2 * val - fp0 - fm0 - f0p - f0m) / (2 * hs**2)
        hm = np.array([[h00, h01], [h01, h11]])
        lo, hi = _eig2(hm)
        if lo > 1e-12 * abs(hi):
            delta = -np.linalg.solve(hm, g)
        else:
            delta = -g / max(abs(hi), abs(lo), 1e-300)
        size = float(np.linalg.norm(delta))
        if size > 0.5:
            delta *= 0.5 / size
            size = 0.5
        if size < tol and lo > 0:
            return val, d, True
        step = 1.0
        while True:
            m = d + step * (delta @ t)
            cand = m / np.linalg.norm(m)
            vc = _line_value(y, c, cand)
            if vc <= val or step < 1e-6:
                break
            step *= 0.5
        if vc > val:  # no descent left at the difference step's accuracy
            return val, d, bool(lo > 0)
        d, val = cand, vc
    return val, d, False


@functools.lru_cache(maxsize=256)
def _chi2_ppf(level: float, dof: int) -> float:
    """``chi2.ppf(level, dof)`` through the special function (≈ 50x faster than
    ``scipy.stats``, which matters per step of a track)."""
    return float(special.chdtri(dof, 1.0 - level))


@dataclass(frozen=True)
class LineTest:
    """The hypothesis "the points are on a line" (the plane is then not determined).

    Attributes
    ----------
    statistic : float
        Minimum of (1.2) over lines, χ²(2N − 4) for points on a line: exact (``exact``)
        whenever it could be below ``threshold``; a lower bound where that bound already
        exceeds it (a clearly curved track: the verdict is then certain).
    dof, threshold, level : int, float, float
        ``2N − 4``, ``chi2.ppf(level, 2N − 4)`` and the level.
    direction : ndarray (3,)
        Unit direction of the best line (largest component > 0).
    resolved : bool
        ``statistic > threshold`` (the line is rejected: the data determine a plane).
        An exact line fit that did not converge counts as not resolved (the safe side).
    exact : bool
        ``statistic`` is the minimum itself, not a lower bound.
    """

    statistic: float
    dof: int
    threshold: float
    level: float
    direction: FloatArray
    resolved: bool
    exact: bool


def line_test(data: PlaneData, level: float = 0.997) -> LineTest:
    r"""The line test behind ``resolved`` for one set of points, with the exact line
    statistic under any covariances.

    Under (1.4) the minimum of (1.2) over lines is :math:`\Lambda_1 + \Lambda_2`, the two
    smallest generalized eigenvalues of ``(Q, D)`` (the line along the largest one's
    eigenvector). For general :math:`D_i` it is :func:`_line_fit` (Newton on the sphere of
    directions, the point of the line eliminated), started from the isotropic lower bound
    :func:`_line_lower_bound`, which alone decides only when it already exceeds the
    threshold -- as :func:`fit_general` does (issue 26: the lower bound alone called real
    turns "unresolved").
    """
    as_instance("plane.line_test data", data, PlaneData)
    lv = as_probability("plane.line_test level", level, low_open=True, high_open=True)
    n = data.n_points
    dof = 2 * n - 4
    thr = _chi2_ppf(lv, dof)
    if data.alpha2 is not None and data.base_cov is not None:
        from optmodels.plane.closedform import _scaled_sums

        s0, s1, s2, _, _, spread = _scaled_sums(data.points, data.alpha2, cumulative=False)
        q = (s2 - s1[..., :, None] * s1[..., None, :] / s0[..., None, None])[0]
        m, h = np.linalg.eigh(data.base_cov / spread**2)
        t = h / np.sqrt(m)
        r = t.T @ q @ t
        lam, g = np.linalg.eigh(0.5 * (r + r.T))
        stat, direction, conv, exact = (
            float(lam[0] + lam[1]),
            (h * np.sqrt(m)) @ g[:, 2],
            True,
            True,
        )
    else:
        centre = data.points.mean(axis=0)
        y = data.points - centre
        scale = float(np.sqrt(np.mean(np.sum(y * y, axis=1))))
        y = y / scale
        c = 0.5 * (data.covs + data.covs.transpose(0, 2, 1)) / scale**2
        lower, lower_dir = _line_lower_bound(y, np.trace(c, axis1=1, axis2=2))
        if lower > thr:
            stat, direction, conv, exact = lower, lower_dir, True, False
        else:
            stat, direction, conv = _line_fit(y, c, lower_dir)
            exact = True
    direction = direction / np.linalg.norm(direction)
    direction = direction if direction[np.argmax(np.abs(direction))] > 0 else -direction
    return LineTest(
        statistic=float(stat),
        dof=dof,
        threshold=thr,
        level=lv,
        direction=direction,
        resolved=bool(conv and stat > thr),
        exact=exact,
    )
