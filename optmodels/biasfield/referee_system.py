r"""The system of :func:`~optmodels.biasfield.referee.adsb_field` and its solve (the
module docstring of :mod:`~optmodels.biasfield.referee` states the estimate).

Unknowns: the seen entries φ_{k,i}, i ∈ S_k (:func:`~optmodels.biasfield.problem.
seen_entries`; every entry without per-cell subsets). An entry of a radar that does not see
the cell enters neither J (9) (R has zero rows and columns there) nor, here, the data: it
is not estimated (0 in the returned field, as in
:class:`~optmodels.biasfield.solution.FieldSolution`). R and the data matrix A have the
seen columns only, and the null space of R is one constant per radar and per connected part
of its own graph over the cells it sees (``r_null_space(data, seen_only=True)``).

* :func:`adsb_system`: each used plot's discrepancy, its row of A and its weight; a plot of
  radar i is assigned to the cells radar i sees (``model="cells"``: the nearest of them;
  ``"interpolant"``: the P1 interpolant on the triangulation of those cells, the map that
  :class:`~optmodels.biasfield.fieldmap.FieldMap` serves radar i with);
* :func:`check_determined`: every part of every radar's graph over its cells has data;
* :func:`solve_level`: (μR + AᵀWA)φ = AᵀWd at the discrepancy or the means level, solved
  with the symmetric diagonal (Jacobi) scaling, and re-checked: the stationarity residual
  and the condition number κ₁ of the scaled matrix (κ₁·ε enters the status like a
  residual, as in :mod:`~optmodels.biasfield.verify`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg
from scipy.spatial import QhullError, cKDTree

from optmodels.biasfield.data import FieldData
from optmodels.biasfield.fieldmap import Triangles
from optmodels.biasfield.geometry import wrap_angle
from optmodels.biasfield.problem import r_matrix, r_null_space, radar_parts, seen_entries
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.biasfield.verify import condition_number, conditioning_residual
from optmodels.core import FloatArray, ProblemError, Status, verified_status

__all__: list[str] = []


class AdsbSystem(NamedTuple):
    """The weighted least-squares data term of ``adsb_field``: A φ ≈ d with weight W (one
    2 × 2 block per used plot) over the seen entries ``keep`` (2mK,) of φ, the per-cell
    mean discrepancies (K, m, 2) and their counts (K, m); ``moved``: the used plots whose
    nearest cell their radar does not see (``model="cells"``: given to the nearest cell it
    sees); ``unused``: the plots with an ADS-B position not used."""

    amat: sparse.csr_matrix
    wmat: sparse.csr_matrix
    dvec: FloatArray
    mean: FloatArray
    counts: np.ndarray
    n_used: int
    keep: np.ndarray
    moved: int
    unused: int


def _own_cells(
    data: FieldData, i: int, tri: Triangles, tree: cKDTree, model: str
) -> tuple[np.ndarray, Triangles | None, cKDTree | None]:
    """Radar i's cells, their k-d tree (None: it sees no cell) and the triangulation of
    the P1 interpolant (``"interpolant"``; None with fewer than 3 cells or no area)."""
    own = np.flatnonzero(data.subsets[:, i])
    if own.size == data.k:
        return own, tri, tree
    if own.size == 0:
        return own, None, None
    own_tri = None
    if model == "interpolant" and own.size >= 3:
        try:
            own_tri = Triangles(data.centers[own])
        except QhullError:
            own_tri = None
    return own, own_tri, cKDTree(data.centers[own])


def _rows_of_a(
    y: FloatArray, own: np.ndarray, cell: np.ndarray, own_tri: Triangles | None, model: str
) -> tuple[FloatArray, np.ndarray]:
    """The plots' weights and cells in A: the nearest cell (``"cells"``, or outside the
    radar's triangulation: the map's constant extension) or the P1 weights of the
    triangle of the radar's cells holding y."""
    if model == "cells":
        return np.ones((y.shape[0], 1)), cell[:, None]
    bary = np.zeros((y.shape[0], 3))
    bary[:, 0] = 1.0
    verts = np.repeat(cell[:, None], 3, axis=1)
    simplex = own_tri.find(y) if own_tri is not None else np.full(y.shape[0], -1)
    inside = simplex >= 0
    if own_tri is not None and inside.any():
        bary[inside] = own_tri.barycentric(y[inside], simplex[inside])
        verts[inside] = own[own_tri.simplices[simplex[inside]]]
    return bary, verts


