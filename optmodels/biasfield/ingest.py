"""Reading real data for the bias-field pipeline (paper 001).

* Radars: a small CSV, one row per radar: ``name, x, y`` (local East-North metres) **or**
  ``name, lat, lon[, alt]`` (degrees, metres; converted to local ENU with pymap3d about an
  origin), plus ``sigma_range`` (m), ``sigma_azimuth`` (degrees) and ``max_range`` (m).
  Latitudes must lie in [-90, 90], longitudes in [-180, 360) (both the ±180 and the 0-360
  conventions), altitudes be finite; the sigmas and ``max_range`` positive and finite;
  names non-empty and distinct.
* Plots: CSV or Parquet with ``time, radar, range, azimuth[, object]``; ``radar`` is the
  radar's name (or its index), ``range`` in metres (≥ 0), ``azimuth`` in degrees clockwise
  from North (``azimuth_unit="rad"`` for radians), within ±360° (±2π rad). Rows with an
  unknown radar raise; rows beyond a radar's ``max_range`` raise unless
  ``drop_out_of_range`` (then counted).
* Aircraft tracks (e.g. ADS-B): ``object, time, lat, lon[, alt]`` → local ENU with
  pymap3d, resampled on a common 1 s grid as :class:`AircraftPaths`, so that radar plots of
  real traffic can be simulated with :func:`optmodels.scenarios.radar_network.simulate_plots`.

CSV files are UTF-8 with or without a byte-order mark (:func:`optmodels.io.read_csv_rows`);
every unusable file or value is one :class:`~optmodels.core.ProblemError` naming the file
(and the line or row, and the column).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from optmodels.biasfield.data import AircraftPaths, PlotTable, RadarSet
from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_flag,
    as_instance,
    as_number,
    as_positive,
)
from optmodels.io import as_path, csv_numbers, input_file, read_csv_rows

__all__ = ["GeodeticOrigin", "read_plots", "read_radars", "read_tracks"]

GeodeticOrigin = tuple[float, float, float]

#: Largest resampled track grid of :func:`read_tracks` (aircraft × instants): 2e7 points
#: of 17 bytes (East, North, active), ~340 MB; a guard against times in ms or a tiny
#: ``step`` (200 aircraft over a day at 1 s are 1.7e7).
MAX_TRACK_GRID = 20_000_000


@dataclass(frozen=True)
class _Table:
    """Columns of a CSV (text cells) or Parquet file (arrays), lower-case names, with the
    file line of each row for CSV (``None`` for Parquet: rows are numbered from 1)."""

    path: Path
    cols: dict[str, np.ndarray]
    lines: list[int] | None

    @property
    def n(self) -> int:
        return len(next(iter(self.cols.values()))) if self.cols else 0

    def where(self, i: int) -> str:
        return f"line {self.lines[i]}" if self.lines is not None else f"row {i + 1}"

    def need(self, name: str) -> np.ndarray:
        if name not in self.cols:
            raise ProblemError(f"{self.path}: missing column {name!r} "
                               f"(have {', '.join(sorted(self.cols))})")
        return self.cols[name]

    def numeric(self, name: str) -> FloatArray:
        return csv_numbers(self.path, name, self.need(name), self.lines)

    def text(self, name: str) -> list[str]:
        return [str(c).strip() for c in self.need(name)]

    def within(self, name: str, v: FloatArray, low: float, high: float, *,
               high_open: bool = False, unit: str = "") -> None:
        """Refuse values outside [low, high] (or [low, high)), naming the first one."""
        bad = (v < low) | (v >= high if high_open else v > high)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            close = ")" if high_open else "]"
            raise ProblemError(f"{self.path}: {self.where(i)}, column {name!r}: {v[i]:g}{unit}"
                               f" is outside [{low:g}, {high:g}{close}{unit} "
                               f"({int(bad.sum())} such value(s))")

    def positive(self, name: str) -> FloatArray:
        v = self.numeric(name)
        bad = v <= 0
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ProblemError(f"{self.path}: {self.where(i)}, column {name!r}: {v[i]:g} "
                               "(must be positive)")
        return v


def _table(path: str | os.PathLike[str], what: str) -> _Table:
    """Read a CSV (as text) or a Parquet file (``.parquet``/``.pq``, as arrays)."""
    p = as_path(f"biasfield.read_{what} path", path)
    if p.suffix.lower() in (".parquet", ".pq"):
        return _parquet(p, what)
    rows = read_csv_rows(p, what=f"{what} CSV")
    cols = list(zip(*rows.rows, strict=True))
    return _Table(p, {h: np.array([c.strip() for c in col])
                      for h, col in zip(rows.header, cols, strict=True)}, rows.lines)


def _parquet(p: Path, what: str) -> _Table:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:  # pragma: no cover - pyarrow is in the test extra
        raise ProblemError(f"{p}: reading Parquet needs pyarrow "
                           "(pip install 'optmodels[parquet]')") from exc
    input_file(p, what=f"{what} Parquet file")
    try:
        tab = pq.read_table(p)
    except (pa.ArrowException, OSError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ProblemError(f"{p}: not a readable Parquet file ({first})") from None
    cols: dict[str, np.ndarray] = {}
    for name in tab.column_names:
        key = name.strip().lower()
        if key in cols:
            raise ProblemError(f"{p}: column {key!r} appears more than once")
        try:
            cols[key] = tab.column(name).to_numpy(zero_copy_only=False)
        except (pa.ArrowException, ValueError, TypeError) as exc:
            raise ProblemError(f"{p}: column {name!r} cannot be read as an array "
                               f"({exc})") from None
    if tab.num_rows == 0:
        raise ProblemError(f"{p}: no data rows")
    return _Table(p, cols, None)


def _as_origin(name: str, origin: Any) -> GeodeticOrigin:
    """(lat, lon, alt): degrees in [-90, 90] and [-180, 360), metres finite."""
    if isinstance(origin, str | bytes) or not isinstance(origin, Sequence | np.ndarray):
        raise ProblemError(f"{name}: expected (lat, lon, alt), got {origin!r:.60}")
    if len(origin) != 3:
        raise ProblemError(f"{name}: expected (lat, lon, alt), got {len(origin)} values")
    return (as_number(f"{name} lat", origin[0], low=-90.0, high=90.0),
            as_number(f"{name} lon", origin[1], low=-180.0, high=360.0, high_open=True),
            as_number(f"{name} alt", origin[2]))


def _geodetic(tab: _Table) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validated lat, lon (degrees) and alt (m, 0 if absent)."""
    lat, lon = tab.numeric("lat"), tab.numeric("lon")
    tab.within("lat", lat, -90.0, 90.0, unit="°")
    tab.within("lon", lon, -180.0, 360.0, high_open=True, unit="°")
    alt = tab.numeric("alt") if "alt" in tab.cols else np.zeros_like(lat)
    return lat, lon, alt


