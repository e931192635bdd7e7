"""The verbs that use a solved field on a recording (issue 17): ``optmodels biasfield
correct`` (the plots corrected with a ``field.npz`` written by ``biasfield solve``: one
CSV row per plot read, or the ASTERIX recording rewritten) and ``optmodels biasfield
registration`` (the cross-radar registration error, and with ADS-B the absolute error).

Like every problem CLI module, it imports :mod:`optmodels.biasfield` only inside the
handlers (``optmodels --help`` imports no problem)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optmodels.cli.contract import Outcome, _leaf, _reading
from optmodels.cli.problems.biasfield_out import (
    CORRECTED_COLUMNS,
    NOT_LOCATABLE,
    corrected_columns,
    interrupt_note,
    say,
    writable_file,
    write_corrected,
)
from optmodels.cli.problems.biasfield_read import RecordingInput, read_input, recording_args
from optmodels.core import ProblemError

if TYPE_CHECKING:
    from optmodels.biasfield import FieldMap, RadarSet


def _load_field(args: argparse.Namespace, radars: RadarSet) -> FieldMap:
    """``--field DIR/field.npz`` (written by ``biasfield solve``), checked against the
    radar set it is applied to (same radars, sites, and for a 3-D field the same origin)."""
    from optmodels.biasfield import FieldMap

    with _reading(str(args.field)):
        fm = FieldMap.load(args.field)
    fm.check_radars(radars, where=f"--field {args.field}")
    return fm


def _check_asterix_inputs(args: argparse.Namespace) -> None:
    """``correct --format asterix``: every RECORDING is ASTERIX (checked before any work)."""
    from optmodels.io import is_asterix

    for f in args.recording:
        if not is_asterix(f):
            raise ProblemError(
                f"biasfield correct --format asterix: {f} is not an ASTERIX "
                "recording (datablocks or a pcap/pcapng capture); a "
                "CSV/Parquet recording is corrected with --format csv"
            )


#: ``correct --out``'s suffixes that say the other format (refused: a binary ASTERIX file
#: named .csv, or a table named .ast, is a file the next program misreads).
TEXT_SUFFIXES = (".csv", ".txt", ".json")
ASTERIX_SUFFIXES = (".ast", ".asterix", ".bin", ".pcap", ".pcapng")


def _correct_out(args: argparse.Namespace) -> Path:
    """``correct --out``: ``corrected.csv`` (``--format csv``) or ``corrected.ast``
    (``--format asterix``) when not given; a name whose suffix says the other format is
    refused (exit 2) before any work."""
    if args.out is None:
        return Path("corrected.ast" if args.format == "asterix" else "corrected.csv")
    out = Path(args.out)
    suffix = out.suffix.lower()
    wrong = TEXT_SUFFIXES if args.format == "asterix" else ASTERIX_SUFFIXES
    if suffix in wrong:
        what = "binary ASTERIX" if args.format == "asterix" else "a CSV table"
        other = "csv" if args.format == "asterix" else "asterix"
        fix = ".ast" if args.format == "asterix" else ".csv"
        raise ProblemError(
            f"--out {out}: --format {args.format} writes {what}, not a {suffix} file; "
            f"name it {out.with_suffix(fix).name}, or give --format {other}"
        )
    return out


def _biasfield_correct(args: argparse.Namespace) -> Outcome:
    out = writable_file("--out", _correct_out(args))  # before any work
    if args.format == "asterix":
        _check_asterix_inputs(args)
    stage = ["reading the recording"]
    with interrupt_note(stage, out, []):
        from optmodels.biasfield import correct_plots

        say(args, f"reading {args.recording[0]} ...")
        inp = read_input(args, locate=False, clean=False)  # one row per plot read
        radars, plots = inp.radars, inp.plots
        fm = _load_field(args, radars)
        # plots a 3-D radar set cannot place (no height, slant range below the height
        # difference) are written as read, with covered = 0
        ok = plots.locatable(radars) if radars.is_3d else np.ones(len(plots), dtype=bool)
        rng, az = plots.range.copy(), plots.azimuth.copy()
        covered = np.zeros(len(plots), dtype=bool)
        reason = np.full(len(plots), NOT_LOCATABLE, dtype="<U20")
        stage[0] = "correcting the plots"
        say(args, f"correcting {int(ok.sum())} plots ...")
        if ok.any():
            cor = correct_plots(plots.subset(ok), radars, fm)
            rng[ok], az[ok] = cor.plots.range, cor.plots.azimuth
            covered[ok] = cor.covered
            reason[ok] = cor.reason
        stage[0] = f"writing {out}"
        say(args, f"writing {out} ...")
        if args.format == "asterix":
            _write_corrected_asterix(args, inp, out, rng, az, covered)
        else:
            write_corrected(out, corrected_columns(inp, rng, az, covered, reason))
    n_cov = int(covered.sum())
    reasons = {str(k): int(v) for k, v in zip(*np.unique(reason, return_counts=True), strict=True)}
    return {
        "out": str(Path(out).resolve()),
        "format": args.format,
        "field": str(args.field),
        "source": inp.source,
        "geometry": inp.geometry,
        "plots": len(plots),
        "corrected": n_cov,
        "not_covered": int(len(plots) - n_cov),
        "not_locatable": int(np.sum(~ok)),
        "reasons": reasons,
        "radars": list(radars.names),
        "columns": CORRECTED_COLUMNS,
        "origin": inp.org_used,
    }, n_cov > 0


def _write_corrected_asterix(
    args: argparse.Namespace,
    inp: RecordingInput,
    out: Path,
    rng: np.ndarray,
    az: np.ndarray,
    covered: np.ndarray,
) -> None:
    """``correct --format asterix``: the recording written again record for record, only
    I048/040 (slant range m, azimuth rad clockwise from the radar's north) of the corrected
    plots replaced (:func:`optmodels.io.rewrite_cat048_positions`); the other plots'
    records, every other item and every other category are copied as read."""
    from optmodels.io import rewrite_cat048_positions
    from optmodels.io.asterix.reports import RECORD_SHIFT

    rec = inp.recording
    if rec is None or rec.file is None or rec.offset is None:
        raise ProblemError(
            "biasfield correct --format asterix: the recording is not ASTERIX "
            f"({inp.source}); a CSV/Parquet recording is corrected with "
            "--format csv"
        )
    ids = (np.asarray(rec.file, np.int64) << RECORD_SHIFT) + np.asarray(rec.offset, np.int64)
    rewrite_cat048_positions(
        list(args.recording),
        out,
        record_id=ids[covered],
        range_m=rng[covered],
        azimuth_rad=az[covered],
    )


def _print_biasfield_correct(res: dict[str, Any]) -> None:
    print(
        f"wrote {res['out']}: {res['plots']} plots, {res['corrected']} corrected, "
        f"{res['not_covered']} written as read"
    )
    for why, n in res["reasons"].items():
        if why != "covered":
            print(f"  {n} not corrected: {why}")


def _biasfield_registration(args: argparse.Namespace) -> Outcome:
    from optmodels.biasfield import absolute_error, adsb_reference, registration_error

    say(args, f"reading {args.recording[0]} ...")
    inp = read_input(args, locate=True, clean=args.clean)
    radars, plots = inp.radars, inp.plots
    within = _load_field(args, radars) if args.field else None
    say(args, f"placing {len(plots)} plots and measuring the registration ...")
    z = plots.cartesian(radars)  # placed once for both figures (3-D: exact, ~11 s / 10⁶)
    reg = registration_error(
        plots, radars, area=args.area, within=within, positions=z, min_samples=MIN_SAMPLES
    )
    res: dict[str, Any] = {
        "source": inp.source,
        "geometry": inp.geometry,
        "plots": len(plots),
        "dropped_plots": inp.dropped,
        "registration": reg.to_dict(),
        "absolute": None,
        "units": "m, on the common horizontal plane",
    }
    if inp.adsb is not None and len(inp.adsb) and radars.is_3d:
        assert radars.origin is not None  # a 3-D radar set has its origin
        ref = adsb_reference(plots, inp.adsb, radars.origin)
        if np.isfinite(ref).all(axis=1).any():
            res["absolute"] = absolute_error(
                plots,
                radars,
                ref,
                area=args.area,
                within=within,
                positions=z,
                min_samples=MIN_SAMPLES,
            ).to_dict()
    if not np.isfinite(reg.overall):
        res["message"] = _no_area(args.area, reg.to_dict())
    return res, bool(np.isfinite(reg.overall))


def _no_area(area: float, reg: dict[str, Any]) -> str:
    """Why the registration figures are NaN: no area held enough differences."""
    n = sum(int(v["samples"]) for v in reg["pairs"].values())
    return (
        f"no area of side {area:g} m holds {MIN_SAMPLES} cross-radar differences of two "
        f"aircraft or more ({n} differences over {len(reg['pairs'])} radar pairs in all), "
        "so no per-area mean and no figure: give a larger --area (m; default 25000) or "
        "a longer recording"
    )


def _metres(v: float | None, noise: float | None = None) -> str:
    """A figure in metres for the text: ``n/a`` when NaN (no area held enough plots);
    a noise-subtracted figure clipped at 0 says so (``0.0 m (at or below the noise
    floor of 51 m)``)."""
    if v is None or not np.isfinite(v):
        return "n/a"
    if v == 0.0 and noise is not None and np.isfinite(noise):
        return f"0.0 m (at or below the noise floor of {noise:.0f} m)"
    return f"{v:.1f} m"


def _print_biasfield_registration(res: dict[str, Any]) -> None:
    reg = res["registration"]
    print(
        f"cross-radar registration error {_metres(reg['overall_m'], reg['noise_m'])} on "
        f"{res['plots']} plots: per-area means of {reg['area_m']:g} m squares less their "
        f"noise (noise {_metres(reg['noise_m'])}; raw {_metres(reg['raw_overall_m'])})"
    )
    for pair, v in reg["pairs"].items():
        print(
            f"  {pair}: {_metres(v['rms_m'], v['noise_m'])}; {v['samples']} samples, "
            f"{v['areas']} areas; raw {_metres(v['raw_rms_m'])}"
        )
    if res["absolute"]:
        ab = res["absolute"]
        print(
            f"absolute error against ADS-B {_metres(ab['overall_m'], ab['noise_m'])} (noise "
            f"{_metres(ab['noise_m'])}): "
            + ", ".join(f"{k} {_metres(v)}" for k, v in ab["radars_m"].items())
        )
    if any(
        v == 0.0
        for v in (reg["overall_m"], *(p["rms_m"] for p in reg["pairs"].values()))
        if v is not None
    ):
        print(
            "  (a figure is the systematic part, |mean|² less the noise variance per area; "
            "0.0 m: at or below the noise floor, nothing systematic left to measure)"
        )
    if res.get("message"):
        print(f"  n/a: {res['message']}")


#: The smallest ``registration --area`` (m): a smaller square holds too few plots of two
#: aircraft for a per-area mean (``--area 25``, km meant, gave every figure NaN).
MIN_AREA_SIDE = 1000.0

#: Cross-radar differences (of two aircraft or more) an area needs for its mean
#: (``registration_error``'s and ``absolute_error``'s ``min_samples``).
MIN_SAMPLES = 20


def _area_side(text: str) -> float:
    """``--area METRES``: a positive side of at least :data:`MIN_AREA_SIDE` m."""
    from optmodels.cli.args import _positive

    v = float(_positive()(text))
    if v < MIN_AREA_SIDE:
        raise argparse.ArgumentTypeError(
            f"{text} is the side of each square area in METRES (default 25000, 25 km); "
            f"a square of {v:g} m holds too few plots of two aircraft for a per-area "
            f"mean: give {MIN_AREA_SIDE:g} m or more"
        )
    return v


def register_use(bsub: Any, positive: Callable[[str], float]) -> None:
    """Add ``optmodels biasfield correct`` and ``registration`` to the verbs ``bsub``."""
    bc = _leaf(bsub, "correct", "plots corrected with a field: one CSV row per plot read")
    recording_args(bc)
    bc.add_argument(
        "--field", type=Path, required=True, help="DIR/field.npz written by `biasfield solve`"
    )
    bc.add_argument(
        "--format",
        choices=("csv", "asterix"),
        default="csv",
        help="csv: the table below; asterix: a corrected CAT048 recording, every "
        "record as read with only I040 (range, azimuth) of the corrected plots "
        "replaced, for replay into a tracker (give --out FILE.ast)",
    )
    bc.add_argument(
        "--out",
        type=Path,
        metavar="FILE",
        help="the FILE written (default: corrected.csv, or corrected.ast with --format "
        "asterix; a .csv/.txt/.json name with --format asterix, or an "
        ".ast/.asterix/.bin/.pcap name with --format csv, is refused); the CSV has one row "
        "per plot read: "
        + ", ".join(CORRECTED_COLUMNS)
        + " (the radar's name and SAC/SIC, the ICAO address in hex, times in s "
        "and UTC, range m, azimuth deg in [0, 360), height m and its source, "
        "covered and why not)",
    )
    bc.set_defaults(func=_biasfield_correct, printer=_print_biasfield_correct, adsb=None)
    br = _leaf(bsub, "registration", "cross-radar registration error (and against ADS-B)")
    recording_args(br)
    br.add_argument(
        "--field",
        type=Path,
        help="measure only where this DIR/field.npz is defined (its covered area)",
    )
    br.add_argument(
        "--area",
        type=_area_side,
        default=25e3,
        metavar="METRES",
        help="SIDE of the square areas of the per-area means, in metres (not km, not m²; "
        f"at least {MIN_AREA_SIDE:g})",
    )
    br.add_argument(
        "--no-clean",
        dest="clean",
        action="store_false",
        help="do not drop glitches, gaps and ground traffic first "
        "(default: cleaning on unless --no-clean)",
    )
    br.set_defaults(func=_biasfield_registration, printer=_print_biasfield_registration, adsb=None)
