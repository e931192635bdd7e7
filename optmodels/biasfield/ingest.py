"""Reading real data for the bias-field pipeline (paper 001).

* Radars: a small CSV, one row per radar: ``name, x, y`` (local East-North metres) **or**
  ``name, lat, lon[, alt]`` (degrees, metres; converted to local ENU with pymap3d about an
  origin), plus ``sigma_range`` (m), ``sigma_azimuth`` (degrees) and ``max_range`` (m).
* Plots: CSV or Parquet with ``time, radar, range, azimuth[, object]``; ``radar`` is the
  radar's name (or its index), ``range`` in metres, ``azimuth`` in degrees clockwise from
  North (``azimuth_unit="rad"`` for radians). Rows with an unknown radar raise; rows beyond
  a radar's ``max_range`` raise unless ``drop_out_of_range`` (then counted).
* Aircraft tracks (e.g. ADS-B): ``object, time, lat, lon[, alt]`` → local ENU with
  pymap3d, resampled on a common 1 s grid as :class:`AircraftPaths`, so that radar plots of
  real traffic can be simulated with :func:`optmodels.scenarios.radar_network.simulate_plots`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from optmodels.biasfield.data import AircraftPaths, PlotTable, RadarSet
from optmodels.core import FloatArray, ProblemError
from optmodels.io import _read_rows

__all__ = ["GeodeticOrigin", "read_plots", "read_radars", "read_tracks"]

GeodeticOrigin = tuple[float, float, float]


def _table(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a CSV (as text) or a Parquet file (as arrays), lower-case names."""
    p = Path(path)
    if p.suffix.lower() in (".parquet", ".pq"):
        try:
            import pyarrow.parquet as pq
        except ImportError as exc:  # pragma: no cover - pyarrow is in the test extra
            raise ProblemError(f"{p}: reading Parquet needs pyarrow "
                               "(pip install 'optmodels[parquet]')") from exc
        if not p.is_file():
            raise ProblemError(f"{p}: no such file")
        tab = pq.read_table(p)
        return {name.strip().lower(): tab.column(name).to_numpy(zero_copy_only=False)
                for name in tab.column_names}
    header, rows = _read_rows(p)
    if any(len(r) != len(header) for r in rows):
        raise ProblemError(f"{p}: rows with a different number of fields than the header")
    cols = list(zip(*rows, strict=True))
    return {h: np.array([c.strip() for c in col]) for h, col in zip(header, cols, strict=True)}


def _numeric(path: str | Path, cols: dict[str, np.ndarray], name: str) -> FloatArray:
    if name not in cols:
        raise ProblemError(f"{path}: missing column {name!r} (have {sorted(cols)})")
    try:
        v = cols[name].astype(float)
    except ValueError as exc:
        raise ProblemError(f"{path}: column {name!r} is not numeric ({exc})") from exc
    if not np.all(np.isfinite(v)):
        raise ProblemError(f"{path}: column {name!r} has NaN/inf")
    return v


def read_radars(path: str | Path, *, origin: GeodeticOrigin | None = None
                ) -> tuple[RadarSet, GeodeticOrigin | None]:
    """Radars from a CSV; returns the :class:`RadarSet` and the geodetic origin used (the
    given one, else the first radar's position; ``None`` for local x, y input)."""
    cols = _table(path)
    if "name" not in cols:
        raise ProblemError(f"{path}: missing column 'name'")
    names = tuple(str(n) for n in cols["name"])
    if "lat" in cols:
        lat, lon = _numeric(path, cols, "lat"), _numeric(path, cols, "lon")
        alt = _numeric(path, cols, "alt") if "alt" in cols else np.zeros_like(lat)
        org = origin or (float(lat[0]), float(lon[0]), float(alt[0]))
        e, n, _ = pymap3d.geodetic2enu(lat, lon, alt, *org)
        sites = np.column_stack([e, n])
    else:
        sites = np.column_stack([_numeric(path, cols, "x"), _numeric(path, cols, "y")])
        org = None
    radars = RadarSet(sites, _numeric(path, cols, "sigma_range"),
                      np.deg2rad(_numeric(path, cols, "sigma_azimuth")),
                      _numeric(path, cols, "max_range"), names)
    return radars, org


