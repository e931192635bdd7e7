"""Radars and radar plots (paper 001, (1)): the tables the bias-field pipeline reads."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.geometry import from_polar, polar_jacobian
from optmodels.core import MAX_MAGNITUDE, FloatArray, ProblemError, as_count, as_finite_array

__all__ = ["AircraftPaths", "PlotTable", "RadarSet"]


@dataclass(frozen=True)
class RadarSet:
    """m 2-D radars: ``sites`` (m, 2) East-North (m); per radar ``sigma_range`` (m),
    ``sigma_azimuth`` (rad), ``max_range`` (m) and ``names``.

    The noise covariance of a plot is V_i = diag(σ_r², σ_az²) in the radar's polar frame,
    and, to first order, ∇p_i⁻¹ V_i ∇p_i⁻ᵀ in Cartesian coordinates (:meth:`cartesian_cov`).
    """

    sites: FloatArray
    sigma_range: FloatArray
    sigma_azimuth: FloatArray
    max_range: FloatArray
    names: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        sites = as_finite_array("biasfield.RadarSet sites", self.sites, ndim=2,
                                max_abs=MAX_MAGNITUDE)
        if sites.shape[1] != 2:
            raise ProblemError(f"biasfield.RadarSet sites: expected (m, 2), got {sites.shape}")
        m = sites.shape[0]
        if m < 2:
            raise ProblemError(f"biasfield.RadarSet sites: the bias field needs at least 2 "
                               f"radars, got {m}")
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
            raise ProblemError(f"biasfield.RadarSet names: expected a sequence of {m} names, "
                               f"got the string {self.names!r:.60}")
        names = tuple(str(n) for n in self.names) or tuple(f"R{i + 1}" for i in range(m))
        if len(names) != m or len(set(names)) != m or "" in names:
            raise ProblemError(f"biasfield.RadarSet names: need {m} distinct non-empty names, "
                               f"got {names}")
        object.__setattr__(self, "names", names)

    @property
    def m(self) -> int:
        return int(self.sites.shape[0])

    def index(self, radar: str | int) -> int:
        """Index of a radar given by name or index."""
        if isinstance(radar, bool | np.bool_):
            raise ProblemError(f"radar: unknown radar id {radar!r} (known: {self.names})")
        if isinstance(radar, int | np.integer) and 0 <= int(radar) < self.m:
            return int(radar)
        if radar in self.names:
            return self.names.index(str(radar))
        raise ProblemError(f"radar: unknown radar id {radar!r} (known: {self.names})")

    def polar_cov(self, i: int) -> FloatArray:
        """V_i = diag(σ_r², σ_az²) of radar ``i`` (m², rad²)."""
        i = as_count("biasfield.RadarSet.polar_cov i", i, maximum=self.m - 1)
        return np.diag([self.sigma_range[i] ** 2, self.sigma_azimuth[i] ** 2])

    def cartesian_cov(self, i: int, x: ArrayLike) -> FloatArray:
        """V_i(x) in Cartesian coordinates, (..., 2, 2), to first order."""
        i = as_count("biasfield.RadarSet.cartesian_cov i", i, maximum=self.m - 1)
        pts = as_finite_array("biasfield.RadarSet.cartesian_cov x", x, max_abs=MAX_MAGNITUDE)
        if pts.shape[-1:] != (2,):
            raise ProblemError("biasfield.RadarSet.cartesian_cov x: expected (..., 2), got "
                               f"{pts.shape}")
        ginv = np.linalg.inv(polar_jacobian(pts, self.sites[i]))
        return ginv @ self.polar_cov(i) @ np.swapaxes(ginv, -1, -2)


@dataclass(frozen=True)
class PlotTable:
    """Radar plots, one row each: ``time`` (s), ``radar`` (index into a :class:`RadarSet`),
    ``range`` (m), ``azimuth`` (rad, clockwise from North), ``object`` (track id, −1 if
    unknown). Rows are kept in the order given."""

    time: FloatArray
    radar: np.ndarray
    range: FloatArray
    azimuth: FloatArray
    object: np.ndarray

    def __post_init__(self) -> None:
        t = as_finite_array("biasfield.PlotTable time", self.time, ndim=1, max_abs=MAX_MAGNITUDE)
        n = t.shape[0]
        r = as_finite_array("biasfield.PlotTable range", self.range, shape=(n,),
                            max_abs=MAX_MAGNITUDE)
        az = as_finite_array("biasfield.PlotTable azimuth", self.azimuth, shape=(n,),
                             max_abs=MAX_MAGNITUDE)
        if np.any(r < 0):
            raise ProblemError(f"biasfield.PlotTable range: {int(np.sum(r < 0))} negative "
                               "ranges")
        rad = np.asarray(self.radar)
        obj = np.asarray(self.object)
        for name, arr in (("radar", rad), ("object", obj)):
            if arr.shape != (n,) or not np.issubdtype(arr.dtype, np.integer):
                raise ProblemError(f"biasfield.PlotTable {name}: expected {n} integers, got "
                                   f"{arr.dtype} {arr.shape}")
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "range", r)
        object.__setattr__(self, "azimuth", az)
        object.__setattr__(self, "radar", rad.astype(np.int64))
        object.__setattr__(self, "object", obj.astype(np.int64))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def check(self, radars: RadarSet) -> None:
        """Radar ids exist and ranges are within each radar's ``max_range``."""
        if not isinstance(radars, RadarSet):
            raise ProblemError(f"biasfield.PlotTable.check radars: expected a RadarSet, got "
                               f"{type(radars).__name__}")
        bad = (self.radar < 0) | (self.radar >= radars.m)
        if bad.any():
            raise ProblemError(f"radar: unknown radar index {int(self.radar[bad][0])} in "
                               f"{int(bad.sum())} plots (radars 0..{radars.m - 1})")
        over = self.range > radars.max_range[self.radar]
        if over.any():
            raise ProblemError(f"range: {int(over.sum())} plots beyond their radar's "
                               "max_range (outside the valid range)")

    def cartesian(self, radars: RadarSet) -> FloatArray:
        """Plot positions z (n, 2) in the common Cartesian frame."""
        if not isinstance(radars, RadarSet):
            raise ProblemError(f"biasfield.PlotTable.cartesian radars: expected a RadarSet, "
                               f"got {type(radars).__name__}")
        bad = (self.radar < 0) | (self.radar >= radars.m)
        if bad.any():  # rows of no radar would be left uninitialised below
            raise ProblemError(f"radar: unknown radar index {int(self.radar[bad][0])} in "
                               f"{int(bad.sum())} plots (radars 0..{radars.m - 1})")
        out = np.empty((len(self), 2))
        for i in range(radars.m):
            sel = self.radar == i
            out[sel] = from_polar(np.column_stack([self.range[sel], self.azimuth[sel]]),
                                  radars.sites[i])
        return out

    def subset(self, mask: np.ndarray) -> PlotTable:
        """The rows selected by a boolean mask (n,) or an index array."""
        sel = np.asarray(mask)
        if sel.dtype == bool and sel.shape != (len(self),):
            raise ProblemError(f"biasfield.PlotTable.subset mask: expected {len(self)} "
                               f"booleans, got shape {sel.shape}")
        if sel.dtype != bool and not np.issubdtype(sel.dtype, np.integer):
            raise ProblemError("biasfield.PlotTable.subset mask: expected booleans or "
                               f"indices, got {sel.dtype}")
        return PlotTable(self.time[mask], self.radar[mask], self.range[mask],
                         self.azimuth[mask], self.object[mask])


