"""Reading real data for the bias-field pipeline (paper 001).

* Radars: a small CSV, one row per radar: ``name, x, y`` (local East-North metres) **or**
  ``name, lat, lon[, alt]`` (degrees, metres; converted to local ENU with pymap3d about an
  origin), plus ``sigma_range`` (m), ``sigma_azimuth`` (degrees) and ``max_range`` (m).
  Latitudes must lie in [-90, 90], longitudes in [-180, 360) (both the ±180 and the 0-360
  conventions), altitudes be finite; the sigmas and ``max_range`` positive and finite;
  names non-empty and distinct.
* Plots: CSV or Parquet with ``time, radar, range, azimuth[, object][, height]``; ``radar`` is the
  radar's name (or its index), ``range`` in metres (≥ 0), ``azimuth`` in degrees clockwise
  from North (``azimuth_unit="rad"`` for radians), within ±360° (±2π rad). Rows with an
  unknown radar raise; rows beyond a radar's ``max_range`` raise unless
  ``drop_out_of_range`` (then counted).
* Aircraft tracks (e.g. ADS-B): ``object, time, lat, lon[, alt]`` → cleaned
  (:mod:`optmodels.biasfield.cleaning`: split at gaps, impossible jumps and ground traffic
  dropped and reported), each kept segment resampled every ``step`` seconds over its own
  span as 3-D :class:`AircraftPaths`, so that radar plots of real traffic can be
  simulated with :func:`optmodels.scenarios.radar_network.simulate_plots`.

CSV files are UTF-8 with or without a byte-order mark (:func:`optmodels.io.read_csv_rows`);
every unusable file or value is one :class:`~optmodels.core.ProblemError` naming the file
(and the line or row, and the column).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from optmodels.biasfield.cleaning import (
    ADSB_LIMITS,
    ADSB_SIGMA,
    CleaningLimits,
    CleaningReport,
    clean_reports,
)
from optmodels.biasfield.paths import AircraftPaths
from optmodels.biasfield.tables import PlotTable, RadarSet
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

#: Largest number of resampled track points of :func:`read_tracks` (all segments): 4e7
#: points of 48 bytes (time, East, North, latitude, longitude, height) ≈ 1.9 GB; a guard
#: against times in ms or a tiny ``step`` (a day of 5000 aircraft of 1.5 h each at 1 s is
#: 2.7e7). Counted on each object's whole span, before the gaps are cut out.
MAX_TRACK_GRID = 40_000_000


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
            raise ProblemError(
                f"{self.path}: missing column {name!r} (have {', '.join(sorted(self.cols))})"
            )
        return self.cols[name]

    def numeric(self, name: str) -> FloatArray:
        return csv_numbers(self.path, name, self.need(name), self.lines)

    def text(self, name: str) -> list[str]:
        return [str(c).strip() for c in self.need(name)]

    def within(
        self,
        name: str,
        v: FloatArray,
        low: float,
        high: float,
        *,
        high_open: bool = False,
        unit: str = "",
    ) -> None:
        """Refuse values outside [low, high] (or [low, high)), naming the first one."""
        bad = (v < low) | (v >= high if high_open else v > high)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            close = ")" if high_open else "]"
            raise ProblemError(
                f"{self.path}: {self.where(i)}, column {name!r}: {v[i]:g}{unit}"
                f" is outside [{low:g}, {high:g}{close}{unit} "
                f"({int(bad.sum())} such value(s))"
            )

    def positive(self, name: str) -> FloatArray:
        v = self.numeric(name)
        bad = v <= 0
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ProblemError(
                f"{self.path}: {self.where(i)}, column {name!r}: {v[i]:g} (must be positive)"
            )
        return v


def table_file(path: str | os.PathLike[str], what: str) -> _Table:
    """Read a CSV (as text) or a Parquet file (``.parquet``/``.pq``, as arrays)."""
    p = as_path(f"biasfield.read_{what} path", path)
    if p.suffix.lower() in (".parquet", ".pq"):
        return _parquet(p, what)
    rows = read_csv_rows(p, what=f"{what} CSV")
    cols = list(zip(*rows.rows, strict=True))
    return _Table(
        p,
        {h: np.array([c.strip() for c in col]) for h, col in zip(rows.header, cols, strict=True)},
        rows.lines,
    )


def _parquet(p: Path, what: str) -> _Table:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:  # pragma: no cover - pyarrow is in the test extra
        raise ProblemError(
            f"{p}: reading Parquet needs pyarrow (pip install 'optmodels[parquet]')"
        ) from exc
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
            raise ProblemError(f"{p}: column {name!r} cannot be read as an array ({exc})") from None
    if tab.num_rows == 0:
        raise ProblemError(f"{p}: no data rows")
    return _Table(p, cols, None)


def _as_origin(name: str, origin: Any) -> GeodeticOrigin:
    """(lat, lon, alt): degrees in [-90, 90] and [-180, 360), metres finite."""
    if isinstance(origin, str | bytes) or not isinstance(origin, Sequence | np.ndarray):
        raise ProblemError(f"{name}: expected (lat, lon, alt), got {origin!r:.60}")
    if len(origin) != 3:
        raise ProblemError(f"{name}: expected (lat, lon, alt), got {len(origin)} values")
    return (
        as_number(f"{name} lat", origin[0], low=-90.0, high=90.0),
        as_number(f"{name} lon", origin[1], low=-180.0, high=360.0, high_open=True),
        as_number(f"{name} alt", origin[2]),
    )


def _geodetic(tab: _Table) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validated lat, lon (degrees) and alt (m, 0 if absent)."""
    lat, lon = tab.numeric("lat"), tab.numeric("lon")
    tab.within("lat", lat, -90.0, 90.0, unit="°")
    tab.within("lon", lon, -180.0, 360.0, high_open=True, unit="°")
    alt = tab.numeric("alt") if "alt" in tab.cols else np.zeros_like(lat)
    return lat, lon, alt


