r"""ADS-B as the referee (issue 17): the bias field estimated against ADS-B positions, where
the per-cell common shift that paper 001 cannot observe *is* observed, and the comparison
of that field with the reference-free smoothest field (paper 001, section 4) on the same
plots.

Estimate (what registration tools in air traffic do, with the paper's smoothness criterion
as the selection rule): for every plot of radar i with an ADS-B position y of the same
aircraft at the plot time, the polar difference d = p̃_i − p_i(y) is a sample of the bias
f_i plus noise. Per cell k and radar i the mean d̄_ki and its covariance C_ki = V_i / n_ki
(V_i = diag(σ_r², σ_α²), plus the ADS-B position error mapped through the radar's
Jacobian) form the data. Among the fields φ consistent with them at the χ² level,

.. math::
    \min_\varphi\ J(\varphi) = \varphi^T (Q\otimes P)\varphi
    \quad\text{s.t.}\quad \sum_{k,i} (\varphi_{ki} - \bar d_{ki})^T C_{ki}^{-1}
    (\varphi_{ki} - \bar d_{ki}) \le n_d

(n_d = the number of data components: the expected χ² — the discrepancy principle), the
smoothest is selected, the same criterion (9) as the paper's, on a different set. Its
Lagrangian gives (μR + W)φ = W d̄ (W = blockdiag C_ki⁻¹), and μ > 0 is found by bisection
on log μ so that the constraint is active (χ²(μ) grows with μ). Cells without ADS-B data
for a radar get their value from the smoothness alone (``level="means"``: μ → 0, the
least-squares field).

The reference positions of the plots come from a recording's ADS-B reports through
:func:`adsb_reference` (or, simulated, ``RadarNetworkScenario.adsb_positions``).
:func:`absolute_error` measures the radars against ADS-B on per-area means, and
:func:`compare_fields` reports both figures before and after correcting with each field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse import linalg as splinalg
from scipy.spatial import cKDTree

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.correction import correct_plots
from optmodels.biasfield.data import FieldData
from optmodels.biasfield.fieldmap import FieldMap, Triangles, field_map
from optmodels.biasfield.geometry import wrap_angle
from optmodels.biasfield.problem import check_graph, r_matrix, r_null_space, radar_parts
from optmodels.biasfield.registration import (
    RegistrationError,
    plane_positions,
    registration_error,
    systematic_square,
)
from optmodels.biasfield.tables import PlotTable, RadarSet, check_tables
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    Status,
    as_choice,
    as_count,
    as_finite_array,
    as_float_array,
    as_instance,
    as_positive,
    timed,
    verified_status,
)

__all__ = [
    "AbsoluteError",
    "AdsbField",
    "absolute_error",
    "adsb_field",
    "adsb_reference",
    "compare_fields",
]


@dataclass(frozen=True)
class AdsbField:
    """The ADS-B-referenced field: ``field`` (K, m, 2) [range m, azimuth rad] on the cells
    of the data, ``mean`` (K, m, 2) the per-cell radar-minus-ADS-B means (NaN without
    data), ``counts`` (K, m) the plots behind them, ``mu`` the multiplier of J at the
    discrepancy level, ``chi2`` and ``dof`` of the data term at the solution,
    ``objective`` J(φ), ``status`` (OPTIMAL; OPTIMAL_INACCURATE if the bisection did not
    close to 1e-2 in χ², or by :func:`~optmodels.core.verified_status` on
    ``stationarity``, the relative residual of (μR + AᵀWA)φ = AᵀWd re-computed in NumPy;
    ERROR above REJECT_TOL, and then :meth:`map` refuses), ``solve_time`` (s)."""

    field: FloatArray
    mean: FloatArray
    counts: np.ndarray
    mu: float
    chi2: float
    dof: int
    objective: float
    status: Status
    solve_time: float
    stationarity: float = float("nan")

    def map(
        self, centers: ArrayLike | FieldData, *, names: tuple[str, ...] | list[str] = ()
    ) -> FieldMap:
        """The field as a :class:`~optmodels.biasfield.usage.FieldMap`: on ``centers``
        (K, 2) (m, common plane; no frame), or on the cells of a :class:`FieldData` (the
        one it was estimated on), which also gives the map its frame (sites; geodetic
        sites and origin in 3-D) and, with ``names``, the radars' names."""
        if not self.status.ok:
            raise ProblemError(
                f"biasfield.AdsbField.map: status {self.status.value}; the field is not returned"
            )
        if isinstance(centers, FieldData):
            return field_map(self, centers, names=names)
        return FieldMap(np.asarray(centers, dtype=float), self.field, names=tuple(names))


