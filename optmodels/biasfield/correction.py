r"""Plots corrected with a bias field (paper 001, after section 4): :func:`correct_plots`
(f_i subtracted from radar i's range and azimuth at each plot's position, fixed point),
:class:`Corrected` and the reasons a plot is left as read (:data:`REASONS`,
:func:`seen_by_others`). Split out of ``usage.py``; the names are re-exported there
unchanged."""

from __future__ import annotations

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


def seen_by_others(plots: PlotTable, window: float = 60.0) -> np.ndarray:
    """(n,) True where another radar has a plot of the same object (``plots.object`` ≥ 0)
    within ``window`` seconds: the plot is seen by two radars or more."""
    plots = as_instance("biasfield.seen_by_others plots", plots, PlotTable)
    window = as_positive("biasfield.seen_by_others window (s)", window)
    out = np.zeros(len(plots), dtype=bool)
    known = np.flatnonzero(plots.object >= 0)
    if known.size == 0:
        return out
    t = plots.time[known]
    # one sorted key per (object, time): objects spaced farther apart than any time gap
    span = float(t.max() - t.min()) + 4.0 * window + 1.0
    key = plots.object[known].astype(np.float64) * span + (t - t.min())
    r = plots.radar[known]
    for i in np.unique(r):
        other = np.sort(key[r != i])
        mine = np.flatnonzero(r == i)
        if other.size == 0:
            continue
        lo = np.searchsorted(other, key[mine] - window, side="left")
        hi = np.searchsorted(other, key[mine] + window, side="right")
        out[known[mine]] = hi > lo
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
    bias = np.zeros((n, 2))
    covered = np.ones(n, dtype=bool)
    rng, az = np.empty(n), np.empty(n)  # the corrected columns, filled block by block
    # in blocks of CORRECT_CHUNK plots: the interpolation's temporaries (simplices,
    # distances, barycentric weights, the positions) scale with the block, not the
    # recording (3.2·10⁷ plots: peak RSS 10.5 GB in one block; see solvers_cmp.biasfield_country)
    for lo in range(0, n, CORRECT_CHUNK):
        sl = slice(lo, min(n, lo + CORRECT_CHUNK))
        block = plots.subset(np.arange(sl.start, sl.stop))
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
    out = replace(plots, range=rng, azimuth=az)
    # an object array of the three REASONS strings (8 bytes a plot, not 72 for '<U18')
    code = np.zeros(n, dtype=np.int8)
    if not covered.all():
        miss = ~covered
        # "seen by another radar" only for the objects with a plot left uncorrected (the
        # test looks at the plots of the same object alone, so this is exact; on all
        # 3.2·10⁷ plots of a day it costs ~2 GB of sort keys)
        objs = np.unique(plots.object[miss & (plots.object >= 0)])
        rows = np.flatnonzero(np.isin(plots.object, objs))
        single = np.zeros(n, dtype=bool)
        single[rows] = ~seen_by_others(plots.subset(rows), window)
        single &= miss
        code[miss] = 2
        code[single] = 1
    reason = np.array(REASONS, dtype=object)[code]
    return Corrected(out, bias, covered, reason)
