r"""The parametric baseline of paper 001, section 2, (2)-(4): one constant azimuth bias
Δ_αi per radar, no range bias, estimated by generalised least squares from joint
observations.

For every object (a piece of its track without long silences) the true motion is a
polyline x(t) = g(t)θ (3) with knots at fixed times, shared by all radars; radar i's plot is

.. math::
    z_i(t) = g(t)\theta + \frac{\partial s_i^\alpha}{\partial\Delta_{\alpha i}}(\tilde x(t))
             \,\Delta_{\alpha i} + w_i(t), \qquad
    \frac{\partial s_i^\alpha}{\partial\Delta}(x) = \rho\,(\cos\alpha, -\sin\alpha)
    \quad (4),

with x̃(t) = z_i(t) (as in the paper's reference [2]) and (ρ, α) its range and azimuth
from radar i (a small clockwise rotation about the site; for a 3-D radar set -- slant range,
azimuth from the radar's own north, plots with heights -- the exact ∂z/∂α at fixed slant
range and height, :func:`~optmodels.biasfield.geometry3d.plane_jacobian`, and the exact 3-D
covariance V). The θ of every object are eliminated by Schur complements, leaving an
m × m system for Δ; its inverse is the covariance of Δ̂. The fit is judged by
χ² = Σ rᵀV⁻¹r with 2n − Σ 2K_a − m degrees of freedom: if the constant model is right
(and the polyline resolves the manoeuvres), χ²/dof ≈ 1; for a position-dependent field it
is rejected, and estimates from different groups of trajectories disagree beyond their
standard errors -- the paper's observation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import linalg, stats

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.geometry import to_polar
from optmodels.biasfield.polyline import polyline_knots, polyline_normal, split_at_gaps, whiten
from optmodels.biasfield.tables import PlotTable, RadarSet, check_tables
from optmodels.core import FloatArray, ProblemError, as_float_array, as_positive

__all__ = ["BaselineResult", "azimuth_bias_baseline"]


@dataclass(frozen=True)
class BaselineResult:
    """``estimate`` (m,) azimuth biases (rad), ``std`` their standard errors, ``cov``
    (m, m); ``chi2`` with ``dof`` degrees of freedom and its ``p_value`` (upper tail);
    ``objects`` and ``plots`` used, ``dropped`` plots (too few for their polyline)."""

    estimate: FloatArray
    std: FloatArray
    cov: FloatArray
    chi2: float
    dof: int
    p_value: float
    objects: int
    plots: int
    dropped: int

    @property
    def chi2_per_dof(self) -> float:
        return self.chi2 / self.dof


def azimuth_bias_baseline(
    plots: PlotTable,
    radars: RadarSet,
    *,
    objects: Sequence[int] | None = None,
    knot_spacing: float = 20.0,
    max_gap: float | None = None,
) -> BaselineResult:
    """GLS estimate of a constant azimuth bias per radar, (2)-(4), from the plots of
    ``objects`` (default: all with an id) that are seen by at least two radars.
    ``knot_spacing`` and ``max_gap`` (default: ``knot_spacing``) in seconds."""
    fn = "biasfield.azimuth_bias_baseline"
    knot_spacing = as_positive(f"{fn} knot_spacing (s)", knot_spacing)
    gap = knot_spacing if max_gap is None else as_positive(f"{fn} max_gap (s)", max_gap)
    if objects is not None:
        # ragged rows, text, None entries, complex values, mappings: one named refusal
        as_float_array(f"{fn} objects", objects)
        obj = np.asarray(objects)
        if obj.ndim != 1 or (obj.size and not np.issubdtype(obj.dtype, np.integer)):
            raise ProblemError(
                f"{fn} objects: expected a list of integer object ids, got {obj.dtype} {obj.shape}"
            )
    check_tables(fn, plots, radars)
    plots.check(radars)
    if objects is not None:
        bad = np.setdiff1d(obj, plots.object[plots.object >= 0])
        if bad.size or np.unique(obj).size != obj.size:
            raise ProblemError(
                f"{fn} objects: expected distinct ids of objects in the plots (≥ 0), got "
                + (f"{bad[:5].tolist()} without plots" if bad.size else "repeated ids")
            )
    m = radars.m
    z_all = plots.cartesian(radars)
    vinv_all = np.empty((len(plots), 2, 2))
    dcol = np.empty((len(plots), 2))
    h_all = plots.height if radars.is_3d else None
    sites = radars.sites
    assert sites is not None  # set by RadarSet.__post_init__
    for i in range(m):
        sel = plots.radar == i
        h_i = None if h_all is None else h_all[sel]
        vinv_all[sel] = np.linalg.inv(radars.cartesian_cov(i, z_all[sel], height=h_i))
        if radars.geodetic is not None and radars.origin is not None and h_i is not None:
            # 3-D (the plots' heights were checked by cartesian above): ∂z/∂α at fixed
            # slant range and height (exact)
            dcol[sel] = g3.plane_jacobian(z_all[sel], h_i, radars.geodetic[i], radars.origin)[
                :, :, 1
            ]
        else:
            pol = to_polar(z_all[sel], sites[i])
            dcol[sel] = pol[:, :1] * np.column_stack([np.cos(pol[:, 1]), -np.sin(pol[:, 1])])
    ids = np.unique(plots.object[plots.object >= 0]) if objects is None else np.asarray(objects)
    s_mat = np.zeros((m, m))
    s_rhs = np.zeros(m)
    parts = []
    dropped = 0
    for a in ids:
        rows_a = np.flatnonzero(plots.object == a)
        rows_a = rows_a[np.argsort(plots.time[rows_a], kind="stable")]
        for piece in split_at_gaps(plots.time[rows_a], gap):
            rows = rows_a[piece]
            t = plots.time[rows]
            knots = polyline_knots(t, knot_spacing)
            if len(np.unique(plots.radar[rows])) < 2 or 2 * rows.size < 2 * knots.size + 2:
                dropped += rows.size
                continue
            vinv, z, d = vinv_all[rows], z_all[rows], dcol[rows]
            n_tt, b_t, h = polyline_normal(t, knots, vinv, z)
            # coupling of θ with Δ: column i of A_Δ is d_j on radar i's plots
            e = np.zeros((rows.size, m))
            e[np.arange(rows.size), plots.radar[rows]] = 1.0
            vd = np.einsum("nab,nb->na", vinv, d)
            n_td = np.einsum("nk,na,ni->kai", h, vd, e).reshape(-1, m)
            n_dd = np.diag(np.einsum("na,na,ni->i", d, vd, e))
            b_d = np.einsum("na,na,ni->i", vd, z, e)
            try:
                chol = linalg.cho_factor(n_tt)
            except linalg.LinAlgError:
                dropped += rows.size
                continue
            x_td = linalg.cho_solve(chol, n_td)
            s_mat += n_dd - n_td.T @ x_td
            s_rhs += b_d - x_td.T @ b_t
            parts.append((rows, knots, chol, n_td, b_t, h, vinv, z, d, e))
    if not parts:
        raise ProblemError("plots: no object is seen by two radars with enough plots")
    try:
        cov = linalg.inv(s_mat)
        est = cov @ s_rhs
    except linalg.LinAlgError as exc:
        raise ProblemError(
            f"plots: the azimuth biases are not identifiable from these trajectories ({exc})"
        ) from None
    chi2 = 0.0
    n_par = m
    used = 0
    for rows, knots, chol, n_td, b_t, h, vinv, z, d, e in parts:
        theta = linalg.cho_solve(chol, b_t - n_td @ est).reshape(knots.size, 2)
        r = z - h @ theta - d * (e @ est)[:, None]
        chi2 += float(np.sum(whiten(vinv, r) ** 2))
        n_par += 2 * knots.size
        used += rows.size
    dof = 2 * used - n_par
    cov = 0.5 * (cov + cov.T)
    return BaselineResult(
        est,
        np.sqrt(np.diag(cov)),
        cov,
        chi2,
        dof,
        float(stats.chi2.sf(chi2, dof)),
        len(ids),
        used,
        dropped,
    )
