"""pandas DataFrames in and out of the bias-field tables (issue 16): radar plots
(:class:`~optmodels.biasfield.tables.PlotTable`) and ADS-B reports
(:class:`~optmodels.biasfield.recording.AdsbReports`), with the column names ADS-B tools
use.

Columns (units stated; ``timestamp`` either float seconds or datetimes):

* ADS-B reports, two conventions (``convention=``; issue 26 item 2):

  - ``"optmodels"`` (what :func:`to_frame` writes): ``timestamp``, ``icao24`` (6-digit
    hex string of the 24-bit address), ``latitude``, ``longitude`` (deg WGS-84),
    ``altitude`` (m above the WGS-84 ellipsoid: the geometric/GNSS height), optional
    ``baroaltitude`` (m, pressure altitude = FL × 30.48).
  - ``"traffic"`` (the *traffic* library's ``Flight.data``): ``altitude`` is the
    **barometric** altitude in **feet** and ``geoaltitude`` the geometric (GNSS) height
    in feet; :func:`from_frame` converts both (× 0.3048 m/ft) into the pressure altitude
    and the height, and :func:`to_frame` writes them back in feet.

  :func:`to_frame` marks its frames (``df.attrs["optmodels.convention"]``); a frame
  without the mark is ambiguous (``altitude`` in metres above the ellipsoid, or
  barometric feet? a 3.28 × error either way) and :func:`from_frame` refuses it unless
  ``convention`` is given.
* Radar plots: ``timestamp``, ``radar`` (the radar's name with ``radars=``, else its
  index ≥ 0, < the radars' count with ``radars=``), ``range`` (m ≥ 0; slant range for a
  3-D radar set), ``azimuth`` (deg clockwise from the radar's north, within ±360° as in
  the plots CSV/Parquet files of :func:`~optmodels.biasfield.ingest.read_plots`),
  ``object`` (int, −1 unknown) and/or ``icao24``, optional ``height`` (m above the
  WGS-84 ellipsoid).

Timestamps: float seconds are the tables' own times (s since their epoch). Datetimes
(``datetime64``, naive = UTC, or tz-aware) become seconds since ``epoch`` (default
:func:`default_epoch`: UTC midnight of the earliest timestamp); :func:`to_frame` with an
``epoch`` writes UTC datetimes (``datetime64[ns, UTC]``), else float seconds; a time
that ``datetime64[ns]`` cannot hold (before 1677-09-21 or after 2262-04-11) is refused,
not written as NaT.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels.core import ProblemError, as_choice

__all__ = ["CONVENTIONS", "FOOT", "MARK", "default_epoch", "from_frame", "to_frame"]

_ADSB = ("timestamp", "icao24", "latitude", "longitude")
_PLOTS = ("timestamp", "radar", "range", "azimuth")

#: The ADS-B column conventions (module docstring) and the mark :func:`to_frame` leaves.
CONVENTIONS = ("optmodels", "traffic")
MARK = "optmodels.convention"
#: m per international foot (the *traffic* library's altitudes are in feet).
FOOT = 0.3048


def _pd() -> Any:
    try:
        import pandas as pd
    except ImportError as exc:  # pragma: no cover - pandas is installed with the extras
        raise ProblemError("frames: pandas is needed (pip install pandas)") from exc
    return pd


def _epoch(name: str, epoch: Any) -> Any:
    pd = _pd()
    if epoch is None:
        return None
    try:
        ts = pd.Timestamp(epoch)
    except (TypeError, ValueError) as exc:
        raise ProblemError(
            f"{name}: expected a date/time (e.g. '2026-03-01'), got {epoch!r:.60}"
        ) from exc
    if ts is pd.NaT:
        raise ProblemError(f"{name}: NaT is not a date")
    return ts.tz_localize("UTC") if ts.tzinfo is None else ts.tz_convert("UTC")


def _utc(col: Any) -> Any:
    pd = _pd()
    s = pd.to_datetime(col)
    return s.dt.tz_localize("UTC") if s.dt.tz is None else s.dt.tz_convert("UTC")


def default_epoch(df: Any) -> Any:
    """UTC midnight (``pandas.Timestamp``) of the earliest ``timestamp`` of a frame with
    datetime timestamps; None for float timestamps."""
    pd = _pd()
    col = _column(df, "timestamp", "frames.default_epoch")
    if not (pd.api.types.is_datetime64_any_dtype(col)):
        return None
    return _utc(col).min().floor("D")


def _column(df: Any, name: str, fn: str) -> Any:
    pd = _pd()
    if not isinstance(df, pd.DataFrame):
        raise ProblemError(f"{fn} df: expected a pandas DataFrame, got {type(df).__name__}")
    if name not in df.columns:
        raise ProblemError(f"{fn} df: missing column {name!r} (have {list(df.columns)})")
    return df[name]


def _seconds(df: Any, fn: str, epoch: Any) -> np.ndarray:
    pd = _pd()
    col = _column(df, "timestamp", fn)
    if pd.api.types.is_datetime64_any_dtype(col):
        t = _utc(col)
        if t.isna().any():
            raise ProblemError(f"{fn} timestamp: {int(t.isna().sum())} missing (NaT) values")
        e = _epoch(f"{fn} epoch", epoch) if epoch is not None else t.min().floor("D")
        return ((t - e).dt.total_seconds()).to_numpy(float)
    if epoch is not None:
        raise ProblemError(
            f"{fn} epoch: only for datetime timestamps (these are numbers, "
            "s since the table's epoch)"
        )
    return _numbers(col, fn, "timestamp")


def _numbers(col: Any, fn: str, name: str, *, nan_ok: bool = False) -> np.ndarray:
    pd = _pd()
    try:
        v = pd.to_numeric(col, errors="raise").to_numpy(float)
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"{fn} {name}: not numeric ({exc})") from None
    bad = np.isinf(v) if nan_ok else ~np.isfinite(v)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ProblemError(f"{fn} {name}: {int(bad.sum())} non-finite values (first at row {i})")
    return v


def _icao(col: Any, fn: str) -> np.ndarray:
    out = np.empty(len(col), np.int64)
    for i, s in enumerate(col):
        text = str(s).strip().lower()
        try:
            v = int(text, 16)
        except ValueError:
            v = -1
        if len(text) > 6 or not 0 <= v < 2**24:
            raise ProblemError(
                f"{fn} icao24: row {i}: {s!r} is not a 24-bit hex address (up to 6 hex digits)"
            )
        out[i] = v
    return out


def _hex(addresses: np.ndarray) -> list[str]:
    return [f"{int(a):06x}" if a >= 0 else "" for a in addresses]


def _timestamps(t: np.ndarray, epoch: Any) -> Any:
    """UTC datetimes (ns) ``epoch + t``; a time outside what ``datetime64[ns]`` holds is
    refused (pandas would write NaT with a RuntimeWarning)."""
    pd = _pd()
    e = _epoch("frames.to_frame epoch", epoch)
    if e is None:
        return t
    # bounds in float seconds from ns integers: the datetime and the offset from the
    # epoch (a Timedelta, int64 ns: ±292 years) must both be representable
    span = np.iinfo(np.int64).max / 1e9 - 1.0
    lo = max((int(pd.Timestamp.min.value) - int(e.value)) / 1e9 + 1.0, -span)
    hi = min((int(pd.Timestamp.max.value) - int(e.value)) / 1e9 - 1.0, span)
    bad = (t < lo) | (t > hi)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ProblemError(
            f"frames.to_frame epoch: {int(bad.sum())} times (first {t[i]:.6g} s, row {i}) "
            f"fall outside datetime64[ns] (1677-09-21 to 2262-04-11, within ±292 years of "
            f"the epoch {e.isoformat()}); are they in seconds? (epoch=None writes float "
            f"seconds)"
        )
    return e + pd.to_timedelta(np.round(t * 1e9).astype(np.int64), unit="ns")


def to_frame(
    table: Any,
    *,
    radars: Any = None,
    addresses: Any = None,
    epoch: Any = None,
    convention: str = "optmodels",
) -> Any:
    """A DataFrame of a :class:`PlotTable`, :class:`AdsbReports` or
    :class:`~optmodels.biasfield.recording.Recording` (its plots, with ``icao24`` and its
    epoch and radars).

    Parameters
    ----------
    radars
        :class:`RadarSet`: write the radar names (else the indices).
    addresses
        Per object its 24-bit address (e.g. ``Recording.addresses``): adds ``icao24``.
    epoch
        UTC date/time the table's times count from: ``timestamp`` as UTC datetimes.
    convention
        ADS-B columns: ``"optmodels"`` (``altitude`` m above the ellipsoid,
        ``baroaltitude`` m) or ``"traffic"`` (``altitude`` barometric ft, ``geoaltitude``
        ft); see the module docstring. The frame carries it in
        ``df.attrs["optmodels.convention"]``.

    Raises
    ------
    ProblemError
        Naming the argument: a table of another type, radar indices beyond ``radars``,
        too few ``addresses``, times that ``datetime64[ns]`` cannot hold from ``epoch``,
        an unknown ``convention``.
    """
    from optmodels.biasfield.recording import AdsbReports, Recording
    from optmodels.biasfield.tables import PlotTable, RadarSet

    pd = _pd()
    conv = as_choice("frames.to_frame convention", convention, CONVENTIONS)
    if isinstance(table, Recording):
        return to_frame(
            table.plots,
            radars=table.radars if radars is None else radars,
            addresses=table.addresses if addresses is None else addresses,
            epoch=table.epoch if epoch is None else epoch,
            convention=conv,
        )
    if isinstance(table, AdsbReports):
        out = pd.DataFrame(
            {
                "timestamp": _timestamps(table.time, epoch),
                "icao24": _hex(table.address),
                "latitude": table.latitude,
                "longitude": table.longitude,
            }
        )
        if conv == "traffic":
            out["altitude"] = table.pressure_altitude / FOOT
            out["geoaltitude"] = table.height / FOOT
        else:
            out["altitude"] = table.height
            if np.isfinite(table.pressure_altitude).any():
                out["baroaltitude"] = table.pressure_altitude
        out.attrs[MARK] = conv
        return out
    if not isinstance(table, PlotTable):
        raise ProblemError(
            "frames.to_frame table: expected a PlotTable, AdsbReports or "
            f"Recording, got {type(table).__name__}"
        )
    if radars is not None and not isinstance(radars, RadarSet):
        raise ProblemError(
            f"frames.to_frame radars: expected a RadarSet, got {type(radars).__name__}"
        )
    radar: Any = table.radar
    if radars is not None:
        if np.any((table.radar < 0) | (table.radar >= radars.m)):
            raise ProblemError(
                "frames.to_frame radars: the plots use radar indices beyond "
                f"the {radars.m} radars given"
            )
        radar = np.asarray(radars.names, dtype=object)[table.radar]
    out = pd.DataFrame(
        {
            "timestamp": _timestamps(table.time, epoch),
            "radar": radar,
            "range": table.range,
            "azimuth": np.degrees(table.azimuth),
            "object": table.object,
        }
    )
    if addresses is not None:
        addr = np.asarray(addresses, dtype=np.int64)
        if np.any(table.object >= addr.size):
            raise ProblemError(
                f"frames.to_frame addresses: {addr.size} addresses for "
                f"object ids up to {int(table.object.max())}"
            )
        out["icao24"] = _hex(np.where(table.object >= 0, addr[np.maximum(table.object, 0)], -1))
    if table.height is not None:
        out["height"] = table.height
    out.attrs[MARK] = conv
    return out


def from_frame(
    df: Any,
    *,
    kind: str | None = None,
    radars: Any = None,
    epoch: Any = None,
    convention: str | None = None,
) -> Any:
    """A :class:`PlotTable` (columns ``timestamp, radar, range, azimuth`` …) or
    :class:`AdsbReports` (``timestamp, icao24, latitude, longitude, altitude`` …) from a
    DataFrame; ``kind`` ("plots" or "adsb") or detected from the columns.

    Plots: ``radar`` names need ``radars`` (a :class:`RadarSet`); integer radars are
    indices. ``object`` gives the track ids; without it, ``icao24`` numbers the objects
    in sorted address order (as :func:`~optmodels.biasfield.recording.read_recording`).
    ADS-B: objects likewise from ``icao24``; rows sorted by (object, time); the altitude
    columns read by ``convention`` (``"optmodels"``: ``altitude`` m above the WGS-84
    ellipsoid, ``baroaltitude`` m; ``"traffic"``: ``altitude`` barometric ft,
    ``geoaltitude`` geometric ft, converted × 0.3048); default: the convention the frame
    carries (``df.attrs["optmodels.convention"]``, set by :func:`to_frame`).

    Raises
    ------
    ProblemError
        Naming the column (and the row): missing column, non-numeric or non-finite values,
        a bad ``icao24``, an unknown radar name, a radar index < 0 (or beyond
        ``radars``), an azimuth outside ±360°, an object id < −1, latitude/longitude out
        of range; an ADS-B frame whose altitude unit is not known (no ``convention``
        given or carried), or whose columns contradict the one given.
    """
    from optmodels.biasfield.recording import AdsbReports
    from optmodels.biasfield.tables import PlotTable, RadarSet

    fn = "frames.from_frame"
    pd = _pd()
    if not isinstance(df, pd.DataFrame):
        raise ProblemError(f"{fn} df: expected a pandas DataFrame, got {type(df).__name__}")
    if kind is None:
        kind = "adsb" if "latitude" in df.columns else "plots"
    if kind not in ("plots", "adsb"):
        raise ProblemError(f"{fn} kind: expected 'plots' or 'adsb', got {kind!r}")
    t = _seconds(df, fn, epoch)
    if kind == "adsb":
        for c in _ADSB:
            _column(df, c, fn)
        addr = _icao(df["icao24"], fn)
        lat = _numbers(df["latitude"], fn, "latitude")
        lon = _numbers(df["longitude"], fn, "longitude")
        if np.any(np.abs(lat) > 90) or np.any((lon < -180) | (lon >= 360)):
            raise ProblemError(f"{fn} latitude/longitude: outside [-90, 90]° / [-180, 360)°")
        h, baro = _altitudes(df, fn, _convention(df, fn, convention), t.size)
        _, obj = np.unique(addr, return_inverse=True)
        order = np.lexsort((t, obj))
        return AdsbReports(
            t[order],
            obj[order].astype(np.int64),
            addr[order],
            lat[order],
            lon[order],
            h[order],
            baro[order],
        )
    for c in _PLOTS:
        _column(df, c, fn)
    if convention is not None:
        as_choice(f"{fn} convention", convention, CONVENTIONS)  # plots: one convention
    if radars is not None and not isinstance(radars, RadarSet):
        raise ProblemError(f"{fn} radars: expected a RadarSet, got {type(radars).__name__}")
    col = df["radar"]
    if pd.api.types.is_integer_dtype(col):
        radar = col.to_numpy(np.int64)
        m = None if radars is None else radars.m
        bad = (radar < 0) if m is None else (radar < 0) | (radar >= m)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            within = "≥ 0" if m is None else f"in 0..{m - 1} (the {m} radars given)"
            raise ProblemError(
                f"{fn} radar: {int(bad.sum())} radar indices not {within} "
                f"(first {int(radar[i])} at row {i})"
            )
    else:
        if not isinstance(radars, RadarSet):
            raise ProblemError(f"{fn} radars: radar names in the frame need the RadarSet (radars=)")
        names = {n: i for i, n in enumerate(radars.names)}
        unknown = sorted({str(r) for r in col if str(r) not in names})
        if unknown:
            raise ProblemError(
                f"{fn} radar: unknown radar(s) {unknown[:5]} (known: {radars.names})"
            )
        radar = np.array([names[str(r)] for r in col], dtype=np.int64)
    if "object" in df.columns:
        obj = _numbers(df["object"], fn, "object")
        if np.any(obj != np.round(obj)):
            raise ProblemError(f"{fn} object: not integers")
        obj = obj.astype(np.int64)
        if np.any(obj < -1):
            i = int(np.flatnonzero(obj < -1)[0])
            raise ProblemError(f"{fn} object: ids are ≥ 0 (−1: unknown), got {obj[i]} at row {i}")
    elif "icao24" in df.columns:
        _, obj = np.unique(_icao(df["icao24"], fn), return_inverse=True)
        obj = obj.astype(np.int64)
    else:
        obj = np.full(t.size, -1, np.int64)
    height = _numbers(df["height"], fn, "height", nan_ok=True) if "height" in df.columns else None
    rng = _numbers(df["range"], fn, "range")
    if np.any(rng < 0):
        i = int(np.flatnonzero(rng < 0)[0])
        raise ProblemError(
            f"{fn} range: {int(np.sum(rng < 0))} negative ranges (m; first {rng[i]:g} at row {i})"
        )
    az = _numbers(df["azimuth"], fn, "azimuth")
    if np.any(np.abs(az) > 360.0):
        i = int(np.flatnonzero(np.abs(az) > 360.0)[0])
        raise ProblemError(
            f"{fn} azimuth: {int(np.sum(np.abs(az) > 360.0))} values outside "
            f"±360° (degrees clockwise from north; first {az[i]:g} at row "
            f"{i}: radians, mils or a damaged column?)"
        )
    return PlotTable(t, radar, rng, np.radians(az), obj, height)


def _convention(df: Any, fn: str, convention: str | None) -> str:
    """The ADS-B frame's altitude convention: the one given (checked against the frame's
    mark and columns), else the one the frame carries; refused when neither says."""
    mark = df.attrs.get(MARK) if isinstance(getattr(df, "attrs", None), dict) else None
    if convention is not None:
        conv = as_choice(f"{fn} convention", convention, CONVENTIONS)
        if mark in CONVENTIONS and mark != conv:
            raise ProblemError(
                f"{fn} convention: {conv!r} given, but the frame was written "
                f"with convention {mark!r} (to_frame)"
            )
    elif mark in CONVENTIONS:
        conv = mark
    else:
        cols = set(df.columns)
        looks = (
            "its columns are the traffic library's (altitude + geoaltitude: feet)"
            if "geoaltitude" in cols
            else "'altitude' may be metres above the WGS-84 ellipsoid or the traffic "
            "library's barometric feet"
        )
        raise ProblemError(
            f"{fn} convention: the altitude unit of this ADS-B frame is not known ({looks});"
            f" give convention='traffic' (altitude = barometric ft, geoaltitude = "
            f"geometric ft) or convention='optmodels' (altitude = m above the WGS-84 "
            f"ellipsoid, baroaltitude = m)"
        )
    cols = set(df.columns)
    if conv == "optmodels":
        if "geoaltitude" in cols:
            raise ProblemError(
                f"{fn} convention: 'optmodels' has no 'geoaltitude' column "
                f"(the traffic library's, in feet): give convention='traffic'"
            )
        _column(df, "altitude", fn)
    elif "baroaltitude" in cols:
        raise ProblemError(
            f"{fn} convention: 'traffic' has no 'baroaltitude' column (its "
            f"barometric altitude is 'altitude', ft): give "
            f"convention='optmodels'"
        )
    elif not cols & {"altitude", "geoaltitude"}:
        raise ProblemError(
            f"{fn} df: missing column 'altitude' or 'geoaltitude' (have {list(df.columns)})"
        )
    return conv


def _altitudes(df: Any, fn: str, conv: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(height m above the ellipsoid, pressure altitude m) of an ADS-B frame, NaN where
    unknown, read in convention ``conv``."""

    def col(name: str, scale: float = 1.0) -> np.ndarray:
        if name not in df.columns:
            return np.full(n, np.nan)
        return _numbers(df[name], fn, name, nan_ok=True) * scale

    if conv == "traffic":
        return col("geoaltitude", FOOT), col("altitude", FOOT)
    return col("altitude"), col("baroaltitude")