def _in_file(path: Path, exc: ProblemError) -> ProblemError:
    return ProblemError(f"{path}: {exc}")


def read_radars(path: str | os.PathLike[str], *, origin: GeodeticOrigin | None = None
                ) -> tuple[RadarSet, GeodeticOrigin | None]:
    """Radars of paper 001 (sites, and the noise V_i of (1)) from a CSV.

    Columns ``name`` and either ``x, y`` (local East-North, m) or ``lat, lon[, alt]``
    (degrees, m; converted to local ENU with pymap3d about ``origin``), plus
    ``sigma_range`` (m), ``sigma_azimuth`` (degrees) and ``max_range`` (m).

    Parameters
    ----------
    path
        CSV (UTF-8, BOM allowed) or Parquet file.
    origin
        (lat °, lon °, alt m) of the local frame; default: the first radar's position.

    Returns
    -------
    tuple
        The :class:`RadarSet` and the geodetic origin used (``None`` for x, y input).

    Raises
    ------
    ProblemError
        Naming the file (and the line and column): unreadable file; missing column;
        latitude outside [-90, 90]°, longitude outside [-180, 360)°, a non-finite
        altitude or coordinate; a non-positive or non-finite sigma or ``max_range``; an
        empty or duplicate name; fewer than 2 radars. ``origin`` is checked likewise.
    """
    org_given = None if origin is None else _as_origin("biasfield.read_radars origin", origin)
    tab = _table(path, "radars")
    names = tab.text("name")
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if not name:
            raise ProblemError(f"{tab.path}: {tab.where(i)}: empty radar name")
        if name in seen:
            raise ProblemError(f"{tab.path}: {tab.where(i)}: radar name {name!r} repeats "
                               f"{tab.where(seen[name])} (names must be distinct)")
        seen[name] = i
    if "lat" in tab.cols or "lon" in tab.cols:
        lat, lon, alt = _geodetic(tab)
        org = org_given or (float(lat[0]), float(lon[0]), float(alt[0]))
        e, n, _ = pymap3d.geodetic2enu(lat, lon, alt, *org)
        sites = np.column_stack([e, n])
    else:
        sites = np.column_stack([tab.numeric("x"), tab.numeric("y")])
        org = None
    sig_r, sig_az = tab.positive("sigma_range"), tab.positive("sigma_azimuth")
    max_range = tab.positive("max_range")
    try:
        radars = RadarSet(sites, sig_r, np.deg2rad(sig_az), max_range, tuple(names))
    except ProblemError as exc:
        raise _in_file(tab.path, exc) from None
    return radars, org


