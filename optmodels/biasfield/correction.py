r"""Plots corrected with a bias field (paper 001, after section 4): :func:`correct_plots`
(f_i subtracted from radar i's range and azimuth at each plot's position, fixed point),
:class:`Corrected` and the reasons a plot is left as read (:data:`REASONS`,
:func:`seen_by_others`). Split out of ``usage.py``; the names are re-exported there
unchanged."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace

import numpy as np

from optmodels.biasfield.fieldmap import FieldMap
from optmodels.biasfield.geometry import wrap_angle
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import (
    FloatArray,
    as_count,
    as_instance,
    as_positive,
)

__all__ = ["REASONS", "Corrected", "correct_plots", "seen_by_others"]


# ----------------------------------------------------------------------------- correct
@dataclass(frozen=True)
class Corrected:
    """:func:`correct_plots`' result: the corrected ``plots`` (same rows and order), the
    ``bias`` (n, 2) subtracted from each (range m, azimuth rad; 0 where not corrected) and
    ``covered`` (n,) where the field was defined (elsewhere the plot is left as read);
    ``reason`` (n,) object array of str, why (:data:`REASONS`): ``"covered"``,
    ``"one radar only"`` (no other radar has a plot of the same object within ``window``
    s: no cross-radar data can place a field there) or ``"outside every cell"`` (seen by
    two radars or more, or of an unknown object, but outside the cells of its radar)."""

    plots: PlotTable
    bias: FloatArray
    covered: np.ndarray
    reason: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))

    @property
    def n_uncovered(self) -> int:
        return int(np.sum(~self.covered))


#: The values of :attr:`Corrected.reason`.
REASONS = ("covered", "one radar only", "outside every cell")

#: Plots corrected per block by :func:`correct_plots` (the memory of one block's
#: interpolation, ~0.2 GB, instead of the recording's).
CORRECT_CHUNK = 1 << 20

#: Plots per group of whole objects in :func:`seen_by_others` (its sort keys, ~80 B a
#: plot, scale with the group, not the recording).
SEEN_CHUNK = 1 << 21


def seen_by_others(plots: PlotTable, window: float = 60.0) -> np.ndarray:
    """(n,) True where another radar has a plot of the same object (``plots.object`` ≥ 0)
    within ``window`` seconds: the plot is seen by two radars or more."""
    plots = as_instance("biasfield.seen_by_others plots", plots, PlotTable)
    window = as_positive("biasfield.seen_by_others window (s)", window)
    return _seen(plots, window, None)


def _seen(plots: PlotTable, window: float, want: np.ndarray | None) -> np.ndarray:
    """:func:`seen_by_others`, in groups of whole objects of about :data:`SEEN_CHUNK`
    plots; with ``want`` (n,) only the groups holding an object of a wanted plot (False
    elsewhere).

    One sorted key per (object, time), objects spaced farther apart than any time gap
    (the same keys for every group, so the same comparisons whatever the grouping): a
    plot is seen by another radar when the plots within ``window`` of its key are not all
    of its radar (a change of radar inside that run of the sorted keys)."""
    n = len(plots)
    out = np.zeros(n, dtype=bool)
    obj, time = plots.object, plots.time
    known = obj >= 0
    if not known.any():
        return out
    t0 = time.min(initial=np.inf, where=known)
    span = float(time.max(initial=-np.inf, where=known) - t0) + 4.0 * window + 1.0
    ids, counts = np.unique(obj if known.all() else obj[known], return_counts=True)
    del known
    # groups of consecutive ids with about SEEN_CHUNK plots (an object is never split)
    cut = np.searchsorted(np.cumsum(counts), np.arange(SEEN_CHUNK, n, SEEN_CHUNK), "right")
    bounds = np.unique(np.concatenate([[0], cut, [ids.size]]))
    wanted = None if want is None else np.unique(obj[want & (obj >= 0)])
    for a, b in itertools.pairwise(bounds.tolist()):
        lo_id, hi_id = ids[a], ids[b - 1]
        if wanted is not None and np.searchsorted(wanted, lo_id) == np.searchsorted(
            wanted, hi_id, "right"
        ):
            continue  # no wanted object in this group
        sel = np.flatnonzero((obj >= lo_id) & (obj <= hi_id))
        key = obj[sel].astype(np.float64)
        key *= span
        key += time[sel] - t0
        order = np.argsort(key, kind="stable")
        key = key[order]
        sel = sel[order]
        del order
        r = plots.radar[sel]
        # changes[j]: radar changes between sorted positions up to j
        changes = np.zeros(sel.size, dtype=np.int64)
        np.cumsum(r[1:] != r[:-1], out=changes[1:])
        del r
        first = np.searchsorted(key, key - window, "left")
        last = np.searchsorted(key, key + window, "right") - 1  # ≥ the plot's own position
        out[sel] = changes[last] > changes[first]
    return out


def correct_plots(
    plots: PlotTable, radars: RadarSet, field: FieldMap, *, passes: int = 2, window: float = 60.0
) -> Corrected:
    """Plots with the estimated bias removed: range − f_r(x), azimuth − f_α(x) for each
    plot of radar i, x its position on the common plane.

    The bias is a function of the true position; it is evaluated at the plot's position,
    then (``passes`` ≥ 2) again at the corrected position (a fixed-point iteration that
    converges at the rate ‖∇f‖ ≈ 1e-3 per pass). Plots outside the covered area are left
    uncorrected and flagged in ``covered``, with the ``reason`` per plot
    (:attr:`Corrected.reason`; ``window`` (s) the time within which another radar's plot
    of the same object counts as seeing it). With per-cell subsets (``field.seen``) each
    radar is corrected over its own cells. Heights and every other column are kept.
    """
    fn = "biasfield.correct_plots"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    field = as_instance(f"{fn} field", field, FieldMap)
    passes = as_count(f"{fn} passes", passes, minimum=1, maximum=10)
    field.check_radars(radars, fn)
    n = len(plots)
    # the results, preallocated and filled block by block (41 B a plot with the reasons;
    # float64 as PlotTable's columns and Corrected.bias are documented: ranges to 250 km
    # and times of a day need it at the noise's mm and ms anyway)
    bias = np.zeros((n, 2))
    covered = np.ones(n, dtype=bool)
    rng, az = np.empty(n), np.empty(n)
    # in blocks of CORRECT_CHUNK plots (views of the columns, no copy): the
    # interpolation's temporaries (simplices, distances, barycentric weights, the
    # positions) scale with the block, not the recording (3.2·10⁷ plots: peak RSS 10.5 GB
    # in one block; see solvers_cmp.biasfield_country)
    for lo in range(0, n, CORRECT_CHUNK):
        sl = slice(lo, min(n, lo + CORRECT_CHUNK))
        block = PlotTable(
            plots.time[sl],
            plots.radar[sl],
            plots.range[sl],
            plots.azimuth[sl],
            plots.object[sl],
            None if plots.height is None else plots.height[sl],
        )
        part = block
        for _ in range(passes):
            b = field.at_radar(part.cartesian(radars), block.radar)  # each plot's own radar
            ok = np.all(np.isfinite(b), axis=1)
            b[~ok] = 0.0
            part = replace(
                block,
                range=np.abs(block.range - b[:, 0]),
                azimuth=wrap_angle(block.azimuth - b[:, 1]),
            )
        bias[sl], covered[sl] = b, ok
        rng[sl], az[sl] = part.range, part.azimuth
    # the other columns are shared with ``plots`` (PlotTable copies none of them)
    out = replace(plots, range=rng, azimuth=az)
    code = np.zeros(n, dtype=np.int8)
    if not covered.all():
        miss = ~covered
        # "seen by another radar" only for the objects with a plot left uncorrected, in
        # groups of whole objects (_seen: the sort keys of one group at a time, not of the
        # 3.2·10⁷ plots of a day)
        single = miss & (plots.object >= 0)
        single &= ~_seen(plots, window, single)
        code[miss] = 2
        code[single] = 1
    # an object array of the three REASONS strings (8 bytes a plot, not 72 for '<U18')
    reason = np.array(REASONS, dtype=object)[code]
    return Corrected(out, bias, covered, reason)