def _in_file(path: Path, exc: ProblemError) -> ProblemError:
    return ProblemError(f"{path}: {exc}")


def read_radars(
    path: str | os.PathLike[str],
    *,
    origin: GeodeticOrigin | str | None = None,
    geometry: str = "2d",
) -> tuple[RadarSet, GeodeticOrigin | None]:
    """Radars of paper 001 (sites, and the noise V_i of (1)) from a CSV.

    Columns ``name`` and either ``x, y`` (local East-North, m) or ``lat, lon[, alt]``
    (degrees, m above the WGS-84 ellipsoid), plus ``sigma_range`` (m), ``sigma_azimuth``
    (degrees) and ``max_range`` (m); optional ``sac, sic`` (ASTERIX I010, integers 0-255).

    Parameters
    ----------
    path
        CSV (UTF-8, BOM allowed) or Parquet file.
    origin
        (lat °, lon °, alt m) of the common frame; ``"mean"``: the mean latitude, longitude
        and altitude of the sites (what ``optmodels biasfield build`` uses by default);
        ``None`` or ``"first"``: the first radar's position.
    geometry
        ``"2d"`` (default): the sites' East-North in the local ENU of ``origin``
        (pymap3d), for plots whose ranges are ground ranges on that plane; ``"3d"``: a
        3-D :class:`RadarSet` (``geodetic`` sites, slant ranges, each radar's own north;
        needs ``lat, lon``; the sites are then the footprints on the common plane of
        :mod:`~optmodels.biasfield.geometry3d`).

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
        empty or duplicate name; SAC/SIC not integers 0-255 or repeated; fewer than 2
        radars; ``geometry="3d"`` without ``lat, lon``. ``origin`` is checked likewise.
    """
    fn = "biasfield.read_radars"
    geometry = as_choice(f"{fn} geometry", geometry, ("2d", "3d"))
    mode = origin if isinstance(origin, str) and origin in ("mean", "first") else None
    org_given = None if origin is None or mode is not None else _as_origin(f"{fn} origin", origin)
    tab = table_file(path, "radars")
    names = tab.text("name")
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if not name:
            raise ProblemError(f"{tab.path}: {tab.where(i)}: empty radar name")
        if name in seen:
            raise ProblemError(
                f"{tab.path}: {tab.where(i)}: radar name {name!r} repeats "
                f"{tab.where(seen[name])} (names must be distinct)"
            )
        seen[name] = i
    ids: tuple[tuple[int, int], ...] = ()
    if "sac" in tab.cols or "sic" in tab.cols:
        sac, sic = tab.numeric("sac"), tab.numeric("sic")
        for col, v in (("sac", sac), ("sic", sic)):
            bad = (v != np.round(v)) | (v < 0) | (v > 255)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ProblemError(
                    f"{tab.path}: {tab.where(i)}, column {col!r}: {v[i]:g} "
                    "is not an integer 0-255 (ASTERIX I010)"
                )
        ids = tuple((int(a), int(b)) for a, b in zip(sac, sic, strict=True))
    geo = None
    if "lat" in tab.cols or "lon" in tab.cols:
        lat, lon, alt = _geodetic(tab)
        if org_given is not None:
            org = org_given
        elif mode == "mean":
            org = (float(lat.mean()), float(_unwrap_lon(lon).mean()) % 360.0, float(alt.mean()))
            if org[1] >= 180.0:
                org = (org[0], org[1] - 360.0, org[2])
        else:
            org = (float(lat[0]), float(lon[0]), float(alt[0]))
        e, n, _ = pymap3d.geodetic2enu(lat, lon, alt, *org)
        sites = np.column_stack([e, n])
        geo = np.column_stack([lat, lon, alt])
    else:
        if geometry == "3d":
            raise ProblemError(
                f"{tab.path}: geometry='3d' needs the columns lat, lon[, alt] "
                "(degrees, m above the WGS-84 ellipsoid)"
            )
        sites = np.column_stack([tab.numeric("x"), tab.numeric("y")])
        org = None
    sig_r, sig_az = tab.positive("sigma_range"), tab.positive("sigma_azimuth")
    max_range = tab.positive("max_range")
    try:
        if geometry == "3d":
            radars = RadarSet(
                None,
                sig_r,
                np.deg2rad(sig_az),
                max_range,
                tuple(names),
                geodetic=geo,
                origin=np.asarray(org),
                ids=ids,
            )
        else:
            radars = RadarSet(sites, sig_r, np.deg2rad(sig_az), max_range, tuple(names), ids=ids)
    except ProblemError as exc:
        raise _in_file(tab.path, exc) from None
    return radars, org