def adsb_reference(
    plots: PlotTable, adsb: Any, origin: ArrayLike, *, max_gap: float = 10.0
) -> FloatArray:
    """The ADS-B position (n, 2) (m, East/North on the common plane of ``origin``) of each
    plot's aircraft at the plot time, the ``reference`` of :func:`adsb_field`,
    :func:`absolute_error` and :func:`compare_fields`.

    ``adsb``: ADS-B reports with ``time`` (s, the plots' clock), ``object`` (the plots'
    object numbering), ``latitude``, ``longitude`` (deg, WGS-84) — e.g.
    :class:`~optmodels.biasfield.recording.AdsbReports` (``Recording.adsb``). ``origin``
    (lat deg, lon deg, h m): the radar set's (``RadarSet.origin``). Each report is placed on
    the plane (:func:`~optmodels.biasfield.geometry3d.common_plane`, the footprint) and the
    aircraft's reports are interpolated linearly in time; NaN where the plot's aircraft
    has no report, the plot time is outside its reports' span, or the two reports around it
    are more than ``max_gap`` s apart (ADS-B squitters come at ~2 Hz; a gap is not
    bridged). Repeated report times keep the first."""
    fn = "biasfield.adsb_reference"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    org = g3.site_geodetic(f"{fn} origin", origin)
    gap = as_positive(f"{fn} max_gap (s)", max_gap)
    cols = {}
    for name in ("time", "object", "latitude", "longitude"):
        if not hasattr(adsb, name):
            raise ProblemError(
                f"{fn} adsb: expected ADS-B reports with time, object, "
                f"latitude, longitude (e.g. Recording.adsb), got "
                f"{type(adsb).__name__} without {name!r}"
            )
        cols[name] = np.asarray(getattr(adsb, name))
    n_rep = cols["time"].shape[0]
    for name, v in cols.items():
        if v.shape != (n_rep,):
            raise ProblemError(f"{fn} adsb: {name} of shape {v.shape}, expected ({n_rep},)")
    t = as_finite_array(f"{fn} adsb time (s)", cols["time"], max_abs=MAX_MAGNITUDE)
    lat = as_finite_array(f"{fn} adsb latitude (deg)", cols["latitude"], max_abs=90.0)
    lon = as_finite_array(f"{fn} adsb longitude (deg)", cols["longitude"], max_abs=360.0)
    objf = as_finite_array(f"{fn} adsb object", cols["object"], max_abs=2**62)
    if np.any(objf != np.round(objf)):
        raise ProblemError(f"{fn} adsb object: expected integer object numbers")
    obj = objf.astype(np.int64)
    en = g3.common_plane(lat, lon, org)
    order = np.lexsort((t, obj))
    t, obj, en = t[order], obj[order], en[order]
    out = np.full((len(plots), 2), np.nan)
    starts = np.flatnonzero(np.r_[True, obj[1:] != obj[:-1]])
    ends = np.r_[starts[1:], obj.size]
    for a, b in zip(starts, ends, strict=True):
        rows = np.flatnonzero(plots.object == obj[a])
        if rows.size == 0:
            continue
        ta, ea = t[a:b], en[a:b]
        keep = np.r_[True, np.diff(ta) > 0]
        ta, ea = ta[keep], ea[keep]
        tq = plots.time[rows]
        j = np.searchsorted(ta, tq, side="right")
        inside = (tq >= ta[0]) & (tq <= ta[-1])
        lo = np.clip(j - 1, 0, ta.size - 1)
        hi = np.clip(j, 0, ta.size - 1)
        ok = inside & ((ta[hi] - ta[lo]) <= gap)
        if not ok.any():
            continue
        out[rows[ok], 0] = np.interp(tq[ok], ta, ea[:, 0])
        out[rows[ok], 1] = np.interp(tq[ok], ta, ea[:, 1])
    return out


def _reference(fn: str, plots: PlotTable, reference: ArrayLike) -> FloatArray:
    # NaN marks a plot without ADS-B position: not as_finite_array
    ref = as_float_array(f"{fn} reference", reference)
    if ref.shape != (len(plots), 2):
        raise ProblemError(
            f"{fn} reference: expected ADS-B positions ({len(plots)}, 2) (m, "
            f"common plane; NaN where none), got {ref.shape}"
        )
    bad = np.isinf(ref) | (np.abs(np.nan_to_num(ref)) > MAX_MAGNITUDE)
    if bad.any():
        raise ProblemError(
            f"{fn} reference: {int(bad.any(axis=1).sum())} infinite or huge "
            "positions (use NaN where there is no ADS-B position)"
        )
    return ref


