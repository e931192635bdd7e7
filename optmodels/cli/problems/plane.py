"""``optmodels plane fit``: the ML plane of maneuver (1.2)-(1.3) of paper 000 fitted to a
CSV of positions (IPOPT on the full or reduced (1.12) form, or the closed form
(1.5)-(1.8)) with the χ² planarity test; ``optmodels plane track``: the plane along a
track in sliding windows with plane-change detection (:func:`optmodels.plane.tracking.track`),
one row per step; and the plane part of ``optmodels demo`` and ``optmodels compare
--details``."""

from __future__ import annotations

import argparse
import csv
import io as _stdio
from pathlib import Path
from typing import Any, Literal

import numpy as np

from optmodels.cli.args import _finite, _level, _positive
from optmodels.cli.contract import Outcome, _group, _leaf, _out_file, _reading
from optmodels.cli.problems.plane_out import SIGN_CONVENTION, orientation, print_plane_fit
from optmodels.core import VERIFY_TOL, ProblemError

# the problem package is imported inside the handlers only: `optmodels --help` imports no
# problem (issue 23 item 4)

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = (
    "- [Plane of maneuver (paper 000)](plane/report.md): figures 1-4, Monte "
    "Carlo vs the Cramér–Rao bound"
)


def _parse_cov(text: str) -> np.ndarray:
    """``--cov``: 6 numbers (cxx,cxy,cxz,cyy,cyz,czz) or 9 (row-major 3x3)."""
    try:
        v = [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError as exc:
        raise ProblemError(f"--cov: not a list of numbers ({exc})") from exc
    if len(v) == 9:
        return np.array(v).reshape(3, 3)
    if len(v) == 6:
        xx, xy, xz, yy, yz, zz = v
        return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    raise ProblemError(f"--cov: expected 6 or 9 numbers, got {len(v)}")


def _method(args: argparse.Namespace) -> str:
    """``--method`` (closed-form or ipopt); the former ``--formulation closed-form`` is
    read as ``--method closed-form``, with a note on stderr."""
    import sys

    if args.formulation == "closed-form":
        print(
            "optmodels: note: --formulation closed-form is now --method closed-form",
            file=sys.stderr,
        )
        return "closed-form"
    return str(args.method)


def _plane_fit(args: argparse.Namespace) -> Outcome:
    from optmodels import plane
    from optmodels.io import read_plane_csv

    method = _method(args)
    if method == "closed-form" and args.formulation == "reduced":
        raise ProblemError(
            "--formulation reduced: the form of the generic NLP (--method ipopt); the closed "
            "form (--method closed-form) has none: drop --formulation, or give --method ipopt"
        )
    formulation: Literal["full", "reduced"] = (
        "full" if args.formulation == "closed-form" else args.formulation
    )
    with _reading(str(args.file)):
        cols = _time_range(read_plane_csv(args.file), args.file, args.start, args.end)
        if "cov" in cols:
            if args.sigma2 is not None or args.cov is not None:
                raise ProblemError("--sigma2/--cov: the file has per-point covariances already")
            cov = cols["cov"]
        elif args.cov is not None:
            cov = _parse_cov(args.cov)
        elif args.sigma2 is not None:
            cov = float(args.sigma2) * np.eye(3)
        else:
            raise ProblemError(
                "covariance: give --sigma2 S, --cov ..., or cxx..czz columns in the file"
            )
        data = plane.PlaneData(cols["points"], cov, cols.get("alpha2"))
    if method == "closed-form":
        sol = plane.closed_form(data, level=args.level)
    else:
        sol = plane.solve(data, formulation, level=args.level)
    out: dict[str, Any] = {
        "file": str(args.file),
        "n_points": data.n_points,
        "time_span": ([float(cols["t"][0]), float(cols["t"][-1])] if "t" in cols else None),
        "method_flag": method,
        "formulation": None if method == "closed-form" else formulation,
        "status": "unresolved" if sol.resolved is False else sol.status.value,
        "method": sol.method,
        "resolved": sol.resolved,
        "normal": np.asarray(sol.normal, dtype=float).tolist(),
        "offset": sol.offset,
        "sign_convention": SIGN_CONVENTION,
        **orientation(sol.normal),
        "line_direction": (
            np.asarray(sol.line_direction, dtype=float).tolist() if sol.resolved is False else None
        ),
        "line_test": sol.info.get("line_test"),
        "objective": sol.objective,
        "residuals": sol.residuals,
        "build_time": sol.build_time,
        "solve_time": sol.solve_time,
        "iterations": sol.iterations,
        "message": sol.message,
        "units": {
            "offset": "m",
            "normal": "unit vector in the file's frame",
            "tilt_deg": "deg from the horizontal (z up)",
            "tilt_azimuth_deg": "deg clockwise from north (y) of the steepest rise",
            "time_span": "s",
        },
    }
    if (sol.ok or sol.resolved is False) and data.n_points >= 4:
        # the same line test as the fit (exact under general covariances)
        test = plane.planarity_test(data, sol, level=args.level)
        out["planarity_test"] = test.to_dict()
    return out, sol.ok


def _time_range(
    cols: dict[str, Any], file: Path, start: float | None, end: float | None
) -> dict[str, Any]:
    """The rows with ``start <= t <= end`` (s) when ``--start``/``--end`` are given."""
    if start is None and end is None:
        return cols
    if "t" not in cols:
        raise ProblemError(f"--start/--end: {file} has no t column (times, s)")
    t = cols["t"]
    keep = np.ones(len(t), dtype=bool)
    if start is not None:
        keep &= t >= start
    if end is not None:
        keep &= t <= end
    if int(np.sum(keep)) < 3:
        raise ProblemError(
            f"--start/--end: {int(np.sum(keep))} rows of {file} have "
            f"{start if start is not None else '-inf'} <= t <= "
            f"{end if end is not None else 'inf'} s; a plane needs 3"
        )
    out = {
        k: (v[keep] if isinstance(v, np.ndarray) and len(v) == len(t) else v)
        for k, v in cols.items()
    }
    return out


def _parse_window(text: str) -> float | int | None:
    """``--window``: ``40s`` (seconds), ``100pts`` (points) or ``growing``; a bare number
    is refused (points or seconds?), as in :func:`optmodels.plane.windows.window_spec`."""
    from optmodels.plane.windows import parse_window_text

    try:
        return parse_window_text(text, "--window")
    except ProblemError:
        raise argparse.ArgumentTypeError(
            f"{text!r} does not say its unit: write seconds like 40s, a number of "
            "points like 100pts, or growing"
        ) from None


def _parse_site(text: str) -> np.ndarray:
    """``--site``: three numbers x,y,z (m)."""
    try:
        v = [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,z in metres, got {text!r}") from None
    if len(v) != 3 or not np.all(np.isfinite(v)):
        raise argparse.ArgumentTypeError(f"expected three finite numbers x,y,z (m), got {text!r}")
    return np.array(v)


def _track_cov(
    args: argparse.Namespace, cols: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The covariances of ``plane track``: the file's columns, a radar (``--site`` and
    the three sigmas), ``--cov`` or ``--sigma2``; exactly one source."""
    radar = [args.sigma_range, args.sigma_azimuth, args.sigma_elevation]
    given = [
        name
        for name, on in (
            ("the file's cxx..czz columns", "cov" in cols),
            ("--site", args.site is not None),
            ("--cov", args.cov is not None),
            ("--sigma2", args.sigma2 is not None),
        )
        if on
    ]
    if len(given) > 1:
        raise ProblemError(f"covariance: give one source, got {' and '.join(given)}")
    if args.site is None and any(v is not None for v in radar):
        raise ProblemError(
            "--sigma-range/--sigma-azimuth/--sigma-elevation: need --site x,y,z (the radar, m)"
        )
    alpha2 = cols.get("alpha2")
    if args.site is not None:
        if any(v is None for v in radar):
            raise ProblemError(
                "--site: give all of --sigma-range (m), --sigma-azimuth (deg)"
                " and --sigma-elevation (deg)"
            )
        from optmodels.plane.radar import radar_covariances

        if alpha2 is not None:
            raise ProblemError(
                "--site: the file's alpha2 column applies to a common --cov/--sigma2 only"
            )
        cov = radar_covariances(
            cols["points"],
            args.site,
            args.sigma_range,
            np.deg2rad(args.sigma_azimuth),
            np.deg2rad(args.sigma_elevation),
        )
        return cov, None, "radar"
    if "cov" in cols:
        return cols["cov"], None, "file"
    if args.cov is not None:
        return _parse_cov(args.cov), alpha2, "cov"
    if args.sigma2 is not None:
        return float(args.sigma2) * np.eye(3), alpha2, "sigma2"
    raise ProblemError(
        "covariance: give --site x,y,z with --sigma-range/--sigma-azimuth/"
        "--sigma-elevation, --cov ..., --sigma2 S, or cxx..czz columns in "
        "the file"
    )


def _step_status(trk: Any) -> list[str]:
    """Per step: ``optimal`` (resolved, normal's estimated error ≤ 1e-6 rad),
    ``optimal_inaccurate`` (≤ 1e-3), ``unresolved`` (the points are on a line at the
    level: the answer is the line, a valid one) or ``error`` (the line is rejected yet no
    plane passed the re-check)."""
    out = []
    for k in range(trk.n_steps):
        if bool(trk.resolved[k]):
            out.append(
                "optimal" if float(trk.numerical_error[k]) <= VERIFY_TOL else "optimal_inaccurate"
            )
        elif not float(trk.line_statistic[k]) > float(trk.line_threshold[k]):
            out.append("unresolved")
        else:
            out.append("error")
    return out


def _csv_text(rows: list[dict[str, Any]]) -> str:
    """The step rows as CSV (floats as Python's shortest round-trip ``repr``: they read
    back exactly, and 0.3 is written ``0.3``, not ``0.29999999999999999``; NaN as
    ``nan``; booleans ``True``/``False``)."""
    buf = _stdio.StringIO(newline="")
    if not rows:
        return ""
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(float(v)) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


#: The step columns that are angles: written in degrees, the unit in the name.
_DEG_COLUMNS = {
    "detectable_tilt": "detectable_tilt_deg",
    "detectable_tilt_any": "detectable_tilt_any_deg",
}


def _cli_row(row: dict[str, Any]) -> dict[str, Any]:
    """One step row for a person: the angles in degrees (``detectable_tilt_deg``), the
    numerical error estimate named with its unit (``numerical_error_rad``)."""
    out: dict[str, Any] = {}
    for k, v in row.items():
        if k in _DEG_COLUMNS:
            out[_DEG_COLUMNS[k]] = float(np.degrees(v))
        elif k == "numerical_error":
            out["numerical_error_rad"] = v
        else:
            out[k] = v
    return out


#: ``plane track``'s default ``--false-alarm-rate-per-h``.
FALSE_ALARMS_PER_H = 1.0


def _former_rate(args: argparse.Namespace) -> None:
    """``--false-alarm-rate R`` (the former name, hidden) is ``--false-alarm-rate-per-h R``
    (the same number, per hour), with a note on stderr; both at once are refused. Without
    either, :data:`FALSE_ALARMS_PER_H`."""
    import sys

    if not hasattr(args, "false_alarm_rate_former"):
        if args.false_alarm_rate_per_h is None:
            args.false_alarm_rate_per_h = FALSE_ALARMS_PER_H
        return
    if args.false_alarm_rate_per_h is not None:
        raise ProblemError(
            "--false-alarm-rate: the former name of --false-alarm-rate-per-h; give one of them"
        )
    print(
        "optmodels: note: --false-alarm-rate is now --false-alarm-rate-per-h "
        "(false alarms per hour of planar track; the same number)",
        file=sys.stderr,
    )
    args.false_alarm_rate_per_h = args.false_alarm_rate_former


def _plane_track(args: argparse.Namespace) -> Outcome:
    from optmodels.io import atomic_write, read_plane_csv
    from optmodels.plane.tracking import track
    from optmodels.plane.windows import window_label

    _former_rate(args)
    out_path = _out_file("--out", args.out) if args.out is not None else None
    with _reading(str(args.file)):
        cols = read_plane_csv(args.file, require_time=True)
        cov, alpha2, source = _track_cov(args, cols)
    win = args.window
    trk = track(
        cols["t"],
        cols["points"],
        cov,
        window_points=win if isinstance(win, int) else None,
        window_seconds=win if isinstance(win, float) else None,
        level=args.level,
        false_alarm_rate_per_h=args.false_alarm_rate_per_h,
        alpha2=alpha2,
        power=args.power,
        start=args.start,
    )
    status = _step_status(trk)
    rows = [{**_cli_row(r), "status": s} for r, s in zip(trk.to_rows(), status, strict=True)]
    if out_path is not None:
        with atomic_write(out_path, name="--out", newline="") as fh:
            fh.write(_csv_text(rows))
    counts = {s: status.count(s) for s in ("optimal", "optimal_inaccurate", "unresolved", "error")}
    ok = counts["error"] == 0
    settings = {
        k: v
        for k, v in trk.to_dict().items()
        if k
        in (
            "level",
            "false_alarm_rate_per_h",
            "power",
            "scales",
            "method",
            "test_level",
            "solve_time",
            "n_steps",
            "change_times",
        )
    }
    doc: dict[str, Any] = {
        "file": str(args.file),
        "n_points": len(cols["t"]),
        "covariance": source,
        "window": window_label(win),
        "units": {
            "time": "s",
            "offset": "m",
            "normal": "unit vector in the file's frame",
            "detectable_tilt_deg": "deg",
            "false_alarm_rate_per_h": "per hour",
            "numerical_error_rad": "rad",
            "scales": "s, or points with a points window",
            "statistic": "dimensionless, chi2(n_points - 3) if planar",
        },
        "sign_convention": SIGN_CONVENTION,
        **settings,
        "status_counts": counts,
        "status": "optimal" if ok else "error",
        "out": str(out_path.resolve()) if out_path is not None else None,
        "steps": rows,
    }
    return doc, ok


def _print_plane_track(res: dict[str, Any]) -> None:
    if res["out"] is None:
        print(_csv_text(res["steps"]), end="")
        return
    c = res["status_counts"]
    times = ", ".join(repr(float(t)) for t in res["change_times"])
    changes = f"plane changes detected at t = {times} s" if times else "no plane change detected"
    print(
        f"{res['file']}: N = {res['n_points']}, {res['n_steps']} steps ({res['method']}, "
        f"window {res['window']}); wrote {res['out']}"
    )
    print(
        f"  steps: {c['optimal']} optimal, {c['optimal_inaccurate']} inaccurate, "
        f"{c['unresolved']} unresolved (on a line), {c['error']} error"
    )
    print(f"  {changes} (bound: {res['false_alarm_rate_per_h']:g} false alarms per hour)")


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the example of paper 000 in ``out/plane``."""
    from optmodels.demo import run_plane_demo

    return run_plane_demo(out / "plane", runs=args.runs, seed=args.seed, progress=progress)


def run_details(
    out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int, progress: bool
) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: timing and Monte Carlo accuracy per size, the
    benchmark and the full NLP's scaling (:mod:`solvers_cmp.plane`); the report section
    and the result entry."""
    from solvers_cmp import plane as cmp_plane

    timing = cmp_plane.timing_rows(sizes, seed=seed, repeats=repeats, progress=progress)
    acc = cmp_plane.accuracy_rows(sizes, runs=runs, seed=seed, progress=progress)
    bench = cmp_plane.benchmark(max(sizes), repeats=repeats, seed=seed)
    # the full NLP's linear-time scaling (issue 19): cold, 3 starts, general D_i
    scaling = cmp_plane.full_nlp_scaling((1_000, 10_000, 20_000), repeats=repeats, seed=seed)
    md = cmp_plane.write_report(out, timing, acc, bench, scaling)
    return md, {"timing": timing, "accuracy": acc, "benchmark": bench, "scaling": scaling}


def register(sub: Any) -> None:
    """Add ``optmodels plane fit`` and ``optmodels plane track`` to the top-level
    sub-commands ``sub``."""
    positive = _positive()
    plsub = _group(sub, "plane", "plane of maneuver (paper 000)")
    fit = _leaf(plsub, "fit", "fit the ML plane to a CSV of positions; prints its tilt")
    fit.epilog = (
        "The normal's sign: offset ≥ 0, i.e. the normal points from the origin (0, 0, 0) "
        "of the file's frame towards the plane (the data fix (normal, offset) only up to "
        "a common sign). Exit 0: a resolved plane; 1: not OK, or unresolved (the points lie on a "
        "line at --level: the line's direction is reported, no plane); 2: bad "
        "input."
    )
    fit.add_argument("file", type=Path, help="CSV with x,y,z [,t] [,alpha2] [,cxx..czz]")
    g = fit.add_mutually_exclusive_group()
    g.add_argument("--sigma2", type=positive, help="error variance per axis, m² (D = σ² I)")
    g.add_argument("--cov", help="common D, m²: cxx,cxy,cxz,cyy,cyz,czz (or 9 numbers)")
    fit.add_argument(
        "--method",
        choices=("ipopt", "closed-form"),
        default="ipopt",
        help="closed-form (1.5)-(1.8), valid under D_i = α_i² D, or the "
        "generic NLP (CasADi + IPOPT) on --formulation",
    )
    fit.add_argument(
        "--formulation",
        choices=("full", "reduced", "closed-form"),
        default="full",
        help="the generic NLP's form: full (1.2)-(1.3) or reduced "
        "(1.12)-(1.13) (closed-form: the former spelling of --method "
        "closed-form)",
    )
    fit.add_argument(
        "--level",
        type=_level(),
        default=0.997,
        help="level of the χ² planarity and line tests, in (0, 1)",
    )
    fit.add_argument("--start", type=_finite(), help="fit only rows with t >= START (s)")
    fit.add_argument("--end", type=_finite(), help="fit only rows with t <= END (s)")
    fit.set_defaults(func=_plane_fit, printer=print_plane_fit)

    tr = _leaf(
        plsub,
        "track",
        "the plane along a track: sliding windows, plane-change detection, one row per step",
    )
    tr.epilog = (
        "One row per step: time (s), nx, ny, nz (unit normal, the file's frame, pointing "
        "from its origin towards the plane: offset ≥ 0; "
        "empty/nan where not resolved), offset (m), statistic and threshold (χ², "
        "dimensionless), resolved, planar, change, detector, detector_threshold, "
        "change_time (s), detectable_tilt_deg, detectable_tilt_any_deg (deg), "
        "n_points, window_start (s), line_x..line_z, numerical_error_rad, "
        "p_value, status. Exit 0: no step in error; 1: some step's plane failed "
        "its re-check; 2: bad input."
    )
    tr.add_argument(
        "file", type=Path, help="CSV with t (s, increasing), x,y,z (m) [,alpha2] [,cxx..czz (m²)]"
    )
    tr.add_argument(
        "--window",
        type=_parse_window,
        required=True,
        metavar="40s|100pts|growing",
        help="window with its unit: seconds like 40s, a number of points like "
        "100pts, or growing (a bare 40 is refused: points or seconds?)",
    )
    tr.add_argument(
        "--level",
        type=_level(),
        default=0.997,
        help="level of the χ² planarity and line tests, in (0, 1)",
    )
    tr.add_argument(
        "--false-alarm-rate-per-h",
        type=positive,
        metavar="PER_HOUR",
        help=f"detector false alarms per HOUR of planar track (default: {FALSE_ALARMS_PER_H:g})",
    )
    tr.add_argument(
        "--false-alarm-rate",
        type=positive,
        dest="false_alarm_rate_former",
        default=argparse.SUPPRESS,
        help=argparse.SUPPRESS,
    )  # the former name: read as --false-alarm-rate-per-h (the same unit), with a note
    tr.add_argument(
        "--power",
        type=_level(),
        default=0.9,
        help="detection probability behind detectable_tilt_deg, in (0, 1)",
    )
    tr.add_argument("--start", type=_finite(), help="first reported time, s")
    tr.add_argument(
        "--site",
        type=_parse_site,
        help="radar position x,y,z (m, the file's local flat ENU frame): "
        "covariances from range/azimuth/elevation errors (first order, at "
        "the measured points)",
    )
    tr.add_argument("--sigma-range", type=positive, help="radar range error std, m")
    tr.add_argument(
        "--sigma-azimuth",
        type=positive,
        help="radar azimuth error std, DEGREES (azimuth clockwise from north)",
    )
    tr.add_argument("--sigma-elevation", type=positive, help="radar elevation error std, DEGREES")
    tr.add_argument("--cov", help="common D, m²: cxx,cxy,cxz,cyy,cyz,czz (or 9 numbers)")
    tr.add_argument("--sigma2", type=positive, help="error variance per axis, m² (D = σ² I)")
    tr.add_argument(
        "--out", metavar="FILE", help="write the steps to this CSV FILE (else the CSV on stdout)"
    )
    tr.set_defaults(func=_plane_track, printer=_print_plane_track)
