"""``optmodels biasfield build`` (a recording -> cleaned plots -> tracks -> cells -> the
FieldData of paper 001)
and ``optmodels biasfield solve`` (the smoothest field (9)-(10) with the box (8), the
closed form (11), or the Lipschitz class; field.csv/.npz and maps); and the bias-field
part of ``optmodels demo`` and ``optmodels compare --details``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.cli.args import _count, _finite, _positive
from optmodels.cli.contract import (
    Outcome,
    _group,
    _leaf,
    _reading,
)
from optmodels.cli.problems.biasfield_out import (
    CORRECTED_COLUMNS,
    NOT_LOCATABLE,
    OBJECTIVE_NOTE,
    corrected_columns,
    field_rows,
    interrupt_note,
    print_build,
    print_solve,
    register_simulate,
    say,
    writable_dir,
    writable_file,
    write_corrected,
)
from optmodels.core import ProblemError, as_positive
from optmodels.execution import scheduler_argument

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = (
    "- [Radar bias fields (paper 001)](biasfield/report.md): plots to "
    "uncertainty sets, the smoothest field with and without the box, "
    "fig. 4 maps, the parametric baseline"
)


def _npz_name(path: Path) -> Path:
    """The file ``np.savez_compressed(path)`` writes (it appends ``.npz`` if missing)."""
    return path if path.name.endswith(".npz") else path.with_name(path.name + ".npz")


def _parse_origin(text: str) -> tuple[float, float, float]:
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


def _is_asterix(path: Path) -> bool:
    """Content detection (B2's :func:`optmodels.io.asterix.is_asterix`); a file that is
    not there is left to the CSV reader's message."""
    try:
        from optmodels.io.asterix import is_asterix
    except ImportError:  # pragma: no cover - the module ships with the package
        return False
    return bool(path.is_file() and is_asterix(path))


def _asterix_recording(
    files: list[Path], args: argparse.Namespace, origin: tuple[float, float, float] | None
) -> Any:
    """ASTERIX CAT048 (+ CAT021) through :func:`optmodels.biasfield.recording.read_recording`:
    the 3-D radars of the sites CSV (keyed by SAC/SIC; ``--origin`` or the mean of the
    sites), the plots (heights from CAT021, else from the flight level), the ADS-B reports
    and the recording's report."""
    from optmodels.biasfield.recording import read_recording, read_sites

    with _reading(str(args.radars)):
        radars = read_sites(args.radars, origin=origin)
    with _reading(str(files[0])):
        return read_recording([str(f) for f in files], radars, date=args.date)


def _read_input(
    args: argparse.Namespace, *, locate: bool, clean: bool, require_all: bool = False
) -> dict[str, Any]:
    """RECORDING [RECORDING2] (+ ``--adsb``) and ``--radars`` → the radar set and the plots
    (ASTERIX or CSV/Parquet, told apart by content), what was read and dropped, and the
    ADS-B reports of an ASTERIX recording (CAT021) — shared by ``build``, ``correct`` and
    ``registration``. With ``locate``, the plots a 3-D radar set cannot place (no height,
    slant range below the height difference) are removed and counted; with ``clean`` (it
    needs ``locate``), also the cleaning's drops (gaps, glitches, ground traffic);
    ``require_all`` (build):
    a radar of the sites without a plot in an ASTERIX recording is refused, naming its
    SAC/SIC and the recording's unknown ones."""
    from optmodels import biasfield as bf
    from optmodels.biasfield.cleaning import clean_plots
    from optmodels.biasfield.ingest import read_tracks

    origin = _parse_origin(args.origin) if args.origin is not None else None
    files = list(args.recording) + ([args.adsb] if getattr(args, "adsb", None) else [])
    if len(args.recording) > 2:
        raise ProblemError(
            f"RECORDING: at most two files (plots, then ADS-B), got {len(args.recording)}"
        )
    kinds = ["asterix" if _is_asterix(f) else "table" for f in files]
    adsb_report: dict[str, Any] | None = None
    adsb = rec = None
    labels: list[str] = []
    read_dropped: dict[str, int] = {}
    if "asterix" in kinds:
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
        rec = _asterix_recording(files, args, origin)
        radars, plots, adsb = rec.radars, rec.plots, rec.adsb
        if len(plots) == 0:
            raise ProblemError(
                f"{files[0]}: no CAT048 plot of the sites in {args.radars} "
                f"(dropped: {dict(rec.report.dropped) or 'none'}; SAC/SIC in "
                f"the recording but not in the sites: "
                f"{[list(i) for i in rec.report.unknown_ids] or 'none'})"
            )
        silent = [radars.names[i] for i in range(radars.m) if not np.any(plots.radar == i)]
        if silent and require_all:  # build: every cell needs all m radars
            raise ProblemError(
                f"--radars {args.radars}: radars {silent} (SAC/SIC "
                f"{[list(radars.ids[radars.names.index(n)]) for n in silent]}) "
                f"have no plot in {files[0]}; SAC/SIC in the recording but "
                f"not in the sites: "
                f"{[list(i) for i in rec.report.unknown_ids] or 'none'}"
            )
        adsb_report = {"reports": len(rec.adsb), **rec.report.as_dict()}
        read_dropped = {str(k): int(v) for k, v in rec.report.dropped.items()}
        source, org_used = "asterix", [float(v) for v in radars.origin]
    else:
        source = "table"
        with _reading(str(args.radars)):
            org_arg: Any = origin if origin is not None else "mean"
            radars, org_used = bf.read_radars(args.radars, origin=org_arg)
        with _reading(str(files[0])):
            plots, read_dropped = bf.read_plots(
                files[0],
                radars,
                azimuth_unit=args.azimuth_unit,
                drop_out_of_range=args.drop_out_of_range,
                labels=labels,
            )
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
                radars, org_used = bf.read_radars(args.radars, origin=org_used, geometry="3d")
            if plots.height is None:
                raise ProblemError(
                    f"--geometry 3d: {files[0]} has no 'height' column "
                    "(target height, m above the WGS-84 ellipsoid)"
                )
        if len(files) > 1:
            if org_used is None:
                raise ProblemError(
                    f"{files[1]}: ADS-B positions need geodetic radar sites "
                    f"(lat, lon, alt in {args.radars}) or --origin"
                )
            with _reading(str(files[1])):
                _, rep = read_tracks(files[1], org_used, report=True)
            adsb_report = rep.to_dict(max_rows=args.max_rows)
    n_read = len(plots)
    dropped = dict(read_dropped)
    cleaning = None
    if locate and getattr(radars, "is_3d", False):
        ok = plots.locatable(radars)
        if not ok.all():
            dropped["no height or slant range below height"] = int(np.sum(~ok))
            plots = plots.subset(ok)
    if clean:
        plots, crep = clean_plots(plots, radars)
        dropped.update(crep.counts)
        cleaning = crep.to_dict(max_rows=args.max_rows)
    return {
        "radars": radars,
        "plots": plots,
        "source": source,
        "org_used": org_used,
        "origin": origin,
        "adsb_report": adsb_report,
        "adsb": adsb,
        "dropped": dropped,
        "cleaning": cleaning,
        "n_read": n_read,
        "recording": rec,
        "labels": labels,
    }


def _biasfield_build(args: argparse.Namespace) -> Outcome:
    if Path(args.out).is_dir():
        raise ProblemError(
            f"--out: {args.out} is an existing folder; give a FILE name (e.g. fielddata.npz)"
        )
    out = writable_file("--out", _npz_name(Path(args.out)))  # before any work
    coverage = getattr(args, "coverage", "union")
    stage = ["reading the recording"]
    with interrupt_note(stage, out, []):
        from optmodels import biasfield as bf
        from optmodels.biasfield.pipeline import save_field_data

        # the reading here; placement, cleaning, fits, cells: the one chain
        # (biasfield.pipeline); a site no plot carries is refused whatever the coverage
        say(args, f"reading {args.recording[0]} ...")
        inp = _read_input(args, locate=False, clean=False, require_all=True)
        radars, org_used = inp["radars"], inp["org_used"]
        extra = {} if args.scheduler == "serial" else {"scheduler": args.scheduler}
        stage[0] = "building the field data (cleaning, track fits, cells)"
        build = bf.field_data_from_plots(
            inp["plots"],
            radars,
            cells=args.cells,
            knot_spacing=args.knot_spacing,
            coverage=coverage,
            clean=args.clean,
            locate=True,
            progress=not getattr(args, "json", False),
            **extra,
        )
        fd, diag = build.data, build.diagnostics
        stage[0] = f"writing {out}"
        save_field_data(fd, out, names=radars.names, name="--out")
    chk = bf.residual_check(diag.fits, radars.m)
    dropped = dict(inp["dropped"])
    for reason, n in build.dropped.items():
        dropped[reason] = dropped.get(reason, 0) + int(n)
    seen = fd.subsets
    return {
        "out": str(Path(out).resolve()),
        "cells": fd.k,
        "radars": list(radars.names),
        "source": inp["source"],
        "coverage": coverage,
        "geometry": "3d" if getattr(radars, "is_3d", False) else "2d",
        "plots": inp["n_read"],
        "plots_used": int(sum(f.rows.size for f in diag.fits)),
        "dropped_plots": dropped,
        "cleaning": None
        if build.cleaning is None
        else build.cleaning.to_dict(max_rows=args.max_rows),
        "adsb": inp["adsb_report"],
        "dropped_cells": diag.dropped_cells,
        "warnings": build.warnings,
        "cells_per_radar": {n: int(seen[:, i].sum()) for i, n in enumerate(radars.names)},
        "radars_per_cell": {
            str(c): int(v) for c, v in enumerate(np.bincount(seen.sum(axis=1))) if v
        },
        "track_chi2_per_dof": (chk.chi2 / np.maximum(chk.dof, 1)).tolist(),
        "origin": None if org_used is None else [float(v) for v in org_used],
        "origin_source": (
            "--origin"
            if inp["origin"] is not None
            else None
            if org_used is None
            else "mean of the sites"
        ),
    }, True


def _print_biasfield_build(res: dict[str, Any]) -> None:
    print_build(res)


def _parse_box(text: str) -> tuple[float, float]:
    """``--box-deg K1,K2``: metres and degrees, both positive -> (K1 m, K2 rad), the unit
    of the API's ``box``."""
    parts = text.split(",")
    if len(parts) != 2:
        raise ProblemError(f"--box-deg: expected K1,K2 (metres, degrees), got {text!r}")
    try:
        k1, k2 = (float(v) for v in parts)
    except ValueError:
        raise ProblemError(f"--box-deg: expected K1,K2 (metres, degrees), got {text!r}") from None
    k1 = as_positive("--box-deg K1 (m)", k1)
    k2 = as_positive("--box-deg K2 (deg)", k2)
    return k1, float(np.deg2rad(k2))


def _biasfield_solve(args: argparse.Namespace) -> Outcome:
    from optmodels import biasfield as bf
    from optmodels import plots as plt_

    if args.box is not None:
        raise ProblemError(
            f"--box {args.box}: renamed --box-deg K1,K2 (K1 in metres, K2 in "
            "DEGREES; the Python API's box=(K1 m, K2 rad) takes radians), so "
            "that the unit is in the flag's name"
        )
    box = _parse_box(args.box_deg) if args.box_deg else None
    closed = args.method == "closed-form" or args.solver == "closed-form"
    given = "--method closed-form" if args.method == "closed-form" else "--solver closed-form"
    if args.lipschitz and closed:
        raise ProblemError(
            f"{given}: the Lipschitz problem (--lipschitz) has no "
            "closed form; choose a CVXPY conic solver (CLARABEL, SCS, ...)"
        )
    if closed and box is not None:
        raise ProblemError("--box-deg: the closed form (11) has no box; use --method qp")
    if args.solver == "closed-form":
        print("optmodels: note: --solver closed-form is now --method closed-form", file=sys.stderr)
    from optmodels.biasfield.pipeline import field_data_names
    from optmodels.biasfield.summary import radar_baseline
    from optmodels.io import save_npz, write_csv

    out = writable_dir("--out", args.out)  # before any work
    for name in ("field.npz", "field.csv"):
        if (out / name).is_dir():
            raise ProblemError(f"--out: {out / name} is a folder; cannot write {name}")
    with _reading(str(args.file)):
        fd = bf.FieldData.load(args.file)
        names = field_data_names(args.file)
    if args.lipschitz:
        sol = bf.solve_lipschitz(fd, box=box, solver=args.solver)
    elif closed:
        sol = bf.closed_form(fd)
    else:
        sol = bf.solve(fd, box=box, solver=args.solver, formulation=args.formulation)
    res: dict[str, Any] = {
        "status": sol.status.value,
        "method": sol.method,
        "message": sol.message,
        "objective": sol.objective,
        "objective_note": OBJECTIVE_NOTE,
        "lipschitz": sol.lipschitz,
        "residuals": sol.residuals,
        "cells": fd.k,
        "out": str(Path(out).resolve()),
        "radar_names": list(names),
    }
    if sol.status.ok:
        # the frame, so that `biasfield correct` can check the radar set it is applied to
        frame: dict[str, Any] = {"chain": np.array("3d" if fd.is_3d else "2d")}
        if fd.is_3d:
            frame.update(geodetic=fd.geodetic, origin=fd.origin)
        if names:
            frame["names"] = np.array(names, dtype=str)
        save_npz(
            out / "field.npz",
            name="--out",
            field=sol.field,
            eta=sol.eta,
            centers=fd.centers,
            radars=fd.radars,
            active=sol.active,
            **frame,
            **({} if fd.seen is None else {"seen": fd.seen}),
        )
        write_csv(out / "field.csv", field_rows(fd, sol, names))
        res["radars"] = radar_baseline(sol.field, fd.centers, fd.radars, fd.subsets, names)
        for comp, name in ((1, "azimuth"), (0, "range")):
            plt_.bias_maps(
                out / f"{name}_map.png",
                fd.centers,
                {"estimate": sol.field},
                fd.radars,
                component=comp,
            )
        res["active_bounds"] = int(np.sum(sol.active != 0))
        res["files"] = ["field.csv", "field.npz", "azimuth_map.png", "range_map.png"]
    return res, sol.status.ok


def _print_biasfield_solve(res: dict[str, Any]) -> None:
    print_solve(res)


def _load_field(args: argparse.Namespace, radars: Any) -> Any:
    """``--field DIR/field.npz`` (written by ``biasfield solve``), checked against the
    radar set it is applied to (same radars, sites, and for a 3-D field the same origin)."""
    from optmodels.biasfield.usage import FieldMap

    with _reading(str(args.field)):
        fm = FieldMap.load(args.field)
    fm.check_radars(radars, where=f"--field {args.field}")
    return fm


def _biasfield_correct(args: argparse.Namespace) -> Outcome:
    out = writable_file("--out", Path(args.out))  # before any work
    if args.format == "asterix":
        from optmodels.io import is_asterix

        for f in args.recording:
            if not is_asterix(f):
                raise ProblemError(
                    f"biasfield correct --format asterix: {f} is not an ASTERIX "
                    "recording (datablocks or a pcap/pcapng capture); a "
                    "CSV/Parquet recording is corrected with --format csv"
                )
    stage = ["reading the recording"]
    with interrupt_note(stage, out, []):
        from optmodels.biasfield.usage import correct_plots

        say(args, f"reading {args.recording[0]} ...")
        inp = _read_input(args, locate=False, clean=False)  # one row per plot read
        radars, plots = inp["radars"], inp["plots"]
        fm = _load_field(args, radars)
        # plots a 3-D radar set cannot place (no height, slant range below the height
        # difference) are written as read, with covered = 0
        ok = (
            plots.locatable(radars)
            if getattr(radars, "is_3d", False)
            else np.ones(len(plots), dtype=bool)
        )
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
        "source": inp["source"],
        "geometry": "3d" if getattr(radars, "is_3d", False) else "2d",
        "plots": len(plots),
        "corrected": n_cov,
        "not_covered": int(len(plots) - n_cov),
        "not_locatable": int(np.sum(~ok)),
        "reasons": reasons,
        "radars": list(radars.names),
        "columns": CORRECTED_COLUMNS,
        "origin": inp["org_used"],
    }, n_cov > 0


