r"""Plane-change detection on a track (paper 000): a GLR / Chow test of "the last points
lie on the plane of the window before them".

Statistic
---------
At step ``j`` and for a test segment ``B`` of the last ``m`` points (one of a few
scales), split at ``s = j - m`` (the last point of the reference): ``A`` is the window
that ends at ``s`` (its ML plane :math:`(n_A, a_A)`, resolved), ``B = (s, j]``. Linearise
the plane about :math:`(n_A, a_A)`: a plane :math:`\langle n_A + E^T\theta, x\rangle = a_A
+ \delta a` (``E`` a tangent basis of :math:`n_A`, θ two small tilts) gives the residual
of a point

.. math::  r_i = \langle n_A, x_i\rangle - a_A = h_i^T\beta + \varepsilon_i,\qquad
    h_i = (E(\hat x_i - x_s)/\ell,\ -1),\quad \varepsilon_i \sim N(0,\ v_i = n_A^TD_in_A),

with :math:`\hat x_i = x_i - (r_i/v_i)D_in_A` the oblique projection (1.8) onto the
reference plane (its in-plane errors are uncorrelated with :math:`r_i`, whatever
:math:`D_i`; with the measured :math:`x_i` instead the score is biased for anisotropic
:math:`D_i`: radar false alarms 1.6 per hour at a bound of 1, 48 in 30 h, against 0.9,
27 in 30 h, with the projections), and
:math:`\beta = (\ell\theta, \delta a - \theta^TEx_s)`: tilts about the junction point
:math:`x_s` (ℓ any length, the reference window's extent, for conditioning). With the
scores :math:`b_S = \sum_{i\in S} h_ir_i/v_i` and informations
:math:`J_S = \sum_{i\in S} h_ih_i^T/v_i` of ``A`` and ``B``, the generalized likelihood
ratio of "B has its own plane" against "A and B share one plane" is the Chow statistic

.. math::  U = b_A^TJ_A^{-1}b_A + b_B^TJ_B^{+}b_B - (b_A + b_B)^T(J_A + J_B)^{-1}(b_A + b_B),

the drop of the minimum of (1.2) when ``B`` gets its own plane, χ²(3) under "no change"
(χ²(rank J_B) ≤ χ²(3) when ``B`` is too short or straight to determine a plane: the test
is then conservative). (:math:`b_A \approx 0`: :math:`(n_A, a_A)` is ``A``'s ML plane.)

Errors in variables
-------------------
The linear model treats the in-plane coordinates in :math:`h_i` as known, but they are
measured: part of every :math:`J_S` is their noise, :math:`N_S = \sum_S
E_t(D_i - D_inn^TD_i/v_i)E_t^T/v_i` in the tilt block (:func:`noise_info_moments`,
:func:`noise_info_points`), and :math:`S_S = J_S - N_S` is the information of the true
positions. Where the arc's curvature hardly beats that noise -- a short window of many
points, e.g. 100 points at 10 Hz: 10 s of a 7 km turn, sagitta 71 m against σ = 50 m --
it matters twice:

* the reference plane's error: the ML plane is consistent, with covariance the sandwich
  :math:`S_A^{-1}J_AS_A^{-1}` (0.49 rad about the chord in that example, as measured)
  where :math:`J_A^{-1}` claims 0.09 rad -- under the 0.1 rad firmness gate, so such
  references were tested: 24 false alarms per hour at a bound of 1. Its inverse
  :math:`K_A = S_AJ_A^{-1}S_A` (:func:`reference_information`) replaces :math:`J_A`: in the
  firmness of the reference (:func:`reference_tilt_sd` of ``K_A``; no test where
  :math:`S_A` is not positive definite) and below;
* the way that error reaches ``B``: the residuals of ``B`` about the reference plane are
  :math:`\varepsilon_i - h^{0T}_i\delta` with the *true* positions :math:`h^0_i`, so
  :math:`b_B - S_B\hat\beta_A` (:math:`\hat\beta_A = J_A^{-1}b_A \approx 0`) has covariance
  :math:`G = J_B + S_BK_A^{-1}S_B`, and the statistic is

  .. math::  U = (b_B - S_B\hat\beta_A)^T G^+ (b_B - S_B\hat\beta_A)

  (:func:`change_statistic`; with :math:`N = 0` it is the Chow statistic above, as
  :math:`J_B(J_B + J_BJ_A^{-1}J_B)^{-1}J_B = (J_A^{-1} + J_B^{-1})^{-1}`). With ``K_A``
  alone and the Chow form, 15 s windows at 20 Hz still gave 6.5 false alarms per hour.

Checked by Monte Carlo (300-point reference over 15 s, 150-point test segment, σ = 50 m):
with the information of the true positions U is χ²(3) to its 1e-4 tail; with the
estimates :math:`S = J - N` its tails are 1.1-1.3 times the nominal at 1e-2 and 1e-3 (the
sampling error of the estimate, relative √((4ρ + 2ρ²)/n) for a noise share ρ of ``n``
points), which the overlap of neighbouring tests absorbs (below). Over the 40 s and 100 s
windows of a 1 Hz track ``N`` is a few per cent of ``J`` or less and nothing changes.

Threshold and false-alarm rate
------------------------------
With ``L`` scales tested at every step, sampling interval ``dt`` (the median of the
track's) and a wanted false-alarm rate ``far`` per second, each test has level
:math:`p = far\,dt/L` and threshold :math:`c = \chi^2_3{}^{-1}(1 - p)`. By the union
bound the expected number of false alarms per second of track is at most
:math:`L\,p/dt = far`: the rate is *controlled* (the tests of neighbouring steps overlap,
so the actual rate is below it; the Monte Carlo figures are in the notes). The window's
kind does not enter: a test is made per step and scale whether the window counts seconds
or points, and ``dt`` turns steps into time (``"100pts"`` is 100 s at 1 Hz, 10 s at
10 Hz). The bound presumes U is χ²(3) whenever a test is made, which is what the
errors-in-variables information above secures on densely sampled short windows. Alarms
cluster: after a restart the new reference begins with the points of the alarming segment,
chosen by the alarm for lying off the old plane, so a false alarm raises the chance of
another within a window's length (1 Hz, 30 h per kind: 16 of 76 alarms of a 100-point
window within 200 s of the previous one, 5 of 77 with 40 s); the rate stays within the
bound (0.63-0.74 per hour at 1 per hour), but an hour with several alarms is more likely
than Poisson counts would say.

Power: the detectable tilt
--------------------------
A plane that rotates by θ (rad) about an axis through :math:`x_s` in direction ``u`` of the
old plane moves a point at distance ``d`` from the axis by :math:`d\sin\theta` out of the
old plane, so ``U`` is non-central χ²(3, λ) with
:math:`\lambda = \ell^2\sin^2\theta\; u^TF_{tt}u`, where
:math:`F = (J_A^{-1} + J_B^{-1})^{-1} = J_A(J_A + J_B)^{-1}J_B` and :math:`F_{tt}` its tilt
block; with errors in variables :math:`F = S_BG^+S_B` (:func:`change_information`: the
mean of :math:`b_B` under the change is :math:`S_B\beta`), the same without noise in the
in-plane coordinates. The tilt detected with probability ``power`` (0.9) in the direction ``u``
(:func:`detectable_tilt`: in :func:`optmodels.plane.tracking.track`, ``detectable_tilt`` for a
rotation about the velocity at the split -- a bank change, the plane change of a
continuous maneuver -- and ``detectable_tilt_any`` for the *least* informed direction) is
:math:`\sin\theta^* = \sqrt{\lambda^*/(\ell^2 u^TF_{tt}u)}` (:math:`\mu_{min}(F_{tt})`
for the least informed direction; inf if > 1),
with :math:`\lambda^*` solving :math:`P(\chi^2_3(\lambda^*) > c) = power`: smaller tilts
(in that direction) are not reliably seen with these covariances, window and scale. This
is linear theory: it holds for small θ* (40 s reference, 20 s test segment, 1000 runs:
measured power 0.90 at θ* = 6°, σ = 10 m; 0.94 at θ* = 41°, σ = 50 m, where ``B``'s
in-plane noise is large -- with :math:`S_B = J_B` the figure was 33° and its power 0.79).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import optimize, special, stats

from optmodels.core import FloatArray
from optmodels.plane.verify import _tangent_basis
from optmodels.plane.windows import Moments

#: Eigenvalues of J_B below this fraction of its largest are treated as zero (rank-deficient
#: test segment: the statistic is then χ² with fewer degrees of freedom, conservative).
_RANK_RTOL = 1e-10
DETECTOR_DOF = 3


def detector_threshold(false_alarm_rate: float, dt: float, n_scales: int) -> tuple[float, float]:
    """``(c, p)``: the χ²(3) threshold and the per-test level ``p = far·dt/L``."""
    p = false_alarm_rate * dt / n_scales
    return float(special.chdtri(DETECTOR_DOF, p)), p


@lru_cache(maxsize=64)
def noncentrality_for_power(threshold: float, power: float) -> float:
    """λ* with ``P(χ²_3(λ*) > threshold) = power`` (non-central χ²)."""

    def f(lam: float) -> float:
        return float(stats.ncx2.sf(threshold, DETECTOR_DOF, lam)) - power

    hi = max(1.0, threshold)
    while f(hi) < 0:
        hi *= 2.0
    return float(optimize.brentq(f, 0.0, hi, xtol=1e-10, rtol=1e-12))


def _frame(normal: FloatArray) -> FloatArray:
    return _tangent_basis(normal)  # (K, 2, 3)


def score_info_moments(
    normal: FloatArray,
    offset: FloatArray,
    junction: FloatArray,
    mom: Moments,
    base_cov: FloatArray,
    ell: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    r"""``(J, b)`` (K, 3, 3), (K, 3) of index ranges from their moments, under (1.4)
    (``v_i = α_i² nᵀDn``; the moments carry the weights 1/α_i²). Lengths in units of
    ``mom.spread``; ``ell`` (K,) in the same units.

    The in-plane coordinates in ``h_i`` are those of the oblique projections (1.8)
    :math:`\hat x_i = x_i - (r_i/v_i) D_i n` onto the reference plane, not of the
    measurements: their errors are uncorrelated with ``r_i`` (the gradient of (1.12) in
    ``n`` has the same form), so that the score has mean zero for any ``D``. Under (1.4)
    :math:`\hat x_i - x_s = P(x_i - x_s) - (n^Tx_s - a)Dn/v`, ``P = I - Dnn^T/v``: linear
    in ``x_i``, so the moments suffice."""
    sp = mom.spread
    e = _frame(normal)  # (K, 2, 3)
    d = base_cov / sp**2
    dn = normal @ d  # (K, 3)
    v = np.sum(normal * dn, axis=1)
    mu = (mom.mean - junction) / sp  # (K, 3)
    m1 = mom.s0[:, None] * mu
    m2 = mom.q + mom.s0[:, None, None] * mu[:, :, None] * mu[:, None, :]
    rho = (np.sum(normal * junction, axis=1) - offset) / sp
    et = e / ell[:, None, None]
    # G = E_t P, g = -rho E_t D n / v
    edn = np.einsum("kaj,kj->ka", et, dn)
    gm = et - (edn / v[:, None])[:, :, None] * normal[:, None, :]
    gv = -(rho / v)[:, None] * edn
    k = len(normal)
    gm1 = np.einsum("kai,ki->ka", gm, m1)
    j = np.empty((k, 3, 3))
    j[:, :2, :2] = (
        np.einsum("kai,kij,kbj->kab", gm, m2, gm)
        + gm1[:, :, None] * gv[:, None, :]
        + gv[:, :, None] * gm1[:, None, :]
        + mom.s0[:, None, None] * gv[:, :, None] * gv[:, None, :]
    )
    j[:, :2, 2] = -(gm1 + mom.s0[:, None] * gv)
    j[:, 2, :2] = j[:, :2, 2]
    j[:, 2, 2] = mom.s0
    rsum = np.sum(normal * m1, axis=1) + mom.s0 * rho  # Σ w r
    b = np.empty((k, 3))
    b[:, :2] = (
        np.einsum("kai,ki->ka", gm, np.einsum("kij,kj->ki", m2, normal) + m1 * rho[:, None])
        + gv * rsum[:, None]
    )
    b[:, 2] = -rsum
    return j / v[:, None, None], b / v[:, None]


def score_info_points(
    normal: FloatArray,
    offset: float,
    junction: FloatArray,
    points: FloatArray,
    covs: FloatArray,
    spread: float,
    ell: float,
    frame: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``(J, b)`` (3, 3), (3,) of one range of points with general covariances
    (``frame``: the tangent basis (2, 3) of ``normal``, computed if not given); in-plane
    coordinates of the oblique projections (1.8), see :func:`score_info_moments`."""
    e = (_frame(normal[None])[0] if frame is None else frame) / ell
    u = (points - junction) / spread
    dn = covs @ normal / spread**2  # (m, 3)
    v = dn @ normal
    r = (points @ normal - offset) / spread
    xh = u - (r / v)[:, None] * dn
    h = np.column_stack([xh @ e.T, -np.ones(len(u))])
    hw = h / v[:, None]
    return hw.T @ h, hw.T @ r


