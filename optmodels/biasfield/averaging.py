r"""Sampling and averaging of the track fits over the cells (paper 001, (6)-(7)): the
helpers of :func:`~optmodels.biasfield.cells.build_field_data`.

For every object seen by **all** m radars in cell k (or, with ``coverage="union"``, by two
radars or more), the fitted ξ̂_i^a(t) are averaged over the instants τ_(k)^a the object
spent in the cell (a regular grid of instants inside the common span of the fits), then
over the objects. The covariance follows exactly (the average is linear in the fitted
knots; objects and radars are independent).

* :func:`object_samples`: one object's sampling instants and positions;
* :func:`sample_cells`: the cell of each sample, and the samples that count;
* :func:`choose_subsets`: the per-cell radar sets S_k of the union coverage;
* :func:`average_cells` (:func:`accumulate` per object): the per-cell sums (:class:`CellSums`);
* :func:`height_interpolants`: the target heights of a 3-D chain;
* :func:`no_samples_message`: why no sampling instant was found.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.biasfield.tracks import TrackFit
from optmodels.core import FloatArray, ProblemError

__all__ = [
    "MAX_UNION_RADARS",
    "CellSums",
    "Samples",
    "accumulate",
    "average_cells",
    "choose_subsets",
    "height_interpolants",
    "no_samples_message",
    "object_samples",
    "progress_bar",
    "sample_cells",
    "scan_intervals",
]


def scan_intervals(plots: PlotTable, m: int) -> FloatArray:
    """(m,) each radar's median time between consecutive plots of one object (s; NaN for
    a radar without two plots of an object)."""
    out = np.full(m, np.nan)
    ok = plots.object >= 0
    for i in range(m):
        sel = ok & (plots.radar == i)
        if sel.sum() < 2:
            continue
        o, t = plots.object[sel], plots.time[sel]
        order = np.lexsort((t, o))
        o, t = o[order], t[order]
        d = np.diff(t)[np.diff(o) == 0]
        d = d[d > 0]
        if d.size:
            out[i] = float(np.median(d))
    return out


def no_samples_message(
    fn: str, plots: PlotTable, fits: list[TrackFit], knot_spacing: float, union: bool, m: int
) -> str:
    """Why no sampling instant was found: a knot spacing shorter than the scans (every
    track split at each plot, no fit), no fit at all, or the geometry (no object seen by
    all m radars / by two radars at the same time)."""
    scans = scan_intervals(plots, m)
    longest = float(np.nanmax(scans)) if np.isfinite(scans).any() else float("nan")
    if np.isfinite(longest) and knot_spacing < 1.5 * longest:
        return (
            f"{fn} knot_spacing: {knot_spacing:g} s is not longer than the radars' scan "
            f"intervals (median per radar {np.round(scans, 1).tolist()} s): the track "
            "fits split a track at every silence longer than the knot spacing and "
            f"keep {len(fits)} fits; give at least 2 × the longest scan interval "
            f"(e.g. {2 * longest:.0f} s; 20 s for 4-10 s scans)"
        )
    if not fits:
        return (
            f"{fn} plots: no track could be fitted (too few plots per track for the "
            f"polyline of knot spacing {knot_spacing:g} s); no cell can be formed"
        )
    if union:
        return (
            "plots: no object is seen by two radars at the same time (after the "
            "track fits); no cell can be formed"
        )
    return (
        "plots: no object is seen by all m radars at the same time; no cell can be "
        "formed (coverage='union' forms cells wherever two radars overlap)"
    )


#: Most radars of ``build_field_data(coverage="union")`` (one bit of a uint64 each).
MAX_UNION_RADARS = 63

#: One object's samples: (instants t, the present radars, each present radar's piece per
#: instant (−1: none), the positions (mean over the radars with a piece), the radar bits).
Samples = tuple[FloatArray, list[int], np.ndarray, FloatArray, np.ndarray]


def progress_bar(items: list[Any], progress: bool, desc: str) -> Any:
    """``items`` wrapped in a tqdm bar on stderr when ``progress`` and stderr is a
    terminal (and tqdm installed)."""
    if not progress:
        return items
    import sys

    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency of the bench extra
        return items
    return tqdm(items, desc=desc, file=sys.stderr, disable=not sys.stderr.isatty(), leave=False)


def object_samples(
    per_radar: list[list[TrackFit]], sample_step: float, union: bool
) -> Samples | None:
    """The sampling instants of one object (``sample_step`` s apart): inside the common
    span of all m radars' fits (``union`` False, the paper's case), or wherever two radars
    or more have a fit (``union``); None if there is none."""
    present = [i for i, p in enumerate(per_radar) if p]
    if union:
        lo = min(p[0].span[0] for p in (per_radar[i] for i in present))
        hi = max(max(f.span[1] for f in per_radar[i]) for i in present)
    else:
        lo = max(min(f.span[0] for f in p) for p in per_radar)
        hi = min(max(f.span[1] for f in p) for p in per_radar)
    if hi <= lo:
        return None
    t = np.arange(lo, hi, sample_step)
    pidx = np.full((len(present), t.size), -1, dtype=np.int32)
    for ii, i in enumerate(present):
        for j, f in enumerate(per_radar[i]):
            pidx[ii, (t >= f.span[0]) & (t <= f.span[1])] = j
    act = pidx >= 0
    count = act.sum(axis=0)
    ok = count >= 2 if union else np.all(act, axis=0)
    if not ok.any():
        return None
    t, pidx, count = t[ok], pidx[:, ok], count[ok]
    pos = np.zeros((t.size, 2))
    bits = np.zeros(t.size, dtype=np.uint64)
    for ii, i in enumerate(present):
        for j in np.unique(pidx[ii]):
            if j < 0:
                continue
            sel = pidx[ii] == j
            if union:
                pos[sel] += per_radar[i][j].at(t[sel]) / count[sel, None]
            else:
                pos[sel] += per_radar[i][j].at(t[sel]) / len(per_radar)
        bits[pidx[ii] >= 0] |= np.uint64(1 << i)
    return t, present, pidx, pos, bits


def sample_cells(
    pos: FloatArray, tree: cKDTree, cell_radius: float, radars: RadarSet, exclude_radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's nearest cell and the samples that count (within ``cell_radius`` of
    it and farther than ``exclude_radius`` from every radar)."""
    dist, cell = tree.query(pos)
    assert radars.sites is not None  # set by RadarSet.__post_init__
    near = np.min(np.linalg.norm(pos[:, None] - radars.sites[None], axis=2), axis=1)
    return cell, np.flatnonzero((dist <= cell_radius) & (near > exclude_radius))


