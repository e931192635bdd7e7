"""Paper 001 demo: a simulated network of four radars with smooth bias fields, end to end —
plots → track fits → cells → uncertainty sets → the smoothest field (closed form (11), the
QP with and without the box (8), the Lipschitz SOCP) — with maps like the paper's fig. 4,
and the parametric baseline of section 2 that fails on a non-constant field."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from optmodels import biasfield as bf
from optmodels import plots
from optmodels.biasfield import selection as sel
from optmodels.io import markdown_table, write_json
from optmodels.scenarios.radar_network import radar_network

__all__ = ["run_biasfield_demo"]


def _true_at_cells(sc: Any, fd: bf.FieldData) -> np.ndarray:
    """True f_i at each cell, evaluated at the cell's mean biased position (the truth the
    sets are built around, up to the shift the data cannot see)."""
    x = fd.xi.mean(axis=1)
    return np.stack([sc.fields[i](x) for i in range(fd.m)], axis=1)


def _rms(a: np.ndarray) -> tuple[float, float]:
    r = np.sqrt(np.nanmean(a**2, axis=(0, 1)))
    return float(r[0]), float(np.rad2deg(r[1]))


def _baseline_rows(seed: int) -> list[dict[str, Any]]:
    out = []
    for kind in ("constant", "smooth"):
        sc = radar_network(seed + 10, n_aircraft=30, duration=1800.0, turn_rate=(0.0, 0.0),
                           fields=kind)  # type: ignore[arg-type]
        res = bf.azimuth_bias_baseline(sc.plots, sc.radars)
        ids = np.unique(sc.plots.object)
        h1 = bf.azimuth_bias_baseline(sc.plots, sc.radars, objects=ids[::2])
        h2 = bf.azimuth_bias_baseline(sc.plots, sc.radars, objects=ids[1::2])
        z = (h1.estimate - h2.estimate) / np.hypot(h1.std, h2.std)
        true = np.array([f(np.zeros((1, 2)))[0, 1] for f in sc.fields])
        out.append({
            "field": kind,
            "Δα̂, deg": ", ".join(f"{v:.3f}" for v in np.rad2deg(res.estimate)),
            "se, deg": ", ".join(f"{v:.4f}" for v in np.rad2deg(res.std)),
            "true Δα at origin, deg": ", ".join(f"{v:.3f}" for v in np.rad2deg(true)),
            "χ²/dof": res.chi2_per_dof, "p-value": res.p_value,
            "max |halves z|": float(np.max(np.abs(z)))})
    return out


def run_biasfield_demo(out: Path, *, seed: int = 0, n_aircraft: int = 80,
                       duration: float = 2400.0, cells: int = 150,
                       progress: bool = False) -> dict[str, Any]:
    """Writes ``out/azimuth_maps.png``, ``out/range_maps.png``, ``out/report.md`` and
    ``out/summary.json``; returns the summary."""
    del progress  # every step takes a second or less
    out.mkdir(parents=True, exist_ok=True)
    sc = radar_network(seed, n_aircraft=n_aircraft, duration=duration, fields="smooth")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fd, diag = bf.build_field_data(sc.plots, sc.radars, cells=cells, seed=seed)
    chk = bf.residual_check(diag.fits, fd.m)
    truth = _true_at_cells(sc, fd)
    cf = bf.closed_form(fd)
    qp = bf.solve(fd)
    qpc = bf.solve(fd, formulation="constrained")
    big = np.abs(cf.field).max(axis=(0, 1))
    box = (0.6 * float(big[0]), 0.6 * float(big[1]))
    frac = 0.6
    while sel.box_feasibility(fd, box).size and frac < 1.0:
        frac += 0.05
        box = (frac * float(big[0]), frac * float(big[1]))
    qb = bf.solve(fd, box=box)
    lip = bf.solve_lipschitz(fd)
    idf = sel.identifiability(fd)
    methods = {"closed form (11)": cf, "QP reduced (Clarabel)": qp,
               "QP constrained (Clarabel)": qpc, f"QP + box at {frac:.0%}": qb,
               "Lipschitz SOCP": lip}
    rows = []
    for name, s in methods.items():
        rr, ra = _rms(s.field - truth)
        rows.append({"method": name, "status": s.status.value, "J = φᵀRφ": s.objective,
                     "J / J(11)": s.objective / cf.objective,
                     "max |Δ vs (11)|, m": float(np.max(np.abs(s.field - cf.field)[..., 0])),
                     "active bounds": int(np.sum(s.active != 0)),
                     "L (max jump)": s.lipschitz if s.lipschitz is not None else float("nan"),
                     "RMS error range, m": rr, "RMS error azimuth, deg": ra,
                     "solve, s": s.solve_time + s.build_time})
    tr_r, tr_a = _rms(truth)
    # truth on a grid for the maps
    gx = np.linspace(-180e3, 180e3, 120)
    gy = np.linspace(-180e3, 180e3, 120)
    gxx, gyy = np.meshgrid(gx, gy)
    pts = np.stack([gxx, gyy], axis=-1)
    gv = np.stack([sc.fields[i](pts) for i in range(fd.m)], axis=-2)  # (ny, nx, m, 2)
    panels = {"smoothest (11)": cf.field, f"with box {frac:.0%}": qb.field}
    fig_a = plots.bias_maps(out / "azimuth_maps.png", fd.centers, panels, fd.radars,
                            component=1, truth_grid=(gx, gy, gv[..., 1]),
                            names=sc.radars.names)
    fig_r = plots.bias_maps(out / "range_maps.png", fd.centers, panels, fd.radars,
                            component=0, truth_grid=(gx, gy, gv[..., 0]),
                            names=sc.radars.names)
    base = _baseline_rows(seed)
    chk_rows = [{"radar": sc.radars.names[i], "χ²/dof": float(chk.chi2[i] / chk.dof[i]),
                 "mean whitened residual": f"{chk.mean[i, 0]:+.3f}, {chk.mean[i, 1]:+.3f}",
                 "plots": int(sum(f.rows.size for f in diag.fits if f.radar == i))}
                for i in range(fd.m)]
    summary = {"seed": seed, "cells": fd.k, "dropped_cells": diag.dropped_cells,
               "dropped_plots": diag.dropped_plots, "plots": len(sc.plots),
               "methods": rows, "baseline": base, "condition": idf.condition,
               "residual_check": chk_rows, "box": box}
    write_json(out / "summary.json", summary)
    fmt = {"J = φᵀRφ": ".4g", "J / J(11)": ".6f", "max |Δ vs (11)|, m": ".1e",
           "L (max jump)": ".3g", "RMS error range, m": ".1f", "RMS error azimuth, deg": ".4f",
           "solve, s": ".3f", "χ²/dof": ".3f", "p-value": ".3g", "max |halves z|": ".1f"}
    warn_text = "; ".join(str(w.message) for w in caught) or "none"
    worst = idf.worst[:5]
    report = f"""# Radar bias fields (paper 001)