def noise_info_moments(
    normal: FloatArray, count: FloatArray, base_cov: FloatArray, ell: FloatArray, spread: float
) -> FloatArray:
    r"""``N`` (K, 3, 3): the part of ``J`` of :func:`score_info_moments` due to the noise of
    the in-plane coordinates of the projections (1.8), under (1.4): its tilt block is
    :math:`n_{pts}\, E_t(D - Dnn^TD/v)E_t^T/v` (``E_t`` the tangent basis over ``ell``,
    ``P = I - Dnn^T/v``, :math:`PDP^T = D - Dnn^TD/v`), the rest zero. Each point adds
    :math:`E_tPD_iP^TE_t^T/v_i`, and :math:`D_i/v_i = D/v` under (1.4)."""
    e = _frame(normal) / ell[:, None, None]
    d = base_cov / spread**2
    dn = normal @ d
    v = np.sum(normal * dn, axis=1)
    pdp = d[None] - dn[:, :, None] * dn[:, None, :] / v[:, None, None]
    out = np.zeros((len(normal), 3, 3))
    out[:, :2, :2] = (count / v)[:, None, None] * np.einsum("kai,kij,kbj->kab", e, pdp, e)
    return out


def noise_info_points(
    normal: FloatArray, covs: FloatArray, spread: float, ell: float, frame: FloatArray | None = None
) -> FloatArray:
    r"""``N`` (3, 3) of :func:`noise_info_moments` for general covariances ``covs`` (m, 3, 3):
    :math:`\sum_i E_t(D_i - D_inn^TD_i/v_i)E_t^T/v_i` in the tilt block."""
    e = (_frame(normal[None])[0] if frame is None else frame) / ell
    d = covs / spread**2
    dn = d @ normal  # (m, 3)
    v = dn @ normal
    pdp = np.sum((d - dn[:, :, None] * dn[:, None, :] / v[:, None, None]) / v[:, None, None], 0)
    out = np.zeros((3, 3))
    out[:2, :2] = e @ pdp @ e.T
    return out


