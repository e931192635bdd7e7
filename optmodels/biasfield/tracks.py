r"""Track fitting (paper 001, (3) and section 3): per radar and object, the biased motion
ξ_i^a(t) = x^a(t) + s_i(x^a(t)) as a polyline g(t)θ with knots at fixed times, fitted to
the radar's plots by generalised least squares with the plot covariances V_i.

A polyline with knots τ_0 < … < τ_K is Σ_k h_k(t)θ_k with hat functions h_k; θ_k ∈ R² is
the position at τ_k. With plots z_j at t_j and Cartesian covariances V_j (first order,
evaluated at the plot), the GLS estimate solves

.. math::
    \min_\theta \sum_j (z_j - g(t_j)\theta)^T V_j^{-1} (z_j - g(t_j)\theta),\qquad
    \operatorname{Cov}\hat\theta = \Big(\sum_j g(t_j)^T V_j^{-1} g(t_j)\Big)^{-1}.

Interior knots are the multiples of ``knot_spacing`` (absolute times, the same for every
radar observing an object, so that the interpolation error of a curved path is nearly
common to all radars -- and a common shift is invisible to the bias field anyway); the end
knots are the first and last plots, so a fit is never evaluated beyond its data. A track is split
where plots are more than ``max_gap`` apart; a piece with fewer plots than its polyline
has parameters (plus ``min_redundancy``) is dropped and reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

from optmodels.biasfield.data import PlotTable, RadarSet
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_positive,
)

__all__ = ["ResidualCheck", "TrackFit", "fit_tracks", "hat_basis", "residual_check"]


def hat_basis(t: ArrayLike, knots: FloatArray) -> FloatArray:
    """(T, K) hat-function values h_k(t) of the polyline with these knots (t inside;
    knots strictly increasing, s)."""
    tt = as_finite_array("biasfield.hat_basis t", t, ndim=(0, 1),
                         max_abs=MAX_MAGNITUDE).reshape(-1)
    knots = as_finite_array("biasfield.hat_basis knots", knots, ndim=1, max_abs=MAX_MAGNITUDE)
    if knots.size < 2 or np.any(np.diff(knots) <= 0):
        raise ProblemError("biasfield.hat_basis knots: need ≥ 2 strictly increasing knots, "
                           f"got {knots.size}")
    k = np.clip(np.searchsorted(knots, tt, side="right") - 1, 0, len(knots) - 2)
    u = (tt - knots[k]) / (knots[k + 1] - knots[k])
    out = np.zeros((tt.size, len(knots)))
    rows = np.arange(tt.size)
    out[rows, k] = 1.0 - u
    out[rows, k + 1] = u
    return out


@dataclass
class TrackFit:
    """One radar's fitted polyline for one object over [knots[0], knots[-1]].

    ``theta`` (K, 2) positions at the knots; ``cov`` (2K, 2K) covariance of
    ``theta.ravel()`` (x0, y0, x1, y1, …); ``rows`` the indices of the plots used;
    ``chi2`` the GLS residual sum Σ rᵀV⁻¹r with ``dof`` = 2n − 2K degrees of freedom;
    ``whitened`` (n, 2) residuals V^{-1/2}(z − ξ̂) (zero mean, unit covariance if the
    motion model and V are right).
    """

    radar: int
    object: int
    knots: FloatArray
    theta: FloatArray
    cov: FloatArray
    rows: np.ndarray
    chi2: float
    dof: int
    whitened: FloatArray = field(repr=False)

    @property
    def span(self) -> tuple[float, float]:
        return float(self.knots[0]), float(self.knots[-1])

    def at(self, t: ArrayLike) -> FloatArray:
        """ξ̂(t), (T, 2), for t inside the span."""
        return hat_basis(t, self.knots) @ self.theta

    def cov_at(self, t: ArrayLike) -> FloatArray:
        """Cov ξ̂(t), (T, 2, 2)."""
        g = self._design(t)
        return np.einsum("tia,ab,tjb->tij", g, self.cov, g)

    def mean_over(self, t: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Average of ξ̂ over the instants t and its covariance (exact: a linear function
        of θ̂)."""
        h = hat_basis(t, self.knots).mean(axis=0)
        g = np.kron(h[None, :], np.eye(2))
        return h @ self.theta, g @ self.cov @ g.T

    def _design(self, t: ArrayLike) -> FloatArray:
        h = hat_basis(t, self.knots)
        return np.einsum("tk,ij->tikj", h, np.eye(2)).reshape(h.shape[0], 2, -1)