def read_plots(path: str | os.PathLike[str], radars: RadarSet, *, azimuth_unit: str = "deg",
               drop_out_of_range: bool = False) -> tuple[PlotTable, dict[str, int]]:
    """Radar plots of paper 001 ((1): range and azimuth per radar and instant).

    Columns ``time`` (s), ``radar`` (a name of ``radars``, or its index), ``range`` (m,
    ≥ 0), ``azimuth`` (degrees clockwise from North, or radians with
    ``azimuth_unit="rad"``; within ±360° / ±2π) and optional ``object`` (track label;
    empty, ``-1`` or ``nan`` for unknown).

    Returns
    -------
    tuple
        The :class:`PlotTable` (azimuth in radians) and the counts of dropped rows.

    Raises
    ------
    ProblemError
        Naming the file (and the line or row, and the column): unreadable file; missing
        column; a time, range or azimuth that is not a finite number; a negative range; an
        azimuth outside ±360° (±2π rad: degrees read as radians?); an unknown radar; plots
        beyond their radar's ``max_range`` unless ``drop_out_of_range``.
    """
    as_instance("biasfield.read_plots radars", radars, RadarSet)
    unit = as_choice("biasfield.read_plots azimuth_unit", azimuth_unit, ("deg", "rad"))
    as_flag("biasfield.read_plots drop_out_of_range", drop_out_of_range)
    tab = _table(path, "plots")
    raw = tab.text("radar")
    t = tab.numeric("time")
    rng = tab.numeric("range")
    neg = np.flatnonzero(rng < 0)
    if neg.size:
        raise ProblemError(f"{tab.path}: {tab.where(int(neg[0]))}, column 'range': "
                           f"{rng[neg[0]]:g} m is negative ({neg.size} such value(s))")
    az = tab.numeric("azimuth")
    if unit == "deg":
        tab.within("azimuth", az, -360.0, 360.0, unit="°")
        az = np.deg2rad(az)
    else:
        tab.within("azimuth", az, -2 * np.pi, 2 * np.pi, unit=" rad")
    lookup: dict[Any, int] = {}
    for i, name in enumerate(radars.names):
        lookup[name] = i
        lookup[str(i)] = lookup.get(str(i), i)
    unknown = sorted({r for r in raw if r not in lookup})
    if unknown:
        i = next(k for k, r in enumerate(raw) if r not in lookup)
        raise ProblemError(f"{tab.path}: unknown radar id(s) {unknown[:5]} (first at "
                           f"{tab.where(i)}; known: {radars.names})")
    radar = np.array([lookup[r] for r in raw], dtype=np.int64)
    if "object" in tab.cols:
        obj_raw = tab.text("object")
        ids = {o: k for k, o in enumerate(dict.fromkeys(o for o in obj_raw if o not in
                                                         ("", "-1", "nan", "None")))}
        obj = np.array([ids.get(o, -1) for o in obj_raw], dtype=np.int64)
    else:
        obj = np.full(t.size, -1, dtype=np.int64)
    try:
        table = PlotTable(t, radar, rng, az, obj)
    except ProblemError as exc:
        raise _in_file(tab.path, exc) from None
    dropped: dict[str, int] = {}
    over = table.range > radars.max_range[table.radar]
    if over.any():
        if not drop_out_of_range:
            i = int(np.flatnonzero(over)[0])
            raise ProblemError(f"{tab.path}: {int(over.sum())} plots beyond their radar's "
                               f"max_range (first at {tab.where(i)}; pass "
                               "drop_out_of_range=True to drop them)")
        dropped["beyond max_range"] = int(over.sum())
        table = table.subset(~over)
    return table, dropped