def choose_subsets(
    objects: list[list[list[TrackFit]]],
    sample_step: float,
    tree: cKDTree,
    cell_radius: float,
    radars: RadarSet,
    exclude_radius: float,
    k0: int,
    share: float,
    progress: bool,
) -> np.ndarray:
    """Per cell the radar set S_k (bits): among the radar sets of its samples, the largest
    contained in the sets of ≥ ``share`` of the samples (ties: the most samples); 0 for a
    cell without samples."""
    counts: dict[tuple[int, int], int] = {}
    for per_radar in progress_bar(objects, progress, "field data: subsets"):
        smp = object_samples(per_radar, sample_step, True)
        assert smp is not None
        cell, idx = sample_cells(smp[3], tree, cell_radius, radars, exclude_radius)
        if idx.size == 0:
            continue
        key = np.column_stack([cell[idx].astype(np.uint64), smp[4][idx]])
        uniq, n = np.unique(key, axis=0, return_counts=True)
        for (c, b), v in zip(uniq.tolist(), n.tolist(), strict=True):
            counts[(c, b)] = counts.get((c, b), 0) + v
    per_cell: dict[int, list[tuple[int, int]]] = {}
    for (c, b), v in counts.items():
        per_cell.setdefault(c, []).append((b, v))
    subset = np.zeros(k0, dtype=np.uint64)
    for c, lst in per_cell.items():
        total = sum(v for _, v in lst)
        best = (-1, -1, 0)
        for b, _ in lst:
            support = sum(v for b2, v in lst if b2 & b == b)
            if support >= share * total:
                cand = (int(b).bit_count(), support, b)
                if cand[:2] > best[:2]:
                    best = cand
        if best[0] >= 2:
            subset[c] = np.uint64(best[2])
    return subset


