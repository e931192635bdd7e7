"""The heights of the plots of a recording (paper 001, the plots of (1) in 3-D): the
standard-atmosphere height of a flight level, the spikes of the ADS-B geometric heights,
and the ADS-B height of a plot interpolated between the reports of its aircraft.

:func:`~optmodels.biasfield.recording.read_recording` uses them in this order (its module
docstring gives the error budget of the ISA): the CAT021 geometric heights cleaned
(:func:`adsb_height_spikes`), interpolated at the plot time (:func:`interp_by_object`),
checked against the plot's own flight level (:func:`fl_to_height`), which is the height
where no ADS-B height exists.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_float_array,
    as_number,
    as_positive,
)

__all__ = ["R_ISA", "adsb_height_spikes", "fl_to_height", "interp_by_object"]

#: Earth radius of the ISA geopotential ↔ geometric conversion (m, ICAO Doc 7488).
R_ISA = 6_356_766.0


def fl_to_height(pressure_altitude: Any, geoid_undulation: float = 0.0) -> FloatArray:
    """Standard-atmosphere height (m above the ellipsoid) of a pressure altitude (m).

    H_p (= FL · 30.48 m) is the ISA geopotential altitude; h = R·H_p/(R − H_p) with
    R = 6 356 766 m is the geometric altitude above mean sea level; + N (the geoid
    undulation, m) above the WGS-84 ellipsoid. Exact only in the standard atmosphere.
    NaN (no flight level) stays NaN; text, ragged rows, ``None`` entries, complex values
    and mappings are one :class:`ProblemError` naming ``pressure_altitude``.
    """
    # fast path for the package's own float64 arrays (the flight levels of every plot)
    hp = pressure_altitude
    if type(hp) is not np.ndarray or hp.dtype != np.float64:
        hp = as_float_array("biasfield.fl_to_height pressure_altitude", pressure_altitude)
    n = as_number(
        "biasfield.fl_to_height geoid_undulation", geoid_undulation, low=-120.0, high=120.0
    )
    return R_ISA * hp / (R_ISA - hp) + n


def adsb_height_spikes(
    obj: np.ndarray,
    t: FloatArray,
    height: FloatArray,
    *,
    neighbours: int = 2,
    tolerance: float = 150.0,
    vertical_rate: float = 100.0,
) -> np.ndarray:
    """(n,) True for the ADS-B geometric heights that are spikes.

    Reports sorted by (object, time). A Hampel filter: each finite height h_k is compared
    with the median of the finite heights of the same object among itself and its
    ``neighbours`` reports on each side (at least 3 values, else the report is kept): a
    spike when |h_k − median| > ``tolerance`` + ``vertical_rate`` · τ_k (m; τ_k the
    largest time distance, s, to a neighbour used). The median of a steady climb or
    descent is the report's own height, and one or two consecutive outliers never carry
    the median of five, so an isolated altitude spike (the +7.8 km of a corrupted
    I021/140) is caught whatever its size while 100 m/s (≈ 20 000 ft/min, beyond any
    airliner) of true vertical motion is not. A longer run of bad heights carries the
    median and is left to the flight-level check of
    :func:`~optmodels.biasfield.recording.read_recording`. Vectorised
    over all objects at once (``scipy.signal.medfilt`` works on one series: a Python call
    per aircraft, and it pads the ends and gaps with zeros).

    ``obj`` (n,) object numbers, ``t`` (n,) times (s), ``height`` (n,) m (NaN: absent);
    ``neighbours`` ≥ 1, ``tolerance`` (m) and ``vertical_rate`` (m/s) ≥ 0: anything else
    is one :class:`ProblemError` naming the argument.
    """
    fn = "biasfield.adsb_height_spikes"
    h = as_float_array(f"{fn} height", height)  # NaN: no height in that report
    if h.ndim != 1:
        raise ProblemError(f"{fn} height: expected (n,) heights (m), got shape {h.shape}")
    n = h.size
    t = as_finite_array(f"{fn} t", t, shape=(n,))
    obj = as_finite_array(f"{fn} obj", obj, shape=(n,))
    neighbours = as_count(f"{fn} neighbours", neighbours, minimum=1)
    tolerance = as_positive(f"{fn} tolerance (m)", tolerance, allow_zero=True)
    vertical_rate = as_positive(f"{fn} vertical_rate (m/s)", vertical_rate, allow_zero=True)
    out = np.zeros(n, dtype=bool)
    if n < 3:
        return out
    vals, dist = [np.where(np.isfinite(h), h, np.nan)], [np.zeros(n)]
    for d in [*range(-neighbours, 0), *range(1, neighbours + 1)]:
        j = np.arange(n) + d
        ok = (j >= 0) & (j < n)
        jc = np.clip(j, 0, n - 1)
        ok &= (obj[jc] == obj) & np.isfinite(h[jc])
        vals.append(np.where(ok, h[jc], np.nan))
        dist.append(np.where(ok, np.abs(t[jc] - t), 0.0))
    v = np.stack(vals, axis=1)
    enough = np.sum(np.isfinite(v), axis=1) >= 3
    judged = enough & np.isfinite(h)
    if not judged.any():
        return out
    med = np.nanmedian(v[judged], axis=1)
    tau = np.max(np.stack(dist, axis=1)[judged], axis=1)
    out[judged] = np.abs(h[judged] - med) > tolerance + vertical_rate * tau
    return out


def interp_by_object(
    obj: np.ndarray,
    t: FloatArray,
    v: FloatArray,
    q_obj: np.ndarray,
    q_t: FloatArray,
    max_gap: float,
) -> FloatArray:
    """Per query (object, time) the linear interpolation of ``v`` between the two
    bracketing reports of the same object with finite ``v``, if they are at most
    ``max_gap`` apart (a query at a report's own time takes its value); NaN otherwise.
    ``obj``/``t`` sorted by (object, time)."""
    out = np.full(q_t.shape, np.nan)
    ok = np.isfinite(v)
    obj, t, v = obj[ok], t[ok], v[ok]
    if t.size == 0 or q_t.size == 0:
        return out
    span = float(max(t.max(), q_t.max()) - min(t.min(), q_t.min())) + 2 * max_gap + 1.0
    base = min(float(t.min()), float(q_t.min())) - max_gap
    key = obj * span + (t - base)
    qkey = q_obj * span + (q_t - base)
    j = np.searchsorted(key, qkey, side="right")  # first report after the query
    lo, hi = j - 1, j
    valid = (lo >= 0) & (hi < t.size)
    lo_c, hi_c = np.clip(lo, 0, t.size - 1), np.clip(hi, 0, t.size - 1)
    valid &= (obj[lo_c] == q_obj) & (obj[hi_c] == q_obj)
    valid &= (t[hi_c] - t[lo_c]) <= max_gap
    dt = np.where(valid, t[hi_c] - t[lo_c], 1.0)
    w = np.where(valid, (q_t - t[lo_c]) / np.where(dt > 0, dt, 1.0), 0.0)
    out = np.where(valid, v[lo_c] + w * (v[hi_c] - v[lo_c]), np.nan)
    # a query exactly at a report's time (also the last report of an object)
    exact = (lo >= 0) & (obj[lo_c] == q_obj) & (t[lo_c] == q_t)
    out = np.where(exact, v[lo_c], out)
    return out