def reference_information(ja: FloatArray, noise: FloatArray) -> tuple[FloatArray, np.ndarray]:
    r"""``(K, valid)``: the information of the reference's parameters with its
    errors in variables, :math:`K = S J_A^{-1} S`, :math:`S = J_A - N_A` (``noise``, from
    :func:`noise_info_moments` / :func:`noise_info_points`); ``valid`` where ``S`` is
    positive definite (elsewhere ``K`` is the identity, a placeholder).

    ``J_A`` is built from the *measured* in-plane coordinates: on a short, nearly straight
    reference their noise, not the arc's curvature, makes most of its tilt block, and
    :math:`J_A^{-1}` understates the error of the reference plane (100 points over 10 s
    of a 7 km turn, σ = 50 m: 0.09 rad claimed, 0.49 rad measured). The ML plane is
    consistent in the errors-in-variables model and its covariance is the sandwich
    :math:`S^{-1}J_AS^{-1}` (:math:`\sigma^2/S_0\,(1 + n\sigma^2/S_0)` in one dimension;
    0.49 rad in that example), whose inverse is ``K``."""
    s = ja - noise
    s = 0.5 * (s + np.swapaxes(s, -1, -2))
    lam = np.linalg.eigvalsh(s)
    valid = (lam[:, 0] > _RANK_RTOL * np.abs(lam[:, -1])) & (lam[:, -1] > 0)
    s = np.where(valid[:, None, None], s, np.eye(3))
    jj = np.where(valid[:, None, None], ja, np.eye(3))
    k = s @ np.linalg.solve(jj, s)
    return 0.5 * (k + np.swapaxes(k, -1, -2)), valid