def adsb_system(
    fn: str,
    data: FieldData,
    plots: PlotTable,
    radars: RadarSet,
    ref: FloatArray,
    radius: float,
    sig_ref: float,
    model: str,
) -> AdsbSystem:
    """Each used plot's discrepancy d = measured − what its radar would measure of the
    ADS-B position, its row of A over the seen entries (the nearest cell its radar sees,
    or the P1 weights at the ADS-B position on the triangulation of those cells) and its
    weight (V_i + σ_ref² J Jᵀ)⁻¹. A plot is used if its ADS-B position lies inside the
    triangulation of all the centres (the covered area), within ``radius`` of a cell its
    radar sees, and (3-D) it has a height. ``"interpolant"`` with subsets: where the plot
    lies outside the triangulation of its radar's cells, its model is the nearest of them,
    as :class:`~optmodels.biasfield.fieldmap.FieldMap` extends a radar's field there."""
    k, m = data.k, data.m
    keep = seen_entries(data)
    pos = np.cumsum(keep) - 1  # index of a seen entry among the unknowns
    tri = Triangles(data.centers)
    tree = cKDTree(data.centers)
    sums = np.zeros((k, m, 2))
    counts = np.zeros((k, m), dtype=np.int64)
    has = np.all(np.isfinite(ref), axis=1)
    a_rows, a_cols, a_vals, w_list, d_list = [], [], [], [], []
    n_used = moved = 0
    for i in range(m):
        rows = np.flatnonzero(has & (plots.radar == i))
        own, own_tri, own_tree = _own_cells(data, i, tri, tree, model)
        if rows.size == 0 or own_tree is None:
            continue
        y = ref[rows]
        dist, loc = own_tree.query(y)
        # the covered area of the cells (their triangulation), near a cell radar i sees
        ok = (dist <= radius) & (tri.find(y) >= 0)
        if getattr(plots, "height", None) is not None:
            ok &= np.isfinite(np.asarray(plots.height)[rows])
        rows, y, cell = rows[ok], y[ok], own[loc[ok]]
        if rows.size == 0:
            continue
        if own.size < k:
            moved += int(np.sum(~data.subsets[tree.query(y)[1], i]))
        h = None if getattr(plots, "height", None) is None else np.asarray(plots.height)[rows]
        # what radar i would measure of the ADS-B position (3-D: slant range and azimuth
        # in its own frame at the plot's height)
        d = np.column_stack([plots.range[rows], plots.azimuth[rows]]) - radars.to_polar(i, y, h)
        d[:, 1] = wrap_angle(d[:, 1])
        np.add.at(sums[:, i], cell, d)
        np.add.at(counts[:, i], cell, 1)
        bary, verts = _rows_of_a(y, own, cell, own_tri, model)
        base = 2 * (n_used + np.arange(rows.size))
        for comp in (0, 1):
            a_rows.append(np.repeat(base + comp, verts.shape[1]))
            a_cols.append(pos[(2 * (verts * m + i) + comp).ravel()])
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
            f"{fn} reference: no plot with an ADS-B position lies in the covered area "
            "of its radar's cells"
        )
    with_data = counts > 0
    mean = np.full((k, m, 2), np.nan)
    mean[with_data] = sums[with_data] / counts[with_data, None]
    amat = sparse.csr_matrix(
        (np.concatenate(a_vals), (np.concatenate(a_rows), np.concatenate(a_cols))),
        shape=(2 * n_used, int(keep.sum())),
    )
    wmat = sparse.block_diag(list(np.concatenate(w_list)), format="csr")
    unused = int(has.sum()) - n_used
    return AdsbSystem(amat, wmat, np.concatenate(d_list), mean, counts, n_used, keep, moved, unused)


def check_determined(fn: str, data: FieldData, names: tuple[str, ...], sys_: AdsbSystem) -> None:
    """Every radar has ADS-B data on every connected part of its own neighbour graph over
    the cells it sees (:func:`~optmodels.biasfield.problem.radar_parts`); else its constant
    there (the null space of R) is determined by no μ: ProblemError naming the radar and
    the cells (all seen by it)."""
    k, m = data.k, data.m
    touched_all = np.zeros(2 * m * k, dtype=bool)
    touched_all[sys_.keep] = np.asarray(abs(sys_.amat).sum(axis=0)).ravel() > 0
    touched = touched_all.reshape(k, m, 2)[:, :, 0]
    seen = data.subsets
    for i, (n, labels) in enumerate(radar_parts(data)):
        own = seen[:, i]
        has = np.zeros(n, dtype=bool)
        np.logical_or.at(has, labels[own], touched[own, i])
        need = np.unique(labels[own])
        missing = need[~has[need]]
        if missing.size:
            cells = np.flatnonzero((labels == missing[0]) & own)
            raise ProblemError(
                f"{fn} reference: radar {names[i]!r} has no plot with an ADS-B position "
                f"in cells {cells[:10].tolist()}{' …' if cells.size > 10 else ''} (a "
                f"connected part of the cells it sees; {missing.size} of its {need.size} "
                "parts without data): its field there is not determined"
            )


class LevelSolve(NamedTuple):
    """:func:`solve_level`'s answer: φ over the seen entries, χ², μ, the status after the
    re-check, J(φ), the stationarity residual and the conditioning term κ₁·ε."""

    phi: FloatArray
    chi2: float
    mu: float
    status: Status
    objective: float
    stationarity: float
    conditioning: float