def _heights(plots: PlotTable, rows: np.ndarray) -> FloatArray | None:
    h = getattr(plots, "height", None)
    return None if h is None else np.asarray(h)[rows]


def adsb_field(
    data: FieldData,
    plots: PlotTable,
    radars: RadarSet,
    reference: ArrayLike,
    *,
    cell_radius: float | None = None,
    sigma_reference: float = 10.0,
    model: str = "cells",
    level: str = "discrepancy",
) -> AdsbField:
    """The bias field referenced to ADS-B (module docstring) on the cells of ``data``.

    ``reference`` (n, 2): the ADS-B position (m, common plane) of each plot's aircraft at
    the plot time, NaN where there is none. ``cell_radius`` (m): plots farther than this
    from every cell centre are not used (default 1.5 × the median nearest-neighbour
    distance of the centres, as :func:`~optmodels.biasfield.build_field_data`).
    ``sigma_reference`` (m): the ADS-B horizontal position error (1σ per axis; NACp 9-10
    is ≤ 10-30 m at 95 %). In 3-D (a geodetic radar set, plots with heights) the data are
    the exact slant range and own-north azimuth of the ADS-B position at the plot's height,
    and the reference error is mapped through the exact 3-D Jacobian there.

    ``model``: ``"cells"`` (each plot's bias is its nearest cell's value, like the paper's
    averages) or ``"interpolant"`` (the P1 interpolant at the ADS-B position, the map that
    :func:`~optmodels.biasfield.usage.correct_plots` applies). ``level``:
    ``"discrepancy"`` (the smoothest field with χ² at its expected value, the number of data
    components) or ``"means"`` (the weighted least-squares field: the per-cell means where
    there are data, the smoothest extension elsewhere; the analogue of the paper's
    equality sets (10); measured less biased, docs/formulations.md).
    """
    fn = "biasfield.adsb_field"
    data = as_instance(f"{fn} data", data, FieldData)
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    sig_ref = as_positive(f"{fn} sigma_reference (m)", sigma_reference, allow_zero=True)
    model = as_choice(f"{fn} model", model, ("cells", "interpolant"))
    level = as_choice(f"{fn} level", level, ("discrepancy", "means"))
    if radars.m != data.m:
        raise ProblemError(f"{fn} radars: {radars.m} radars for data of {data.m}")
    check_graph(data)
    ref = _reference(fn, plots, reference)
    plots.check(radars)
    tree = cKDTree(data.centers)
    if cell_radius is None:
        cell_radius = 1.5 * float(np.median(tree.query(data.centers, k=2)[0][:, 1]))
    radius = as_positive(f"{fn} cell_radius (m)", cell_radius)
    k, m = data.k, data.m
    with timed() as tm:
        sys_ = _adsb_system(fn, data, plots, radars, ref, tree, radius, sig_ref, model)
        _check_determined(fn, data, radars, sys_.amat)
        awa = (sys_.amat.T @ sys_.wmat @ sys_.amat).tocsc()
        rhs = sys_.amat.T @ (sys_.wmat @ sys_.dvec)
        r = r_matrix(data).tocsc()
        dof = 2 * sys_.n_used
        null = r_null_space(data)
        phi, chi2, mu, status = _smoothing_level(sys_, awa, rhs, r, null, dof, level)
        if not np.all(np.isfinite(phi)):
            raise ProblemError(
                f"{fn}: the solve overflowed (the data and the smoothness "
                "do not determine the field)"
            )
        obj = float(phi @ (r @ phi))
        resid = _stationarity(phi, mu, awa, rhs, r, null)
        status = verified_status(status, resid)
    return AdsbField(
        phi.reshape(k, m, 2), sys_.mean, sys_.counts, mu, chi2, dof, obj, status, tm.elapsed, resid
    )


class _AdsbSystem(NamedTuple):
    """The weighted least-squares data term of :func:`adsb_field`: A φ ≈ d with weight W
    (one 2 × 2 block per used plot), the per-cell mean discrepancies and their counts."""

    amat: sparse.csr_matrix
    wmat: sparse.csr_matrix
    dvec: FloatArray
    mean: FloatArray
    counts: np.ndarray
    n_used: int


