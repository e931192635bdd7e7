"""The input side of the ``optmodels biasfield`` verbs that read a recording (``build``,
``correct``, ``registration``): RECORDING [RECORDING2] (+ ``--adsb``) and ``--radars`` →
the radar set and the plots of paper 001's (1), told apart by content (ASTERIX CAT048
[+ CAT021] or CSV/Parquet), what was read and dropped, and the ADS-B reports; and the
input flags the three verbs share (:func:`recording_args`).

Like every problem CLI module, it imports :mod:`optmodels.biasfield` only inside the
functions (``optmodels --help`` imports no problem)."""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from optmodels.cli.args import _count
from optmodels.cli.contract import _reading
from optmodels.core import ProblemError

if TYPE_CHECKING:
    from optmodels.biasfield import AdsbReports, PlotTable, RadarSet, Recording

#: (lat deg, lon deg, h m above the WGS-84 ellipsoid) of the common plane's origin.
Origin = tuple[float, float, float]


@dataclass(frozen=True)
class RecordingInput:
    """What :func:`read_input` read: ``radars`` and ``plots`` (after the drops asked
    for), ``source`` (``"asterix"`` or ``"table"``), ``org_used`` (the common plane's
    origin, ``None`` for x, y sites) and ``origin`` (``--origin``, if given),
    ``adsb_report`` (the ADS-B part of the report, if any) and ``adsb`` (an ASTERIX
    recording's CAT021 reports), ``dropped`` (plots dropped, by reason), ``cleaning``
    (the cleaning's report, with ``clean``), ``n_read`` (plots read), ``recording`` (the
    ASTERIX :class:`~optmodels.biasfield.Recording`) and ``labels`` (a CSV/Parquet
    input's object labels, by object index)."""

    radars: RadarSet
    plots: PlotTable
    source: Literal["asterix", "table"]
    org_used: Origin | None
    origin: Origin | None
    adsb_report: dict[str, Any] | None
    adsb: AdsbReports | None
    dropped: dict[str, int]
    cleaning: dict[str, Any] | None
    n_read: int
    recording: Recording | None
    labels: list[str]

    @property
    def geometry(self) -> Literal["2d", "3d"]:
        """``"3d"`` for a geodetic radar set (slant ranges, each radar's own north)."""
        return "3d" if self.radars.is_3d else "2d"


def parse_origin(text: str) -> Origin:
    """``--origin LAT,LON,H``: degrees, degrees, metres above the WGS-84 ellipsoid."""
    parts = text.split(",")
    try:
        vals = [float(v) for v in parts]
    except ValueError:
        vals = []
    if len(vals) != 3:
        raise ProblemError(
            f"--origin: expected LAT,LON,H (degrees, degrees, metres above the "
            f"WGS-84 ellipsoid), got {text!r}"
        )
    from optmodels.core import as_number

    return (
        as_number("--origin LAT (deg)", vals[0], low=-90.0, high=90.0),
        as_number("--origin LON (deg)", vals[1], low=-180.0, high=360.0, high_open=True),
        as_number("--origin H (m)", vals[2]),
    )


#: ``--origin`` farther than this (m) from every site is refused (LAT and LON swapped?).
ORIGIN_REACH = 1000e3

#: With ``--azimuth-unit`` not given, a CSV/Parquet file of at least this many plots whose
#: azimuths all lie within ±2π is refused as radians read as degrees.
AZIMUTH_CHECK_PLOTS = 50