@dataclass(frozen=True)
class AircraftPaths:
    """Dense true paths: ``times`` (T,) shared grid (s) and ``positions`` (A, T, 2) (m);
    ``active`` (A, T) where each aircraft is airborne."""

    times: FloatArray
    positions: FloatArray
    active: np.ndarray

    def __post_init__(self) -> None:
        t = as_finite_array("biasfield.AircraftPaths times", self.times, ndim=1,
                            max_abs=MAX_MAGNITUDE)
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise ProblemError("biasfield.AircraftPaths times: need at least 2 strictly "
                               f"increasing instants, got {t.size}")
        pos = as_finite_array("biasfield.AircraftPaths positions", self.positions,
                              shape=(None, t.size, 2), max_abs=MAX_MAGNITUDE)
        act = np.asarray(self.active)
        if act.dtype != bool or act.shape != pos.shape[:2]:
            raise ProblemError(f"biasfield.AircraftPaths active: expected {pos.shape[:2]} "
                               f"booleans, got {act.dtype} {act.shape}")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "active", act)

    def at(self, a: int, t: ArrayLike) -> FloatArray:
        """Position of aircraft ``a`` at times t (linear interpolation on the grid)."""
        a = as_count("biasfield.AircraftPaths.at a", a, maximum=self.positions.shape[0] - 1)
        tt = as_finite_array("biasfield.AircraftPaths.at t", t)
        p = self.positions[a]
        return np.stack([np.interp(tt, self.times, p[:, 0]), np.interp(tt, self.times, p[:, 1])],
                        axis=-1)