def _adsb_system(
    fn: str,
    data: FieldData,
    plots: PlotTable,
    radars: RadarSet,
    ref: FloatArray,
    tree: cKDTree,
    radius: float,
    sig_ref: float,
    model: str,
) -> _AdsbSystem:
    """Each used plot's discrepancy d = measured − what its radar would measure of the
    ADS-B position, its row of A (the plot's cell, or the P1 weights at the ADS-B
    position) and its weight (V_i + σ_ref² J Jᵀ)⁻¹."""
    k, m = data.k, data.m
    tri = Triangles(data.centers)
    sums = np.zeros((k, m, 2))
    counts = np.zeros((k, m), dtype=np.int64)
    has = np.all(np.isfinite(ref), axis=1)
    a_rows, a_cols, a_vals, w_list, d_list = [], [], [], [], []
    n_used = 0
    for i in range(m):
        rows = np.flatnonzero(has & (plots.radar == i))
        if rows.size == 0:
            continue
        y = ref[rows]
        simplex = tri.find(y)
        dist, cell = tree.query(y)
        ok = (simplex >= 0) & (dist <= radius)
        if getattr(plots, "height", None) is not None:
            ok &= np.isfinite(np.asarray(plots.height)[rows])
        rows, y, cell, simplex = rows[ok], y[ok], cell[ok], simplex[ok]
        if rows.size == 0:
            continue
        h = _heights(plots, rows)
        # what radar i would measure of the ADS-B position (3-D: slant range and azimuth
        # in its own frame at the plot's height)
        d = np.column_stack([plots.range[rows], plots.azimuth[rows]]) - radars.to_polar(i, y, h)
        d[:, 1] = wrap_angle(d[:, 1])
        np.add.at(sums[:, i], cell, d)
        np.add.at(counts[:, i], cell, 1)
        if model == "interpolant":  # barycentric weights of the FieldMap's P1 at y
            bary = tri.barycentric(y, simplex)
            verts = tri.simplices[simplex]
        else:  # the plot's cell
            bary = np.ones((rows.size, 1))
            verts = cell[:, None]
        base = 2 * (n_used + np.arange(rows.size))
        for comp in (0, 1):
            a_rows.append(np.repeat(base + comp, verts.shape[1]))
            a_cols.append((2 * (verts * m + i) + comp).ravel())
            a_vals.append(bary.ravel())
        # per-plot covariance V_i + σ_ref² J Jᵀ (the ADS-B error seen in polar)
        jac = radars.polar_jacobian(i, y, h)
        cov = np.diag(
            [radars.sigma_range[i] ** 2, radars.sigma_azimuth[i] ** 2]
        ) + sig_ref**2 * jac @ jac.transpose(0, 2, 1)
        w_list.append(np.linalg.inv(cov))
        d_list.append(d.reshape(-1))
        n_used += rows.size
    if n_used == 0:
        raise ProblemError(
            f"{fn} reference: no plot with an ADS-B position lies in the covered area of the cells"
        )
    seen = counts > 0
    mean = np.full((k, m, 2), np.nan)
    mean[seen] = sums[seen] / counts[seen, None]
    amat = sparse.csr_matrix(
        (np.concatenate(a_vals), (np.concatenate(a_rows), np.concatenate(a_cols))),
        shape=(2 * n_used, 2 * m * k),
    )
    wmat = sparse.block_diag(list(np.concatenate(w_list)), format="csr")
    return _AdsbSystem(amat, wmat, np.concatenate(d_list), mean, counts, n_used)


def _check_determined(fn: str, data: FieldData, radars: RadarSet, amat: sparse.csr_matrix) -> None:
    """Every radar has ADS-B data on every connected part of its own neighbour graph
    (:func:`~optmodels.biasfield.problem.radar_parts`); else its constant there (the null
    space of R) is determined by no μ: ProblemError naming the radar and the cells."""
    k, m = data.k, data.m
    touched = np.asarray(abs(amat).sum(axis=0)).reshape(k, m, 2)[:, :, 0] > 0
    for i, (n, labels) in enumerate(radar_parts(data)):
        has = np.zeros(n, dtype=bool)
        np.logical_or.at(has, labels, touched[:, i])
        if not has.all():
            cells = np.flatnonzero(labels == np.flatnonzero(~has)[0])
            raise ProblemError(
                f"{fn} reference: radar {radars.names[i]!r} has no plot with an ADS-B "
                f"position in cells {cells[:10].tolist()} (a connected part of the cells "
                "it sees): its field there is not determined"
            )