def accumulate(
    smp: Samples,
    per_radar: list[list[TrackFit]],
    tree: cKDTree,
    cell_radius: float,
    radars: RadarSet,
    exclude_radius: float,
    sample_step: float,
    plot_times: FloatArray,
    height_of: dict[int, tuple[FloatArray, FloatArray]],
    subset: np.ndarray | None,
    sum_xi: FloatArray,
    sum_cov: FloatArray,
    sum_h: FloatArray,
    n_obj: np.ndarray,
    n_smp: np.ndarray,
    n_plt: np.ndarray,
) -> None:
    """One object's share of the averages (6)-(7), added in place to the per-cell sums.

    The object's sampling instants (positions, each present radar's piece) are sorted by
    cell once (stable: time order kept inside a cell); per radar and piece ONE
    :meth:`TrackFit.means_over` gives the means and covariances over all the cells at
    once (the same numbers as one :meth:`TrackFit.mean_over` per cell), and the plots
    behind each (cell, piece) are counted by binary search in the piece's sorted plot
    times: O(samples log) per object instead of O(samples × cells crossed) Python calls.

    ``subset`` (K,) radar bits S_k (union coverage): only the samples whose radar set
    contains S_k count for cell k, and only the radars of S_k are averaged there."""
    t, present, pidx, pos, bits = smp
    cell, idx = sample_cells(pos, tree, cell_radius, radars, exclude_radius)
    if subset is not None and idx.size:
        need = subset[cell[idx]]
        idx = idx[(need != 0) & ((bits[idx] & need) == need)]
    if idx.size == 0:
        return
    idx = idx[np.argsort(cell[idx], kind="stable")]
    cs = cell[idx]
    first = np.flatnonzero(np.concatenate([[True], cs[1:] != cs[:-1]]))
    cells_here = cs[first]
    n_sel = np.diff(np.append(first, cs.size))
    grp = np.repeat(np.arange(first.size), n_sel)  # cell label 0..G−1 of each sample
    n_obj[cells_here] += 1
    n_smp[cells_here] += n_sel
    ts_all = t[idx]
    if radars.is_3d:
        ht, hv = height_of[per_radar[present[0]][0].object]
        sum_h[cells_here] += np.bincount(grp, np.interp(ts_all, ht, hv)) / n_sel
    for ii, i in enumerate(present):
        pieces_i = pidx[ii, idx]
        if subset is not None:  # radar i only in the cells whose S_k holds it
            mine = ((subset[cs] >> np.uint64(i)) & np.uint64(1)) == 1
            pieces_i = np.where(mine, pieces_i, -1)
        for j in np.unique(pieces_i):
            if j < 0:
                continue
            fit = per_radar[i][j]
            on = pieces_i == j
            ts, g = ts_all[on], grp[on]
            # the cells this piece covers, relabelled 0..G'−1 (g is sorted)
            starts = np.flatnonzero(np.concatenate([[True], g[1:] != g[:-1]]))
            local = np.repeat(np.arange(starts.size), np.diff(np.append(starts, g.size)))
            gs = g[starts]
            kk = cells_here[gs]
            mean_p, cov_p = fit.means_over(ts, local)
            w = np.diff(np.append(starts, g.size)) / n_sel[gs]
            sum_xi[kk, i] += w[:, None] * mean_p
            sum_cov[kk, i] += (w * w)[:, None, None] * cov_p
            pt = plot_times[fit.rows]
            if np.any(pt[1:] < pt[:-1]):
                pt = np.sort(pt)
            lo = np.minimum.reduceat(ts, starts)
            hi = np.maximum.reduceat(ts, starts) + sample_step
            n_plt[kk] += np.searchsorted(pt, hi, side="right") - np.searchsorted(
                pt, lo, side="left"
            )


def height_interpolants(plots: PlotTable) -> dict[int, tuple[FloatArray, FloatArray]]:
    """Per object: the (time, height) of its plots with a known height (all radars), sorted
    by time, for np.interp (the target's height as ADS-B or a corrected flight level gives
    it, the same for every radar)."""
    if plots.height is None:
        raise ProblemError(
            "biasfield.build_field_data plots: a 3-D radar set needs the "
            "target heights (PlotTable height)"
        )
    ok = ~np.isnan(plots.height) & (plots.object >= 0)
    obj, t, h = plots.object[ok], plots.time[ok], plots.height[ok]
    order = np.lexsort((t, obj))
    obj, t, h = obj[order], t[order], h[order]
    cuts = np.flatnonzero(np.diff(obj)) + 1
    return {
        int(o[0]): (tt, hh)
        for o, tt, hh in zip(np.split(obj, cuts), np.split(t, cuts), np.split(h, cuts), strict=True)
        if o.size
    }


@dataclass
class CellSums:
    """The per-cell sums of the averages (6)-(7) over K cells and m radars: ``xi`` (K, m, 2)
    Σ weights·mean, ``cov`` (K, m, 2, 2) Σ weights²·covariance, ``height`` (K,) Σ mean
    target heights, and the counts of objects, samples and plots per cell."""

    xi: FloatArray
    cov: FloatArray
    height: FloatArray
    objects: np.ndarray
    samples: np.ndarray
    plots: np.ndarray

    @classmethod
    def zeros(cls, k: int, m: int) -> CellSums:
        return cls(
            np.zeros((k, m, 2)),
            np.zeros((k, m, 2, 2)),
            np.zeros(k),
            np.zeros(k, dtype=int),
            np.zeros(k, dtype=int),
            np.zeros(k, dtype=int),
        )


def average_cells(
    objects: list[list[list[TrackFit]]],
    *,
    k: int,
    tree: cKDTree,
    cell_radius: float,
    radars: RadarSet,
    exclude_radius: float,
    sample_step: float,
    union: bool,
    plot_times: FloatArray,
    height_of: dict[int, tuple[FloatArray, FloatArray]],
    subset: np.ndarray | None,
    progress: bool,
) -> CellSums:
    """The sums of (6)-(7) over the ``k`` cells: :func:`accumulate` for each object
    (``objects``: per object its fits per radar, sorted by time)."""
    sums = CellSums.zeros(k, radars.m)
    for per_radar in progress_bar(objects, progress, "field data: averaging"):
        smp = object_samples(per_radar, sample_step, union)
        assert smp is not None
        accumulate(
            smp,
            per_radar,
            tree,
            cell_radius,
            radars,
            exclude_radius,
            sample_step,
            plot_times,
            height_of,
            subset,
            sums.xi,
            sums.cov,
            sums.height,
            sums.objects,
            sums.samples,
            sums.plots,
        )
    return sums
