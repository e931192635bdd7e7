r"""The sensor in the joint assignment of paper 004: a resolution cell, the probability that
a group of objects gives one (merged) return, the prior of an unresolved variant π built
from it, and polar measurement covariances.

Resolution model (``docs/formulations.md``; the paper leaves P(π) open and uses a
constant ρ):

* a pair (i, j) is *unresolved* when the difference of the true positions lies in the
  resolution cell: for a radar |Δr| < Δr_res and |Δaz| < Δaz_res (polar cell, range r
  = |p − site| over all coordinates, azimuth az = atan2(y − y_s, x − x_s) in the first two,
  counter-clockwise from the x axis, rad), or Δpᵀ E⁻¹ Δp < 1 (Cartesian resolution
  ellipse with shape matrix E, semi-axes the square roots of its eigenvalues, m);
* with the predictions N(m_i, K_i), the difference is Gaussian: Δp ~ N(m_i − m_j,
  K_i + K_j) in Cartesian coordinates, linearised in polar ones:
  Δ(r, az) ~ N(h(m_i) − h(m_j), J_i K_i J_iᵀ + J_j K_j J_jᵀ) (J = ∂h/∂p at the
  prediction, the azimuth difference wrapped to (−π, π]); the pair probability u_ij is
  that Gaussian's mass on the cell, by Gauss–Legendre quadrature (deterministic, smooth in
  the inputs; :meth:`Resolution.pair_probabilities`);
* the returns of the scene merge along chains of unresolved pairs (the sensor's plot
  extraction joins adjacent cells), pairs taken independent: the unresolved variant π is
  the set of connected components of the random graph with edge probabilities u_ij. Then
  P(π) = Π_{S∈π} P_conn(S) · Π_{i,j in different blocks}(1 − u_ij) exactly; with
  C = Σ_{i<j} ln(1 − u_ij) (the same for every π):

  .. math::
      \ln P(\pi) = C + \sum_{S\in\pi} \ln w(S),\quad
      w(S) = P_{conn}(S) / \prod_{i<j\in S}(1 - u_{ij});

  the prior decomposes over blocks and the MILP stays one exact MILP (a block's column cost
  gets ln w(S); C is dropped from the score, like any constant).
* P_conn(S) is computed exactly for that model (:func:`connected_probability`: up to
  five members the sum over the connected edge subsets, positive terms only; from six on
  the recursion over the first member's component, memoised over subsets, and where it
  would lose its digits to cancellation -- an almost surely resolved group, P_conn below
  ~2^|S|·1e-10 -- the lower bound max_T Π_{e∈T} u_e over spanning trees). The only
  approximation is the independence of the pairs (they share the members' positions):
  for a cross-range chain of three at 90 km (σ 50 m × 150 m, cell 500 m × 1.4°) P_conn is
  0.9994 vs 0.9956 by Monte Carlo at 700 m spacing, 0.597 vs 0.530 at 1000 m (see the
  notes). Summed over every π, P(π) = 1 (≤ 1 where the max-tree bound is used).

The paper's constant ρ is the special case of a pair odds u_ij/(1 − u_ij) = ρ for every
pair with groups of at most two objects (``max_group_size = 2``): then ln w(S) = ln ρ =
(|S| − 1) ln ρ, the paper's prior, and the scores equal the constant-ρ ones up to C. For
larger groups the constant model's ρ^{|S|−1} is one chain's weight, while w(S) counts
every connected graph on S (3ρ² + ρ³ for a triple with equal pairs).

Merged measurement (centroid): N(x_i; Σ_{j∈S} w_j m_j, Σ_{j∈S} w_j² K_j + R_i), weights
equal (1/|S|) or proportional to given per-object amplitudes a_j (w_j = a_j / Σ_{k∈S} a_k).

Holds :class:`Resolution`, :func:`connected_probability`, :func:`log_group_weight`,
:func:`polar_measurement_covs`, :func:`cartesian_to_polar`, :func:`polar_to_cartesian`,
and the quadratures :func:`_box_probability`, :func:`_ball_probability`.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import ndtr, ndtri
from scipy.stats import chi2

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_finite_array,
    as_positive,
    check_spd,
    check_spd_stack,
)

#: Pair probabilities are clipped to [U_FLOOR, 1 − U_CEIL_GAP]: every block weight stays
#: finite (a group below the floor never beats its resolved alternative in practice).
U_FLOOR = 1e-100
U_CEIL_GAP = 1e-12
#: Gauss–Legendre nodes per integration level, and the window (± this many standard
#: deviations) of the outer Gaussian.
_NODES = 96
_WINDOW = 9.0
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_NODES)
#: A pair whose unresolved probability u_ij is proven (by :func:`pair_bounds`) to be at most
#: this is *neglected*: treated as resolved (u_ij = U_FLOOR), no quadrature, and no candidate
#: group joins it. The prior mass of every unresolved variant that merges a neglected pair
#: is at most Σ_neglected u_ij ≤ PAIR_NEGLECT · Q(Q − 1)/2 (4.5e-8 at Q = 3000).
PAIR_NEGLECT = 1e-15
#: Work memory of one quadrature batch (bytes): the pairs are integrated in chunks of this
#: size; the dense (Q, Q) table of :meth:`Resolution.pair_probabilities` is refused above
#: MAX_PAIR_TABLE_BYTES (a ProblemError naming the remedy, never a raw MemoryError).
QUADRATURE_BYTES = 64 * 2**20
MAX_PAIR_TABLE_BYTES = 2 * 2**30


@functools.lru_cache(maxsize=64)
def _chi_quantile(eps: float, d: int) -> float:
    """t with P(χ²_d > t²) = eps (scipy.stats is slow to call: cached)."""
    return float(np.sqrt(chi2.isf(eps, d)))


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


def cartesian_to_polar(points: FloatArray, site: FloatArray) -> FloatArray:
    """(N, d ≥ 2) Cartesian points (m) → (N, 2) range (m, over all coordinates) and
    azimuth atan2(y − y_s, x − x_s) (rad, counter-clockwise from the x axis).

    Raises
    ------
    ProblemError
        Naming the argument: ``points`` not (N, d ≥ 2) finite, ``site`` not (d,) finite.
    """
    pts = as_finite_array("assignment.cartesian_to_polar points", points, ndim=2)
    if pts.shape[1] < 2:
        raise ProblemError(
            f"assignment.cartesian_to_polar points: expected (N, d ≥ 2), got {pts.shape}"
        )
    s = as_finite_array("assignment.cartesian_to_polar site", site, shape=(pts.shape[1],))
    return _cartesian_to_polar(pts, s)


def _cartesian_to_polar(points: FloatArray, site: FloatArray) -> FloatArray:
    """:func:`cartesian_to_polar` without the checks (the model's own calls)."""
    dp = np.asarray(points, dtype=float) - site
    return np.column_stack([np.linalg.norm(dp, axis=1), np.arctan2(dp[:, 1], dp[:, 0])])


def polar_to_cartesian(polar: FloatArray, site: FloatArray) -> FloatArray:
    """(N, 2) range (m) and azimuth (rad, counter-clockwise from the x axis) → (N, 2)
    Cartesian points (m) around the 2-D ``site``."""
    w = "assignment.polar_to_cartesian"
    pol = as_finite_array(f"{w} polar", polar, ndim=2)
    s = as_finite_array(f"{w} site", site, shape=(2,))
    if pol.shape[1] != 2:
        raise ProblemError(f"{w} polar: expected (N, 2) range, azimuth; got {pol.shape}")
    return s + pol[:, :1] * np.column_stack([np.cos(pol[:, 1]), np.sin(pol[:, 1])])


def _polar_jacobian(points: FloatArray, site: FloatArray) -> FloatArray:
    """∂(r, az)/∂p (N, 2, d) at Cartesian points (N, d)."""
    dp = points - site
    r = np.linalg.norm(dp, axis=1)
    rho2 = dp[:, 0] ** 2 + dp[:, 1] ** 2
    jac = np.zeros((len(dp), 2, dp.shape[1]))
    jac[:, 0, :] = dp / r[:, None]
    jac[:, 1, 0] = -dp[:, 1] / rho2
    jac[:, 1, 1] = dp[:, 0] / rho2
    return jac


def polar_measurement_covs(
    measurements: Any,
    site: Any,
    sigma_range: Any,
    sigma_azimuth: Any,
    *,
    coordinates: str = "cartesian",
) -> FloatArray:
    """Cartesian covariances R_i (N, 2, 2) of 2-D polar measurements, each converted with
    its own Jacobian: R_i = G_i diag(σ_r², σ_az²) G_iᵀ, G_i = ∂(x, y)/∂(r, az) =
    [[cos az, −r sin az], [sin az, r cos az]] at the measurement (first-order; the
    neglected bias is O(σ_az²) relative).

    Parameters
    ----------
    measurements : (N, 2)
        Cartesian points (m) or, with ``coordinates="polar"``, range (m) and azimuth (rad,
        counter-clockwise from the x axis).
    site : (2,)
        The sensor's position, m, in the measurements' Cartesian frame.
    sigma_range : float
        Range standard deviation, m (> 0).
    sigma_azimuth : float
        Azimuth standard deviation, rad (> 0).
    coordinates : {"cartesian", "polar"}
    """
    w = "assignment.polar_measurement_covs"
    kind = as_choice(f"{w} coordinates", coordinates, ("cartesian", "polar"))
    meas = as_finite_array(f"{w} measurements", measurements, ndim=2)
    if meas.shape[1] != 2:
        raise ProblemError(f"{w} measurements: expected (N, 2), got {meas.shape}")
    s = as_finite_array(f"{w} site", site, shape=(2,))
    sr = as_positive(f"{w} sigma_range (m)", sigma_range)
    sa = as_positive(f"{w} sigma_azimuth (rad)", sigma_azimuth)
    if sa > 0.5:  # ~29°: no radar's angle noise; found by review (10 "rad" accepted)
        raise ProblemError(
            f"{w} sigma_azimuth (rad): {sa:g} rad is {np.rad2deg(sa):.3g}°, "
            "not an angle noise (degrees given as radians?)"
        )
    if kind == "cartesian":
        pol = _cartesian_to_polar(meas, s)
    else:
        pol = meas
        if np.any(pol[:, 0] < 0):
            raise ProblemError(f"{w} measurements: a negative range")
    if np.any(pol[:, 0] <= 0):
        raise ProblemError(
            f"{w} measurements: a measurement at the sensor's site (range 0: no azimuth)"
        )
    r, az = pol[:, 0], pol[:, 1]
    g = np.empty((len(r), 2, 2))
    g[:, 0, 0], g[:, 0, 1] = np.cos(az), -r * np.sin(az)
    g[:, 1, 0], g[:, 1, 1] = np.sin(az), r * np.cos(az)
    d = np.array([sr**2, sa**2])
    out = np.einsum("nij,j,nkj->nik", g, d, g)
    return 0.5 * (out + out.transpose(0, 2, 1))


class Resolution:
    """A sensor's resolution cell (units SI; angles in rad).

    Parameters
    ----------
    range : float, optional
        Range resolution Δr_res, m (> 0); with ``azimuth``: the polar cell
        |Δr| < range, |Δaz| < azimuth.
    azimuth : float, optional
        Azimuth resolution Δaz_res, rad, in (0, π].
    site : (d,), optional
        The sensor's position in the measurement frame, m (default the origin).
    ellipse : (d, d), optional
        Instead of the polar cell: a Cartesian resolution ellipse, shape matrix E (SPD, m²):
        a pair is unresolved when Δpᵀ E⁻¹ Δp < 1.
    weights : "equal" or (Q,) array
        The merged return's centroid weights: equal, or proportional to these positive
        per-object amplitudes (w_j = a_j / Σ_{k∈S} a_k).
    """

    def __init__(
        self,
        range: Any = None,
        azimuth: Any = None,
        site: Any = None,
        ellipse: Any = None,
        weights: Any = "equal",
    ) -> None:
        w = "assignment.Resolution"
        polar = range is not None or azimuth is not None
        if polar and ellipse is not None:
            raise ProblemError(f"{w}: give range and azimuth (a polar cell) or ellipse, not both")
        if not polar and ellipse is None:
            raise ProblemError(f"{w}: give range and azimuth (a polar cell) or ellipse")
        self.range: float | None = None
        self.azimuth: float | None = None
        self.ellipse: FloatArray | None = None
        self.site: FloatArray | None = None
        if polar:
            if range is None or azimuth is None:
                raise ProblemError(f"{w}: a polar cell needs both range (m) and azimuth (rad)")
            self.range = as_positive(f"{w} range (m)", range)
            self.azimuth = as_positive(f"{w} azimuth (rad)", azimuth)
            if self.azimuth > math.pi:
                raise ProblemError(
                    f"{w} azimuth (rad): expected at most π, got "
                    f"{self.azimuth:g} (degrees given as radians?)"
                )
            if site is not None:
                self.site = as_finite_array(f"{w} site (m)", site, ndim=1)
                if self.site.shape[0] < 2:
                    raise ProblemError(
                        f"{w} site (m): expected (d,) with d ≥ 2, got {self.site.shape}"
                    )
        else:
            if site is not None:
                raise ProblemError(f"{w} site: only for a polar cell (an ellipse is Cartesian)")
            self.ellipse = as_finite_array(f"{w} ellipse (m²)", ellipse, ndim=2)
            check_spd(f"{w} ellipse (m²)", self.ellipse)
        if isinstance(weights, str):
            as_choice(f"{w} weights", weights, ("equal",))
            self.weights: str | FloatArray = "equal"
        else:
            self.weights = as_finite_array(f"{w} weights", weights, ndim=1)
            if np.any(self.weights <= 0):
                raise ProblemError(f"{w} weights: amplitudes must be positive")

    def __repr__(self) -> str:
        if self.ellipse is not None:
            return f"Resolution(ellipse={self.ellipse.tolist()}, weights={self._wtext()})"
        site = None if self.site is None else self.site.tolist()
        return (
            f"Resolution(range={self.range}, azimuth={self.azimuth}, site={site}, "
            f"weights={self._wtext()})"
        )

    def _wtext(self) -> str:
        return "'equal'" if isinstance(self.weights, str) else str(self.weights.tolist())

    @property
    def polar(self) -> bool:
        return self.ellipse is None

    def _check(self, where: str, d: int, q: int | None = None) -> None:
        """The dimension (and the number of weights) against a scene's."""
        if self.polar:
            if d < 2:
                raise ProblemError(f"{where}: a polar resolution cell needs d ≥ 2, got d = {d}")
            if self.site is not None and self.site.shape != (d,):
                raise ProblemError(
                    f"{where}: site (m) has shape {self.site.shape}, the scene d = {d}"
                )
        elif self.ellipse is not None and self.ellipse.shape != (d, d):
            raise ProblemError(
                f"{where}: ellipse (m²) has shape {self.ellipse.shape}, the scene d = {d}"
            )
        if q is not None and not isinstance(self.weights, str) and self.weights.shape != (q,):
            raise ProblemError(
                f"{where}: weights has {self.weights.shape[0]} amplitudes, "
                f"expected one per object ({q})"
            )

    def centroid_weights(self, group: tuple[int, ...]) -> FloatArray:
        """The centroid weights w_j (summing to 1) of the group's members."""
        if isinstance(self.weights, str):
            return np.full(len(group), 1.0 / len(group))
        a = self.weights[list(group)]
        return a / a.sum()

    def pair_probabilities(self, means: Any, covs: Any) -> FloatArray:
        """u_ij (Q, Q), the probability that objects i and j are unresolved (module
        docstring), clipped to [U_FLOOR, 1 − U_CEIL_GAP]; the diagonal is 1."""
        w = "assignment.Resolution.pair_probabilities"
        m = as_finite_array(f"{w} means", means, ndim=2)
        q, d = m.shape
        k = as_finite_array(f"{w} covs", covs, shape=(q, d, d))
        check_spd_stack(f"{w} covs", k)
        self._check(w, d)
        if q * q * 8 > MAX_PAIR_TABLE_BYTES:
            raise ProblemError(
                f"{w}: the dense (Q, Q) table for Q = {q} needs {q * q * 8 / 2**30:.3g} "
                f"GiB (limit {MAX_PAIR_TABLE_BYTES / 2**30:.3g} GiB); use "
                f"Resolution.gated_pairs (the pairs that can be unresolved, as "
                f"AssignmentData does)"
            )
        out = np.eye(q)
        if q < 2:
            return out
        pos, kk = self._frame(m, k, w)
        ii, jj = np.triu_indices(q, 1)
        u = self._pair_u(pos, kk, ii, jj)
        out[ii, jj] = out[jj, ii] = u
        return out

    def _frame(self, m: FloatArray, k: FloatArray, w: str) -> tuple[FloatArray, FloatArray]:
        """The objects in the cell's frame: polar (range, azimuth) and J K Jᵀ, or the
        whitened positions E^{-1/2} m and E^{-1/2} K E^{-1/2}."""
        d = m.shape[1]
        if self.polar:
            site = np.zeros(d) if self.site is None else self.site
            if np.any(np.linalg.norm(m - site, axis=1) <= 0):
                raise ProblemError(f"{w} means: a prediction at the sensor's site (no azimuth)")
            jac = _polar_jacobian(m, site)
            return _cartesian_to_polar(m, site), jac @ k @ jac.transpose(0, 2, 1)
        ew, ev = np.linalg.eigh(self.ellipse)
        white = ev @ np.diag(ew**-0.5) @ ev.T  # E^{-1/2}
        return m @ white.T, white @ k @ white.T

    def _pair_u(
        self, pos: FloatArray, kk: FloatArray, ii: FloatArray, jj: FloatArray
    ) -> FloatArray:
        """The quadrature u_ij of the pairs (ii, jj) in the frame of :meth:`_frame`,
        chunked (:data:`QUADRATURE_BYTES` of work arrays per batch), clipped."""
        u = np.empty(len(ii))
        if not len(ii):
            return u
        d = pos.shape[1]
        if self.polar:
            half = np.array([self.range, self.azimuth])
            for sl in _chunks(len(ii), 12 * _NODES * 8):
                a, b = ii[sl], jj[sl]
                mu = pos[a] - pos[b]
                mu[:, 1] = (mu[:, 1] + math.pi) % (2 * math.pi) - math.pi
                u[sl] = _box_probability(mu, kk[a] + kk[b], half)
        else:
            for sl in _chunks(len(ii), 12 * _NODES ** max(1, d - 1) * 8):
                a, b = ii[sl], jj[sl]
                lam, vec = np.linalg.eigh(kk[a] + kk[b])  # ascending: the narrowest first
                nu = np.einsum("pdk,pd->pk", vec, pos[a] - pos[b])
                u[sl] = _ball_probability(nu, np.sqrt(lam), np.ones((len(a), 1)))[:, 0]
        return np.clip(u, U_FLOOR, 1.0 - U_CEIL_GAP)

    def pair_bounds(self, means: Any, covs: Any, ii: Any, jj: Any) -> FloatArray:
        """Upper bounds b_ij ≥ u_ij of the pairs (ii, jj), in closed form (no quadrature).

        Polar cell: u_ij ≤ P(|Δr| < Δr_res) ≤ Φ((Δr_res − |μ_r|)/σ_r), and the same in
        azimuth; b_ij is the smaller (μ, σ² the predicted difference's mean and variance
        in that coordinate). Ellipse: with Δ' = E^{-1/2}Δ ~ N(μ', C'), u_ij = P(‖Δ'‖ < 1)
        ≤ P(χ²_d > (‖μ'‖ − 1)²/(λ_max(C'_i) + λ_max(C'_j))) for ‖μ'‖ > 1 (else 1)."""
        w = "assignment.Resolution.pair_bounds"
        m = as_finite_array(f"{w} means", means, ndim=2)
        q, d = m.shape
        k = as_finite_array(f"{w} covs", covs, shape=(q, d, d))
        self._check(w, d)
        pos, kk = self._frame(m, k, w)
        return self._bounds(pos, kk, np.asarray(ii, dtype=int), np.asarray(jj, dtype=int))

    def _bounds(
        self, pos: FloatArray, kk: FloatArray, ii: np.ndarray, jj: np.ndarray
    ) -> FloatArray:
        d = pos.shape[1]
        if self.polar:
            mu = pos[ii] - pos[jj]
            mu[:, 1] = (mu[:, 1] + math.pi) % (2 * math.pi) - math.pi
            sd = np.sqrt(
                np.stack([kk[ii, 0, 0] + kk[jj, 0, 0], kk[ii, 1, 1] + kk[jj, 1, 1]], axis=1)
            )
            half = np.array([self.range, self.azimuth])
            return ndtr((half - np.abs(mu)) / sd).min(axis=1)
        lam = np.linalg.eigvalsh(kk)[:, -1]
        gap = np.maximum(np.linalg.norm(pos[ii] - pos[jj], axis=1) - 1.0, 0.0)
        out = chi2.sf(gap**2 / (lam[ii] + lam[jj]), d)
        return np.where(gap > 0, out, 1.0)

    def gated_pairs(
        self, means: Any, covs: Any, *, neglect: float = PAIR_NEGLECT
    ) -> tuple[np.ndarray, np.ndarray, FloatArray]:
        """The pairs that can be unresolved, found without visiting all Q(Q − 1)/2: the
        pairs (i < j) whose bound :meth:`pair_bounds` exceeds ``neglect``, with their
        quadrature u_ij (as :meth:`pair_probabilities`); every other pair has
        u_ij ≤ ``neglect`` (proven, not estimated).

        Candidates come from a k-d tree (:class:`scipy.spatial.cKDTree`). Polar cell: the
        points r_i (cos az_i, sin az_i) are at distance D_ij with D² = μ_r² +
        4 r_i r_j sin²(μ_az/2) ≤ (|μ_r| + r_max |μ_az|)²; a bound above ``neglect`` needs
        |μ_r| < Δr_res + t σ_r and |μ_az| < Δaz_res + t σ_az (t = Φ⁻¹(1 − neglect)), with
        σ ≤ σ_i + σ_j, so D_ij < c₀ + a_i + a_j (c₀ = Δr_res + r_max Δaz_res,
        a_i = t (σ_{r,i} + r_max σ_{az,i})). Ellipse: whitened points, ‖μ'‖ < 1 +
        t_d (σ_i + σ_j) with t_d² the χ²_d quantile of 1 − neglect. The tree returns the
        pairs within c₀ + 2 max a_i; the per-pair radius and then the bound filter them.

        Returns
        -------
        ii, jj : (P,) int, i < j
        u : (P,) float, clipped to [U_FLOOR, 1 − U_CEIL_GAP]
        """
        w = "assignment.Resolution.gated_pairs"
        m = as_finite_array(f"{w} means", means, ndim=2)
        q, d = m.shape
        k = as_finite_array(f"{w} covs", covs, shape=(q, d, d))
        check_spd_stack(f"{w} covs", k)
        self._check(w, d)
        eps = float(neglect)
        if not 0.0 < eps < 0.5:
            raise ProblemError(f"{w} neglect: expected a probability in (0, 0.5), got {eps}")
        return self._gated_pairs(w, m, k, eps)

    def _gated_pairs(
        self, w: str, m: FloatArray, k: FloatArray, eps: float
    ) -> tuple[np.ndarray, np.ndarray, FloatArray]:
        """:meth:`gated_pairs` on checked arrays."""
        q, d = m.shape
        empty = np.zeros(0, dtype=int)
        if q < 2:
            return empty, empty.copy(), np.zeros(0)
        pos, kk = self._frame(m, k, w)
        if self.polar:
            t = float(-ndtri(eps))
            r = pos[:, 0]
            pts = r[:, None] * np.column_stack([np.cos(pos[:, 1]), np.sin(pos[:, 1])])
            rmax = float(r.max())
            c0 = self.range + rmax * self.azimuth
            a = t * (np.sqrt(kk[:, 0, 0]) + rmax * np.sqrt(kk[:, 1, 1]))
        else:
            t = _chi_quantile(eps, d)
            pts = pos
            c0 = 1.0
            a = t * np.sqrt(np.linalg.eigvalsh(kk)[:, -1])
        if q <= 64:  # all pairs directly: cheaper than building a tree (measured, ~60 µs)
            iu = np.triu_indices(q, 1)
            cand = np.column_stack(iu)
        else:
            tree = cKDTree(pts)
            cand = tree.query_pairs(c0 + 2.0 * float(a.max()), output_type="ndarray")
        if len(cand) == 0:
            return empty, empty.copy(), np.zeros(0)
        ii, jj = np.minimum(cand[:, 0], cand[:, 1]), np.maximum(cand[:, 0], cand[:, 1])
        dist = np.linalg.norm(pts[ii] - pts[jj], axis=1)
        near = dist < c0 + a[ii] + a[jj]
        ii, jj = ii[near], jj[near]
        keep = self._bounds(pos, kk, ii, jj) > eps
        ii, jj = ii[keep], jj[keep]
        order = np.lexsort((jj, ii))
        ii, jj = ii[order], jj[order]
        return ii, jj, self._pair_u(pos, kk, ii, jj)

    def unresolved_probability(self, means: Any, covs: Any) -> float:
        """The probability that the k objects (means (k, d), m; covs (k, d, d), m²) give
        one merged return: 1 for k = 1, u_12 for a pair (the mass of the predicted
        difference on the cell), for k ≥ 3 the probability that they form one chain of
        unresolved pairs, pairs independent (:func:`connected_probability`)."""
        m = as_finite_array("assignment.Resolution.unresolved_probability means", means, ndim=2)
        u = self.pair_probabilities(m, covs)
        group = tuple(range(m.shape[0]))
        return connected_probability(u, group)


def log_not_merged(u: FloatArray, group: tuple[int, ...]) -> float:
    """Σ_{i<j∈S} ln(1 − u_ij)."""
    idx = list(group)
    sub = u[np.ix_(idx, idx)]
    return float(np.sum(np.log1p(-sub[np.triu_indices(len(idx), 1)])))


def _log_max_tree(u: FloatArray, group: tuple[int, ...]) -> float:
    """ln max_T Π_{e∈T} u_e over the spanning trees T of S (Prim's algorithm on ln u): the
    probability that the most likely tree's pairs are all unresolved, a lower bound on
    P_conn(S) within a factor of the number of trees (≤ |S|^{|S|−2}); no cancellation."""
    idx = list(group)
    lu = np.log(u[np.ix_(idx, idx)])
    k = len(idx)
    done = np.zeros(k, dtype=bool)
    done[0] = True
    best = lu[0].copy()
    total = 0.0
    for _ in range(k - 1):
        cand = np.where(done, -np.inf, best)
        j = int(np.argmax(cand))
        total += float(cand[j])
        done[j] = True
        best = np.maximum(best, lu[j])
    return total


#: Groups up to this size: P_conn by the sum over the connected edge subsets (positive
#: terms, exact to rounding whatever the u_ij); larger ones by the recursion.
_ENUMERATE_UP_TO = 5
#: The recursion 1 − Σ is trusted above this many times its rounding bound 2^|S|·1e-16;
#: below (an almost surely resolved group) the max-tree lower bound is used.
_CANCEL_MARGIN = 1e6
_CONNECTED_SUBSETS: dict[int, tuple[np.ndarray, list[tuple[int, int]]]] = {}


def _connected_subsets(k: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The edge subsets (rows, boolean over the k(k−1)/2 pairs) that connect k nodes."""
    if k not in _CONNECTED_SUBSETS:
        edges = [(i, j) for i in range(k) for j in range(i + 1, k)]
        rows = []
        for mask in range(2 ** len(edges)):
            parent = list(range(k))

            def find(a: int, parent: list[int] = parent) -> int:
                while parent[a] != a:
                    a = parent[a]
                return a

            on = [(mask >> e) & 1 for e in range(len(edges))]
            for (i, j), bit in zip(edges, on, strict=True):
                if bit:
                    parent[find(i)] = find(j)
            if len({find(i) for i in range(k)}) == 1:
                rows.append(on)
        _CONNECTED_SUBSETS[k] = (np.array(rows, dtype=bool), edges)
    return _CONNECTED_SUBSETS[k]


def connected_probability(
    u: FloatArray, group: tuple[int, ...], memo: dict[Any, float] | None = None
) -> float:
    """P_conn(S): the probability that the members of S form one chain of unresolved
    pairs (the random graph on S with independent edges u_ij is connected).

    |S| ≤ 5: the sum over the connected edge subsets of S of Π u_e Π (1 − u_e) (at most
    728 positive terms: exact to rounding). |S| ≥ 6: the recursion over the component T
    of S's first member, P_conn(S) = 1 − Σ_{T∋s₁, T⊊S} P_conn(T) Π_{i∈T, j∈S∖T}(1 − u_ij)
    (memoised over subsets in ``memo``, as logarithms keyed by bit mask); where it is within
    ``_CANCEL_MARGIN`` of its rounding bound (an almost surely resolved group) the
    max-tree lower bound :func:`_log_max_tree` is used instead."""
    return math.exp(_log_connected(u, tuple(group), {} if memo is None else memo))


def _log_connected(u: FloatArray, group: tuple[int, ...], memo: dict[Any, float]) -> float:
    """ln P_conn(S) (:func:`connected_probability`); ``memo`` maps the members' bit mask
    (Σ 2^j) to the value."""
    k = len(group)
    if k == 1:
        return 0.0
    if k == 2:
        return float(math.log(u[group[0], group[1]]))
    key = sum(1 << int(j) for j in group)
    got = memo.get(key)
    if got is not None:
        return got
    idx = np.array(group)
    if k <= _ENUMERATE_UP_TO:
        rows, edges = _connected_subsets(k)
        ue = np.array([u[idx[i], idx[j]] for i, j in edges])
        terms = rows @ np.log(ue) + (~rows) @ np.log1p(-ue)
        out = float(np.logaddexp.reduce(terms))
    else:
        sub = u[np.ix_(idx, idx)].copy()
        np.fill_diagonal(sub, 0.0)
        lg = np.log1p(-sub)
        masks = np.arange(2 ** (k - 1) - 1)  # the other members' subsets, not the full one
        inside = np.column_stack(
            [np.ones(len(masks), dtype=bool), (masks[:, None] >> np.arange(k - 1)) & 1]
        ).astype(bool)
        cut = np.einsum("mi,ij,mj->m", inside.astype(float), lg, (~inside).astype(float))
        bits = [1 << int(j) for j in idx]
        keys = (inside.astype(object) @ np.array(bits, dtype=object)).tolist()
        parts = np.array(
            [
                memo[m] if m in memo else _log_connected(u, tuple(int(x) for x in idx[row]), memo)
                for m, row in zip(keys, inside, strict=True)
            ]
        )
        rec = -math.expm1(float(np.logaddexp.reduce(parts + cut)))
        low = _log_max_tree(u, group)
        if rec > _CANCEL_MARGIN * 1e-16 * 2.0**k:
            out = max(math.log(min(rec, 1.0)), low)
        else:
            out = low
    memo[key] = out
    return out


def log_group_weight(
    u: FloatArray, group: tuple[int, ...], memo: dict[Any, float] | None = None
) -> float:
    """ln w(S) = ln P_conn(S) − Σ_{i<j∈S} ln(1 − u_ij): the block's share of ln P(π)
    (module docstring); 0 for a singleton, ln(u_ij/(1 − u_ij)) for a pair."""
    if len(group) == 1:
        return 0.0
    if len(group) == 2:
        v = u[group[0], group[1]]
        return float(math.log(v) - math.log1p(-v))
    return _log_connected(u, tuple(group), {} if memo is None else memo) - log_not_merged(u, group)