class _Scaled(NamedTuple):
    """The factorised Jacobi-scaled matrix S(μR + AᵀWA)S, S = diag(h_jj)^(-1/2)."""

    lu: splinalg.SuperLU
    s: FloatArray
    hs: sparse.csc_matrix


def _factor(fn: str, mu: float, r: sparse.csc_matrix, awa: sparse.csc_matrix) -> _Scaled:
    """S(μR + AᵀWA)S and its sparse LU. The symmetric scaling makes the entries fixed by
    the data (scale AᵀWA) and those fixed by the smoothness alone (scale μR) O(1) alike: at
    the means level (μ → 0) the unscaled matrix has κ ≈ 1e12 · κ(R) and a backward-stable
    solve loses the digits of the second kind (measured: 2.4e-5 relative on the sweep's
    tiny case with a residual of 1e-16)."""
    h = (mu * r + awa).tocsc()
    dg = h.diagonal()
    s = 1.0 / np.sqrt(np.where(dg > 0, dg, 1.0))
    hs = (sparse.diags(s) @ h @ sparse.diags(s)).tocsc()
    try:
        lu = splinalg.splu(hs)
    except RuntimeError:
        raise ProblemError(
            f"{fn}: the system is singular (the data and the smoothness do not determine the field)"
        ) from None
    return _Scaled(lu, s, hs)


def solve_level(fn: str, data: FieldData, sys_: AdsbSystem, level: str) -> LevelSolve:
    """The field of the smoothing weight μ: (μR + AᵀWA)φ = AᵀWd over the seen entries with
    χ²(μ) at the expected level 2·n_used (``"discrepancy"``, bisection in log μ; μ = ∞
    when even the smoothest fields fit) or μ → 0 (``"means"``), re-checked."""
    amat, wmat, dvec = sys_.amat, sys_.wmat, sys_.dvec
    idx = np.flatnonzero(sys_.keep)
    r = r_matrix(data).tocsr()[idx][:, idx].tocsc()
    null = r_null_space(data, seen_only=True)
    awa = (amat.T @ wmat @ amat).tocsc()
    rhs = amat.T @ (wmat @ dvec)
    dof = 2 * sys_.n_used

    def chi(phi: FloatArray) -> float:
        res = amat @ phi - dvec
        return float(res @ (wmat @ res))

    def fit(mu: float) -> tuple[FloatArray, float, _Scaled]:
        f = _factor(fn, mu, r, awa)
        phi = f.s * f.lu.solve(f.s * rhs)
        return phi, chi(phi), f

    # χ²(μ) increases with μ from its least-squares minimum towards that of the smoothest
    # fields (μ → ∞: J = 0, constant per radar on each part of its graph, fitted exactly in
    # that null space); the level is the expected χ² = 2n
    m_null = (null.T @ awa @ null).toarray()
    sn = 1.0 / np.sqrt(np.diag(m_null))
    m_scaled = sn[:, None] * m_null * sn[None, :]
    kappa_inf = float(np.linalg.cond(m_scaled, 1))
    try:
        phi_inf = null @ (sn * np.linalg.solve(m_scaled, sn * (null.T @ rhs)))
    except np.linalg.LinAlgError:
        raise ProblemError(
            f"{fn} reference: the plots do not determine the radars' constants (the "
            "smoothest fields) on the parts of their cells"
        ) from None
    chi_inf = chi(phi_inf)
    status = Status.OPTIMAL
    scale = float(np.log10(max(abs(awa).max(), 1e-300) / max(abs(r).max(), 1e-300)))
    f = None
    if level == "means":  # the least-squares field: the means, smoothness fills the rest
        mu = 10.0 ** (scale - 12.0)
        phi, chi2, f = fit(mu)
    elif chi_inf <= dof:  # even the smoothest fields fit the data: take the best of them
        phi, chi2, mu = phi_inf, chi_inf, float("inf")
    else:
        lo, hi = scale - 20.0, scale + 14.0
        phi, chi2, f = fit(10.0**lo)
        mid = lo
        if chi2 >= dof:  # no field reaches the level: the least-squares one
            status = Status.OPTIMAL_INACCURATE
        else:
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                phi, chi2, f = fit(10.0**mid)
                if chi2 > dof:
                    hi = mid
                else:
                    lo = mid
                # the level itself is uncertain by √(2 dof): 1e-4 relative is ample
                if abs(chi2 - dof) <= 1e-4 * dof or hi - lo < 1e-12:
                    break
            if abs(chi2 - dof) > 1e-2 * dof:
                status = Status.OPTIMAL_INACCURATE
        mu = 10.0**mid
    if not np.all(np.isfinite(phi)):
        raise ProblemError(
            f"{fn}: the solve overflowed (the data and the smoothness do not determine the field)"
        )
    kappa = kappa_inf if f is None else condition_number(f.hs, f.lu)
    resid = _stationarity(phi, mu, awa, rhs, r, null)
    cond = conditioning_residual(kappa)
    status = verified_status(status, max(resid, cond))
    return LevelSolve(phi, chi2, mu, status, float(phi @ (r @ phi)), resid, cond)


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