@dataclass
class Dropped:
    """Plots not used, with the reason: ``counts`` reason → number of plots."""

    counts: dict[str, int] = field(default_factory=dict)

    def add(self, reason: str, n: int) -> None:
        if n:
            self.counts[reason] = self.counts.get(reason, 0) + int(n)

    @property
    def total(self) -> int:
        return sum(self.counts.values())


def _check_tables(where: str, plots: object, radars: object) -> None:
    """``plots`` a :class:`PlotTable` and ``radars`` a :class:`RadarSet`, or ProblemError."""
    if not isinstance(plots, PlotTable):
        raise ProblemError(f"{where} plots: expected a PlotTable (see biasfield.read_plots), "
                           f"got {type(plots).__name__}")
    if not isinstance(radars, RadarSet):
        raise ProblemError(f"{where} radars: expected a RadarSet (see biasfield.read_radars), "
                           f"got {type(radars).__name__}")


def _pieces(t: FloatArray, max_gap: float) -> list[np.ndarray]:
    cuts = np.flatnonzero(np.diff(t) > max_gap) + 1
    return np.split(np.arange(t.size), cuts)


def fit_tracks(plots: PlotTable, radars: RadarSet, *, knot_spacing: float = 20.0,
               max_gap: float | None = None, min_redundancy: int = 2
               ) -> tuple[list[TrackFit], Dropped]:
    """GLS polyline fits of every (radar, object) track of ``plots``.

    Plots with ``object == -1`` cannot be assigned to a track and are dropped (counted).
    ``max_gap`` (default ``knot_spacing``) splits tracks at longer silences; each piece
    gets knots at the multiples of ``knot_spacing`` that bracket it, and knots whose
    support holds no plot are removed (the polyline then spans the gap linearly). Returns
    the fits and the dropped-plot counts.
    """
    fn = "biasfield.fit_tracks"
    knot_spacing = as_positive(f"{fn} knot_spacing (s)", knot_spacing)
    gap = knot_spacing if max_gap is None else as_positive(f"{fn} max_gap (s)", max_gap)
    min_redundancy = as_count(f"{fn} min_redundancy", min_redundancy)
    _check_tables(fn, plots, radars)
    plots.check(radars)
    z_all = plots.cartesian(radars)
    dropped = Dropped()
    dropped.add("no object id", int(np.sum(plots.object < 0)))
    fits: list[TrackFit] = []
    for i in range(radars.m):
        sel_r = np.flatnonzero((plots.radar == i) & (plots.object >= 0))
        if sel_r.size == 0:
            continue
        vcov = radars.cartesian_cov(i, z_all[sel_r])
        vinv = np.linalg.inv(vcov)
        pos_in = {int(r): k for k, r in enumerate(sel_r)}
        for a in np.unique(plots.object[sel_r]):
            rows_a = sel_r[plots.object[sel_r] == a]
            rows_a = rows_a[np.argsort(plots.time[rows_a], kind="stable")]
            for piece in _pieces(plots.time[rows_a], gap):
                rows = rows_a[piece]
                fit = _fit_piece(i, int(a), rows, plots.time[rows], z_all[rows],
                                 vinv[[pos_in[int(r)] for r in rows]], knot_spacing,
                                 min_redundancy)
                if fit is None:
                    dropped.add("too few plots for the polyline", rows.size)
                else:
                    fits.append(fit)
    return fits, dropped


def _knots(t: FloatArray, spacing: float) -> FloatArray:
    """Knots of a piece: its first and last plot times, and the multiples of ``spacing``
    between them (the same absolute instants for every radar). Interior knots closer than
    spacing/2 to an end, or whose hat support carries less than half a plot of weight,
    are dropped (the polyline then spans them linearly): no knot is left to be determined
    by a stray plot at the far end of its support, and no position is ever extrapolated
    beyond the plots."""
    t0, t1 = float(t[0]), float(t[-1])
    if t1 - t0 < 1e-9:
        return np.array([t0, t0 + spacing])
    inner = np.arange(np.ceil(t0 / spacing), np.floor(t1 / spacing) + 1) * spacing
    inner = inner[(inner > t0 + 0.5 * spacing) & (inner < t1 - 0.5 * spacing)]
    knots = np.concatenate([[t0], inner, [t1]])
    while knots.size > 2:
        support = hat_basis(t, knots).sum(axis=0)
        weak = np.flatnonzero(support[1:-1] < 0.5) + 1
        if weak.size == 0:
            break
        knots = np.delete(knots, weak[np.argmin(support[weak])])
    return knots


