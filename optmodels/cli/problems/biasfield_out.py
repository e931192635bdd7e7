"""The outputs of the ``optmodels biasfield`` verbs: output paths checked before any work,
interrupts that say what was and was not written, ``corrected.csv`` with each plot's
identity, ``field.csv`` through :func:`optmodels.io.write_csv`, the per-radar summary,
readable text, and ``optmodels biasfield simulate``. Every file goes through
:func:`optmodels.io.atomic_write` / :func:`~optmodels.io.save_npz` /
:func:`~optmodels.io.write_csv` (a kill part-way leaves the previous file readable)."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optmodels.cli.contract import _leaf
from optmodels.core import ProblemError

if TYPE_CHECKING:
    from optmodels.cli.problems.biasfield_read import RecordingInput

#: Columns of ``corrected.csv`` and their units (``--json`` echoes them).
CORRECTED_COLUMNS = {
    "radar": "the radar's name (sites CSV)",
    "sac": "its System Area Code (I048/010; empty for a CSV input without sac)",
    "sic": "its System Identification Code",
    "address": "ICAO 24-bit address, 6 hex digits (I048/220); a CSV input's object label",
    "time": "s since the recording's UTC midnight (--date) or its first day",
    "time_of_day": "s after UTC midnight, [0, 86400) (I048/140); empty for a CSV input",
    "utc": "UTC date-time, ISO 8601 with ms (only with --date or a dated recording)",
    "range": "corrected slant range, m",
    "azimuth": "corrected azimuth, deg clockwise from the radar's own north, [0, 360)",
    "height": "target height, m above the WGS-84 ellipsoid (empty if unknown)",
    "height_source": "adsb | flight level | flight level, ADS-B rejected | input | none",
    "covered": "1 corrected, 0 written as read",
    "reason": "covered | one radar only | outside every cell | not locatable",
}
NOT_LOCATABLE = "not locatable"


# --------------------------------------------------------------------------- paths
def _probe(flag: str, folder: Path) -> None:
    """Create and remove a temporary file in ``folder``: refused (exit 2) before any work
    if the folder cannot be written (permission, read-only or virtual file system)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".optmodels-probe.", dir=folder)
    except OSError as exc:
        raise ProblemError(f"{flag}: cannot write in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(name)


def writable_file(flag: str, path: str | os.PathLike[str]) -> Path:
    """``--out FILE``: not an existing folder, its folder created if missing and writable;
    checked before any work."""
    from optmodels.io import output_file

    p = Path(path)
    if p.is_dir():
        raise ProblemError(
            f"{flag}: {p} is an existing folder; give a file name (this flag names a FILE)"
        )
    try:
        p = output_file(p, name=flag)
    except ProblemError as exc:
        raise ProblemError(f"{flag}: {exc}") from None
    _probe(flag, p.parent)
    return p


def writable_dir(flag: str, path: str | os.PathLike[str]) -> Path:
    """``--out FOLDER``: created if missing, not a file, writable; before any work."""
    from optmodels.io import output_dir

    try:
        p = output_dir(path, name=flag)
    except ProblemError as exc:
        raise ProblemError(f"{flag}: {exc}") from None
    _probe(flag, p)
    return p


@contextlib.contextmanager
def interrupt_note(stage: list[str], out: Path, written: list[str]) -> Iterator[None]:
    """Ctrl-C inside the block becomes ``KeyboardInterrupt`` with a message that says
    what was and was not written (the CLI contract exits 130 with it)."""
    try:
        yield
    except KeyboardInterrupt:
        done = f"written: {', '.join(written)}" if written else "nothing written"
        raise KeyboardInterrupt(
            f"interrupted while {stage[0]}: {out} not written (a previous {out.name}, if "
            f"any, is unchanged); {done}"
        ) from None


def say(args: argparse.Namespace, text: str) -> None:
    """A progress line on stderr: not under ``--json``, only when stderr is a terminal."""
    if not getattr(args, "json", False) and sys.stderr.isatty():
        print(text, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- correct
def _fmt(fmt: str, v: np.ndarray) -> np.ndarray:
    """``fmt`` of each finite value; empty where NaN."""
    s = np.char.mod(fmt, np.where(np.isfinite(v), v, 0.0))
    return np.where(np.isfinite(v), s, "")


def corrected_columns(
    inp: RecordingInput,
    rng: np.ndarray,
    az: np.ndarray,
    covered: np.ndarray,
    reason: np.ndarray,
) -> dict[str, np.ndarray]:
    """The columns of ``corrected.csv`` (:data:`CORRECTED_COLUMNS`), as string arrays, for
    the plots of ``inp`` (:func:`~optmodels.cli.problems.biasfield_read.read_input`'s
    result, one row per plot read)."""
    from optmodels.biasfield.recording import HEIGHT_SOURCES

    radars, plots, rec = inp.radars, inp.plots, inp.recording
    n = len(plots)
    names = np.asarray(radars.names, dtype=object)
    cols: dict[str, np.ndarray] = {"radar": names[plots.radar].astype(str)}
    if radars.ids:
        ids = np.asarray(radars.ids, dtype=np.int64)
        cols["sac"] = ids[plots.radar, 0].astype(str)
        cols["sic"] = ids[plots.radar, 1].astype(str)
    else:
        cols["sac"] = cols["sic"] = np.full(n, "", dtype=object).astype(str)
    if rec is not None:
        hexes = np.array([f"{int(a):06x}" for a in rec.addresses] + [""])
        cols["address"] = hexes[np.where(plots.object >= 0, plots.object, -1)]
    else:
        labels = np.array([*inp.labels, ""], dtype=object).astype(str)
        ok = (plots.object >= 0) & (plots.object < labels.size - 1)
        cols["address"] = labels[np.where(ok, plots.object, -1)]
    t = np.asarray(plots.time, dtype=float)
    cols["time"] = np.char.mod("%.7f", t)  # the I140 LSB is 1/128 s
    if rec is not None:
        cols["time_of_day"] = np.char.mod("%.7f", np.mod(t, 86400.0))
        if rec.epoch is not None:
            us = np.round(t * 1e6).astype(np.int64).astype("timedelta64[us]")
            stamp = np.datetime_as_string(rec.epoch.astype("datetime64[us]") + us, unit="ms")
            cols["utc"] = np.char.add(stamp.astype(str), "Z")
        else:
            cols["utc"] = np.full(n, "", dtype="<U1")
    else:
        cols["time_of_day"] = cols["utc"] = np.full(n, "", dtype="<U1")
    cols["range"] = np.char.mod("%.3f", rng)
    deg = np.mod(np.rad2deg(az), 360.0)
    deg = np.where(deg >= 360.0 - 5e-10, 0.0, deg)  # what "%.9f" would print as 360
    cols["azimuth"] = np.char.mod("%.9f", deg)
    h = np.full(n, np.nan) if plots.height is None else np.asarray(plots.height, float)
    cols["height"] = _fmt("%.2f", h)
    if rec is not None:
        cols["height_source"] = np.asarray(HEIGHT_SOURCES)[rec.height_source]
    else:
        cols["height_source"] = np.where(np.isfinite(h), "input", "none")
    cols["covered"] = covered.astype(np.int64).astype(str)
    cols["reason"] = np.asarray(reason).astype(str)
    return {k: cols[k] for k in CORRECTED_COLUMNS}


def write_corrected(out: Path, cols: dict[str, np.ndarray], chunk: int = 200_000) -> None:
    """``corrected.csv`` atomically (:func:`optmodels.io.atomic_write`), in chunks of
    rows (a cell with a comma or quote is quoted by the :mod:`csv` module)."""
    import csv

    from optmodels.io import atomic_write

    names = list(cols)
    n = len(next(iter(cols.values()))) if cols else 0
    with atomic_write(out, name="--out", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(names)
        for a in range(0, n, chunk):
            w.writerows(zip(*(cols[c][a : a + chunk].tolist() for c in names), strict=True))


# --------------------------------------------------------------------------- solve
def field_rows(fd: Any, sol: Any, names: tuple[str, ...]) -> list[dict[str, Any]]:
    """``field.csv``: one row per (cell, radar that sees it): numbers as numbers, radars by
    name."""
    seen = fd.subsets
    labels = names or tuple(f"R{i + 1}" for i in range(fd.m))
    rows = []
    for k in range(fd.k):
        for i in np.flatnonzero(seen[k]):
            rows.append(
                {
                    "cell": k,
                    "x_m": float(fd.centers[k, 0]),
                    "y_m": float(fd.centers[k, 1]),
                    "radar": labels[int(i)],
                    "range_bias_m": float(sol.field[k, i, 0]),
                    "azimuth_bias_deg": float(np.rad2deg(sol.field[k, i, 1])),
                    "active_range": int(sol.active[k, i, 0]),
                    "active_azimuth": int(sol.active[k, i, 1]),
                }
            )
    return rows


#: What ``objective`` in ``solve --json`` is.
OBJECTIVE_NOTE = (
    "J of (9): the smoothness functional, Σ over neighbouring cells of the "
    "squared bias differences in the metric P divided by the squared centre "
    "distance (P-weighted (m, rad)² per m²); a figure of merit for comparing "
    "methods on the same data, not an error in metres"
)


#: What ``lipschitz`` in ``solve --json`` is, and its unit.
LIPSCHITZ_NOTE = (
    "L: the largest ‖Lᵀ_P (f(x̌_i) − f(x̌_j))‖ / ‖x̌_i − x̌_j‖ over neighbouring cells, i.e. "
    "the field's change in the P-norm of (9) per metre between cell centres; with "
    "biasfield build's P = diag(1/σ_r², 1/σ_az²) per radar, in noise standard "
    "deviations per m"
)


def print_solve(res: dict[str, Any]) -> None:
    from optmodels.cli.contract import _OK_STATUSES

    print(f"{res['method']}: {res['status']}" + (f" ({res['message']})" if res["message"] else ""))
    if res["status"] not in _OK_STATUSES:
        return
    lip = (
        f", Lipschitz constant {res['lipschitz']:.4g} per m (the field's change between "
        "neighbouring cells in the P-norm of (9) per metre between their centres; with "
        "build's P = diag(1/σ_r², 1/σ_az²): noise σ per m)"
        if res["lipschitz"] is not None
        else ""
    )
    print(
        f"{res['cells']} cells{lip}, {res.get('active_bounds', 0)} active bounds; wrote "
        f"{', '.join(res['files'])} to {res['out']}"
    )
    print(
        "per radar, the constant-plus-gain baseline fitted to the field (± its fit's "
        "standard error) and the field's spread over the radar's cells:"
    )
    print(
        f"  {'radar':<8}{'cells':>6}  {'range bias m':>16}  {'gain ppm':>14}  "
        f"{'azimuth bias deg':>20}  {'spread m':>9}  {'spread deg':>10}"
    )
    for r in res.get("radars", []):
        if not r.get("cells"):
            print(f"  {r['radar']:<8}{0:>6}  (no cell)")
            continue
        print(
            f"  {r['radar']:<8}{r['cells']:>6}  "
            f"{r['range_bias_m']:>8.1f} ± {r['range_bias_sigma_m']:<5.1f}  "
            f"{r['range_gain_ppm']:>6.0f} ± {r['range_gain_sigma_ppm']:<5.0f}  "
            f"{r['azimuth_bias_deg']:>9.4f} ± {r['azimuth_bias_sigma_deg']:<7.4f}  "
            f"{r['range_spread_m']:>9.1f}  {r['azimuth_spread_deg']:>10.4f}"
        )


# --------------------------------------------------------------------------- build
def print_build(res: dict[str, Any]) -> None:
    print(f"wrote {res['out']}")
    print(
        f"  {res['cells']} cells ({res['coverage']} coverage), radars "
        f"{', '.join(res['radars'])} ({res['geometry']} chain, {res['source']} input)"
    )
    print(f"  plots: {res['plots']} read, {res['plots_used']} used in the track fits")
    for reason, n in (res["dropped_plots"] or {}).items():
        print(f"    dropped {n}: {reason}")
    if res.get("cells_per_radar"):
        print(
            "  cells per radar: " + ", ".join(f"{k} {v}" for k, v in res["cells_per_radar"].items())
        )
        print(
            "  radars per cell: "
            + ", ".join(f"{v} cells seen by {k}" for k, v in res["radars_per_cell"].items())
        )
    if res["dropped_cells"]:
        print(f"  cells dropped for lack of data: {res['dropped_cells']}")
    if res["origin"] is not None:
        lat, lon, h = res["origin"]
        print(
            f"  common plane origin {lat:.6f}° N, {lon:.6f}° E, {h:.1f} m ({res['origin_source']})"
        )
    ad = res.get("adsb")
    if ad:
        hs = ", ".join(f"{k} {v}" for k, v in ad.get("heights", {}).items())
        print(
            f"  ASTERIX: {ad.get('plots_read', 0)} CAT048 plots, {ad.get('reports', 0)} "
            f"CAT021 reports ({ad.get('adsb_heights_rejected', 0)} height spikes "
            f"rejected); plot heights from {hs or 'n/a'}"
        )
    print(
        "  track model χ²/dof per radar (≈ 1 when the noise model fits): "
        + ", ".join(
            f"{n} {v:.2f}" for n, v in zip(res["radars"], res["track_chi2_per_dof"], strict=False)
        )
    )
    for w in res.get("warnings", []):
        print(f"  warning: {w}")


# --------------------------------------------------------------------------- simulate
#: WGS-84 semi-major axis (m): sites beyond 0.9 of it from the origin have no footprint on
#: the common plane (:func:`optmodels.biasfield.geometry3d.plane_to_geodetic` refuses them).
WGS84_A = 6378137.0
#: Neighbouring sites closer than this many times a plot's cross-range noise at the
#: traffic area's half-side are one site to the simulated plots (``--spacing``).
SITE_SEPARATION_NOISES = 5.0


def _network_limits() -> dict[str, float]:
    """The simulator's own figures behind the refusals of ``--spacing`` and
    ``--max-range``: ``min_separation`` (m), the closest two neighbouring sites may be
    (:data:`SITE_SEPARATION_NOISES` × the plots' azimuth noise × the half-side of the
    square the traffic enters in); ``min_range`` (m), the slant range below which no
    radar ever sees an aircraft (the lowest flight level, above the highest site, inside
    the cone of silence: (level − site height) / sin(max elevation), rounded down to
    100 m); ``site_height`` (m), the highest site; and the figures they come from."""
    import inspect

    from optmodels.scenarios.radar_network import (
        DEFAULT_SITE_HEIGHTS,
        MAX_ELEVATION,
        radar_network,
    )
    from optmodels.scenarios.recording import simulate_recording

    sim = inspect.signature(simulate_recording).parameters
    region = float(sim["region"].default)
    sigma_az = float(np.deg2rad(sim["sigma_azimuth_deg"].default))
    lowest = float(inspect.signature(radar_network).parameters["levels"].default[0])
    site_h = float(np.max(DEFAULT_SITE_HEIGHTS))
    return {
        "min_separation": SITE_SEPARATION_NOISES * sigma_az * region,
        "min_range": float(np.floor((lowest - site_h) / np.sin(MAX_ELEVATION) / 100) * 100),
        "site_height": site_h,
        "region": region,
        "sigma_azimuth_deg": float(sim["sigma_azimuth_deg"].default),
        "lowest_level": lowest,
        "max_elevation_deg": float(np.rad2deg(MAX_ELEVATION)),
    }


def _check_network(n: int, spacing: float, max_range: float) -> None:
    """Refuse a ``--spacing`` or ``--max-range`` that cannot be meant in metres for a
    radar network (km typed for m): neighbouring sites closer than
    ``min_separation`` (one site, not a network), a range below ``min_range`` (no radar
    ever sees an aircraft), or neighbouring sites more than twice the range apart (no
    aircraft is ever within range of two radars: nothing to register; the bound allows
    for the sites' heights, so that it holds in 3-D). :func:`_network_limits`."""
    lim = _network_limits()
    # the ring of radius `spacing`: neighbours 2·R·sin(π/n) apart (2R for two radars)
    gap = 2.0 * spacing * float(np.sin(np.pi / n))
    if gap < lim["min_separation"]:
        smallest = lim["min_separation"] / (2.0 * np.sin(np.pi / n))
        raise ProblemError(
            f"--spacing {spacing:.10g}: the radius of the ring of sites is in METRES: {n} radars "
            f"on a ring of {spacing:.10g} m are {gap:.0f} m apart, closer than "
            f"{lim['min_separation']:.0f} m ({SITE_SEPARATION_NOISES:g} × a plot's "
            f"cross-range noise, {lim['sigma_azimuth_deg']:g}° at {lim['region'] / 1e3:g} km, "
            f"the traffic area's half-side): one site, not a network; give at least "
            f"{np.ceil(smallest):.0f} (m) for {n} radars ({spacing:.10g} km is "
            f"--spacing {spacing * 1e3:.10g})"
        )
    if spacing >= 0.9 * WGS84_A:
        raise ProblemError(
            f"--spacing {spacing:.10g}: the radius of the ring of sites is in METRES; sites "
            f"farther than {0.9 * WGS84_A:.0f} m (0.9 earth radii) from the origin have no "
            "place on the common plane"
        )
    if max_range < lim["min_range"]:
        raise ProblemError(
            f"--max-range {max_range:.10g}: the slant range is in METRES: below "
            f"{lim['min_range']:.0f} m no radar ever sees an aircraft (the lowest fly "
            f"{lim['lowest_level']:.0f} m up, {lim['lowest_level'] - lim['site_height']:.0f} m "
            f"above the highest site, and a radar sees nothing above "
            f"{lim['max_elevation_deg']:g}° elevation) ({max_range:.10g} km is --max-range "
            f"{max_range * 1e3:.10g})"
        )
    if gap > 2.0 * (max_range + lim["site_height"]):
        raise ProblemError(
            f"--spacing {spacing:.10g} with --max-range {max_range:.10g} (both METRES): "
            f"neighbouring sites are {gap:.0f} m apart, more than twice the range: no "
            "aircraft is ever within range of two radars (nothing to register); give a "
            f"smaller --spacing or a larger --max-range"
        )


def _simulate(args: argparse.Namespace) -> tuple[dict[str, Any], bool]:
    from optmodels.scenarios.recording import simulate_recording

    _check_network(args.n_radars, args.spacing, args.max_range)
    out = writable_dir("--out", args.out)
    for f in ("recording.ast", "sites.csv"):
        if (out / f).is_dir():
            raise ProblemError(f"--out: {out / f} is a folder; cannot write the {f} there")
    say(
        args,
        f"simulating {args.n_radars} radars, {args.aircraft} aircraft, "
        f"{args.duration:g} s and encoding ASTERIX ...",
    )
    sim = simulate_recording(
        out,
        seed=args.seed,
        radars=args.n_radars,
        aircraft=args.aircraft,
        duration=args.duration,
        spacing=args.spacing,
        max_range=args.max_range,
        biases=args.biases,
        start=args.start,
        adsb_interval=args.adsb_interval,
        adsb_spikes=args.adsb_spikes,
    )
    res = sim.to_dict()
    res["recording"], res["sites"] = str(sim.recording.resolve()), str(sim.sites.resolve())
    res["next"] = (
        f"optmodels biasfield build {sim.recording} --radars {sim.sites} "
        f"--out {out / 'fielddata.npz'}"
    )
    return res, True


def _print_simulate(res: dict[str, Any]) -> None:
    print(
        f"wrote {res['recording']} ({res['cat048']} CAT048 plots of radars "
        f"{', '.join(res['radars'])}, {res['cat021']} CAT021 reports of {res['aircraft']} "
        f"aircraft, {res['spikes']} height spikes) and {res['sites']}"
    )
    print(f"next: {res['next']}")


SIMULATE_HELP = """\
A simulated recording to try the bias field on: a ring of radars, random traffic, each
radar's bias field and noise, written as ASTERIX (CAT048 plots with flight levels and
ICAO addresses, CAT021 ADS-B) in FOLDER/recording.ast, with FOLDER/sites.csv. Then:
build -> solve -> correct -> registration (see the README).

How the simulated traffic differs from real traffic: aircraft enter at uniform random
places and times and fly random legs and turns (no airways or terminal areas); every
radar sees every aircraft in range and above its horizon on every scan (no missed or
false plots, clutter or multipath); ADS-B is the exact truth, every aircraft equipped
(but for --adsb-spikes); flight levels are the exact standard-atmosphere image of the
true height; each bias field is smooth on the plane and constant in time and height."""


def register_simulate(bsub: Any, positive: Any, count: Any, finite: Any) -> None:
    """``optmodels biasfield simulate``."""
    p = _leaf(bsub, "simulate", "a simulated ASTERIX recording and its sites CSV")
    p.description = SIMULATE_HELP
    p.add_argument(
        "--out",
        default="biasfield_sim",
        metavar="FOLDER",
        help="output FOLDER: recording.ast and sites.csv",
    )
    p.add_argument("--seed", type=count(0), default=0, help="seed of every random draw")
    p.add_argument(
        "--n-radars", type=count(2), default=4, help="number of radars, on a ring about the origin"
    )
    p.add_argument(
        "--spacing",
        type=positive,
        default=150e3,
        metavar="METRES",
        help="radius of the ring of sites, in metres (150 km: 150000); refused when "
        "neighbouring sites would be closer than ~1 km (5 × a plot's cross-range noise, "
        "0.08° at the traffic area's 150 km half-side: one site, not a network) or more "
        "than twice --max-range apart (no aircraft within range of two radars)",
    )
    p.add_argument(
        "--max-range",
        type=positive,
        default=250e3,
        metavar="METRES",
        help="each radar's maximum slant range, in metres (250 km: 250000); refused below "
        "3.7 km, where no radar sees any aircraft (the lowest fly 3 km up, and nothing is "
        "seen above 40° elevation)",
    )
    p.add_argument("--aircraft", type=count(1), default=30, help="number of aircraft")
    p.add_argument("--duration", type=positive, default=1800.0, help="simulated span, s")
    p.add_argument(
        "--biases",
        choices=("smooth", "linear", "constant", "zero"),
        default="smooth",
        help="each radar's bias field",
    )
    p.add_argument(
        "--start",
        type=finite,
        default=36000.0,
        help="UTC time of day of simulated time 0, s after midnight (36000: 10:00)",
    )
    p.add_argument(
        "--adsb-interval",
        type=count(1),
        default=1,
        help="seconds between two ADS-B reports of an aircraft",
    )
    p.add_argument(
        "--adsb-spikes",
        type=count(0),
        default=0,
        help="CAT021 reports given a +7.8 km altitude spike (to see the reader's cleaning at work)",
    )
    p.set_defaults(func=_simulate, printer=_print_simulate)