def read_plots(path: str | Path, radars: RadarSet, *, azimuth_unit: str = "deg",
               drop_out_of_range: bool = False) -> tuple[PlotTable, dict[str, int]]:
    """Plots from CSV/Parquet; returns the table and the counts of dropped rows."""
    cols = _table(path)
    if "radar" not in cols:
        raise ProblemError(f"{path}: missing column 'radar'")
    t = _numeric(path, cols, "time")
    rng = _numeric(path, cols, "range")
    az = _numeric(path, cols, "azimuth")
    if azimuth_unit == "deg":
        az = np.deg2rad(az)
    elif azimuth_unit != "rad":
        raise ProblemError(f"azimuth_unit: expected 'deg' or 'rad', got {azimuth_unit!r}")
    lookup: dict[Any, int] = {}
    for i, name in enumerate(radars.names):
        lookup[name] = i
        lookup[str(i)] = lookup.get(str(i), i)
    raw = [str(r).strip() for r in cols["radar"]]
    unknown = sorted({r for r in raw if r not in lookup})
    if unknown:
        raise ProblemError(f"{path}: unknown radar id(s) {unknown[:5]} (known: {radars.names})")
    radar = np.array([lookup[r] for r in raw], dtype=np.int64)
    if "object" in cols:
        obj_raw = [str(o).strip() for o in cols["object"]]
        ids = {o: k for k, o in enumerate(dict.fromkeys(o for o in obj_raw if o not in
                                                         ("", "-1", "nan")))}
        obj = np.array([ids.get(o, -1) for o in obj_raw], dtype=np.int64)
    else:
        obj = np.full(t.size, -1, dtype=np.int64)
    table = PlotTable(t, radar, rng, az, obj)
    dropped: dict[str, int] = {}
    over = table.range > radars.max_range[table.radar]
    if over.any():
        if not drop_out_of_range:
            raise ProblemError(f"{path}: {int(over.sum())} plots beyond their radar's "
                               "max_range (pass drop_out_of_range=True to drop them)")
        dropped["beyond max_range"] = int(over.sum())
        table = table.subset(~over)
    return table, dropped


def read_tracks(path: str | Path, origin: GeodeticOrigin, *, step: float = 1.0
                ) -> AircraftPaths:
    """Aircraft tracks ``object, time, lat, lon[, alt]`` → local East-North paths about
    ``origin`` (lat, lon, alt), linearly resampled every ``step`` seconds; each aircraft is
    active between its first and last report."""
    cols = _table(path)
    if "object" not in cols:
        raise ProblemError(f"{path}: missing column 'object'")
    t = _numeric(path, cols, "time")
    lat, lon = _numeric(path, cols, "lat"), _numeric(path, cols, "lon")
    alt = _numeric(path, cols, "alt") if "alt" in cols else np.zeros_like(lat)
    e, n, _ = pymap3d.geodetic2enu(lat, lon, alt, *origin)
    obj = np.array([str(o).strip() for o in cols["object"]])
    names = list(dict.fromkeys(obj))
    grid = np.arange(np.floor(t.min()), np.ceil(t.max()) + step, step)
    pos = np.zeros((len(names), grid.size, 2))
    active = np.zeros((len(names), grid.size), dtype=bool)
    for a, name in enumerate(names):
        sel = np.flatnonzero(obj == name)
        sel = sel[np.argsort(t[sel], kind="stable")]
        if sel.size < 2:
            raise ProblemError(f"{path}: object {name!r} has fewer than 2 reports")
        ts = t[sel]
        pos[a, :, 0] = np.interp(grid, ts, e[sel])
        pos[a, :, 1] = np.interp(grid, ts, n[sel])
        active[a] = (grid >= ts[0]) & (grid <= ts[-1])
    return AircraftPaths(grid, pos, active)