def polyline_normal(t: FloatArray, knots: FloatArray, vinv: FloatArray, z: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Normal equations of the polyline GLS: N = Σ_j (h_j h_jᵀ) ⊗ V_j⁻¹ (2K, 2K),
    b = Σ_j h_j ⊗ V_j⁻¹z_j (θ row-major), and the hat values h (n, K). Each plot touches
    the two knots of its interval, so N is block-tridiagonal; it is assembled by scatter."""
    k = knots.size
    idx = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, k - 2)
    u = (t - knots[idx]) / (knots[idx + 1] - knots[idx])
    wts = np.column_stack([1.0 - u, u])
    nblk = np.zeros((k, k, 2, 2))
    bblk = np.zeros((k, 2))
    vz = np.einsum("nab,nb->na", vinv, z)
    for p_ in range(2):
        np.add.at(bblk, idx + p_, wts[:, p_, None] * vz)
        for q_ in range(2):
            np.add.at(nblk, (idx + p_, idx + q_), (wts[:, p_] * wts[:, q_])[:, None, None] * vinv)
    return nblk.transpose(0, 2, 1, 3).reshape(2 * k, 2 * k), bblk.reshape(-1), \
        hat_basis(t, knots)


def whiten(vinv: FloatArray, r: FloatArray) -> FloatArray:
    """Lᵀr with V⁻¹ = LLᵀ: residuals in noise units (unit covariance if V is right)."""
    return np.einsum("nab,na->nb", np.linalg.cholesky(vinv), r)


def _fit_piece(radar: int, obj: int, rows: np.ndarray, t: FloatArray, z: FloatArray,
               vinv: FloatArray, spacing: float, redundancy: int) -> TrackFit | None:
    knots = _knots(t, spacing)
    k = knots.size
    if 2 * t.size < 2 * k + redundancy:
        return None
    nmat, b, h = polyline_normal(t, knots, vinv, z)
    try:
        chol = linalg.cho_factor(nmat)
    except linalg.LinAlgError:
        return None
    theta = linalg.cho_solve(chol, b).reshape(k, 2)
    cov = linalg.cho_solve(chol, np.eye(2 * k))
    white = whiten(vinv, z - h @ theta)
    return TrackFit(radar, obj, knots, theta, 0.5 * (cov + cov.T), rows,
                    float(np.sum(white**2)), int(2 * t.size - 2 * k), white)


@dataclass(frozen=True)
class ResidualCheck:
    """Per radar: whitened-residual ``mean`` (m, 2) and covariance ``cov`` (m, 2, 2),
    ``chi2``, ``dof`` and the upper-tail ``p_value`` of Σχ² (the paper's check that the
    track model (3) fits: mean ≈ 0 and covariance ≈ V_i, i.e. ≈ (1 − p/n)I whitened)."""

    mean: FloatArray
    cov: FloatArray
    chi2: FloatArray
    dof: np.ndarray
    p_value: FloatArray


def residual_check(fits: list[TrackFit], m: int) -> ResidualCheck:
    """Pool the whitened residuals of ``fits`` per radar (0..m−1)."""
    from scipy import stats

    m = as_count("biasfield.residual_check m", m, minimum=1)
    if not all(isinstance(f, TrackFit) for f in fits):
        raise ProblemError("biasfield.residual_check fits: expected a list of TrackFit")

    mean = np.full((m, 2), np.nan)
    cov = np.full((m, 2, 2), np.nan)
    chi2 = np.zeros(m)
    dof = np.zeros(m, dtype=int)
    for i in range(m):
        mine = [f for f in fits if f.radar == i]
        if not mine:
            continue
        w = np.concatenate([f.whitened for f in mine])
        mean[i], cov[i] = w.mean(axis=0), np.cov(w.T)
        chi2[i] = sum(f.chi2 for f in mine)
        dof[i] = sum(f.dof for f in mine)
    with np.errstate(invalid="ignore"):
        p = np.where(dof > 0, stats.chi2.sf(chi2, np.maximum(dof, 1)), np.nan)
    return ResidualCheck(mean, cov, chi2, dof, p)
