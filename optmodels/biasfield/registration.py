r"""Cross-radar registration error (paper 001's aim, measured): :func:`registration_error`
and :class:`RegistrationError` (per-area means of the difference between two radars'
positions of the same aircraft at the same time, their noise removed). Split out of
``usage.py``; the names are re-exported there unchanged."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.fieldmap import FieldMap
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_instance,
    as_positive,
)

__all__ = ["RegistrationError", "registration_error"]


# ----------------------------------------------------------------------------- registration
@dataclass(frozen=True)
class RegistrationError:
    """Cross-radar disagreement (m) on the common plane.

    ``overall`` and ``pairs[(a, b)]`` (radar names): the RMS over areas of the per-area
    mean horizontal difference between the two radars' positions of the same aircraft at
    the same time, with the noise part of each squared mean (its sample variance / n)
    removed (so that a perfectly registered network scores ≈ 0, not σ/√n); areas weighted
    by their sample counts (areas seen by fewer than 2 aircraft are left out).
    ``noise`` / ``noise_pairs``: the RMS standard error of the area means, the scale below
    which a disagreement is not seen (a perfectly registered network reads 0 to ~this).
    ``raw_overall`` / ``raw_pairs``: the plain RMS of the
    per-sample differences (noise included). ``samples`` per pair, ``areas`` per pair.
    """

    overall: float
    pairs: dict[tuple[str, str], float]
    raw_overall: float
    raw_pairs: dict[tuple[str, str], float]
    samples: dict[tuple[str, str], int]
    areas: dict[tuple[str, str], int]
    area: float
    noise: float = float("nan")
    noise_pairs: dict[tuple[str, str], float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        def key(p: tuple[str, str]) -> str:
            return f"{p[0]}-{p[1]}"

        return {
            "overall_m": self.overall,
            "raw_overall_m": self.raw_overall,
            "noise_m": self.noise,
            "area_m": self.area,
            "pairs": {
                key(p): {
                    "rms_m": v,
                    "raw_rms_m": self.raw_pairs[p],
                    "noise_m": self.noise_pairs.get(p, float("nan")),
                    "samples": self.samples[p],
                    "areas": self.areas[p],
                }
                for p, v in self.pairs.items()
            },
        }


def plane_positions(
    fn: str, plots: PlotTable, radars: RadarSet, positions: ArrayLike | None
) -> FloatArray:
    """The plots' positions (n, 2) on the common plane: ``positions`` checked, or computed
    (``plots.cartesian(radars)``, exact in 3-D)."""
    if positions is None:
        return plots.cartesian(radars)
    return as_finite_array(
        f"{fn} positions (m)", positions, shape=(len(plots), 2), max_abs=MAX_MAGNITUDE
    )


def _local_quadratic(
    t: FloatArray, z: FloatArray, tq: FloatArray, half: float
) -> tuple[FloatArray, np.ndarray]:
    """Radar j's track at times ``tq``: a least-squares quadratic in time through its plots
    (t, z) within ±``half`` s of each query time (≥ 2 plots on each side). Returns (q, 2)
    positions and the mask of the times that could be served."""
    lo = np.searchsorted(t, tq - half, side="left")
    hi = np.searchsorted(t, tq + half, side="right")
    mid = np.searchsorted(t, tq, side="left")
    ok = ((mid - lo) >= 2) & ((hi - mid) >= 2)
    out = np.full((tq.size, 2), np.nan)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return out, ok
    # batched: every query's window padded to the widest, 3x3 normal equations per query
    width = int(np.max(hi[idx] - lo[idx]))
    take = lo[idx, None] + np.arange(width)[None, :]
    mask = take < hi[idx, None]
    take = np.minimum(take, t.size - 1)
    dt = np.where(mask, t[take] - tq[idx, None], 0.0)
    w = mask.astype(float)
    basis = np.stack([w, w * dt, w * dt * dt], axis=-1)  # (q, width, 3), zero rows padded
    normal = np.einsum("qwa,qwb->qab", basis, basis)
    rhs = np.einsum("qwa,qwc->qac", basis, z[take] * w[..., None])
    out[idx] = (np.linalg.pinv(normal) @ rhs)[:, 0, :]  # pinv: robust to repeated times
    return out, ok


def systematic_square(d: FloatArray, obj: np.ndarray) -> tuple[float, float] | None:
    """|d̄|² less its noise, an unbiased estimate of the squared systematic difference (it
    can be negative; only sums of it are clipped at 0): the area mean d̄ over every
    sample, and its variance estimated from the scatter of the per-aircraft means about
    it (aircraft are independent; the samples of one aircraft are not: neighbouring plots
    share the interpolating track). Returns (that estimate, var(d̄)); None with fewer than 2
    aircraft."""
    labels, inv, counts = np.unique(obj, return_inverse=True, return_counts=True)
    if labels.size < 2:
        return None
    sums = np.zeros((labels.size, 2))
    np.add.at(sums, inv.ravel(), d)
    n = float(counts.sum())
    mean = sums.sum(axis=0) / n
    dev = sums - counts[:, None] * mean  # n_o (d̄_o − d̄)
    var = float(np.sum(dev * dev)) / n**2 * labels.size / (labels.size - 1)
    return float(mean @ mean) - var, var


def registration_error(
    plots: PlotTable,
    radars: RadarSet,
    *,
    area: float = 25e3,
    window: float | None = None,
    min_samples: int = 20,
    within: FieldMap | None = None,
    positions: ArrayLike | None = None,
) -> RegistrationError:
    """RMS horizontal distance (m) between two radars' positions of the same aircraft at
    the same time, per radar pair and overall, measured on per-area means.

    For each aircraft (``object`` ≥ 0) and ordered pair of radars (a, b), b's track is
    interpolated at a's plot times (local quadratic through b's plots within ±``window``
    s; default 2.5 × b's median scan interval) and the difference d = z_a − ẑ_b taken on
    the common plane. The differences are grouped by area (squares of side ``area`` m on
    the common plane, about each plot's position); in each area with ≥ ``min_samples``
    differences from ≥ 2 aircraft, the mean d̄ less its noise variance (estimated from the
    scatter of the per-aircraft means, which are independent) gives the systematic part
    |d̄|² − var(d̄). The pair's figure is the sample-weighted RMS of these over its
    areas (the weighted mean of the squares, clipped at 0 before the root; both orders
    (a, b) and (b, a) pooled), the overall figure the same over every pair. ``within``:
    only positions in the covered area of this :class:`FieldMap` (to compare before and
    after a correction on the same area). ``positions`` (n, 2) m: the plots' plane
    positions if already computed (``plots.cartesian(radars)``; in 3-D ~11 s per 10⁶ plots).
    """
    fn = "biasfield.registration_error"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    area = as_positive(f"{fn} area (m)", area)
    if window is not None:
        window = as_positive(f"{fn} window (s)", window)
    min_samples = as_count(f"{fn} min_samples", min_samples, minimum=2)
    if within is not None:
        within = as_instance(f"{fn} within", within, FieldMap)
        within.check_radars(radars, f"{fn} within")
    plots.check(radars)
    z = plane_positions(fn, plots, radars, positions)
    inside = np.ones(len(plots), dtype=bool) if within is None else within.covered(z)
    keep = plots.object >= 0
    rows_of: dict[tuple[int, int], list[int]] = {}
    for idx in np.flatnonzero(keep):
        rows_of.setdefault((int(plots.object[idx]), int(plots.radar[idx])), []).append(int(idx))
    tracks: dict[tuple[int, int], np.ndarray] = {}
    for key, rows in rows_of.items():
        r = np.asarray(rows)
        tracks[key] = r[np.argsort(plots.time[r], kind="stable")]
    half = {}
    for i in range(radars.m):
        gaps = [np.diff(plots.time[r]) for (_, j), r in tracks.items() if j == i and r.size > 1]
        g = np.concatenate(gaps) if gaps else np.array([])
        g = g[g > 0]
        half[i] = window if window is not None else (2.5 * float(np.median(g)) if g.size else 1.0)
    diffs: dict[tuple[int, int], list[FloatArray]] = {}
    where: dict[tuple[int, int], list[FloatArray]] = {}
    owner: dict[tuple[int, int], list[np.ndarray]] = {}
    for (obj, a), ra in tracks.items():
        for b in range(radars.m):
            if b == a or (obj, b) not in tracks:
                continue
            rb = tracks[(obj, b)]
            if rb.size < 4:
                continue
            zb, ok = _local_quadratic(plots.time[rb], z[rb], plots.time[ra], half[b])
            ok &= inside[ra]
            if not ok.any():
                continue
            pair = (min(a, b), max(a, b))
            sign = 1.0 if a < b else -1.0  # both orders as z_min(a,b) − z_max(a,b)
            diffs.setdefault(pair, []).append(sign * (z[ra][ok] - zb[ok]))
            where.setdefault(pair, []).append(z[ra][ok])
            owner.setdefault(pair, []).append(np.full(int(ok.sum()), obj))
    names = radars.names
    pairs: dict[tuple[str, str], float] = {}
    raw: dict[tuple[str, str], float] = {}
    count: dict[tuple[str, str], int] = {}
    areas: dict[tuple[str, str], int] = {}
    floor: dict[tuple[str, str], float] = {}
    tot_sys = tot_raw = tot_var = 0.0
    tot_n = tot_raw_n = 0
    for pair in sorted(diffs):
        d = np.vstack(diffs[pair])
        pos = np.vstack(where[pair])
        cell = np.floor(pos / area).astype(np.int64)
        _, label = np.unique(cell, axis=0, return_inverse=True)
        label = label.ravel()
        sys_sum = var_sum = 0.0
        n_used = 0
        n_areas = 0
        objects = np.concatenate(owner[pair])
        for c in np.unique(label):
            sel = label == c
            dc, oc = d[sel], objects[sel]
            if dc.shape[0] < min_samples:
                continue
            est = systematic_square(dc, oc)
            if est is None:
                continue
            sys_sum += dc.shape[0] * est[0]
            var_sum += dc.shape[0] * est[1]
            n_used += dc.shape[0]
            n_areas += 1
        named = (names[pair[0]], names[pair[1]])
        raw[named] = float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
        pairs[named] = float(np.sqrt(max(sys_sum, 0.0) / n_used)) if n_used else float("nan")
        count[named] = int(d.shape[0])
        areas[named] = n_areas
        floor[named] = float(np.sqrt(var_sum / n_used)) if n_used else float("nan")
        tot_var += var_sum
        tot_sys += sys_sum
        tot_n += n_used
        tot_raw += float(np.sum(d * d))
        tot_raw_n += d.shape[0]
    if not pairs:
        raise ProblemError(
            f"{fn} plots: no aircraft is seen by two radars at the same time (nothing to register)"
        )
    overall = float(np.sqrt(max(tot_sys, 0.0) / tot_n)) if tot_n else float("nan")
    noise = float(np.sqrt(tot_var / tot_n)) if tot_n else float("nan")
    return RegistrationError(
        overall, pairs, float(np.sqrt(tot_raw / tot_raw_n)), raw, count, areas, area, noise, floor
    )