def _solve_psd(j: FloatArray, b: FloatArray) -> FloatArray:
    """``bᵀ J⁺ b`` for stacks, eigenvalues below ``_RANK_RTOL`` of the largest dropped."""
    lam, vec = np.linalg.eigh(j)
    keep = lam > _RANK_RTOL * lam[..., -1:]
    proj = np.einsum("kij,ki->kj", vec, b)
    return np.sum(np.where(keep, proj**2 / np.where(keep, lam, 1.0), 0.0), axis=-1)


def _solve_pd(j: FloatArray, b: FloatArray) -> FloatArray:
    """``bᵀ J⁻¹ b`` for stacks of positive definite ``J`` (Cholesky)."""
    c = np.linalg.cholesky(j)
    y = np.linalg.solve(c, b[..., None])[..., 0]
    return np.sum(y * y, axis=-1)


def chow_statistic(ja: FloatArray, ba: FloatArray, jb: FloatArray, bb: FloatArray) -> FloatArray:
    """U of the module docstring, for stacks (K, 3, 3), (K, 3); ≥ 0 up to round-off.
    ``J_A`` must be positive definite (a firm reference); ``J_B`` may be singular."""
    u = _solve_pd(ja, ba) + _solve_psd(jb, bb) - _solve_pd(ja + jb, ba + bb)
    return np.maximum(u, 0.0)


