"""ASTERIX recordings → the bias-field tables (paper 001, the plots of (1)).

:func:`read_recording` reads CAT048 plots and CAT021 ADS-B reports
(:func:`optmodels.io.asterix.read_asterix`) and builds a 3-D :class:`PlotTable` (slant
range, azimuth from each radar's own north, target height) for a 3-D :class:`RadarSet`
keyed by SAC/SIC (:func:`read_sites`), the ADS-B reports (:class:`AdsbReports`) and a
report of what was read, dropped and where each height came from (:class:`RecordingReport`).

Heights of the plots (m above the WGS-84 ellipsoid), in this order:

1. ``"adsb"``: the CAT021 geometric height (I021/140) of the same 24-bit address
   (I048/220 = I021/080), linearly interpolated at the plot time between the two
   bracketing ADS-B reports when they are at most ``max_gap`` s apart;
2. ``"flight level"``: the plot's flight level (I048/090) through the ICAO standard
   atmosphere: pressure altitude H_p = FL · 30.48 m is, in the ISA, the geopotential
   altitude above mean sea level; the geometric altitude is h = R·H_p / (R − H_p)
   (R = 6 356 766 m, ICAO Doc 7488), plus ``geoid_undulation`` N (m, default 0) to put it
   above the ellipsoid. Its error is the atmosphere's departure from the ISA (the
   hypsometric equation): (R_d/g)·ln(p₀/p) per K of mean temperature deviation — 11, 23,
   35, 49 m/K at FL 100, 200, 300, 400 — and ≈ 8.3 m per hPa of sea-level pressure
   deviation; ±10 K and ±15 hPa give up to ±480 m at FL 300. Add the geoid undulation if
   not given (40-55 m over Europe). The geopotential → geometric step itself is 13 m at
   FL 300. Use it only where no ADS-B height exists;
3. NaN (counted) when neither exists; such plots cannot be placed on the plane by a 3-D
   radar set (:meth:`PlotTable.locatable`).

Heights you can trust (issue 24): before the interpolation, the CAT021 geometric heights
are cleaned (:func:`adsb_height_spikes`: a report whose height departs from the median of
its neighbours of the same address by more than a physical bound is a spike; its height
is discarded, its position kept), and an interpolated ADS-B height that disagrees with the
plot's own flight level by more than ``height_margin`` + ``height_margin_rel`` · H_p (m;
default 300 m + 8 %: the ISA's error budget above at ±20 K and ±30 hPa, with the geoid)
is rejected for the flight-level height (source ``"flight level, ADS-B rejected"``,
counted in ``report.heights``; the spikes in ``report.adsb_heights_rejected``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optmodels.biasfield.heights import adsb_height_spikes, fl_to_height, interp_by_object
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import (
    FloatArray,
    ProblemError,
    as_finite_array,
    as_flag,
    as_instance,
    as_number,
    as_positive,
)

if TYPE_CHECKING:  # the ASTERIX codec is imported when a recording is read
    from optmodels.io.asterix import AsterixData, Cat021Reports, Cat048Reports

__all__ = [
    "HEIGHT_SOURCES",
    "AdsbReports",
    "Recording",
    "RecordingReport",
    "read_recording",
    "read_sites",
]

#: Height sources of :attr:`Recording.height_source`.
HEIGHT_SOURCES = ("none", "adsb", "flight level", "flight level, ADS-B rejected")
#: The entry point the argument errors name.
_FN = "biasfield.read_recording"


@dataclass(frozen=True)
class AdsbReports:
    """ADS-B reports (CAT021), one row each, sorted by (object, time).

    ``time`` (s since the recording's epoch), ``object`` (index into
    :attr:`Recording.addresses`), ``address`` (24-bit ICAO address, −1 if unknown),
    ``latitude``/``longitude`` (deg WGS-84), ``height`` (m above the WGS-84 ellipsoid,
    geometric height I021/140; NaN if absent), ``pressure_altitude`` (m, I021/145 FL ×
    30.48; NaN if absent).
    """

    time: FloatArray
    object: np.ndarray
    address: np.ndarray
    latitude: FloatArray
    longitude: FloatArray
    height: FloatArray
    pressure_altitude: FloatArray

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class RecordingReport:
    """Counts: ``plots_read`` (CAT048 records with a radar position), ``plots_kept``,
    ``dropped`` (plots by reason), ``heights`` (kept plots by height source),
    ``adsb_read``, ``adsb_kept``, ``adsb_dropped`` (by reason), ``records`` (records per
    ASTERIX category read), ``decoder`` (reports the decoder itself discarded),
    ``unknown_ids`` (the SAC/SIC pairs of the plots dropped as "unknown SAC/SIC"),
    ``adsb_heights_rejected`` (CAT021 geometric heights discarded as spikes,
    :func:`adsb_height_spikes`; the reports' positions are kept)."""

    plots_read: int
    plots_kept: int
    dropped: dict[str, int] = field(default_factory=dict)
    heights: dict[str, int] = field(default_factory=dict)
    adsb_read: int = 0
    adsb_kept: int = 0
    adsb_dropped: dict[str, int] = field(default_factory=dict)
    records: dict[int, int] = field(default_factory=dict)
    decoder: dict[str, int] = field(default_factory=dict)
    unknown_ids: tuple[tuple[int, int], ...] = ()
    adsb_heights_rejected: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready (for ``--json``)."""
        return {
            "plots_read": self.plots_read,
            "plots_kept": self.plots_kept,
            "plots_dropped": dict(self.dropped),
            "heights": dict(self.heights),
            "adsb_read": self.adsb_read,
            "adsb_kept": self.adsb_kept,
            "adsb_dropped": dict(self.adsb_dropped),
            "records": {f"CAT{k:03d}": v for k, v in self.records.items()},
            "decoder_dropped": dict(self.decoder),
            "unknown_sac_sic": [list(i) for i in self.unknown_ids],
            "adsb_heights_rejected": self.adsb_heights_rejected,
        }


@dataclass(frozen=True)
class Recording:
    """What :func:`read_recording` gives: ``plots`` (3-D :class:`PlotTable`, sorted by
    time; ``object`` indexes :attr:`addresses`), ``adsb`` (:class:`AdsbReports`, same
    object numbering), ``radars`` (the 3-D :class:`RadarSet`), ``addresses`` (per object
    its 24-bit ICAO address), ``height_source`` (per plot an index into
    :data:`HEIGHT_SOURCES`), ``mode3a`` (per plot, −1 if absent), ``epoch``
    (``datetime64[ns]`` of the UTC midnight the times count from, or None), ``report``;
    per plot, where its CAT048 record is: ``record`` (its row in
    :attr:`AsterixData.cat048 <optmodels.io.asterix.AsterixData>`), ``offset`` (byte offset
    in its file) and ``file`` (index into the paths read) -- what a rewrite of the
    recording with corrected plots needs."""

    plots: PlotTable
    adsb: AdsbReports
    radars: RadarSet
    addresses: np.ndarray
    height_source: np.ndarray
    mode3a: np.ndarray
    epoch: np.datetime64 | None
    report: RecordingReport
    record: np.ndarray | None = None
    offset: np.ndarray | None = None
    file: np.ndarray | None = None

    @property
    def dropped(self) -> dict[str, int]:
        """Every report dropped, by reason, in one flat dict: the plots' reasons, the
        decoder's (``cat048 …``, ``cat021 …``) and the ADS-B ones (``adsb: …``)."""
        out = dict(self.report.dropped)
        out.update(self.report.decoder)
        out.update({f"adsb: {k}": v for k, v in self.report.adsb_dropped.items()})
        return out

    @property
    def icao24(self) -> list[str]:
        """Per object its address as the usual 6-digit lower-case hex string."""
        return [f"{int(a):06x}" for a in self.addresses]


def read_sites(
    path: str | os.PathLike[str], *, origin: tuple[float, float, float] | str | None = None
) -> RadarSet:
    """Radar sites of a recording: a CSV (or Parquet) with ``name, sac, sic, lat, lon,
    alt`` (deg, deg, m above the WGS-84 ellipsoid) and the noise columns ``sigma_range``
    (m), ``sigma_azimuth`` (deg), ``max_range`` (m) → a 3-D :class:`RadarSet` with
    ``geodetic``, ``origin`` and ``ids`` (SAC, SIC).

    ``origin``: (lat °, lon °, h m) of the common plane; default ``"mean"`` (the sites'
    mean latitude, longitude and height); ``"first"``: the first site.

    Raises
    ------
    ProblemError
        Naming the file, line and column (as :func:`~optmodels.biasfield.ingest.read_radars`),
        and if ``sac``/``sic`` or ``lat``/``lon`` are missing.
    """
    from optmodels.biasfield.ingest import read_radars, table_file

    tab = table_file(path, "radars")
    for col in ("sac", "sic", "lat", "lon", "alt"):
        tab.need(col)
    radars, _ = read_radars(path, origin="mean" if origin is None else origin, geometry="3d")
    return radars


def _paths(paths: Any) -> list[Any]:
    if isinstance(paths, str | os.PathLike):
        return [paths]
    if isinstance(paths, Iterable):
        return list(paths)
    raise ProblemError(
        f"biasfield.read_recording paths: expected a file path or a list of "
        f"paths, got {type(paths).__name__}"
    )


def read_recording(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    radars: RadarSet | str | os.PathLike[str],
    *,
    origin: tuple[float, float, float] | str | None = None,
    date: Any = None,
    max_gap: float = 20.0,
    geoid_undulation: float = 0.0,
    drop_out_of_range: bool = True,
    editions: dict[int, tuple[int, int]] | None = None,
    height_margin: float = 300.0,
    height_margin_rel: float = 0.08,
    clean_heights: bool = True,
) -> Recording:
    """Read an ASTERIX recording (CAT048 plots, CAT021 ADS-B; one file or several) into the
    bias-field tables.

    Parameters
    ----------
    paths
        The ASTERIX file(s) (raw datablocks), read in order.
    radars
        A 3-D :class:`RadarSet` with ``ids`` (SAC, SIC), or the sites CSV of
        :func:`read_sites`.
    origin
        With a sites CSV: the common plane's origin (see :func:`read_sites`); with a
        RadarSet it must equal the set's own origin (or be None).
    date
        UTC date of the first record (see :func:`~optmodels.io.asterix.read_asterix`).
    max_gap
        Largest interval (s) between the two ADS-B reports an ADS-B height is interpolated
        in (default 20 s); beyond, the flight level is used.
    geoid_undulation
        N (m) added to the standard-atmosphere height from a flight level (see
        :func:`fl_to_height`).
    drop_out_of_range
        Drop (and count) plots beyond their radar's ``max_range`` (default) instead of
        refusing the recording.
    height_margin, height_margin_rel
        An ADS-B height farther than ``height_margin`` (m) + ``height_margin_rel`` · H_p
        from the plot's own flight-level height (H_p its pressure altitude, m) is rejected
        for the flight-level height (default 300 m + 8 %: the ISA error budget of the
        module docstring at ±20 K mean temperature and ±30 hPa, plus the geoid).
    clean_heights
        Discard the CAT021 height spikes first (:func:`adsb_height_spikes`, default).

    Raises
    ------
    ProblemError
        For an unreadable or foreign file (naming it and the byte offset), a radar set
        that is not 3-D or has no SAC/SIC ids, and bad arguments.

    Notes
    -----
    Drops (counted in ``report.dropped``): plots of a SAC/SIC not in ``radars``, plots
    without an aircraft address (I220: no object to build a track of), plots beyond
    ``max_range``; the decoder's own drops (no I010/I140/I040) are in ``report.decoder``.
    ADS-B reports without an address are dropped (``report.adsb_dropped``).
    """
    from optmodels.io.asterix import read_asterix

    radars, opts = _validate(
        radars,
        origin=origin,
        max_gap=max_gap,
        geoid_undulation=geoid_undulation,
        drop_out_of_range=drop_out_of_range,
        height_margin=height_margin,
        height_margin_rel=height_margin_rel,
        clean_heights=clean_heights,
    )
    data = read_asterix(
        [Path(p) if isinstance(p, str) else p for p in _paths(paths)], date=date, editions=editions
    )
    if not any(data.records.get(cat, 0) for cat in (48, 21)):
        raise ProblemError(
            f"{_FN} paths: no CAT048 plot and no CAT021 report in {', '.join(data.files)} "
            f"(an empty file, or other categories only: {data.skipped or 'none'})"
        )
    sel = _select_plots(data.cat048, radars, opts.drop_out_of_range)
    adsb, addresses, adsb_dropped = _adsb_reports(data.cat021, data.cat048.address[sel.keep])
    heights = _plot_heights(data.cat048, sel.keep, addresses, adsb, opts)
    return _package(data, radars, sel, adsb, addresses, adsb_dropped, heights)


@dataclass(frozen=True)
class _Options:
    """The checked options of :func:`read_recording`."""

    max_gap: float
    geoid_undulation: float
    drop_out_of_range: bool
    height_margin: float
    height_margin_rel: float
    clean_heights: bool


def _validate(
    radars: RadarSet | str | os.PathLike[str],
    *,
    origin: tuple[float, float, float] | str | None,
    max_gap: float,
    geoid_undulation: float,
    drop_out_of_range: bool,
    height_margin: float,
    height_margin_rel: float,
    clean_heights: bool,
) -> tuple[RadarSet, _Options]:
    """The radar set (read from a sites file, or given: a 3-D set with SAC/SIC ids whose
    origin is ``origin`` if that is given) and the checked options, or ProblemError."""
    given = read_sites(radars, origin=origin) if isinstance(radars, str | os.PathLike) else radars
    checked = as_instance(f"{_FN} radars", given, RadarSet)
    if origin is not None and not isinstance(origin, str) and checked.origin is not None:
        org = as_finite_array(f"{_FN} origin", origin, shape=(3,))
        if not np.allclose(org, checked.origin, rtol=0, atol=1e-9):
            raise ProblemError(
                f"{_FN} origin: {origin!r:.60} differs from the RadarSet's "
                f"origin {tuple(map(float, checked.origin))}; give the origin "
                "to read_sites (a RadarSet carries its own)"
            )
    if not checked.is_3d or not checked.ids:
        raise ProblemError(
            f"{_FN} radars: need a 3-D RadarSet (geodetic sites) with SAC/SIC "
            "ids, e.g. from read_sites"
        )
    opts = _Options(
        max_gap=as_positive(f"{_FN} max_gap", max_gap),
        geoid_undulation=geoid_undulation,
        drop_out_of_range=as_flag(f"{_FN} drop_out_of_range", drop_out_of_range),
        height_margin=as_positive(f"{_FN} height_margin (m)", height_margin),
        height_margin_rel=as_number(
            f"{_FN} height_margin_rel", height_margin_rel, low=0.0, high=1.0
        ),
        clean_heights=as_flag(f"{_FN} clean_heights", clean_heights),
    )
    fl_to_height(0.0, geoid_undulation)  # checks it
    return checked, opts


@dataclass(frozen=True)
class _PlotSelection:
    """The CAT048 plots kept: per plot its ``radar`` (index, −1 for an unknown SAC/SIC) and
    ``keep``; the drops by reason and the unknown (SAC, SIC) pairs."""

    radar: np.ndarray
    keep: np.ndarray
    dropped: dict[str, int]
    unknown: tuple[tuple[int, int], ...]


def _select_plots(c: Cat048Reports, radars: RadarSet, drop_out_of_range: bool) -> _PlotSelection:
    """The plots of a radar of ``radars`` (by SAC/SIC) with an aircraft address, within
    their radar's ``max_range`` (beyond it: dropped, or ProblemError with
    ``drop_out_of_range=False``)."""
    dropped: dict[str, int] = {}

    def drop(reason: str, mask: np.ndarray) -> None:
        if mask.any():
            dropped[reason] = dropped.get(reason, 0) + int(mask.sum())

    lut = np.full(256 * 256, -1, np.int64)
    for i, (sac, sic) in enumerate(radars.ids):
        lut[256 * sac + sic] = i
    radar = lut[256 * c.sac + c.sic] if len(c) else np.zeros(0, np.int64)
    keep = radar >= 0
    unknown = tuple(
        sorted({(int(s), int(t)) for s, t in zip(c.sac[~keep], c.sic[~keep], strict=True)})
    )
    drop("unknown SAC/SIC", ~keep)
    no_addr = keep & (c.address < 0)
    drop("no aircraft address (I048/220)", no_addr)
    keep &= ~no_addr
    over = keep & (c.range > radars.max_range[np.maximum(radar, 0)])
    if over.any() and not drop_out_of_range:
        raise ProblemError(
            f"{_FN}: {int(over.sum())} plots beyond their radar's max_range "
            "(drop_out_of_range=False)"
        )
    drop("beyond max_range", over)
    keep &= ~over
    return _PlotSelection(radar, keep, dropped, unknown)


def _adsb_reports(
    a: Cat021Reports, plot_addresses: np.ndarray
) -> tuple[AdsbReports, np.ndarray, dict[str, int]]:
    """The ADS-B reports with an address, sorted by (object, time); the objects' addresses
    (those of the kept plots and of the reports, sorted) and the reports dropped."""
    a_keep = a.address >= 0
    adsb_dropped: dict[str, int] = {}
    if (~a_keep).any():
        adsb_dropped["no target address (I021/080)"] = int((~a_keep).sum())
    addresses = np.unique(np.concatenate([plot_addresses, a.address[a_keep]]))
    a_obj = np.searchsorted(addresses, a.address[a_keep])
    a_t = a.time[a_keep]
    order = np.lexsort((a_t, a_obj))
    adsb = AdsbReports(
        a_t[order],
        a_obj[order],
        a.address[a_keep][order],
        a.latitude[a_keep][order],
        a.longitude[a_keep][order],
        a.height[a_keep][order],
        a.pressure_altitude[a_keep][order],
    )
    return adsb, addresses, adsb_dropped


@dataclass(frozen=True)
class _Heights:
    """Per kept plot (in file order) its ``object``, ``height`` (m above the ellipsoid)
    and ``source`` (index into :data:`HEIGHT_SOURCES`); the CAT021 ``spikes`` discarded."""

    object: np.ndarray
    height: FloatArray
    source: np.ndarray
    spikes: int


def _plot_heights(
    c: Cat048Reports,
    keep: np.ndarray,
    addresses: np.ndarray,
    adsb: AdsbReports,
    opts: _Options,
) -> _Heights:
    """The heights of the kept plots (module docstring): the CAT021 spikes out, the ADS-B
    height interpolated, then checked against the plot's flight level."""
    spikes = (
        adsb_height_spikes(adsb.object, adsb.time, adsb.height)
        if opts.clean_heights
        else np.zeros(len(adsb), dtype=bool)
    )
    h_clean = np.where(spikes, np.nan, adsb.height)
    p_obj = np.searchsorted(addresses, c.address[keep])
    h_adsb = interp_by_object(adsb.object, adsb.time, h_clean, p_obj, c.time[keep], opts.max_gap)
    hp = c.pressure_altitude[keep]
    h_fl = fl_to_height(hp, opts.geoid_undulation)
    off = (
        np.isfinite(h_adsb)
        & np.isfinite(h_fl)
        & (np.abs(h_adsb - h_fl) > opts.height_margin + opts.height_margin_rel * np.abs(hp))
    )
    source = np.where(off, 3, np.where(np.isfinite(h_adsb), 1, np.where(np.isfinite(h_fl), 2, 0)))
    height = np.where(source == 1, h_adsb, np.where(source >= 2, h_fl, np.nan))
    return _Heights(p_obj, height, source, int(spikes.sum()))


def _package(
    data: AsterixData,
    radars: RadarSet,
    sel: _PlotSelection,
    adsb: AdsbReports,
    addresses: np.ndarray,
    adsb_dropped: dict[str, int],
    h: _Heights,
) -> Recording:
    """The kept plots sorted by time as a 3-D :class:`PlotTable`, with the report of the
    counts and, per plot, where its CAT048 record is."""
    c = data.cat048
    keep = sel.keep
    p_t = c.time[keep]
    order_p = np.argsort(p_t, kind="stable")
    plots = PlotTable(
        p_t[order_p],
        sel.radar[keep][order_p],
        c.range[keep][order_p],
        c.azimuth[keep][order_p],
        h.object[order_p],
        h.height[order_p],
    )
    heights = {HEIGHT_SOURCES[k]: int(np.sum(h.source == k)) for k in (1, 2, 0)}
    if (h.source == 3).any():
        heights[HEIGHT_SOURCES[3]] = int(np.sum(h.source == 3))
    report = RecordingReport(
        len(c),
        len(plots),
        sel.dropped,
        heights,
        len(data.cat021),
        len(adsb),
        adsb_dropped,
        dict(data.records),
        dict(data.dropped),
        sel.unknown,
        h.spikes,
    )
    rows = np.flatnonzero(keep)[order_p]
    return Recording(
        plots,
        adsb,
        radars,
        addresses,
        h.source[order_p],
        c.mode3a[keep][order_p],
        data.epoch,
        report,
        rows,
        np.asarray(c.offset)[rows],
        np.asarray(c.file)[rows],
    )
