"""True (or reference) aircraft paths (paper 001, (1)): the positions x^a(t) the plots of
:mod:`~optmodels.biasfield.tables` are made from (synthetic scenes) or checked against
(ADS-B, :mod:`~optmodels.biasfield.referee`); the third input table."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield import geometry3d as g3
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_float_array,
)

__all__ = ["AircraftPaths"]


def _track_arrays(
    fn: str,
    a: int,
    times: ArrayLike,
    lat: ArrayLike,
    lon: ArrayLike,
    height: ArrayLike,
    org: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One aircraft's checked times (T,), plane positions (T, 2) and geodetic (T, 3)."""
    t = as_finite_array(f"{fn} times[{a}]", times, ndim=1, max_abs=MAX_MAGNITUDE)
    if t.size < 1 or np.any(np.diff(t) <= 0):
        raise ProblemError(f"{fn} times[{a}]: need ≥ 1 strictly increasing instants")
    geo = np.column_stack(
        [
            as_finite_array(f"{fn} lat[{a}]", lat, shape=t.shape),
            as_finite_array(f"{fn} lon[{a}]", lon, shape=t.shape),
            as_finite_array(f"{fn} height[{a}]", height, shape=t.shape, max_abs=1e6),
        ]
    )
    if np.any(np.abs(geo[:, 0]) >= 90):
        raise ProblemError(f"{fn} lat[{a}]: latitudes must be within (−90, 90) deg")
    return t, g3.common_plane(geo[:, 0], geo[:, 1], org), geo


