r"""Cleaning of real tracks before the track fits (paper 001, (3)): gaps, physically
impossible jumps, ground traffic -- every dropped point counted and listed with its reason.

The track model (3) of paper 001 is a smooth motion observed with the radar noise V_i; real
recordings break it in three ways (issue 16: ADS-B glitches with apparent speeds of
400-727 m/s, taxiing aircraft, gaps, χ²/dof 6-11 on those tracks):

* **Gaps.** A sequence is split where consecutive points are more than ``max_gap`` apart;
  nothing is interpolated across a gap. ADS-B default 10 s: the chord of a standard-rate
  turn (3 °/s at 120-250 m/s, radius 2.3-4.8 km) over 10 s is 0.8-1.6 km long and its
  sagitta is 78-160 m, the size of the biases themselves; over the 1 s of a normal report
  interval the sagitta is 0.8-1.6 m. Radar plots: 60 s (the fits split at their own
  ``max_gap``; the cleaning only uses the gaps to bound its checks).
* **Impossible speed.** Two points are *compatible* when
  ‖x_b − x_a‖ ≤ v_max·|t_b − t_a| + k·√(σ_a² + σ_b²) (v_max = 350 m/s: the fastest civil
  ground speeds recorded, Mach 0.85 with a 100 m/s jet-stream tail wind, are 350-360 m/s;
  σ the per-axis position noise, k = 6: a false alarm per link has probability
  < 10⁻⁷ for Gaussian noise in 3-D). The links of a segment that are not compatible cut it
  into chains; a chain of fewer than ``glitch_run`` points (default 3) is a glitch and
  dropped point by point (reason ``"impossible speed"``): one wrong report between good
  ones is a chain of one and is the only point dropped. What remains is joined again where
  compatible; two long chains that are not (a real jump: a track swap, an offset position
  source) are split into separate segments (ADS-B) or the shorter one is dropped
  (radar plots, reason ``"track jump"``: one radar track must be one object).
* **Impossible acceleration.** For consecutive points a, b, c (times t_a < t_b < t_c) the
  deviation of x_b from the chord, d = x_b − (w_a x_a + w_c x_c), w_a = (t_c − t_b)/(t_c −
  t_a), w_c = 1 − w_a, is bounded by a_max (t_b − t_a)(t_c − t_b)/2 for any motion with
  |acceleration| ≤ a_max (the bound is reached by a constant acceleration); the noise adds
  k·√(σ_b² + w_a²σ_a² + w_c²σ_c²). a_max = 3 g horizontal: civil manoeuvres stay below
  1.5 g (a rate-one turn at 250 m/s is 1.3 g; 60° of bank is 2 g). The point with the
  largest excess is dropped first (it is the glitch: its own deviation is about twice its
  neighbours'), then the check is repeated (reason ``"impossible acceleration"``).
* **Ground traffic.** A point whose speed over a ``ground_window`` (30 s for ADS-B, 60 s
  for radar plots; centred on the point, moved inside the segment at its ends, measured
  over at least half of it, else not judged; the chord
  of a 90° standard-rate turn at 120 m/s still gives 108 m/s) is below ``ground_speed``
  (40 m/s = 78 kt, below the approach speed of any airliner, above taxi speeds of
  5-15 m/s), and, if ``ground_ceiling`` is given, whose height is at most that (m above the
  WGS-84 ellipsoid), is ground traffic (reason ``"ground traffic"``). Slow light aircraft
  are dropped too without a ceiling: they are a minor part of en-route traffic.
* Duplicated instants of one object keep their first point (reason ``"duplicate time"``);
  ADS-B segments with fewer than ``min_points`` points after all this are dropped (reason
  ``"short segment"``).

Positions are Cartesian metres: the 3-D local ENU of the common origin for ADS-B (so that
distances are the exact chords), the common plane (:meth:`PlotTable.cartesian`) for radar
plots, with σ = the largest standard deviation of each plot's Cartesian covariance.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_float_array,
    as_instance,
    as_number,
    as_positive,
)

__all__ = [
    "ADSB_LIMITS",
    "ADSB_SIGMA",
    "PLOT_LIMITS",
    "REASONS",
    "CleaningLimits",
    "CleaningReport",
    "clean_plots",
    "clean_reports",
]

#: Per-axis position noise (m) assumed for ADS-B reports (GNSS positions; NACp ≥ 8 bounds
#: the 95 % error by 93 m, real errors are a few metres).
ADSB_SIGMA = 10.0

#: The reasons a point is dropped, in the order the checks run.
REASONS = (
    "no position (height)",
    "duplicate time",
    "impossible speed",
    "track jump",
    "impossible acceleration",
    "ground traffic",
    "short segment",
)

_G0 = 9.80665


@dataclass(frozen=True)
class CleaningLimits:
    """Physical limits of the cleaning (module docstring: values and why).

    ``max_speed`` (m/s), ``max_acceleration`` (m/s²), ``ground_speed`` (m/s),
    ``ground_window`` (s), ``ground_ceiling`` (m above the WGS-84 ellipsoid, or ``None``:
    speed alone), ``max_gap`` (s), ``min_points`` (≥ 1), ``glitch_run`` (points, ≥ 1),
    ``noise_sigmas`` k (≥ 0).
    """

    max_speed: float = 350.0
    max_acceleration: float = 3.0 * _G0
    ground_speed: float = 40.0
    ground_window: float = 30.0
    ground_ceiling: float | None = None
    max_gap: float = 10.0
    min_points: int = 2
    glitch_run: int = 3
    noise_sigmas: float = 6.0

    def __post_init__(self) -> None:
        fn = "biasfield.CleaningLimits"
        for name in ("max_speed", "max_acceleration", "ground_window", "max_gap"):
            object.__setattr__(
                self, name, as_positive(f"{fn} {name}", getattr(self, name), allow_inf=True)
            )
        object.__setattr__(
            self,
            "ground_speed",
            as_positive(f"{fn} ground_speed (m/s)", self.ground_speed, allow_zero=True),
        )
        object.__setattr__(
            self,
            "noise_sigmas",
            as_positive(f"{fn} noise_sigmas", self.noise_sigmas, allow_zero=True),
        )
        if self.ground_ceiling is not None:
            object.__setattr__(
                self, "ground_ceiling", as_number(f"{fn} ground_ceiling (m)", self.ground_ceiling)
            )
        object.__setattr__(
            self, "min_points", as_count(f"{fn} min_points", self.min_points, minimum=1)
        )
        object.__setattr__(
            self, "glitch_run", as_count(f"{fn} glitch_run", self.glitch_run, minimum=1)
        )


#: Defaults for ADS-B reports (:func:`optmodels.biasfield.ingest.read_tracks`).
ADSB_LIMITS = CleaningLimits()
#: Defaults for radar plots (:func:`clean_plots`): gaps of 60 s (several missed scans)
#: only bound the checks (the track fits split at their own ``max_gap``); the ground
#: speed over 60 s (plot noise of 100-300 m across the window: 3-7 m/s).
PLOT_LIMITS = CleaningLimits(max_gap=60.0, min_points=1, ground_window=60.0)


@dataclass
class CleaningReport:
    """Every point dropped, by reason: ``rows[reason]`` the indices (into the input) of the
    points dropped for it; ``segments`` the number of segments kept; ``points`` the number
    of points read."""

    points: int = 0
    segments: int = 0
    rows: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def counts(self) -> dict[str, int]:
        """Reason → number of points dropped (reasons with none left out)."""
        return {r: int(v.size) for r, v in self.rows.items() if v.size}

    @property
    def total(self) -> int:
        return int(sum(self.counts.values()))

    def to_dict(self, max_rows: int | None = None) -> dict[str, Any]:
        """JSON-ready: points, kept, segments, dropped counts by reason and the rows
        (at most ``max_rows`` per reason if given; ``rows_truncated`` says so)."""
        rows = {
            r: v.tolist() if max_rows is None else v[:max_rows].tolist()
            for r, v in self.rows.items()
            if v.size
        }
        out: dict[str, Any] = {
            "points": self.points,
            "kept": self.points - self.total,
            "segments": self.segments,
            "dropped": self.counts,
            "rows": rows,
        }
        if max_rows is not None:
            out["rows_truncated"] = any(v.size > max_rows for v in self.rows.values())
        return out

    def merge(self, other: CleaningReport, offset: int = 0) -> None:
        """Add ``other`` (rows shifted by ``offset``)."""
        self.points += other.points
        self.segments += other.segments
        for r, v in other.rows.items():
            self.rows[r] = np.concatenate([self.rows.get(r, np.zeros(0, np.int64)), v + offset])


def _compatible(
    t: FloatArray, x: FloatArray, s: FloatArray, a: np.ndarray, b: np.ndarray, lim: CleaningLimits
) -> np.ndarray:
    """Speed test between points a and b (index arrays)."""
    dist = np.linalg.norm(x[b] - x[a], axis=1)
    allow = lim.max_speed * np.abs(t[b] - t[a]) + lim.noise_sigmas * np.hypot(s[a], s[b])
    return np.asarray(dist <= allow)


def _chains(
    idx: np.ndarray,
    t: FloatArray,
    x: FloatArray,
    s: FloatArray,
    lim: CleaningLimits,
    on_jump: str,
    code: np.ndarray,
) -> list[np.ndarray]:
    """Speed check of one gap-free segment ``idx`` (sorted by time): drop glitches
    (code 1), resolve jumps (split, or drop with code 2); returns the kept segments."""
    if idx.size < 2:
        return [idx]
    ok = _compatible(t, x, s, idx[:-1], idx[1:], lim)
    if ok.all():
        return [idx]
    chains = np.split(idx, np.flatnonzero(~ok) + 1)
    long = [c for c in chains if c.size >= lim.glitch_run]
    for c in chains:
        if c.size < lim.glitch_run:
            code[c] = 1
    if not long:
        return []
    # join what is compatible again (the good parts on either side of a glitch)
    groups = [long[0]]
    for c in long[1:]:
        if _compatible(t, x, s, groups[-1][-1:], c[:1], lim)[0]:
            groups[-1] = np.concatenate([groups[-1], c])
        else:
            groups.append(c)
    if on_jump == "split" or len(groups) == 1:
        return groups
    best = max(range(len(groups)), key=lambda g: groups[g].size)
    for g, c in enumerate(groups):
        if g != best:
            code[c] = 2
    return [groups[best]]


def _accel(
    idx: np.ndarray,
    t: FloatArray,
    x: FloatArray,
    s: FloatArray,
    lim: CleaningLimits,
    code: np.ndarray,
) -> np.ndarray:
    """Acceleration check of one segment: drop the worst point while any exceeds (code 3)."""
    keep = idx
    while keep.size >= 3:
        a, b, c = keep[:-2], keep[1:-1], keep[2:]
        d1, d2 = t[b] - t[a], t[c] - t[b]
        wa = d2 / (d1 + d2)
        wc = 1.0 - wa
        dev = np.linalg.norm(x[b] - wa[:, None] * x[a] - wc[:, None] * x[c], axis=1)
        allow = 0.5 * lim.max_acceleration * d1 * d2 + lim.noise_sigmas * np.sqrt(
            s[b] ** 2 + (wa * s[a]) ** 2 + (wc * s[c]) ** 2
        )
        excess = dev - allow
        worst = int(np.argmax(excess))
        if excess[worst] <= 0:
            break
        code[b[worst]] = 3
        keep = np.delete(keep, worst + 1)
    return keep


def _ground(
    idx: np.ndarray, t: FloatArray, x: FloatArray, h: FloatArray | None, lim: CleaningLimits
) -> np.ndarray:
    """Boolean (len(idx),): ground traffic by the windowed speed (and the ceiling)."""
    if lim.ground_speed <= 0 or idx.size < 2:
        return np.zeros(idx.size, dtype=bool)
    tt, xx = t[idx], x[idx]
    half = 0.5 * lim.ground_window
    # the window centred on each point, moved inside the segment at its ends
    c = (
        np.clip(tt, tt[0] + half, tt[-1] - half)
        if tt[-1] - tt[0] > 2 * half
        else np.full(tt.size, 0.5 * (tt[0] + tt[-1]))
    )
    lo = np.searchsorted(tt, c - half, side="left")
    hi = np.searchsorted(tt, c + half, side="right") - 1
    span = tt[hi] - tt[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.linalg.norm(xx[hi] - xx[lo], axis=1) / span
    # judged only on a speed measured over at least half the window (a short, slow
    # piece of track is too little evidence)
    slow = np.where(span >= 0.5 * lim.ground_window, v < lim.ground_speed, False)
    if lim.ground_ceiling is not None and h is not None:
        hh = h[idx]
        slow &= ~(hh > lim.ground_ceiling)  # unknown (NaN) height: speed alone
    return np.asarray(slow)


def _clean_sequence(
    t: FloatArray,
    x: FloatArray,
    s: FloatArray,
    h: FloatArray | None,
    lim: CleaningLimits,
    on_jump: str,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """One object's points sorted by time → (reason code per point, 0 = kept;
    the kept segments as index arrays)."""
    n = t.size
    code = np.zeros(n, dtype=np.int8)
    idx = np.arange(n)
    dup = np.concatenate([[False], np.diff(t) <= 0])
    code[dup] = 6
    idx = idx[~dup]
    segs = np.split(idx, np.flatnonzero(np.diff(t[idx]) > lim.max_gap) + 1)
    out: list[np.ndarray] = []
    for seg in segs:
        for part in _chains(seg, t, x, s, lim, on_jump, code):
            part = _accel(part, t, x, s, lim, code)
            gnd = _ground(part, t, x, h, lim)
            code[part[gnd]] = 4
            part = part[~gnd]
            if part.size == 0:
                continue
            for piece in np.split(part, np.flatnonzero(np.diff(t[part]) > lim.max_gap) + 1):
                if piece.size < lim.min_points:
                    code[piece] = 5
                else:
                    out.append(piece)
    return code, out


_CODE_REASON = {
    7: "no position (height)",
    6: "duplicate time",
    1: "impossible speed",
    2: "track jump",
    3: "impossible acceleration",
    4: "ground traffic",
    5: "short segment",
}


def _group_rows(keys: np.ndarray, times: FloatArray) -> list[np.ndarray]:
    """Row indices per distinct key, each sorted by time (stable)."""
    order = np.lexsort((times, keys))
    ks = keys[order]
    cuts = np.flatnonzero(ks[1:] != ks[:-1]) + 1
    return np.split(order, cuts)


def _report(n: int, codes: np.ndarray, segments: int) -> CleaningReport:
    rep = CleaningReport(points=n, segments=segments)
    for c in sorted(_CODE_REASON, key=lambda c: REASONS.index(_CODE_REASON[c])):
        rep.rows[_CODE_REASON[c]] = np.flatnonzero(codes == c).astype(np.int64)
    return rep


def _labels(name: str, value: Any, n: int) -> np.ndarray:
    """(n,) labels (numbers or strings), or one ProblemError naming ``name``."""
    try:
        obj = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged rows
        raise ProblemError(f"{name}: expected {n} labels, not usable as an array ({exc})") from None
    if obj.shape != (n,) or obj.dtype.kind not in "biufUS":
        raise ProblemError(
            f"{name}: expected {n} labels (numbers or strings), got {obj.dtype} shape {obj.shape}"
        )
    return obj


def clean_reports(
    objects: ArrayLike,
    times: ArrayLike,
    positions: ArrayLike,
    *,
    sigma: float | ArrayLike = ADSB_SIGMA,
    heights: ArrayLike | None = None,
    limits: CleaningLimits = ADSB_LIMITS,
) -> tuple[np.ndarray, CleaningReport]:
    """Clean aircraft reports (ADS-B): per object, gaps, impossible jumps, ground traffic.

    Parameters
    ----------
    objects
        (n,) labels (any hashable values: ICAO addresses, integers).
    times
        (n,) report times (s).
    positions
        (n, 2) or (n, 3) Cartesian positions (m): the local ENU of the common origin, so
        that distances are exact chords.
    sigma
        Per-axis position noise (m), one value or (n,); default :data:`ADSB_SIGMA`.
    heights
        (n,) heights (m above the WGS-84 ellipsoid; NaN unknown) for
        ``limits.ground_ceiling``.
    limits
        :class:`CleaningLimits` (default :data:`ADSB_LIMITS`).

    Returns
    -------
    tuple
        ``segment`` (n,) int: the kept segment of each report (0..S−1, numbered object by
        object in order of first appearance, then in time), −1 where dropped; and the
        :class:`CleaningReport` (rows index the input).
    """
    fn = "biasfield.clean_reports"
    lim = as_instance(f"{fn} limits", limits, CleaningLimits)
    t = as_finite_array(f"{fn} times (s)", times, ndim=1, max_abs=MAX_MAGNITUDE)
    n = t.size
    x = as_finite_array(f"{fn} positions (m)", positions, ndim=2, max_abs=MAX_MAGNITUDE)
    if x.shape[0] != n or x.shape[1] not in (2, 3):
        raise ProblemError(f"{fn} positions (m): expected ({n}, 2) or ({n}, 3), got {x.shape}")
    sg = as_finite_array(f"{fn} sigma (m)", sigma, ndim=(0, 1))
    if sg.size not in (1, n) or np.any(sg < 0):
        raise ProblemError(f"{fn} sigma (m): expected one value ≥ 0 or {n}, got {sg.shape}")
    s = np.broadcast_to(sg.reshape(-1) if sg.ndim else sg, (n,))
    obj = _labels(f"{fn} objects", objects, n)
    h = None
    if heights is not None:
        h = as_float_array(f"{fn} heights (m)", heights)  # NaN: unknown height
        if h.shape != (n,):
            raise ProblemError(f"{fn} heights (m): expected {n} values, got {h.shape}")
    _, first, inv = np.unique(obj, return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))  # objects in order of first appearance
    keys = rank[inv.reshape(-1)]
    codes = np.zeros(n, dtype=np.int8)
    segment = np.full(n, -1, dtype=np.int64)
    nseg = 0
    for rows in _group_rows(keys, t):
        code, pieces = _clean_sequence(
            t[rows], x[rows], s[rows], None if h is None else h[rows], lim, "split"
        )
        codes[rows] = code
        for piece in pieces:
            segment[rows[piece]] = nseg
            nseg += 1
    return segment, _report(n, codes, nseg)


def plot_sigma(plots: PlotTable, radars: RadarSet, z: FloatArray | None = None) -> FloatArray:
    """Per plot, the largest standard deviation (m) of its covariance on the common plane
    (a 3-D radar set uses each plot's height)."""
    z = plots.cartesian(radars) if z is None else z
    h = plots.height if getattr(radars, "is_3d", False) else None
    out = np.empty(len(plots))
    for i in range(radars.m):
        sel = np.flatnonzero(plots.radar == i)
        if sel.size:
            cov = (
                radars.cartesian_cov(i, z[sel])
                if h is None
                else radars.cartesian_cov(i, z[sel], height=h[sel])
            )
            out[sel] = np.sqrt(np.linalg.eigvalsh(cov)[:, -1])
    return out


def clean_plots(
    plots: PlotTable, radars: RadarSet, *, limits: CleaningLimits = PLOT_LIMITS
) -> tuple[PlotTable, CleaningReport]:
    """Clean radar plots per (radar, object) before the track fits (3).

    Each radar's track of each object (``object ≥ 0``; unassigned plots are left for
    :func:`~optmodels.biasfield.tracks.fit_tracks`, which drops them) is checked on the
    common plane with σ from the radar's noise (module docstring); of two incompatible long
    chains the shorter is dropped (``"track jump"``). With a 3-D radar set, plots that
    cannot be placed on the plane (no height, or a slant range shorter than the height
    difference: :meth:`PlotTable.locatable`) are dropped first (``"no position
    (height)"``).

    Returns
    -------
    tuple
        The kept plots (input order) and the :class:`CleaningReport` (rows index the
        input table).
    """
    fn = "biasfield.clean_plots"
    as_instance(f"{fn} plots", plots, PlotTable)
    as_instance(f"{fn} radars", radars, RadarSet)
    lim = as_instance(f"{fn} limits", limits, CleaningLimits)
    plots.check(radars)
    n = len(plots)
    codes = np.zeros(n, dtype=np.int8)
    where = np.ones(n, dtype=bool)
    if getattr(radars, "is_3d", False):
        where = plots.locatable(radars)
        codes[~where] = 7
    if where.all():  # no copy of the table (2-D: every plot has a position)
        z = plots.cartesian(radars)
        s = plot_sigma(plots, radars, z)
    else:
        z = np.full((n, 2), np.nan)
        s = np.full(n, np.nan)
        sub = plots.subset(where)
        z[where] = sub.cartesian(radars)
        s[where] = plot_sigma(sub, radars, z[where])
        del sub
    h = getattr(plots, "height", None)
    h = None if h is None else np.asarray(h, dtype=float)
    nseg = 0
    known = np.flatnonzero((plots.object >= 0) & where)
    if known.size:
        keys = plots.radar[known] * (int(plots.object.max()) + 1) + plots.object[known]
        for grp in _group_rows(keys, plots.time[known]):
            rows = known[grp]
            code, pieces = _clean_sequence(
                plots.time[rows], z[rows], s[rows], None if h is None else h[rows], lim, "drop"
            )
            codes[rows] = code
            nseg += len(pieces)
    del z, s
    keep = codes == 0
    return (plots if keep.all() else plots.subset(keep)), _report(n, codes, nseg)


def with_limits(limits: CleaningLimits, **changes: Any) -> CleaningLimits:
    """A copy of ``limits`` with some values changed (checked again)."""
    return replace(limits, **changes)
