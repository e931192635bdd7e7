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
* P_conn(S) is computed exactly for that model, and the paper's constant ρ is the special
  case of equal pair odds: :mod:`~optmodels.assignment.merge_prior`.

Merged measurement (centroid): N(x_i; Σ_{j∈S} w_j m_j, Σ_{j∈S} w_j² K_j + R_i), weights
equal (1/|S|) or proportional to given per-object amplitudes a_j (w_j = a_j / Σ_{k∈S} a_k).

Holds :class:`Resolution` (the pair probabilities, their closed-form bounds and the gated
pairs), :class:`PairTable` (the gated pairs' u_ij, indexed like the dense table) and the
constants of the model's gate. The quadratures are in
:mod:`~optmodels.assignment.quadrature`, the polar coordinates in
:mod:`~optmodels.assignment.polar`.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import ndtr, ndtri
from scipy.stats import chi2

from optmodels.assignment.merge_prior import connected_probability
from optmodels.assignment.polar import _cartesian_to_polar, _polar_jacobian
from optmodels.assignment.quadrature import (
    _NODES,
    _ball_probability,
    _box_probability,
    _chunks,
)
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
#: A pair whose unresolved probability u_ij is proven (by :func:`pair_bounds`) to be at most
#: this is *neglected*: treated as resolved (u_ij = U_FLOOR), no quadrature, and no candidate
#: group joins it. The prior mass of every unresolved variant that merges a neglected pair
#: is at most Σ_neglected u_ij ≤ PAIR_NEGLECT · Q(Q − 1)/2 (4.5e-8 at Q = 3000).
PAIR_NEGLECT = 1e-15
#: The dense (Q, Q) table of :meth:`Resolution.pair_probabilities` is refused above this
#: many bytes (a ProblemError naming the remedy, never a raw MemoryError).
MAX_PAIR_TABLE_BYTES = 2 * 2**30


@functools.lru_cache(maxsize=64)
def _chi_quantile(eps: float, d: int) -> float:
    """t with P(χ²_d > t²) = eps (scipy.stats is slow to call: cached)."""
    return float(np.sqrt(chi2.isf(eps, d)))


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

    def _cell(self) -> tuple[float, float]:
        """The polar cell's half-widths (Δr_res m, Δaz_res rad) (a polar cell has both)."""
        assert self.range is not None and self.azimuth is not None, "not a polar cell"
        return self.range, self.azimuth

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
        if self.ellipse is None:  # a polar cell
            site = np.zeros(d) if self.site is None else self.site
            if np.any(np.linalg.norm(m - site, axis=1) <= 0):
                raise ProblemError(f"{w} means: a prediction at the sensor's site (no azimuth)")
            jac = _polar_jacobian(m, site)
            return _cartesian_to_polar(m, site), jac @ k @ jac.transpose(0, 2, 1)
        ew, ev = np.linalg.eigh(self.ellipse)
        white = ev @ np.diag(ew**-0.5) @ ev.T  # E^{-1/2}
        return m @ white.T, white @ k @ white.T

    def _pair_u(
        self, pos: FloatArray, kk: FloatArray, ii: np.ndarray, jj: np.ndarray
    ) -> FloatArray:
        """The quadrature u_ij of the pairs (ii, jj) in the frame of :meth:`_frame`,
        chunked (:data:`QUADRATURE_BYTES` of work arrays per batch), clipped."""
        u = np.empty(len(ii))
        if not len(ii):
            return u
        d = pos.shape[1]
        if self.polar:
            half = np.array(self._cell())
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
            half = np.array(self._cell())
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
            cell_r, cell_az = self._cell()
            c0 = cell_r + rmax * cell_az
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


# ----------------------------------------------------------------------------- pairs
class PairTable:
    """The sensor's pair probabilities u_ij stored for the gated pairs only
    (:meth:`~optmodels.assignment.sensor.Resolution.gated_pairs`); every other pair is
    neglected (u_ij ≤ PAIR_NEGLECT, read as U_FLOOR). Indexed like the dense (Q, Q) table
    (``u[i, j]``, ``u[np.ix_(a, b)]``), which is what the group weights read."""

    def __init__(self, q: int, ii: np.ndarray, jj: np.ndarray, u: FloatArray) -> None:
        self.q, self.ii, self.jj, self.u = q, ii, jj, u
        self._map = {(int(a), int(b)): float(v) for a, b, v in zip(ii, jj, u, strict=True)}

    @property
    def shape(self) -> tuple[int, int]:
        return (self.q, self.q)

    def _one(self, a: int, b: int) -> float:
        if a == b:
            return 1.0
        return self._map.get((a, b) if a < b else (b, a), U_FLOOR)

    def __getitem__(self, key: Any) -> Any:
        rows, cols = key
        if np.ndim(rows) == 0 and np.ndim(cols) == 0:
            return self._one(int(rows), int(cols))
        r, c = np.broadcast_arrays(np.asarray(rows, dtype=int), np.asarray(cols, dtype=int))
        return np.array(
            [self._one(a, b) for a, b in zip(r.ravel().tolist(), c.ravel().tolist(), strict=True)]
        ).reshape(r.shape)

    def edges(self, neglect: float = PAIR_NEGLECT) -> tuple[np.ndarray, np.ndarray]:
        """The pairs (i < j) with u_ij above ``neglect``: the edges of the gating graph."""
        on = self.u > neglect
        return self.ii[on], self.jj[on]

    def log_not_merged_total(self) -> float:
        """Σ_{i<j} ln(1 − u_ij) over every pair (the neglected ones at U_FLOOR)."""
        rest = self.q * (self.q - 1) // 2 - len(self.u)
        return float(np.sum(np.log1p(-self.u)) + rest * math.log1p(-U_FLOOR))

    def dense(self, where: str) -> FloatArray:
        """The (Q, Q) table (diagonal 1), refused above MAX_PAIR_TABLE_BYTES."""
        if self.q * self.q * 8 > MAX_PAIR_TABLE_BYTES:
            raise ProblemError(
                f"{where}: the dense (Q, Q) table for Q = {self.q} needs "
                f"{self.q * self.q * 8 / 2**30:.3g} GiB; read the gated pairs "
                f"from AssignmentData.pair_table instead"
            )
        out = np.full((self.q, self.q), U_FLOOR)
        np.fill_diagonal(out, 1.0)
        out[self.ii, self.jj] = out[self.jj, self.ii] = self.u
        return out


def _dense_edges(u: FloatArray, neglect: float = PAIR_NEGLECT) -> tuple[np.ndarray, np.ndarray]:
    ii, jj = np.triu_indices(u.shape[0], 1)
    on = u[ii, jj] > neglect
    return ii[on], jj[on]