def _smoothing_level(
    sys_: _AdsbSystem,
    awa: sparse.csc_matrix,
    rhs: FloatArray,
    r: sparse.csc_matrix,
    null: sparse.csr_matrix,
    dof: int,
    level: str,
) -> tuple[FloatArray, float, float, Status]:
    """The field of the smoothing weight μ: (μR + AᵀWA)φ = AᵀWd with χ²(μ) at the expected
    level ``dof`` (``"discrepancy"``, bisection in log μ) or μ → 0 (``"means"``). Returns
    φ, χ², μ and the status (OPTIMAL_INACCURATE when the level is not reached)."""
    amat, wmat, dvec = sys_.amat, sys_.wmat, sys_.dvec

    def fit(mu: float) -> tuple[FloatArray, float]:
        phi = splinalg.spsolve((mu * r + awa).tocsc(), rhs)
        res = amat @ phi - dvec
        return phi, float(res @ (wmat @ res))

    # χ²(μ) increases with μ from its least-squares minimum towards that of the
    # smoothest fields (μ → ∞: J = 0, constant per radar on each connected part of the
    # graph, fitted exactly in that null space); the level is the expected χ² = 2n
    c_inf = np.linalg.solve((null.T @ awa @ null).toarray(), null.T @ rhs)
    phi_inf = null @ c_inf
    res_inf = amat @ phi_inf - dvec
    chi_inf = float(res_inf @ (wmat @ res_inf))
    status = Status.OPTIMAL
    scale = float(np.log10(max(abs(awa).max(), 1e-300) / max(abs(r).max(), 1e-300)))
    if level == "means":  # the least-squares field: the means, smoothness fills the rest
        mu = 10.0 ** (scale - 12.0)
        phi, chi2 = fit(mu)
    elif chi_inf <= dof:  # even the smoothest fields fit the data: take the best of them
        phi, chi2, mu = phi_inf, chi_inf, float("inf")
    else:
        lo, hi = scale - 20.0, scale + 14.0
        phi, chi2 = fit(10.0**lo)
        if chi2 >= dof:  # no field reaches the level: the least-squares one
            mu = 10.0**lo
            status = Status.OPTIMAL_INACCURATE
        else:
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                phi, chi2 = fit(10.0**mid)
                if chi2 > dof:
                    hi = mid
                else:
                    lo = mid
                # the level itself is uncertain by √(2 dof): 1e-4 relative is ample
                if abs(chi2 - dof) <= 1e-4 * dof or hi - lo < 1e-12:
                    break
            mu = 10.0**mid
            if abs(chi2 - dof) > 1e-2 * dof:
                status = Status.OPTIMAL_INACCURATE
    return phi, chi2, mu, status


def _stationarity(
    phi: FloatArray,
    mu: float,
    awa: sparse.csc_matrix,
    rhs: FloatArray,
    r: sparse.csc_matrix,
    null: sparse.csr_matrix,
) -> float:
    """The re-check: the stationarity of the Lagrangian, (μR + AᵀWA)φ − AᵀWd (μ = ∞: Rφ = 0
    and the data term stationary in the null space of R), relative."""
    ref_scale = max(float(np.max(np.abs(rhs))), 1e-300)
    if np.isinf(mu):
        return max(
            float(np.max(np.abs(null.T @ (awa @ phi - rhs)))) / ref_scale,
            float(np.max(np.abs(r @ phi))) / max(float(abs(r).max() * np.max(np.abs(phi))), 1e-300),
        )
    return float(np.max(np.abs(mu * (r @ phi) + awa @ phi - rhs))) / ref_scale


# ----------------------------------------------------------------------------- absolute error
@dataclass(frozen=True)
class AbsoluteError:
    """Horizontal error (m) of the radars' plot positions against ADS-B, measured on
    per-area means (as :class:`~optmodels.biasfield.usage.RegistrationError`): ``overall``,
    ``radars[name]``; ``raw_overall`` the plain RMS (noise included); ``noise`` the RMS
    standard error of the area means."""

    overall: float
    radars: dict[str, float]
    raw_overall: float
    noise: float
    area: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "overall_m": self.overall,
            "raw_overall_m": self.raw_overall,
            "noise_m": self.noise,
            "area_m": self.area,
            "radars_m": dict(self.radars),
        }


