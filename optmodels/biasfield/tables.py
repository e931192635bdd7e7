"""Radars and radar plots (paper 001, (1)): the input tables the bias-field pipeline reads
(the inputs stage; the third table, :class:`~optmodels.biasfield.paths.AircraftPaths`, has
its own module).

Two geometries share the tables. **2-D** (``RadarSet`` without ``geodetic``): sites and
targets on one flat plane, ``range`` the distance on it, azimuth from the plane's North.
**3-D** (``RadarSet(..., geodetic=...)``): sites at their latitude, longitude and height
above the WGS-84 ellipsoid, each plot's ``range`` is the SLANT range and its azimuth is
clockwise from the radar's OWN north, and plots carry the target ``height`` (m above the
ellipsoid); positions on the common plane are exact through ECEF
(:mod:`optmodels.biasfield.geometry3d`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.geometry import from_polar, polar_jacobian
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_float_array,
)

__all__ = ["PlotTable", "RadarSet", "check_tables"]


@dataclass(frozen=True)
class RadarSet:
    """m radars: ``sites`` (m, 2) East-North (m) on the common plane; per radar
    ``sigma_range`` (m), ``sigma_azimuth`` (rad), ``max_range`` (m) and ``names``.

    3-D (``geodetic`` given): ``geodetic`` (m, 3) site latitude (deg), longitude (deg),
    height (m above the WGS-84 ellipsoid); ``origin`` (3,) (lat deg, lon deg, h m) of the
    common plane (default: the mean latitude and longitude of the sites, height 0);
    ``sites`` is then computed (the East-North of each site's footprint on the plane of
    ``origin``, :func:`~optmodels.biasfield.geometry3d.common_plane`) and may be ``None``;
    a given one is replaced. Plots of a 3-D set have SLANT ranges and azimuths clockwise
    from each radar's own north. ``ids``: per radar a (SAC, SIC) pair of ints 0-255
    (ASTERIX I010), or empty.

    The noise covariance of a plot is V_i = diag(σ_r², σ_az²) in the radar's polar frame,
    and, to first order, ∇p_i⁻¹ V_i ∇p_i⁻ᵀ on the plane (:meth:`cartesian_cov`; in 3-D
    ∇p_i is the exact Jacobian at the target's plane position and height).
    """

    sites: FloatArray | None
    sigma_range: FloatArray
    sigma_azimuth: FloatArray
    max_range: FloatArray
    names: tuple[str, ...] = field(default=())
    geodetic: FloatArray | None = None
    origin: FloatArray | None = None
    ids: tuple[tuple[int, int], ...] = field(default=())

    def __post_init__(self) -> None:
        if self.geodetic is not None:
            geo = as_finite_array("biasfield.RadarSet geodetic", self.geodetic, ndim=2)
            if geo.shape[1] != 3:
                raise ProblemError(
                    "biasfield.RadarSet geodetic: expected (m, 3) latitude "
                    f"(deg), longitude (deg), height (m), got {geo.shape}"
                )
            for j in range(geo.shape[0]):
                g3.site_geodetic(f"biasfield.RadarSet geodetic[{j}]", geo[j])
            if self.origin is None:
                org = np.array([geo[:, 0].mean(), geo[:, 1].mean(), 0.0])
            else:
                org = g3.site_geodetic("biasfield.RadarSet origin", self.origin)
            object.__setattr__(self, "geodetic", geo)
            object.__setattr__(self, "origin", org)
            object.__setattr__(self, "sites", g3.common_plane(geo[:, 0], geo[:, 1], org))
        elif self.origin is not None:
            object.__setattr__(
                self, "origin", g3.site_geodetic("biasfield.RadarSet origin", self.origin)
            )
        if self.sites is None:
            raise ProblemError(
                "biasfield.RadarSet sites: give the sites (m, 2) East-North "
                "(m) or their geodetic positions (geodetic=)"
            )
        sites = as_finite_array(
            "biasfield.RadarSet sites", self.sites, ndim=2, max_abs=MAX_MAGNITUDE
        )
        if sites.shape[1] != 2:
            raise ProblemError(f"biasfield.RadarSet sites: expected (m, 2), got {sites.shape}")
        m = sites.shape[0]
        if m < 2:
            raise ProblemError(
                f"biasfield.RadarSet sites: the bias field needs at least 2 radars, got {m}"
            )
        object.__setattr__(self, "sites", sites)
        for name in ("sigma_range", "sigma_azimuth", "max_range"):
            arg = f"biasfield.RadarSet {name}"
            v = as_finite_array(arg, getattr(self, name), ndim=(0, 1), max_abs=MAX_MAGNITUDE)
            if v.shape not in ((), (1,), (m,)):
                raise ProblemError(f"{arg}: expected one value or {m}, got shape {v.shape}")
            v = np.broadcast_to(v, (m,)).astype(float)
            if np.any(v <= 0):
                raise ProblemError(f"{arg}: need positive values, got {v}")
            object.__setattr__(self, name, v)
        if isinstance(self.names, str):
            raise ProblemError(
                f"biasfield.RadarSet names: expected a sequence of {m} names, "
                f"got the string {self.names!r:.60}"
            )
        names = tuple(str(n) for n in self.names) or tuple(f"R{i + 1}" for i in range(m))
        if len(names) != m or len(set(names)) != m or "" in names:
            raise ProblemError(
                f"biasfield.RadarSet names: need {m} distinct non-empty names, got {names}"
            )
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "ids", _as_ids(self.ids, m))

    @property
    def m(self) -> int:
        """The number of radars."""
        return int(self.sigma_range.shape[0])

    @property
    def is_3d(self) -> bool:
        """True when the sites are geodetic: slant ranges, each radar's own north."""
        return self.geodetic is not None

    def _site(self, i: int) -> FloatArray:
        """Radar ``i``'s site (2,) East-North (m) on the common plane (in 3-D its
        footprint, computed from ``geodetic``)."""
        assert self.sites is not None  # set by __post_init__ for every RadarSet
        return self.sites[i]

    def _geodetic_frame(self, i: int) -> tuple[FloatArray, FloatArray] | None:
        """(radar ``i``'s geodetic site (3,), the common plane's origin (3,)) of a 3-D set;
        None in 2-D."""
        if self.geodetic is None or self.origin is None:
            return None
        return self.geodetic[i], self.origin

    def index(self, radar: str | int) -> int:
        """Index of a radar given by name or index."""
        if isinstance(radar, bool | np.bool_):
            raise ProblemError(f"radar: unknown radar id {radar!r} (known: {self.names})")
        if isinstance(radar, int | np.integer) and 0 <= int(radar) < self.m:
            return int(radar)
        if radar in self.names:
            return self.names.index(str(radar))
        raise ProblemError(f"radar: unknown radar id {radar!r} (known: {self.names})")

    def index_of_id(self, sac: int, sic: int) -> int:
        """Index of the radar with ASTERIX identifier (SAC, SIC)."""
        key = (int(sac), int(sic))
        if key not in self.ids:
            raise ProblemError(f"radar: no radar with SAC/SIC {key} (known: {self.ids})")
        return self.ids.index(key)

    def polar_cov(self, i: int) -> FloatArray:
        """V_i = diag(σ_r², σ_az²) of radar ``i`` (m², rad²)."""
        i = as_count("biasfield.RadarSet.polar_cov i", i, maximum=self.m - 1)
        return np.diag([self.sigma_range[i] ** 2, self.sigma_azimuth[i] ** 2])

    def polar_jacobian(self, i: int, x: ArrayLike, height: ArrayLike | None = None) -> FloatArray:
        """∇p_i at plane positions x (..., 2) (m), (..., 2, 2): ∂(range, azimuth)/∂(E, N);
        in 3-D the exact Jacobian at fixed target ``height`` (..., ) (m above the
        ellipsoid), required there."""
        i = as_count("biasfield.RadarSet.polar_jacobian i", i, maximum=self.m - 1)
        pts = as_finite_array("biasfield.RadarSet.polar_jacobian x", x, max_abs=MAX_MAGNITUDE)
        if pts.shape[-1:] != (2,):
            raise ProblemError(
                f"biasfield.RadarSet.polar_jacobian x: expected (..., 2), got {pts.shape}"
            )
        frame = self._geodetic_frame(i)
        if frame is None:
            return polar_jacobian(pts, self._site(i))
        h = _heights("biasfield.RadarSet.polar_jacobian height", height, pts.shape[:-1])
        return g3.polar_jacobian3d(pts, h, *frame)

    def cartesian_cov(self, i: int, x: ArrayLike, height: ArrayLike | None = None) -> FloatArray:
        """V_i(x) on the common plane, (..., 2, 2), to first order: ∇p_i⁻¹ V_i ∇p_i⁻ᵀ at
        x (..., 2) (m); a 3-D set needs the target ``height`` (...,) (m above the
        ellipsoid) and uses the exact Jacobian there."""
        i = as_count("biasfield.RadarSet.cartesian_cov i", i, maximum=self.m - 1)
        pts = as_finite_array("biasfield.RadarSet.cartesian_cov x", x, max_abs=MAX_MAGNITUDE)
        if pts.shape[-1:] != (2,):
            raise ProblemError(
                f"biasfield.RadarSet.cartesian_cov x: expected (..., 2), got {pts.shape}"
            )
        frame = self._geodetic_frame(i)
        if frame is not None:
            h = _heights("biasfield.RadarSet.cartesian_cov height", height, pts.shape[:-1])
            jac = g3.polar_jacobian3d(pts, h, *frame)
        else:
            jac = polar_jacobian(pts, self._site(i))
        ginv = np.linalg.inv(jac)
        return ginv @ self.polar_cov(i) @ np.swapaxes(ginv, -1, -2)

    def to_polar(self, i: int, x: ArrayLike, height: ArrayLike | None = None) -> FloatArray:
        """p_i(x): plane positions (..., 2) → [range (m), azimuth (rad)] of radar ``i``; in
        3-D the slant range and the azimuth from the radar's own north of a target at
        ``height`` (m above the ellipsoid)."""
        from optmodels.biasfield.geometry import to_polar

        i = as_count("biasfield.RadarSet.to_polar i", i, maximum=self.m - 1)
        frame = self._geodetic_frame(i)
        if frame is None:
            return to_polar(x, self._site(i))
        pts = as_finite_array("biasfield.RadarSet.to_polar x", x, max_abs=MAX_MAGNITUDE)
        h = _heights("biasfield.RadarSet.to_polar height", height, pts.shape[:-1])
        return g3.to_polar3d(pts, h, *frame)


def _as_ids(ids: Any, m: int) -> tuple[tuple[int, int], ...]:
    """() or m distinct (SAC, SIC) pairs of ints 0-255."""
    arg = "biasfield.RadarSet ids"
    if ids is None or (not isinstance(ids, np.ndarray) and len(ids) == 0):
        return ()
    try:
        arr = np.asarray(ids)
    except (TypeError, ValueError) as exc:  # ragged
        raise ProblemError(f"{arg}: expected {m} (SAC, SIC) pairs, got {ids!r:.80}") from exc
    if arr.size == 0:
        return ()
    if arr.shape != (m, 2) or not (
        np.issubdtype(arr.dtype, np.integer)
        or (np.issubdtype(arr.dtype, np.floating) and np.all(np.mod(arr, 1) == 0))
    ):
        raise ProblemError(
            f"{arg}: expected {m} (SAC, SIC) pairs of integers, got {arr.dtype} {arr.shape}"
        )
    if arr.min() < 0 or arr.max() > 255:
        raise ProblemError(f"{arg}: SAC and SIC are integers 0-255, got {arr.tolist()}")
    out = tuple((int(a), int(b)) for a, b in arr)
    if len(set(out)) != m:
        raise ProblemError(f"{arg}: need {m} distinct (SAC, SIC) pairs, got {out}")
    return out


def _heights(name: str, height: ArrayLike | None, shape: tuple[int, ...]) -> FloatArray:
    """Target heights (m above the ellipsoid) broadcast to ``shape``; required, finite."""
    if height is None:
        raise ProblemError(
            f"{name}: a 3-D radar set needs the target height (m above the WGS-84 ellipsoid)"
        )
    h = as_finite_array(name, height, max_abs=1e6)
    try:
        return np.broadcast_to(h, shape)
    except ValueError:
        raise ProblemError(f"{name}: expected shape {shape}, got {h.shape}") from None


@dataclass(frozen=True)
class PlotTable:
    """Radar plots, one row each: ``time`` (s), ``radar`` (index into a :class:`RadarSet`),
    ``range`` (m), ``azimuth`` (rad, clockwise from North), ``object`` (track id, −1 if
    unknown), ``height`` (m above the WGS-84 ellipsoid, NaN where unknown; ``None``: no
    heights). With a 3-D :class:`RadarSet`, ``range`` is the slant range and the azimuth is
    clockwise from the radar's own north. Rows are kept in the order given."""

    time: FloatArray
    radar: np.ndarray
    range: FloatArray
    azimuth: FloatArray
    object: np.ndarray
    height: FloatArray | None = None

    def __post_init__(self) -> None:
        t = as_finite_array("biasfield.PlotTable time", self.time, ndim=1, max_abs=MAX_MAGNITUDE)
        n = t.shape[0]
        r = as_finite_array(
            "biasfield.PlotTable range", self.range, shape=(n,), max_abs=MAX_MAGNITUDE
        )
        az = as_finite_array(
            "biasfield.PlotTable azimuth", self.azimuth, shape=(n,), max_abs=MAX_MAGNITUDE
        )
        if np.any(r < 0):
            raise ProblemError(f"biasfield.PlotTable range: {int(np.sum(r < 0))} negative ranges")
        for name, value in (("radar", self.radar), ("object", self.object)):
            if not isinstance(value, np.ndarray):  # ragged, text, None entries...: refused
                as_float_array(f"biasfield.PlotTable {name}", value)
        rad = np.asarray(self.radar)
        obj = np.asarray(self.object)
        for name, arr in (("radar", rad), ("object", obj)):
            if arr.shape != (n,) or not np.issubdtype(arr.dtype, np.integer):
                raise ProblemError(
                    f"biasfield.PlotTable {name}: expected {n} integers, got "
                    f"{arr.dtype} {arr.shape}"
                )
        if self.height is not None:
            h = as_float_array("biasfield.PlotTable height", self.height)  # NaN: unknown
            if h.shape != (n,):
                raise ProblemError(
                    f"biasfield.PlotTable height: expected {n} heights (m), got shape {h.shape}"
                )
            known = h[~np.isnan(h)]
            if np.any(~np.isfinite(known)) or np.any(np.abs(known) > 1e6):
                raise ProblemError(
                    "biasfield.PlotTable height: heights must be finite "
                    "(within ±1000 km) or NaN for unknown"
                )
            object.__setattr__(self, "height", h)
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "range", r)
        object.__setattr__(self, "azimuth", az)
        # int64 columns are kept as given, not copied (like the float columns): a table
        # derived from another (a subset, corrected ranges) costs no copy of them
        object.__setattr__(self, "radar", rad.astype(np.int64, copy=False))
        object.__setattr__(self, "object", obj.astype(np.int64, copy=False))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def check(self, radars: RadarSet) -> None:
        """Radar ids exist and ranges are within each radar's ``max_range``."""
        if not isinstance(radars, RadarSet):
            raise ProblemError(
                f"biasfield.PlotTable.check radars: expected a RadarSet, got "
                f"{type(radars).__name__}"
            )
        bad = (self.radar < 0) | (self.radar >= radars.m)
        if bad.any():
            raise ProblemError(
                f"radar: unknown radar index {int(self.radar[bad][0])} in "
                f"{int(bad.sum())} plots (radars 0..{radars.m - 1})"
            )
        over = self.range > radars.max_range[self.radar]
        if over.any():
            raise ProblemError(
                f"range: {int(over.sum())} plots beyond their radar's "
                "max_range (outside the valid range)"
            )

    def locatable(self, radars: RadarSet) -> np.ndarray:
        """(n,) booleans: plots whose plane position :meth:`cartesian` can compute (2-D:
        all; 3-D: a known height and a slant range that reaches it)."""
        if not isinstance(radars, RadarSet):
            raise ProblemError(
                f"biasfield.PlotTable.locatable radars: expected a RadarSet, "
                f"got {type(radars).__name__}"
            )
        if not radars.is_3d:
            return np.ones(len(self), dtype=bool)
        return np.all(np.isfinite(self._positions3d(radars)), axis=1)

    def _positions3d(self, radars: RadarSet) -> FloatArray:
        out = np.full((len(self), 2), np.nan)
        h = self.height if self.height is not None else np.full(len(self), np.nan)
        for i in range(radars.m):
            frame = radars._geodetic_frame(i)
            sel = (self.radar == i) & ~np.isnan(h)
            if frame is not None and sel.any():
                _, _, e, n = g3.locate(
                    frame[0], self.range[sel], self.azimuth[sel], h[sel], frame[1]
                )
                out[sel] = np.column_stack([e, n])
        return out

    def cartesian(self, radars: RadarSet) -> FloatArray:
        """Plot positions z (n, 2) East-North (m) on the common plane: 2-D polar → plane;
        3-D the exact position (:func:`~optmodels.biasfield.geometry3d.locate`) of the
        target at the plot's slant range, azimuth and height. ProblemError for a 3-D set if
        a plot has no height or a slant range shorter than its height difference (select
        them out with :meth:`locatable`)."""
        if not isinstance(radars, RadarSet):
            raise ProblemError(
                f"biasfield.PlotTable.cartesian radars: expected a RadarSet, "
                f"got {type(radars).__name__}"
            )
        bad = (self.radar < 0) | (self.radar >= radars.m)
        if bad.any():  # rows of no radar would be left uninitialised below
            raise ProblemError(
                f"radar: unknown radar index {int(self.radar[bad][0])} in "
                f"{int(bad.sum())} plots (radars 0..{radars.m - 1})"
            )
        if radars.is_3d:
            if self.height is None or np.isnan(self.height).any():
                n_bad = len(self) if self.height is None else int(np.isnan(self.height).sum())
                raise ProblemError(
                    f"biasfield.PlotTable height: {n_bad} plots of a 3-D radar "
                    "set have no height (m above the ellipsoid); drop them "
                    "(PlotTable.locatable) or give their heights"
                )
            out = self._positions3d(radars)
            miss = ~np.all(np.isfinite(out), axis=1)
            if miss.any():
                raise ProblemError(
                    f"range: {int(miss.sum())} plots have a slant range shorter "
                    "than the height difference to their radar (no position);"
                    " drop them (PlotTable.locatable)"
                )
            return out
        out = np.empty((len(self), 2))
        for i in range(radars.m):
            sel = self.radar == i
            out[sel] = from_polar(
                np.column_stack([self.range[sel], self.azimuth[sel]]), radars._site(i)
            )
        return out

    def subset(self, mask: np.ndarray) -> PlotTable:
        """The rows selected by a boolean mask (n,) or an index array."""
        sel = np.asarray(mask)
        if sel.dtype == bool and sel.shape != (len(self),):
            raise ProblemError(
                f"biasfield.PlotTable.subset mask: expected {len(self)} "
                f"booleans, got shape {sel.shape}"
            )
        if sel.dtype != bool and not np.issubdtype(sel.dtype, np.integer):
            raise ProblemError(
                f"biasfield.PlotTable.subset mask: expected booleans or indices, got {sel.dtype}"
            )
        return PlotTable(
            self.time[mask],
            self.radar[mask],
            self.range[mask],
            self.azimuth[mask],
            self.object[mask],
            None if self.height is None else self.height[mask],
        )


def check_tables(where: str, plots: object, radars: object) -> None:
    """``plots`` a :class:`PlotTable` and ``radars`` a :class:`RadarSet`, or ProblemError
    naming ``where``'s argument."""
    if not isinstance(plots, PlotTable):
        raise ProblemError(
            f"{where} plots: expected a PlotTable (see biasfield.read_plots), "
            f"got {type(plots).__name__}"
        )
    if not isinstance(radars, RadarSet):
        raise ProblemError(
            f"{where} radars: expected a RadarSet (see biasfield.read_radars), "
            f"got {type(radars).__name__}"
        )