def read_plots(
    path: str | os.PathLike[str],
    radars: RadarSet,
    *,
    azimuth_unit: str = "deg",
    drop_out_of_range: bool = False,
    labels: list[str] | None = None,
) -> tuple[PlotTable, dict[str, int]]:
    """Radar plots of paper 001 ((1): range and azimuth per radar and instant).

    Columns ``time`` (s), ``radar`` (a name of ``radars``, or its index), ``range`` (m,
    ≥ 0; the slant range for a 3-D radar set), ``azimuth`` (degrees clockwise from North
    -- the radar's own north in 3-D --, or radians with ``azimuth_unit="rad"``; within
    ±360° / ±2π), optional ``object`` (track label; empty, ``-1`` or ``nan`` for unknown)
    and optional ``height`` (target height, m above the WGS-84 ellipsoid; empty or
    ``nan`` for unknown), which a 3-D radar set needs. Without an ``object`` column, an
    ``address`` column (the ICAO address that ``optmodels biasfield correct`` writes)
    labels the tracks. ``labels``: a list that receives, per object index, its label as
    written in the file (so that a writer can give the plots their own names back).

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
    if labels is not None and not isinstance(labels, list):
        raise ProblemError(
            "biasfield.read_plots labels: expected a list (it receives the object labels) "
            f"or None, got {type(labels).__name__}"
        )
    unit = as_choice("biasfield.read_plots azimuth_unit", azimuth_unit, ("deg", "rad"))
    as_flag("biasfield.read_plots drop_out_of_range", drop_out_of_range)
    tab = table_file(path, "plots")
    raw = tab.text("radar")
    t = tab.numeric("time")
    rng = tab.numeric("range")
    neg = np.flatnonzero(rng < 0)
    if neg.size:
        raise ProblemError(
            f"{tab.path}: {tab.where(int(neg[0]))}, column 'range': "
            f"{rng[neg[0]]:g} m is negative ({neg.size} such value(s))"
        )
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
        raise ProblemError(
            f"{tab.path}: unknown radar id(s) {unknown[:5]} (first at "
            f"{tab.where(i)}; known: {radars.names})"
        )
    radar = np.array([lookup[r] for r in raw], dtype=np.int64)
    label_col = "object" if "object" in tab.cols else "address" if "address" in tab.cols else None
    if label_col is not None:
        obj_raw = tab.text(label_col)
        ids = {
            o: k
            for k, o in enumerate(
                dict.fromkeys(o for o in obj_raw if o not in ("", "-1", "nan", "None"))
            )
        }
        obj = np.array([ids.get(o, -1) for o in obj_raw], dtype=np.int64)
        if labels is not None:
            labels[:] = list(ids)
    else:
        obj = np.full(t.size, -1, dtype=np.int64)
    height = None
    if "height" in tab.cols:
        cells = tab.text("height")
        blank = np.array([c.lower() in ("", "nan") for c in cells])
        height = np.full(t.size, np.nan)
        if (~blank).any():
            sub = _Table(
                tab.path,
                {"height": np.asarray(tab.need("height"))[~blank]},
                None
                if tab.lines is None
                else [ln for ln, b in zip(tab.lines, blank, strict=True) if not b],
            )
            height[~blank] = sub.numeric("height")
    try:
        table = PlotTable(t, radar, rng, az, obj, height=height)
    except ProblemError as exc:
        raise _in_file(tab.path, exc) from None
    dropped: dict[str, int] = {}
    over = table.range > radars.max_range[table.radar]
    if over.any():
        if not drop_out_of_range:
            i = int(np.flatnonzero(over)[0])
            raise ProblemError(
                f"{tab.path}: {int(over.sum())} plots beyond their radar's "
                f"max_range (first at {tab.where(i)}; pass "
                "drop_out_of_range=True to drop them)"
            )
        dropped["beyond max_range"] = int(over.sum())
        table = table.subset(~over)
    return table, dropped


def read_tracks(
    path: str | os.PathLike[str],
    origin: GeodeticOrigin,
    *,
    step: float | None = 1.0,
    clean: bool = True,
    limits: CleaningLimits = ADSB_LIMITS,
    sigma: float = ADSB_SIGMA,
    report: bool = False,
) -> AircraftPaths | tuple[AircraftPaths, CleaningReport]:
    """Aircraft tracks ``object, time, lat, lon[, alt]`` (e.g. ADS-B) → 3-D paths, each
    aircraft over its own span.

    Positions (lat, lon in degrees, alt in m above the WGS-84 ellipsoid, 0 if absent) are
    cleaned per object (:func:`~optmodels.biasfield.cleaning.clean_reports` with
    ``limits``, on the exact 3-D chords of the local ENU of ``origin``: gaps longer than
    ``limits.max_gap`` split a track, impossible jumps and ground traffic are dropped; every
    dropped report is in the :class:`~optmodels.biasfield.cleaning.CleaningReport`), then
    each kept segment is resampled every ``step`` seconds (the multiples of ``step`` within
    the segment; ``None``: the report times) -- nothing is interpolated across a gap. The
    paths (:meth:`AircraftPaths.from_tracks`, plane positions on the common plane of
    ``origin`` (lat °, lon °, alt m)) hold one entry per segment, labelled by the object
    (``"label#j"``, j = 1, 2, … when the object's track was split). Memory: 48 bytes per
    resampled point, only over each segment.

    Parameters
    ----------
    clean
        Apply the cleaning (default); ``False`` keeps every report (only repeated instants
        are merged) and still never interpolates across ``limits.max_gap``.
    sigma
        Per-axis noise of the reported positions (m) for the jump tests.
    report
        Also return the cleaning report (rows are the file's data rows, from 0).

    Raises
    ------
    ProblemError
        Naming the file (and the line or row, and the column): unreadable file; missing
        column; a time, latitude, longitude or altitude that is not a finite number;
        latitude outside [-90, 90]°, longitude outside [-180, 360)°; an empty object label;
        an object with fewer than 2 reports at distinct times; resampled segments of more
        than :data:`MAX_TRACK_GRID` points in all (times in ms?); nothing left after the
        cleaning. ``origin``, ``step`` (s, positive), ``limits`` and ``sigma`` are checked
        too.
    """
    fn = "biasfield.read_tracks"
    org = _as_origin(f"{fn} origin", origin)
    dt = None if step is None else as_positive(f"{fn} step", step)
    as_flag(f"{fn} clean", clean)
    as_flag(f"{fn} report", report)
    lim = as_instance(f"{fn} limits", limits, CleaningLimits)
    sig = as_positive(f"{fn} sigma (m)", sigma, allow_zero=True)
    tab = table_file(path, "tracks")
    obj = np.array(tab.text("object"))
    empty = np.flatnonzero(obj == "")
    if empty.size:
        raise ProblemError(f"{tab.path}: {tab.where(int(empty[0]))}: empty 'object' label")
    t = tab.numeric("time")
    lat, lon, alt = _geodetic(tab)
    names, first, inv = np.unique(obj, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    lo = np.full(names.size, np.inf)
    hi = np.full(names.size, -np.inf)
    np.minimum.at(lo, inv, t)
    np.maximum.at(hi, inv, t)
    distinct = np.unique(np.column_stack([inv, t]), axis=0)[:, 0].astype(np.int64)
    few = np.flatnonzero(np.bincount(distinct, minlength=names.size) < 2)
    if few.size:
        name = names[few[np.argmin(first[few])]]
        raise ProblemError(
            f"{tab.path}: object {name!r} has fewer than 2 reports at distinct times"
        )
    span = float(np.sum(hi - lo))
    size = span / (dt or 1.0) + 2.0 * names.size
    if dt is not None and size > MAX_TRACK_GRID:
        raise ProblemError(
            f"{tab.path}: resampling {names.size} aircraft over {span:g} s "
            f"in all every {dt:g} s needs {size:.3g} grid values (limit "
            f"{MAX_TRACK_GRID:.0e}); are the times in seconds?"
        )
    e, n, u = pymap3d.geodetic2enu(lat, lon, alt, *org)
    xyz = np.column_stack([e, n, u])
    if clean:
        segment, rep = clean_reports(obj, t, xyz, sigma=sig, heights=alt, limits=lim)
    else:
        segment, rep = clean_reports(
            obj,
            t,
            xyz,
            sigma=sig,
            limits=replace(
                lim,
                max_speed=np.inf,
                max_acceleration=np.inf,
                ground_speed=0.0,
                min_points=1,
                glitch_run=1,
            ),
        )
    if not np.any(segment >= 0):
        raise ProblemError(f"{tab.path}: no usable track after the cleaning (dropped {rep.counts})")
    order = np.lexsort((t, segment))
    order = order[segment[order] >= 0]
    cuts = np.flatnonzero(np.diff(segment[order])) + 1
    groups = np.split(order, cuts)
    per_obj: dict[str, int] = {}
    for g in groups:
        per_obj[str(obj[g[0]])] = per_obj.get(str(obj[g[0]]), 0) + 1
    seen: dict[str, int] = {}
    times, lats, lons, hts, labels = [], [], [], [], []
    for g in groups:
        name = str(obj[g[0]])
        seen[name] = seen.get(name, 0) + 1
        labels.append(name if per_obj[name] == 1 else f"{name}#{seen[name]}")
        ts = t[g]
        grid = ts
        if dt is not None:
            cand = np.arange(np.ceil(ts[0] / dt), np.floor(ts[-1] / dt) + 1) * dt
            grid = cand if cand.size >= 2 else ts
        times.append(grid)
        lats.append(np.interp(grid, ts, lat[g]))
        lons.append(np.interp(grid, ts, _unwrap_lon(lon[g])))
        hts.append(np.interp(grid, ts, alt[g]))
    try:
        paths = AircraftPaths.from_tracks(times, lats, lons, hts, org, tuple(labels))
    except ProblemError as exc:
        raise _in_file(tab.path, exc) from None
    return (paths, rep) if report else paths


def _unwrap_lon(lon: FloatArray) -> FloatArray:
    """Longitudes without the ±180° jump, for interpolation (degrees)."""
    return np.rad2deg(np.unwrap(np.deg2rad(lon)))
