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

Over the union of coverage (per-cell radar subsets S_k, ``FieldData.seen``) the unknowns
are the entries φ_ki with i ∈ S_k only (J (9) sums radar i over the cells it sees); a
plot of radar i is referred to the cells radar i sees; the entries of the other radars
are not estimated (0 in :attr:`AdsbField.field`). The system and its solve are in
:mod:`~optmodels.biasfield.referee_system`.

The reference positions of the plots come from a recording's ADS-B reports through
:func:`adsb_reference` (or, simulated, ``RadarNetworkScenario.adsb_positions``).
:func:`absolute_error` measures the radars against ADS-B on per-area means, and
:func:`compare_fields` reports both figures before and after correcting with each field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.correction import correct_plots
from optmodels.biasfield.data import FieldData
from optmodels.biasfield.fieldmap import FieldMap, field_map
from optmodels.biasfield.problem import check_graph
from optmodels.biasfield.referee_system import adsb_system, check_determined, solve_level
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
    of the data (0 where a radar does not see a cell: those entries are not estimated, as
    in :class:`~optmodels.biasfield.solution.FieldSolution`; ``seen`` (K, m) the radars of
    each cell, None: all), ``mean`` (K, m, 2) the per-cell radar-minus-ADS-B means (NaN
    without data), ``counts`` (K, m) the plots behind them, ``mu`` the multiplier of J at
    the discrepancy level, ``chi2`` and ``dof`` (2 × the plots used) of the data term at
    the solution, ``objective`` J(φ), ``status`` (OPTIMAL; OPTIMAL_INACCURATE if the
    bisection did not close to 1e-2 in χ², or by :func:`~optmodels.core.verified_status`
    on the larger of ``stationarity``, the relative residual of (μR + AᵀWA)φ = AᵀWd
    re-computed in NumPy, and ``conditioning``, κ₁·ε of the (Jacobi-scaled) matrix solved;
    ERROR above REJECT_TOL, and then :meth:`map` refuses), ``solve_time`` (s); ``moved``:
    plots whose nearest cell their radar does not see, given to the nearest cell it sees
    (``model="cells"``); ``unused``: plots with an ADS-B position not used (outside the
    covered area of their radar's cells, or without a height in 3-D)."""

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
    conditioning: float = float("nan")
    seen: np.ndarray | None = None
    moved: int = 0
    unused: int = 0

    def map(
        self, centers: ArrayLike | FieldData, *, names: tuple[str, ...] | list[str] = ()
    ) -> FieldMap:
        """The field as a :class:`~optmodels.biasfield.usage.FieldMap`: on ``centers``
        (K, 2) (m, common plane; no frame), or on the cells of a :class:`FieldData` (the
        one it was estimated on), which also gives the map its frame (sites; geodetic
        sites and origin in 3-D) and, with ``names``, the radars' names. With per-cell
        subsets each radar is served over the cells it sees only (``seen``)."""
        if not self.status.ok:
            raise ProblemError(
                f"biasfield.AdsbField.map: status {self.status.value}; the field is not returned"
            )
        if isinstance(centers, FieldData):
            return field_map(self, centers, names=names)
        return FieldMap(
            np.asarray(centers, dtype=float), self.field, names=tuple(names), seen=self.seen
        )


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
    from every cell centre its radar sees are not used (default 1.5 × the median nearest-neighbour
    distance of the centres, as :func:`~optmodels.biasfield.build_field_data`).
    ``sigma_reference`` (m): the ADS-B horizontal position error (1σ per axis; NACp 9-10
    is ≤ 10-30 m at 95 %). In 3-D (a geodetic radar set, plots with heights) the data are
    the exact slant range and own-north azimuth of the ADS-B position at the plot's height,
    and the reference error is mapped through the exact 3-D Jacobian there.

    ``model``: ``"cells"`` (each plot's bias is its nearest cell's value, like the paper's
    averages) or ``"interpolant"`` (the P1 interpolant at the ADS-B position, the map that
    :func:`~optmodels.biasfield.usage.correct_plots` applies). With per-cell subsets
    (``data.seen``) both use only the cells the plot's radar sees: the nearest of them
    (a plot nearest to a cell its radar does not see is moved there, counted in
    :attr:`AdsbField.moved`), or the P1 interpolant on their triangulation (as the
    :class:`~optmodels.biasfield.usage.FieldMap` serves that radar). ``level``:
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
        sys_ = adsb_system(fn, data, plots, radars, ref, radius, sig_ref, model)
        check_determined(fn, data, radars.names, sys_)
        sol = solve_level(fn, data, sys_, level)
    field = np.zeros(2 * m * k)  # the entries of a radar that does not see a cell: 0
    field[sys_.keep] = sol.phi
    return AdsbField(
        field.reshape(k, m, 2),
        sys_.mean,
        sys_.counts,
        sol.mu,
        sol.chi2,
        2 * sys_.n_used,
        sol.objective,
        sol.status,
        tm.elapsed,
        sol.stationarity,
        sol.conditioning,
        None if data.seen is None else data.seen.copy(),
        sys_.moved,
        sys_.unused,
    )


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