def read_tracks(path: str | os.PathLike[str], origin: GeodeticOrigin, *, step: float = 1.0
                ) -> AircraftPaths:
    """Aircraft tracks ``object, time, lat, lon[, alt]`` → local East-North paths.

    Positions (lat, lon in degrees, alt in m) are converted to ENU about ``origin``
    (lat °, lon °, alt m) and linearly resampled every ``step`` seconds; each aircraft is
    active between its first and last report.

    Raises
    ------
    ProblemError
        Naming the file (and the line or row, and the column): unreadable file; missing
        column; a time, latitude, longitude or altitude that is not a finite number;
        latitude outside [-90, 90]°, longitude outside [-180, 360)°; an empty object label;
        an object with fewer than 2 reports at distinct times; a resampled grid larger
        than :data:`MAX_TRACK_GRID` values (times in ms?). ``origin`` and ``step`` (s,
        positive) are checked too.
    """
    org = _as_origin("biasfield.read_tracks origin", origin)
    dt = as_positive("biasfield.read_tracks step", step)
    tab = _table(path, "tracks")
    obj = np.array(tab.text("object"))
    empty = np.flatnonzero(obj == "")
    if empty.size:
        raise ProblemError(f"{tab.path}: {tab.where(int(empty[0]))}: empty 'object' label")
    t = tab.numeric("time")
    lat, lon, alt = _geodetic(tab)
    names = list(dict.fromkeys(obj))
    span = float(np.ceil(t.max()) - np.floor(t.min()))
    size = (span / dt + 2.0) * len(names)
    if size > MAX_TRACK_GRID:
        raise ProblemError(f"{tab.path}: resampling {len(names)} aircraft over {span:g} s "
                           f"every {dt:g} s needs {size:.3g} grid values (limit "
                           f"{MAX_TRACK_GRID:.0e}); are the times in seconds?")
    e, n, _ = pymap3d.geodetic2enu(lat, lon, alt, *org)
    grid = np.arange(np.floor(t.min()), np.ceil(t.max()) + dt, dt)
    pos = np.zeros((len(names), grid.size, 2))
    active = np.zeros((len(names), grid.size), dtype=bool)
    for a, name in enumerate(names):
        sel = np.flatnonzero(obj == name)
        sel = sel[np.argsort(t[sel], kind="stable")]
        ts = t[sel]
        if np.unique(ts).size < 2:
            raise ProblemError(f"{tab.path}: object {name!r} has fewer than 2 reports at "
                               "distinct times")
        pos[a, :, 0] = np.interp(grid, ts, e[sel])
        pos[a, :, 1] = np.interp(grid, ts, n[sel])
        active[a] = (grid >= ts[0]) & (grid <= ts[-1])
    try:
        return AircraftPaths(grid, pos, active)
    except ProblemError as exc:
        raise _in_file(tab.path, exc) from None