class AircraftPaths:
    """True (or reference) aircraft paths, each over its OWN time span.

    Per aircraft a: ``times`` (T_a,) (s, strictly increasing), plane positions East-North
    (T_a, 2) (m) and, for 3-D paths, geodetic positions (T_a, 3) latitude (deg), longitude
    (deg), height (m above the WGS-84 ellipsoid) in the frame of ``origin`` (lat deg, lon
    deg, h m). Memory is per-aircraft arrays only: 48 bytes per report for 3-D paths (a day
    of 5000 aircraft at 1 report/s, ≈ 1.5 h each, is ≈ 1.3 GB).

    Constructors: :meth:`from_reports` (one row per report, e.g. ADS-B), :meth:`from_tracks`
    (per-aircraft geodetic arrays), :meth:`from_plane` (per-aircraft plane positions and
    heights), and the old dense 2-D form ``AircraftPaths(times (T,), positions (A, T, 2),
    active (A, T))`` still accepted for callers not yet migrated. The dense attributes
    ``times``, ``positions``, ``active`` exist for every form (built on the union of all
    instants for per-aircraft paths, O(A·T) memory: for small studies only).
    """

    #: Reports dropped by :meth:`from_reports` as repeated instants of an aircraft.
    duplicates: int = 0

    def __init__(self, times: ArrayLike, positions: ArrayLike, active: ArrayLike) -> None:
        t = as_finite_array("biasfield.AircraftPaths times", times, ndim=1, max_abs=MAX_MAGNITUDE)
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise ProblemError(
                "biasfield.AircraftPaths times: need at least 2 strictly "
                f"increasing instants, got {t.size}"
            )
        pos = as_finite_array(
            "biasfield.AircraftPaths positions",
            positions,
            shape=(None, t.size, 2),
            max_abs=MAX_MAGNITUDE,
        )
        # ragged rows, text, None entries, complex values, mappings: one named refusal
        as_float_array("biasfield.AircraftPaths active", active)
        act = np.asarray(active)
        if act.dtype != bool or act.shape != pos.shape[:2]:
            raise ProblemError(
                f"biasfield.AircraftPaths active: expected {pos.shape[:2]} "
                f"booleans, got {act.dtype} {act.shape}"
            )
        self._dense: tuple[FloatArray, FloatArray, np.ndarray] | None = (t, pos, act)
        self._view: tuple[FloatArray, FloatArray, np.ndarray] | None = None
        # the dense form interpolates over the whole grid (as before); spans from ``active``
        self._t: list[FloatArray] = [t] * pos.shape[0]
        self._en: list[FloatArray] = list(pos)
        self._geo: list[FloatArray] | None = None
        self.origin: FloatArray | None = None
        self.labels: tuple[Any, ...] = tuple(range(pos.shape[0]))

    # ----------------------------------------------------------------- constructors
    @classmethod
    def _per_aircraft(
        cls,
        times: list[FloatArray],
        en: list[FloatArray],
        geo: list[FloatArray] | None,
        origin: FloatArray | None,
        labels: tuple[Any, ...],
    ) -> AircraftPaths:
        obj = cls.__new__(cls)
        obj._dense = None
        obj._view = None
        obj._t, obj._en, obj._geo = times, en, geo
        obj.origin = origin
        obj.labels = labels
        return obj

    @classmethod
    def from_tracks(
        cls,
        times: Sequence[ArrayLike],
        lat: Sequence[ArrayLike],
        lon: Sequence[ArrayLike],
        height: Sequence[ArrayLike],
        origin: ArrayLike,
        labels: tuple[Any, ...] | None = None,
    ) -> AircraftPaths:
        """3-D paths from per-aircraft arrays: times (s, strictly increasing), latitude,
        longitude (deg), height (m above the ellipsoid); ``origin`` of the common plane."""
        fn = "biasfield.AircraftPaths.from_tracks"
        org = g3.site_geodetic(f"{fn} origin", origin)
        if not (len(times) == len(lat) == len(lon) == len(height)) or not len(times):
            raise ProblemError(
                f"{fn} times: need the same number (≥ 1) of per-aircraft "
                "times, lat, lon and height arrays"
            )
        ts, ens, geos = [], [], []
        for a in range(len(times)):
            t, en, geo = _track_arrays(fn, a, times[a], lat[a], lon[a], height[a], org)
            ts.append(t)
            geos.append(geo)
            ens.append(en)
        lab = tuple(range(len(ts))) if labels is None else tuple(labels)
        if len(lab) != len(ts):
            raise ProblemError(f"{fn} labels: expected {len(ts)} labels, got {len(lab)}")
        return cls._per_aircraft(ts, ens, geos, org, lab)

    @classmethod
    def from_plane(
        cls,
        times: Sequence[ArrayLike],
        en: Sequence[ArrayLike],
        height: Sequence[ArrayLike],
        origin: ArrayLike,
        labels: tuple[Any, ...] | None = None,
    ) -> AircraftPaths:
        """3-D paths from per-aircraft plane positions East-North (T_a, 2) (m) and heights
        (m above the ellipsoid); latitude and longitude by the exact inverse of the plane."""
        fn = "biasfield.AircraftPaths.from_plane"
        org = g3.site_geodetic(f"{fn} origin", origin)
        lats, lons = [], []
        for a in range(len(en)):
            p = as_finite_array(f"{fn} en[{a}]", en[a], shape=(None, 2), max_abs=MAX_MAGNITUDE)
            la, lo = g3.plane_to_geodetic(p, org)
            lats.append(la)
            lons.append(lo)
        return cls.from_tracks(times, lats, lons, height, org, labels)

    @classmethod
    def from_reports(
        cls,
        objects: ArrayLike,
        times: ArrayLike,
        lat: ArrayLike,
        lon: ArrayLike,
        height: ArrayLike,
        origin: ArrayLike,
    ) -> AircraftPaths:
        """3-D paths from reports, one row each (e.g. ADS-B): ``objects`` (n,) aircraft
        labels (ints or strings, e.g. icao24), ``times`` (s), ``lat``, ``lon`` (deg),
        ``height`` (m above the ellipsoid). Aircraft are indexed in sorted label order
        (``labels``); each one's reports are sorted by time, and repeated instants keep the
        first report (``duplicates`` counts the others). No cleaning, no resampling."""
        fn = "biasfield.AircraftPaths.from_reports"
        t = as_finite_array(f"{fn} times", times, ndim=1, max_abs=MAX_MAGNITUDE)
        n = t.size
        la = as_finite_array(f"{fn} lat", lat, shape=(n,))
        lo = as_finite_array(f"{fn} lon", lon, shape=(n,))
        h = as_finite_array(f"{fn} height", height, shape=(n,), max_abs=1e6)
        obj = np.asarray(objects)
        if obj.shape != (n,) or n == 0:
            raise ProblemError(f"{fn} objects: expected {n} (≥ 1) labels, got shape {obj.shape}")
        org = g3.site_geodetic(f"{fn} origin", origin)
        labels, inv = np.unique(obj, return_inverse=True)
        order = np.lexsort((t, inv))
        inv_s = inv[order]
        del inv
        keep = np.ones(n, dtype=bool)
        keep[1:] = (inv_s[1:] != inv_s[:-1]) | (t[order[1:]] != t[order[:-1]])
        order, inv_s = order[keep], inv_s[keep]
        cuts = np.flatnonzero(np.diff(inv_s)) + 1
        del inv_s
        ts, ens, geos = [], [], []
        # one aircraft at a time: the peak memory is the tables, the index and the result
        for a, g in enumerate(np.split(order, cuts)):
            tt, en, geo = _track_arrays(fn, a, t[g], la[g], lo[g], h[g], org)
            ts.append(tt)
            ens.append(en)
            geos.append(geo)
        out = cls._per_aircraft(
            ts, ens, geos, org, tuple(lab.item() if hasattr(lab, "item") else lab for lab in labels)
        )
        out.duplicates = int(n - keep.sum())
        return out

    # ----------------------------------------------------------------- access
    def __len__(self) -> int:
        return len(self._t)

    @property
    def is_3d(self) -> bool:
        """True when the geodetic positions (and heights) are known."""
        return self._geo is not None

    @property
    def nbytes(self) -> int:
        """Bytes held by the per-aircraft arrays (the dense form: its three arrays)."""
        if self._dense is not None:
            return int(sum(x.nbytes for x in self._dense))
        return int(
            sum(x.nbytes for x in self._t)
            + sum(x.nbytes for x in self._en)
            + sum(x.nbytes for x in (self._geo or []))
        )

    def _index(self, name: str, a: int) -> int:
        return as_count(f"biasfield.AircraftPaths.{name} a", a, maximum=len(self) - 1)

    def track(self, a: int) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Aircraft ``a`` over its own span: times (T_a,), East-North (T_a, 2), geodetic
        (T_a, 3) lat, lon (deg), height (m) or ``None`` for 2-D paths."""
        a = self._index("track", a)
        if self._dense is not None:
            on = self._dense[2][a]
            return self._dense[0][on], self._dense[1][a, on], None
        return self._t[a], self._en[a], None if self._geo is None else self._geo[a]

    def span(self, a: int) -> tuple[float, float]:
        """First and last instant (s) of aircraft ``a`` (NaN, NaN if never active)."""
        t = self.track(a)[0]
        return (float(t[0]), float(t[-1])) if t.size else (np.nan, np.nan)

    def at(self, a: int, t: ArrayLike) -> FloatArray:
        """Plane position (len(t), 2) East-North (m) of aircraft ``a`` at times t (linear
        interpolation between its samples; held constant beyond its span, as np.interp)."""
        a = self._index("at", a)
        tt = as_finite_array("biasfield.AircraftPaths.at t", t)
        p = self._en[a]
        return np.stack(
            [np.interp(tt, self._t[a], p[:, 0]), np.interp(tt, self._t[a], p[:, 1])], axis=-1
        )

    def geodetic_at(self, a: int, t: ArrayLike) -> FloatArray:
        """Geodetic position (len(t), 3) latitude, longitude (deg), height (m above the
        ellipsoid) of aircraft ``a`` at times t: linear interpolation of latitude,
        longitude and height between samples (a rhumb-line step; it departs from the
        plane-linear :meth:`at` by L² tan φ / (8R): 2 mm for 250 m steps at 55°N)."""
        a = self._index("geodetic_at", a)
        if self._geo is None:
            raise ProblemError(
                "biasfield.AircraftPaths.geodetic_at: these paths are 2-D "
                "(no geodetic positions); build them with from_reports, "
                "from_tracks or from_plane"
            )
        tt = as_finite_array("biasfield.AircraftPaths.geodetic_at t", t)
        g = self._geo[a]
        return np.stack([np.interp(tt, self._t[a], g[:, j]) for j in range(3)], axis=-1)

    def height_at(self, a: int, t: ArrayLike) -> FloatArray:
        """Height (m above the ellipsoid) of aircraft ``a`` at times t."""
        return self.geodetic_at(a, t)[..., 2]

    # ----------------------------------------------------------------- dense view
    def _dense_view(self) -> tuple[FloatArray, FloatArray, np.ndarray]:
        if self._dense is not None:
            return self._dense
        if self._view is None:
            grid = np.unique(np.concatenate(self._t))
            pos = np.empty((len(self), grid.size, 2))
            act = np.zeros((len(self), grid.size), dtype=bool)
            for a in range(len(self)):
                pos[a] = self.at(a, grid)
                act[a] = (grid >= self._t[a][0]) & (grid <= self._t[a][-1])
            self._view = (grid, pos, act)
        return self._view

    def sample_step(self) -> float:
        """Typical sampling step (s): the dense grid's step, or the median over aircraft
        of each one's median step."""
        if self._dense is not None:
            return float(self._dense[0][1] - self._dense[0][0])
        steps = [np.median(np.diff(t)) for t in self._t if t.size > 1]
        return float(np.median(steps)) if steps else np.inf

    @property
    def times(self) -> FloatArray:
        """Dense view: the shared instants (T,) (s)."""
        return self._dense_view()[0]

    @property
    def positions(self) -> FloatArray:
        """Dense view: positions (A, T, 2) East-North (m)."""
        return self._dense_view()[1]

    @property
    def active(self) -> np.ndarray:
        """Dense view: (A, T) where each aircraft is within its span."""
        return self._dense_view()[2]