def _great_circle(lat0: float, lon0: float, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Distances (m) on a sphere of the mean Earth radius from (lat0, lon0) to each (lat,
    lon), degrees (haversine)."""
    p0, p1 = np.radians(lat0), np.radians(lat)
    dlat, dlon = p1 - p0, np.radians(lon - lon0)
    a = np.sin(dlat / 2) ** 2 + np.cos(p0) * np.cos(p1) * np.sin(dlon / 2) ** 2
    return 2 * 6_371_008.8 * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0)))


def check_origin(origin: Origin, radars_path: Path) -> None:
    """``--origin LAT,LON,H`` within :data:`ORIGIN_REACH` of some site of ``radars_path``
    (checked before the recording is read); a sites CSV of x, y has no geodetic origin
    and is not checked here. Refused (exit 2) naming ``--origin``, the nearest site and
    the order of the three numbers: ``83,55,0`` for ``55,83,0`` put the common plane's
    origin ~3000 km from the sites, and every plot's position with it."""
    from optmodels.biasfield import read_radars

    with _reading(str(radars_path)):
        _, org = read_radars(radars_path, origin="mean")
        if org is None:  # x, y sites: --origin does not apply
            return
        sites, _ = read_radars(radars_path, origin="mean", geometry="3d")
    geo = sites.geodetic
    assert geo is not None  # a 3-D radar set has its geodetic sites
    d = _great_circle(origin[0], origin[1], geo[:, 0], geo[:, 1])
    if float(d.min()) <= ORIGIN_REACH:
        return
    k = int(np.argmin(d))
    swapped = _great_circle(origin[1], origin[0], geo[:, 0], geo[:, 1]).min() <= ORIGIN_REACH
    raise ProblemError(
        f"--origin {origin[0]:g},{origin[1]:g},{origin[2]:g}: {d[k] / 1e3:.0f} km from "
        f"the nearest site ({sites.names[k]} at lat {geo[k, 0]:.4f}°, lon "
        f"{geo[k, 1]:.4f}°), more than {ORIGIN_REACH / 1e3:.0f} km; the order is "
        "LAT,LON,H (degrees north, degrees east, m above the WGS-84 ellipsoid)"
        + (
            f": latitude and longitude swapped? (--origin {origin[1]:g},{origin[0]:g},"
            f"{origin[2]:g} is near the sites)"
            if swapped
            else ""
        )
    )


def check_azimuth_unit(plots: PlotTable, path: Path) -> None:
    """``--azimuth-unit`` not given (degrees, checked): a file of at least
    :data:`AZIMUTH_CHECK_PLOTS` plots whose azimuths all lie within ±2π (±6.3) is
    radians read as degrees, refused (exit 2) naming ``--azimuth-unit``; degrees spread
    over a radar's coverage never all fall within ±6.3°. ``plots.azimuth``: the file's
    numbers read as degrees, in radians."""
    n = len(plots)
    if n < AZIMUTH_CHECK_PLOTS:
        return
    deg = np.rad2deg(plots.azimuth)
    if float(np.max(np.abs(deg))) <= 2 * np.pi * (1 + 1e-12):
        raise ProblemError(
            f"--azimuth-unit: all {n} azimuths of {path} lie within ±6.3 "
            f"({float(deg.min()):.3g} to {float(deg.max()):.3g}): radians? give "
            "--azimuth-unit rad, or --azimuth-unit deg if they really are degrees"
        )


def _is_asterix(path: Path) -> bool:
    """Content detection (B2's :func:`optmodels.io.asterix.is_asterix`); a file that is
    not there is left to the CSV reader's message."""
    try:
        from optmodels.io.asterix import is_asterix
    except ImportError:  # pragma: no cover - the module ships with the package
        return False
    return bool(path.is_file() and is_asterix(path))


def _asterix_input(
    files: list[Path],
    kinds: list[str],
    args: argparse.Namespace,
    origin: Origin | None,
    require_all: bool,
) -> RecordingInput:
    """ASTERIX CAT048 (+ CAT021) through :func:`optmodels.biasfield.read_recording`: the
    3-D radars of the sites CSV (keyed by SAC/SIC; ``--origin`` or the mean of the sites),
    the plots (heights from CAT021, else from the flight level), the ADS-B reports and the
    recording's report. ``require_all`` (build): a radar of the sites without a plot is
    refused, naming its SAC/SIC and the recording's unknown ones."""
    from optmodels.biasfield import read_recording, read_sites

    if kinds[0] != "asterix":
        raise ProblemError(
            f"{files[0]}: the plots are CSV/Parquet and {files[1]} is "
            "ASTERIX; give either ASTERIX files or tables"
        )
    tables = [f for f, k in zip(files, kinds, strict=True) if k == "table"]
    if tables:
        raise ProblemError(
            f"{tables[0]}: mixing an ASTERIX recording with a CSV/Parquet "
            "file is not supported; give the CAT021 ADS-B as ASTERIX"
        )
    if args.geometry == "2d":
        raise ProblemError(
            f"--geometry 2d: {files[0]} is ASTERIX, whose plots are slant "
            "ranges from geodetic sites: always the exact 3-D chain"
        )
    with _reading(str(args.radars)):
        sites = read_sites(args.radars, origin=origin)
    with _reading(str(files[0])):
        rec = read_recording([str(f) for f in files], sites, date=args.date)
    radars, plots = rec.radars, rec.plots
    unknown = [list(i) for i in rec.report.unknown_ids] or "none"
    if len(plots) == 0:
        raise ProblemError(
            f"{files[0]}: no CAT048 plot of the sites in {args.radars} "
            f"(dropped: {dict(rec.report.dropped) or 'none'}; SAC/SIC in "
            f"the recording but not in the sites: {unknown})"
        )
    silent = [radars.names[i] for i in range(radars.m) if not np.any(plots.radar == i)]
    if silent and require_all:  # build: every cell needs all m radars
        raise ProblemError(
            f"--radars {args.radars}: radars {silent} (SAC/SIC "
            f"{[list(radars.ids[radars.names.index(n)]) for n in silent]}) "
            f"have no plot in {files[0]}; SAC/SIC in the recording but "
            f"not in the sites: {unknown}"
        )
    org = radars.origin
    assert org is not None  # a sites CSV is geodetic: read_sites sets the origin
    return RecordingInput(
        radars=radars,
        plots=plots,
        source="asterix",
        org_used=(float(org[0]), float(org[1]), float(org[2])),
        origin=origin,
        adsb_report={"reports": len(rec.adsb), **rec.report.as_dict()},
        adsb=rec.adsb,
        dropped={str(k): int(v) for k, v in rec.report.dropped.items()},
        cleaning=None,
        n_read=len(plots),
        recording=rec,
        labels=[],
    )


def _table_input(
    files: list[Path], args: argparse.Namespace, origin: Origin | None
) -> RecordingInput:
    """CSV/Parquet plots (:func:`optmodels.biasfield.read_plots`) and sites
    (:func:`~optmodels.biasfield.read_radars`), in 2-D or, with ``--geometry 3d`` (or
    ``auto`` on geodetic sites and plots with heights), the exact 3-D chain; a second
    file is ADS-B (:func:`~optmodels.biasfield.read_tracks`), only reported here."""
    from optmodels.biasfield import read_plots, read_radars, read_tracks

    labels: list[str] = []
    with _reading(str(args.radars)):
        radars, org_used = read_radars(args.radars, origin=origin if origin is not None else "mean")
    try:
        with _reading(str(files[0])):
            plots, read_dropped = read_plots(
                files[0],
                radars,
                azimuth_unit=args.azimuth_unit or "deg",
                drop_out_of_range=args.drop_out_of_range,
                labels=labels,
            )
    except ProblemError as exc:  # the API's keyword is the flag here
        text = str(exc).replace("pass drop_out_of_range=True", "give --drop-out-of-range")
        raise ProblemError(text) from None
    if args.azimuth_unit is None:  # not given: degrees, checked
        check_azimuth_unit(plots, files[0])
    geometry = args.geometry
    if geometry == "auto":
        geometry = "3d" if (org_used is not None and plots.height is not None) else "2d"
    if geometry == "3d":
        if org_used is None:
            raise ProblemError(
                f"--geometry 3d: {args.radars} gives x, y sites; 3-D "
                "needs lat, lon, alt (m above the WGS-84 ellipsoid)"
            )
        with _reading(str(args.radars)):
            radars, org_used = read_radars(args.radars, origin=org_used, geometry="3d")
        if plots.height is None:
            raise ProblemError(
                f"--geometry 3d: {files[0]} has no 'height' column "
                "(target height, m above the WGS-84 ellipsoid)"
            )
    adsb_report = None
    if len(files) > 1:
        if org_used is None:
            raise ProblemError(
                f"{files[1]}: ADS-B positions need geodetic radar sites "
                f"(lat, lon, alt in {args.radars}) or --origin"
            )
        with _reading(str(files[1])):
            tracks = read_tracks(files[1], org_used, report=True)
        assert isinstance(tracks, tuple)  # report=True: (paths, report)
        adsb_report = tracks[1].to_dict(max_rows=args.max_rows)
    return RecordingInput(
        radars=radars,
        plots=plots,
        source="table",
        org_used=org_used,
        origin=origin,
        adsb_report=adsb_report,
        adsb=None,
        dropped=dict(read_dropped),
        cleaning=None,
        n_read=len(plots),
        recording=None,
        labels=labels,
    )


def read_input(
    args: argparse.Namespace, *, locate: bool, clean: bool, require_all: bool = False
) -> RecordingInput:
    """RECORDING [RECORDING2] (+ ``--adsb``) and ``--radars`` → the radar set and the plots
    (ASTERIX or CSV/Parquet, told apart by content), what was read and dropped, and the
    ADS-B reports of an ASTERIX recording (CAT021) — shared by ``build``, ``correct`` and
    ``registration``. With ``locate``, the plots a 3-D radar set cannot place (no height,
    slant range below the height difference) are removed and counted; with ``clean`` (it
    needs ``locate``), also the cleaning's drops (gaps, glitches, ground traffic);
    ``require_all`` (build): a radar of the sites without a plot in an ASTERIX recording
    is refused, naming its SAC/SIC and the recording's unknown ones."""
    from optmodels.biasfield import clean_plots

    origin = parse_origin(args.origin) if args.origin is not None else None
    files = list(args.recording) + ([args.adsb] if getattr(args, "adsb", None) else [])
    if len(args.recording) > 2:
        raise ProblemError(
            f"RECORDING: at most two files (plots, then ADS-B), got {len(args.recording)}"
        )
    if origin is not None:
        check_origin(origin, args.radars)  # before the recording is read
    kinds = ["asterix" if _is_asterix(f) else "table" for f in files]
    if "asterix" in kinds:
        inp = _asterix_input(files, kinds, args, origin, require_all)
    else:
        inp = _table_input(files, args, origin)
    plots, radars, dropped = inp.plots, inp.radars, dict(inp.dropped)
    cleaning = None
    if locate and radars.is_3d:
        ok = plots.locatable(radars)
        if not ok.all():
            dropped["no height or slant range below height"] = int(np.sum(~ok))
            plots = plots.subset(ok)
    if clean:
        plots, crep = clean_plots(plots, radars)
        dropped.update(crep.counts)
        cleaning = crep.to_dict(max_rows=args.max_rows)
    return dataclasses.replace(inp, plots=plots, dropped=dropped, cleaning=cleaning)


def recording_args(p: argparse.ArgumentParser) -> None:
    """The input flags ``correct`` and ``registration`` share (``build`` has its own
    wording of the same flags)."""
    p.add_argument(
        "recording",
        type=Path,
        nargs="+",
        metavar="RECORDING",
        help="ASTERIX (CAT048 plots [+ CAT021 ADS-B], or a second file with the "
        "CAT021) or CSV/Parquet (time,radar,range,azimuth[,object][,height]); "
        "told apart by content",
    )
    p.add_argument(
        "--radars",
        type=Path,
        required=True,
        help="sites CSV: name,[sac,sic,]lat,lon,alt (alt m above the WGS-84 "
        "ellipsoid) | name,x,y; sigma_range (m), sigma_azimuth (deg), max_range (m)",
    )
    p.add_argument(
        "--origin",
        metavar="LAT,LON,H",
        help="origin of the common plane (deg, deg, m above the ellipsoid); "
        "default: the mean of the sites, as `build` (the field's origin must "
        "match)",
    )
    p.add_argument(
        "--geometry",
        choices=("auto", "2d", "3d"),
        default="auto",
        help="auto: 3-D (slant range, each radar's own north) when the sites are "
        "geodetic and the plots have heights",
    )
    azimuth_unit_arg(p)
    p.add_argument(
        "--drop-out-of-range",
        action="store_true",
        help="drop plots beyond their radar's max_range instead of refusing",
    )
    p.add_argument(
        "--date",
        help="UTC date of an ASTERIX recording (YYYY-MM-DD; time of day rolls over at midnight)",
    )
    p.add_argument(
        "--max-rows", type=_count(0), default=100, help="dropped rows listed per reason in --json"
    )


#: ``--azimuth-unit``'s help (``build``, ``correct``, ``registration``).
AZIMUTH_UNIT_HELP = (
    "azimuth unit of CSV/Parquet plots (default: deg, checked: a file of "
    f"{AZIMUTH_CHECK_PLOTS} plots or more whose azimuths all lie within ±6.3 is refused "
    "as radians; --azimuth-unit deg takes them as degrees)"
)


def azimuth_unit_arg(p: argparse.ArgumentParser) -> None:
    """``--azimuth-unit deg|rad``; not given (``None``): degrees, checked
    (:func:`check_azimuth_unit`)."""
    p.add_argument("--azimuth-unit", choices=("deg", "rad"), help=AZIMUTH_UNIT_HELP)