def change_statistic(
    ka: FloatArray, beta_a: FloatArray, jb: FloatArray, bb: FloatArray, sb: FloatArray
) -> FloatArray:
    r"""U with errors in variables, for stacks (K, 3, 3), (K, 3):
    :math:`U = d^T G^+ d`, :math:`d = b_B - S_B\hat\beta_A`, :math:`G = J_B + S_BK_A^{-1}S_B`.

    ``ka``: the reference's information :math:`K_A` (:func:`reference_information`, positive
    definite); ``beta_a``: :math:`J_A^{-1}b_A` (≈ 0 at the reference's ML plane); ``sb``:
    :math:`S_B = J_B - N_B`. Under "no change" the residuals of ``B`` about the reference
    plane are :math:`r_i = \varepsilon_i - h^0_i{}^T\delta` with the *true* in-plane
    positions :math:`h^0_i` and δ the reference's error (covariance :math:`K_A^{-1}`), so
    :math:`b_B - S_B\hat\beta_A` has covariance :math:`J_B + S_BK_A^{-1}S_B`
    (:math:`E\sum h_ih^{0T}_i/v_i = S_B`): χ²(3), or χ²(rank) ≤ χ²(3) where ``B`` does not
    determine a plane. With no noise in the in-plane coordinates (:math:`S_B = J_B`,
    :math:`K_A = J_A`) it is :func:`chow_statistic`:
    :math:`J_B(J_B + J_BJ_A^{-1}J_B)^{-1}J_B = (J_A^{-1} + J_B^{-1})^{-1}`."""
    g = jb + sb @ np.linalg.solve(ka, np.swapaxes(sb, -1, -2))
    g = 0.5 * (g + np.swapaxes(g, -1, -2))
    d = bb - np.einsum("kij,kj->ki", sb, beta_a)
    return np.maximum(_solve_psd(g, d), 0.0)