def absolute_error(
    plots: PlotTable,
    radars: RadarSet,
    reference: ArrayLike,
    *,
    area: float = 25e3,
    min_samples: int = 20,
    within: FieldMap | None = None,
    positions: ArrayLike | None = None,
) -> AbsoluteError:
    """RMS over areas of the systematic part of z − y, z a plot's position on the common
    plane and y its ADS-B position (per-area means less their noise, estimated from the
    scatter of the per-aircraft means; areas of ≥ ``min_samples`` plots of ≥ 2 aircraft),
    per radar and overall. ``within``: only plots in the covered area of a field;
    ``positions`` (n, 2) m: the plots' plane positions if already computed."""
    fn = "biasfield.absolute_error"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    area = as_positive(f"{fn} area (m)", area)
    min_samples = as_count(f"{fn} min_samples", min_samples, minimum=1)
    if within is not None:
        within = as_instance(f"{fn} within", within, FieldMap)
    ref = _reference(fn, plots, reference)
    z = plane_positions(fn, plots, radars, positions)
    ok = np.all(np.isfinite(ref), axis=1) & (plots.object >= 0)
    if within is not None:
        ok &= within.covered(z)
    out: dict[str, float] = {}
    tot = var_tot = raw = 0.0
    n_tot = n_raw = 0
    for i in range(radars.m):
        rows = np.flatnonzero(ok & (plots.radar == i))
        if rows.size == 0:
            continue
        d = z[rows] - ref[rows]
        raw += float(np.sum(d * d))
        n_raw += rows.size
        _, label = np.unique(np.floor(z[rows] / area).astype(np.int64), axis=0, return_inverse=True)
        label = label.ravel()
        s_i = 0.0
        n_i = 0
        for c in np.unique(label):
            sel = label == c
            if sel.sum() < min_samples:
                continue
            est = systematic_square(d[sel], plots.object[rows][sel])
            if est is None:
                continue
            s_i += sel.sum() * est[0]
            var_tot += sel.sum() * est[1]
            n_i += int(sel.sum())
        out[radars.names[i]] = float(np.sqrt(max(s_i, 0.0) / n_i)) if n_i else float("nan")
        tot += s_i
        n_tot += n_i
    if n_raw == 0:
        raise ProblemError(f"{fn} reference: no plot has an ADS-B position")
    return AbsoluteError(
        float(np.sqrt(max(tot, 0.0) / n_tot)) if n_tot else float("nan"),
        out,
        float(np.sqrt(raw / n_raw)),
        float(np.sqrt(var_tot / n_tot)) if n_tot else float("nan"),
        area,
    )


# ----------------------------------------------------------------------------- comparison
def compare_fields(
    plots: PlotTable,
    radars: RadarSet,
    reference: ArrayLike,
    fields: dict[str, FieldMap],
    *,
    area: float = 25e3,
) -> dict[str, Any]:
    """Cross-radar disagreement and absolute error against ADS-B, before and after
    correcting the plots with each field of ``fields`` (e.g. ``{"smoothest": ...,
    "adsb": ...}``), all measured on the area covered by every field. Returns a dict
    ``{"before": {...}, name: {...}}`` of ``registration`` and ``absolute`` figures (m)."""
    fn = "biasfield.compare_fields"
    check_tables(fn, plots, radars)
    if not isinstance(fields, Mapping) or not fields:
        raise ProblemError(
            f"{fn} fields: expected a dict of at least one name → FieldMap, got {fields!r:.60}"
        )
    maps = {str(k): as_instance(f"{fn} fields[{k!r}]", v, FieldMap) for k, v in fields.items()}
    area = as_positive(f"{fn} area (m)", area)
    ref = _reference(fn, plots, reference)
    first = next(iter(maps.values()))
    covered_all = np.ones(len(plots), dtype=bool)
    z = plots.cartesian(radars)
    for fm in maps.values():
        covered_all &= fm.covered(z)
    sub = plots.subset(covered_all)
    ref_sub = ref[covered_all]

    def figures(p: PlotTable, zp: FloatArray | None = None) -> dict[str, Any]:
        zp = p.cartesian(radars) if zp is None else zp  # placed once for both figures
        reg: RegistrationError = registration_error(
            p, radars, area=area, within=first, positions=zp
        )
        ab = absolute_error(p, radars, ref_sub, area=area, positions=zp)
        return {"registration": reg.to_dict(), "absolute": ab.to_dict()}

    out: dict[str, Any] = {"before": figures(sub, z[covered_all]), "plots": int(covered_all.sum())}
    for name, fm in maps.items():
        out[name] = figures(correct_plots(sub, radars, fm).plots)
    return out