Four radars (crosses), {n_aircraft} aircraft over {duration / 60:.0f} min, smooth bias fields
(range ±150 m, azimuth ±0.3° scale), σ_r = {sc.radars.sigma_range[0]:.0f} m,
σ_az = {np.rad2deg(sc.radars.sigma_azimuth[0]):.2f}°: {len(sc.plots)} plots.

## Pipeline (part 1)

Track fits (GLS polylines, knots every 20 s) per radar and object, then {cells} k-means
cells; {fd.k} cells hold objects seen by all four radars (warnings: {warn_text}).
Plots dropped: {diag.dropped_plots or "none"}. Residual check of the track model:

{markdown_table(chk_rows, list(chk_rows[0]), fmt)}
χ²/dof slightly above 1 is the polyline's error in turns (docs/formulations.md).

## The smoothest field (part 2)

Uncertainty sets (10) (Φ¹ block-diagonal), J = φᵀ(Q ⊗ P)φ with P = diag(1/σ_r², 1/σ_az²)
per radar. RMS of the true field over the cells: {tr_r:.1f} m, {tr_a:.4f}°. The error
includes the per-cell common shift that no method can recover; the box is the smallest of
60 %, 65 %, … of the unconstrained field's largest |f| that every cell's set meets.

{markdown_table(rows, list(rows[0]), fmt)}
![azimuth]({fig_a.name})

![range]({fig_r.name})

Identifiability: cond(Φ¹ᵀRΦ¹) = {idf.condition:.3g}; the least determined cells (largest
spread of their common shift per unit √J) are {worst.tolist()}, at
{", ".join(f"({c[0] / 1e3:.0f}, {c[1] / 1e3:.0f}) km" for c in fd.centers[worst])} — at the
edge of the traffic, with few neighbours.

## The parametric baseline (section 2)

A constant azimuth bias per radar, (2)-(4), by GLS with the trajectories eliminated; the
same straight-flight traffic with a constant field, then with a smooth one. "max |halves
z|": the largest difference between the estimates from two halves of the trajectories, in
standard errors.

{markdown_table(base, list(base[0]), fmt)}
Exact for a constant field; for a smooth field the χ² test rejects it and different
trajectories give incompatible estimates — the paper's observation.
"""
    (out / "report.md").write_text(report)
    return summary