def change_information(ka: FloatArray, jb: FloatArray, sb: FloatArray | None = None) -> FloatArray:
    r"""``F`` (K, 3, 3): the noncentrality of :func:`change_statistic` is
    :math:`\beta^TF\beta` for a change β of the plane at the junction,
    :math:`F = S_BG^+S_B` (``G`` of :func:`change_statistic`; the mean of
    :math:`b_B` under the change is :math:`S_B\beta`). ``sb=None``: :math:`S_B = J_B`, and
    ``F = K_A(K_A + J_B)^{-1}J_B`` = :math:`(K_A^{-1} + J_B^{-1})^{-1}`."""
    if sb is None:
        f = ka @ np.linalg.solve(ka + jb, jb)
    else:
        g = jb + sb @ np.linalg.solve(ka, np.swapaxes(sb, -1, -2))
        g = 0.5 * (g + np.swapaxes(g, -1, -2))
        lam, vec = np.linalg.eigh(g)
        keep = lam > _RANK_RTOL * lam[..., -1:]
        ginv = np.einsum(
            "kij,kj,klj->kil", vec, np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0), vec
        )
        f = sb @ ginv @ np.swapaxes(sb, -1, -2)
    return 0.5 * (f + np.swapaxes(f, -1, -2))


def _eig2(m: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(smallest, largest) eigenvalues of symmetric 2x2 stacks, in closed form."""
    a, b, d = m[:, 0, 0], 0.5 * (m[:, 0, 1] + m[:, 1, 0]), m[:, 1, 1]
    mid = 0.5 * (a + d)
    rad = np.sqrt(0.25 * (a - d) ** 2 + b * b)
    return mid - rad, mid + rad


def reference_tilt_sd(ja: FloatArray, ell: FloatArray) -> FloatArray:
    r"""Largest standard deviation (rad) of the reference plane's tilts about the junction,
    :math:`\sqrt{\lambda_{max}((J_A^{-1})_{tt})}/\ell` (its Cramér–Rao bound at the
    fitted plane); inf where ``J_A`` is not positive definite to working precision."""
    lam = np.linalg.eigvalsh(ja)
    good = lam[:, 0] > _RANK_RTOL * lam[:, -1]
    inv = np.linalg.inv(np.where(good[:, None, None], ja, np.eye(3)))
    sd = np.sqrt(np.maximum(_eig2(inv[:, :2, :2])[1], 0.0)) / ell
    return np.where(good, sd, np.inf)


def detectable_tilt(
    ja: FloatArray,
    jb: FloatArray,
    ell: FloatArray,
    lam_star: float,
    direction: FloatArray | None = None,
    sb: FloatArray | None = None,
) -> FloatArray:
    """θ* (rad) of the module docstring, for stacks; ``ell`` in the units of ``J``'s
    lengths (the same as the ``ell`` that built them). ``direction`` (K, 2): the unit
    direction ``u`` of the normal's change in the tangent basis (e.g. a rotation about
    the velocity); default the least informed one. ``ja``: the reference's information
    (``K_A`` in the tracker), ``sb``: ``S_B`` (errors in variables; default ``J_B``), see
    :func:`change_information`."""
    ftt = change_information(ja, jb, sb)[:, :2, :2]
    if direction is None:
        mu = _eig2(ftt)[0]
    else:
        mu = np.einsum("ka,kab,kb->k", direction, ftt, direction)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.sqrt(lam_star / (ell**2 * mu))  # sin θ*: out-of-plane moves are d·sin θ
        theta = np.arcsin(np.minimum(s, 1.0))
    return np.where((mu > 0) & (s < 1.0), theta, np.inf)


def velocity_direction(
    normal: FloatArray, frame: FloatArray, points: FloatArray, split: np.ndarray, back: np.ndarray
) -> FloatArray:
    """Direction ``u`` (K, 2) in the tangent basis ``frame`` of the change of the normal
    when the plane rotates about the velocity at the split (a bank change: the new plane
    of a continuous maneuver contains the velocity): the velocity is estimated from
    ``points[split] - points[split - back]``, projected into the plane ``k``; the normal
    then moves along ``k × n``."""
    d = points[split] - points[split - back]
    k = d - np.sum(d * normal, axis=1)[:, None] * normal
    k = k / np.maximum(np.linalg.norm(k, axis=1, keepdims=True), np.finfo(float).tiny)
    u = np.einsum("kaj,kj->ka", frame, np.cross(k, normal))
    return u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), np.finfo(float).tiny)
