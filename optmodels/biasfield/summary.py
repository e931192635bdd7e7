r"""Per-radar figures of an estimated field, as air-traffic registration tools report them
(paper 001's parametric model (2), extended by a range gain, fitted to the field).

For radar i over the cells k it sees (S_i), the field's range component is fitted by
least squares with a constant and a gain on the range, f_r(x_k) ≈ b_r + g·ρ_ik (ρ_ik the
distance from the radar's site to the cell centre on the common plane, m), and the
azimuth component by a constant, f_α(x_k) ≈ b_α. The ± are the standard errors of those
least-squares fits, s²(AᵀA)⁻¹ with s² the residual variance: they say how well the
constant-plus-gain baseline describes the field over the radar's coverage, treating the
cells as independent, not how well the data determine the field. Beside them, the field's
spread (standard deviation over S_i of each component) and the RMS residual of the
baseline: a field the baseline describes has a residual far below its spread.

The field is determined up to a per-cell common shift of all radars (paper 001, section 3;
the smoothest field removes it), so the constant biases are those of the smoothest
solution: a bias common to every radar (the whole network turned or stretched together)
is not seen by cross-radar data.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import ProblemError, as_finite_array

__all__ = ["radar_baseline"]


def _fit(a: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Least squares y ≈ a·β: (β, standard errors, RMS residual); NaN errors when the fit
    has no residual degree of freedom."""
    beta, *_ = np.linalg.lstsq(a, y, rcond=None)
    res = y - a @ beta
    dof = y.size - a.shape[1]
    rms = float(np.sqrt(np.mean(res * res)))
    if dof <= 0:
        return beta, np.full(a.shape[1], np.nan), rms
    s2 = float(res @ res) / dof
    try:
        cov = s2 * np.linalg.inv(a.T @ a)
    except np.linalg.LinAlgError:
        return beta, np.full(a.shape[1], np.nan), rms
    return beta, np.sqrt(np.maximum(np.diag(cov), 0.0)), rms


def radar_baseline(
    field: ArrayLike,
    centers: ArrayLike,
    sites: ArrayLike,
    seen: ArrayLike | None = None,
    names: tuple[str, ...] | list[str] = (),
) -> list[dict[str, Any]]:
    """Per radar: constant range and azimuth bias ± σ, range gain ± σ, the field's spread
    and the baseline's residual (module docstring).

    Parameters
    ----------
    field : (K, m, 2)
        The field at the cells: range bias (m), azimuth bias (rad).
    centers : (K, 2)
        Cell centres on the common plane (m).
    sites : (m, 2)
        The radars' East-North on the common plane (m).
    seen : (K, m) bool, optional
        Radar i sees cell k (default: every radar every cell).
    names : radar names (default ``R1`` ...).

    Returns
    -------
    list of dict
        One per radar, units in the keys: ``radar``, ``cells``, ``range_bias_m``,
        ``range_bias_sigma_m``, ``range_gain_ppm`` (10⁻⁶ m per m of range),
        ``range_gain_sigma_ppm``, ``azimuth_bias_deg``, ``azimuth_bias_sigma_deg``,
        ``range_spread_m``, ``azimuth_spread_deg`` (standard deviations of the field over
        the radar's cells), ``baseline_residual_range_m``,
        ``baseline_residual_azimuth_deg`` (RMS of the field less the baseline).
    """
    fn = "biasfield.radar_baseline"
    f = as_finite_array(f"{fn} field", field, ndim=3)
    k, m = f.shape[:2]
    c = as_finite_array(f"{fn} centers (m)", centers, shape=(k, 2))
    s = as_finite_array(f"{fn} sites (m)", sites, shape=(m, 2))
    sub = np.ones((k, m), dtype=bool) if seen is None else np.asarray(seen, dtype=bool)
    if sub.shape != (k, m):
        raise ProblemError(f"{fn} seen: expected ({k}, {m}), got {sub.shape}")
    labels = tuple(names) if names else tuple(f"R{i + 1}" for i in range(m))
    out = []
    for i in range(m):
        idx = np.flatnonzero(sub[:, i])
        row: dict[str, Any] = {"radar": labels[i], "cells": int(idx.size)}
        if idx.size == 0:
            out.append(row)
            continue
        rho = np.hypot(*(c[idx] - s[i]).T)
        fr, fa = f[idx, i, 0], np.rad2deg(f[idx, i, 1])
        if idx.size >= 2 and np.ptp(rho) > 0:
            beta, se, rms_r = _fit(np.column_stack([np.ones(idx.size), rho]), fr)
        else:
            beta, se, rms_r = np.array([fr.mean(), np.nan]), np.full(2, np.nan), 0.0
        ba, sa, rms_a = _fit(np.ones((idx.size, 1)), fa)
        row.update(
            {
                "range_bias_m": float(beta[0]),
                "range_bias_sigma_m": float(se[0]),
                "range_gain_ppm": float(beta[1] * 1e6),
                "range_gain_sigma_ppm": float(se[1] * 1e6),
                "azimuth_bias_deg": float(ba[0]),
                "azimuth_bias_sigma_deg": float(sa[0]),
                "range_spread_m": float(np.std(fr)),
                "azimuth_spread_deg": float(np.std(fa)),
                "baseline_residual_range_m": rms_r,
                "baseline_residual_azimuth_deg": rms_a,
            }
        )
        out.append(row)
    return out
