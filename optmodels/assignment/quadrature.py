r"""The Gaussian masses of the resolution model (:mod:`~optmodels.assignment.sensor`) by
deterministic quadrature: the probability that the predicted difference of two objects
lies in a polar resolution cell (a box in range and azimuth, :func:`_box_probability`) or
in a whitened resolution ellipse (a ball, :func:`_ball_probability`), by Gauss–Legendre
quadrature (smooth in the inputs), in work chunks of bounded memory (:func:`_chunks`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from optmodels.core import FloatArray

#: Gauss–Legendre nodes per integration level, and the window (± this many standard
#: deviations) of the outer Gaussian.
_NODES = 96
_WINDOW = 9.0
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_NODES)
#: Work memory of one quadrature batch (bytes): the pairs are integrated in chunks of this
#: size.
QUADRATURE_BYTES = 64 * 2**20


def _chunks(total: int, row_bytes: int) -> list[slice]:
    """Slices of ``total`` rows, each using at most :data:`QUADRATURE_BYTES`."""
    step = max(1, QUADRATURE_BYTES // max(1, row_bytes))
    return [slice(a, min(total, a + step)) for a in range(0, total, step)]


def _interval_prob(
    c_lo: FloatArray, c_hi: FloatArray, mu: FloatArray, sd: FloatArray
) -> FloatArray:
    """P(c_lo < z < c_hi) for z ~ N(mu, sd²), without cancellation in either tail."""
    a, b = (c_lo - mu) / sd, (c_hi - mu) / sd
    upper = a > 0  # both in the upper tail: use the mirrored lower tail
    return np.where(upper, ndtr(-a) - ndtr(-b), ndtr(b) - ndtr(a)).clip(0.0, 1.0)


def _box_probability(mu: FloatArray, cov: FloatArray, half: FloatArray) -> FloatArray:
    """P(|Δ_1| < half_1, |Δ_2| < half_2) for Δ ~ N(mu, cov), rows of (P, 2), (P, 2, 2):
    one Gauss–Legendre quadrature over the outer coordinate (window ± 9σ) of the
    conditional interval probability of the inner one; the inner one is the coordinate
    whose conditional distribution is the wider relative to its half-width (the smoother
    integrand)."""
    s = np.sqrt(np.stack([cov[:, 0, 0], cov[:, 1, 1]], axis=1))
    rho = cov[:, 0, 1] / (s[:, 0] * s[:, 1])
    cond = s * np.sqrt(np.maximum(1.0 - rho**2, 1e-300))[:, None]
    # inner = the coordinate with the larger conditional sd / half-width
    inner = (cond[:, 1] / half[1] >= cond[:, 0] / half[0]).astype(int)
    outer = 1 - inner
    rows = np.arange(len(mu))
    mo, mi = mu[rows, outer], mu[rows, inner]
    so, si = s[rows, outer], s[rows, inner]
    ho, hi_ = half[outer], half[inner]
    lo = np.maximum(-ho, mo - _WINDOW * so)
    hi = np.minimum(ho, mo + _WINDOW * so)
    ok = lo < hi
    mid, rad = 0.5 * (lo + hi), 0.5 * np.where(ok, hi - lo, 0.0)
    t = mid[:, None] + rad[:, None] * _GL_X[None, :]
    dens = np.exp(-0.5 * ((t - mo[:, None]) / so[:, None]) ** 2) / (
        so[:, None] * math.sqrt(2 * math.pi)
    )
    cmean = mi[:, None] + (rho * si / so)[:, None] * (t - mo[:, None])
    csd = cond[rows, inner][:, None]
    inside = _interval_prob(-hi_[:, None], hi_[:, None], cmean, csd)
    out = rad * np.sum(_GL_W[None, :] * dens * inside, axis=1)
    return np.where(ok, out, 0.0).clip(0.0, 1.0)


def _ball_probability(nu: FloatArray, sd: FloatArray, c: FloatArray) -> FloatArray:
    """P(Σ_k z_k² < c²) for independent z_k ~ N(nu_k, sd_k²): ``nu``, ``sd`` (P, k) in
    order of increasing sd, ``c`` (P, M) radii; returns (P, M). Nested Gauss–Legendre in
    z_1 = c sin θ (smooth at the ends; window ± 9 sd_1), the last coordinate in closed
    form (the widest: the smoothest inner integrand)."""
    if nu.shape[1] == 1:
        return _interval_prob(-c, c, nu[:, :1], sd[:, :1])
    m0, s0 = nu[:, :1], sd[:, :1]
    safe = np.where(c > 0, c, 1.0)
    lo = np.clip(np.maximum(-c, m0 - _WINDOW * s0) / safe, -1.0, 1.0)
    hi = np.clip(np.minimum(c, m0 + _WINDOW * s0) / safe, -1.0, 1.0)
    ok = (hi > lo) & (c > 0)
    tlo, thi = np.arcsin(lo), np.arcsin(hi)
    mid, rad = 0.5 * (tlo + thi), 0.5 * np.where(ok, thi - tlo, 0.0)
    theta = mid[..., None] + rad[..., None] * _GL_X  # (P, M, n)
    z = c[..., None] * np.sin(theta)
    jac = c[..., None] * np.cos(theta)
    dens = np.exp(-0.5 * ((z - m0[..., None]) / s0[..., None]) ** 2) / (
        s0[..., None] * math.sqrt(2 * math.pi)
    )
    p, m = c.shape
    inner = _ball_probability(
        nu[:, 1:], sd[:, 1:], (c[..., None] * np.cos(theta)).reshape(p, m * _NODES)
    ).reshape(p, m, _NODES)
    out = rad * np.sum(_GL_W * dens * jac * inner, axis=-1)
    return np.where(ok, out, 0.0).clip(0.0, 1.0)