def _write_corrected_asterix(
    args: argparse.Namespace,
    inp: dict[str, Any],
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

    rec = inp.get("recording")
    if rec is None or rec.file is None or rec.offset is None:
        raise ProblemError(
            "biasfield correct --format asterix: the recording is not ASTERIX "
            f"({inp['source']}); a CSV/Parquet recording is corrected with "
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
    from optmodels.biasfield.referee import absolute_error, adsb_reference
    from optmodels.biasfield.usage import registration_error

    say(args, f"reading {args.recording[0]} ...")
    inp = _read_input(args, locate=True, clean=args.clean)
    radars, plots = inp["radars"], inp["plots"]
    within = _load_field(args, radars) if args.field else None
    say(args, f"placing {len(plots)} plots and measuring the registration ...")
    z = plots.cartesian(radars)  # placed once for both figures (3-D: exact, ~11 s / 10⁶)
    reg = registration_error(plots, radars, area=args.area, within=within, positions=z)
    res: dict[str, Any] = {
        "source": inp["source"],
        "geometry": "3d" if getattr(radars, "is_3d", False) else "2d",
        "plots": len(plots),
        "dropped_plots": inp["dropped"],
        "registration": reg.to_dict(),
        "absolute": None,
        "units": "m, on the common horizontal plane",
    }
    if inp["adsb"] is not None and len(inp["adsb"]) and getattr(radars, "is_3d", False):
        ref = adsb_reference(plots, inp["adsb"], radars.origin)
        if np.isfinite(ref).all(axis=1).any():
            res["absolute"] = absolute_error(
                plots, radars, ref, area=args.area, within=within, positions=z
            ).to_dict()
    return res, bool(np.isfinite(reg.overall))


def _print_biasfield_registration(res: dict[str, Any]) -> None:
    reg = res["registration"]
    print(
        f"cross-radar registration error {reg['overall_m']:.1f} m (per-area means, noise "
        f"{reg['noise_m']:.1f} m; raw {reg['raw_overall_m']:.1f} m) on {res['plots']} plots"
    )
    for pair, v in reg["pairs"].items():
        print(f"  {pair}: {v['rms_m']:.1f} m ({v['samples']} samples, {v['areas']} areas)")
    if res["absolute"]:
        ab = res["absolute"]
        print(
            f"absolute error against ADS-B {ab['overall_m']:.1f} m (noise "
            f"{ab['noise_m']:.1f} m): "
            + ", ".join(f"{k} {v:.1f} m" for k, v in ab["radars_m"].items())
        )


def _recording_args(p: Any, positive: Any) -> None:
    """The input flags ``build``, ``correct`` and ``registration`` share."""
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
    p.add_argument(
        "--azimuth-unit",
        choices=("deg", "rad"),
        default="deg",
        help="azimuth unit of CSV/Parquet plots",
    )
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


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the radar-network example of paper 001 in ``out/biasfield``
    (it shows no progress bar)."""
    from optmodels.demo import run_biasfield_demo

    return run_biasfield_demo(out / "biasfield", seed=args.seed)


def run_details(
    out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int, progress: bool
) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: :mod:`solvers_cmp.biasfield`'s rows; the report
    section and the result entry."""
    from solvers_cmp import biasfield as cmp_bf

    rows = cmp_bf.rows(seed=seed, repeats=1, progress=progress)
    md = cmp_bf.write_report(out, rows)
    return md, {"results": rows}


def register(sub: Any) -> None:
    """Add ``optmodels biasfield build``, ``solve``, ``correct`` and ``registration`` to
    the top-level sub-commands ``sub``."""
    positive = _positive()
    bsub = _group(sub, "biasfield", "radar bias fields (paper 001)")
    bb = _leaf(bsub, "build", "plots -> FieldData .npz (cleaning, track fits, cells, averaging)")
    bb.add_argument(
        "recording",
        type=Path,
        nargs="+",
        metavar="RECORDING",
        help="ASTERIX (CAT048 plots, optionally CAT021 ADS-B in the same or a "
        "second file) or CSV/Parquet plots time,radar,range,azimuth[,object]"
        "[,height] (then an optional second CSV/Parquet: ADS-B object,time,"
        "lat,lon[,alt]); the format is detected from the content",
    )
    bb.add_argument("--adsb", type=Path, help="ADS-B file (same as a second RECORDING)")
    bb.add_argument(
        "--radars",
        type=Path,
        required=True,
        help="sites CSV: name,[sac,sic,]x,y|lat,lon[,alt] (alt m above the WGS-84 "
        "ellipsoid),sigma_range (m),sigma_azimuth (deg),max_range (m)",
    )
    bb.add_argument(
        "--origin",
        metavar="LAT,LON,H",
        help="origin of the common plane: degrees, degrees, m above the "
        "ellipsoid (default: the mean of the sites' lat, lon, alt)",
    )
    bb.add_argument(
        "--geometry",
        choices=("auto", "2d", "3d"),
        default="auto",
        help="3d: slant ranges, each radar's own north, plot heights (auto: 3d "
        "when the sites are geodetic and the plots have a height column)",
    )
    bb.add_argument("--cells", type=_count(2), default=200, help="number of k-means cells")
    bb.add_argument(
        "--knot-spacing",
        type=positive,
        default=20.0,
        help="polyline knots, s (also the longest silence inside a track: "
        "more than the scan interval)",
    )
    bb.add_argument(
        "--coverage",
        choices=("union", "all"),
        default="union",
        help="union: cells wherever two radars or more see the traffic, each "
        "with its own radars (default); all: only where every radar does "
        "(paper 001 as printed)",
    )
    bb.add_argument(
        "--azimuth-unit",
        choices=("deg", "rad"),
        default="deg",
        help="azimuth unit of CSV/Parquet plots",
    )
    bb.add_argument(
        "--drop-out-of-range",
        action="store_true",
        help="drop plots beyond their radar's max_range instead of refusing",
    )
    bb.add_argument(
        "--no-clean",
        dest="clean",
        action="store_false",
        help="skip the cleaning (glitches, track jumps, ground traffic)",
    )
    bb.add_argument(
        "--max-rows",
        type=_count(0),
        default=100,
        help="dropped rows listed per reason in the report (default 100)",
    )
    bb.add_argument(
        "--date",
        help="UTC date of an ASTERIX recording (YYYY-MM-DD; time of day rolls over at midnight)",
    )
    bb.add_argument(
        "--scheduler",
        type=scheduler_argument,
        default="serial",
        help="where the track fits run: serial (default), processes (all "
        "local cores) or a Dask address tcp://host:8786",
    )
    bb.add_argument(
        "--out",
        type=Path,
        default=Path("fielddata.npz"),
        metavar="FILE",
        help="the FieldData .npz FILE written",
    )
    bb.set_defaults(func=_biasfield_build, printer=_print_biasfield_build)
    bs = _leaf(bsub, "solve", "the smoothest field on a FieldData .npz")
    bs.add_argument("file", type=Path, help="FieldData .npz written by biasfield build")
    bs.add_argument(
        "--box-deg",
        metavar="K1,K2",
        help="the box (8): |range bias| ≤ K1 metres, |azimuth bias| ≤ K2 DEGREES "
        "(the API's box=(K1, K2) takes radians)",
    )
    bs.add_argument("--box", help=argparse.SUPPRESS)
    bs.add_argument(
        "--method",
        choices=("closed-form", "qp"),
        default="qp",
        help="closed-form (11) (no box, no --lipschitz), or the QP (9)-(10) on --solver",
    )
    bs.add_argument("--solver", default="CLARABEL", help="CVXPY solver (CLARABEL, OSQP, SCS, ...)")
    bs.add_argument(
        "--formulation",
        choices=("reduced", "constrained"),
        default="reduced",
        help="the QP's form: reduced or constrained",
    )
    bs.add_argument(
        "--lipschitz",
        action="store_true",
        help="smallest Lipschitz constant instead of the quadratic criterion",
    )
    bs.add_argument(
        "--out",
        default="biasfield_out",
        metavar="FOLDER",
        help="output FOLDER for field.csv, field.npz and the two maps",
    )
    bs.set_defaults(func=_biasfield_solve, printer=_print_biasfield_solve)
    register_simulate(bsub, positive, _count, _finite())
    bc = _leaf(bsub, "correct", "plots corrected with a field: one CSV row per plot read")
    _recording_args(bc, positive)
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
        default=Path("corrected.csv"),
        metavar="FILE",
        help="CSV FILE, one row per plot read: "
        + ", ".join(CORRECTED_COLUMNS)
        + " (the radar's name and SAC/SIC, the ICAO address in hex, times in s "
        "and UTC, range m, azimuth deg in [0, 360), height m and its source, "
        "covered and why not)",
    )
    bc.set_defaults(func=_biasfield_correct, printer=_print_biasfield_correct, adsb=None)
    br = _leaf(bsub, "registration", "cross-radar registration error (and against ADS-B)")
    _recording_args(br, positive)
    br.add_argument(
        "--field",
        type=Path,
        help="measure only where this DIR/field.npz is defined (its covered area)",
    )
    br.add_argument(
        "--area",
        type=positive,
        default=25e3,
        help="side of the square areas of the per-area means, m",
    )
    br.add_argument(
        "--no-clean",
        dest="clean",
        action="store_false",
        help="do not drop glitches, gaps and ground traffic first",
    )
    br.set_defaults(func=_biasfield_registration, printer=_print_biasfield_registration, adsb=None)
