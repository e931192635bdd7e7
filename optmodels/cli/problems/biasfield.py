"""``optmodels biasfield build`` (a recording -> cleaned plots -> tracks -> cells -> the
FieldData of paper 001)
and ``optmodels biasfield solve`` (the smoothest field (9)-(10) with the box (8), the
closed form (11), or the Lipschitz class; field.csv/.npz and maps); and the bias-field
part of ``optmodels demo`` and ``optmodels compare --details``.

The problem's other modules here: ``biasfield_read`` (the recording read for ``build``,
``correct`` and ``registration``), ``biasfield_use`` (the verbs ``correct`` and
``registration``), ``biasfield_out`` (output paths, files, readable text, ``simulate``)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from optmodels.cli.args import _count, _finite, _positive
from optmodels.cli.contract import Outcome, _group, _leaf, _reading
from optmodels.cli.problems.biasfield_out import (
    LIPSCHITZ_NOTE,
    OBJECTIVE_NOTE,
    field_rows,
    interrupt_note,
    print_build,
    print_solve,
    register_simulate,
    say,
    writable_dir,
    writable_file,
)
from optmodels.cli.problems.biasfield_read import azimuth_unit_arg, read_input
from optmodels.cli.problems.biasfield_use import register_use
from optmodels.core import ProblemError, as_positive
from optmodels.execution import scheduler_argument

if TYPE_CHECKING:
    from optmodels.biasfield import FieldBuild, FieldData, FieldSolution
    from optmodels.cli.problems.biasfield_read import RecordingInput

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = (
    "- [Radar bias fields (paper 001)](biasfield/report.md): plots to "
    "uncertainty sets, the smoothest field with and without the box, "
    "fig. 4 maps, the parametric baseline"
)


# --------------------------------------------------------------------------- build
def _npz_name(path: Path) -> Path:
    """The file ``np.savez_compressed(path)`` writes (it appends ``.npz`` if missing)."""
    return path if path.name.endswith(".npz") else path.with_name(path.name + ".npz")


def _biasfield_build(args: argparse.Namespace) -> Outcome:
    if Path(args.out).is_dir():
        raise ProblemError(
            f"--out: {args.out} is an existing folder; give a FILE name (e.g. fielddata.npz)"
        )
    out = writable_file("--out", _npz_name(Path(args.out)))  # before any work
    coverage: Literal["all", "union"] = getattr(args, "coverage", "union")
    stage = ["reading the recording"]
    with interrupt_note(stage, out, []):
        from optmodels.biasfield import field_data_from_plots, save_field_data

        # the reading here; placement, cleaning, fits, cells: the one chain
        # (biasfield.pipeline); a site no plot carries is refused whatever the coverage
        say(args, f"reading {args.recording[0]} ...")
        inp = read_input(args, locate=False, clean=False, require_all=True)
        extra = {} if args.scheduler == "serial" else {"scheduler": args.scheduler}
        stage[0] = "building the field data (cleaning, track fits, cells)"
        build = field_data_from_plots(
            inp.plots,
            inp.radars,
            cells=args.cells,
            knot_spacing=args.knot_spacing,
            coverage=coverage,
            clean=args.clean,
            locate=True,
            progress=not getattr(args, "json", False),
            **extra,
        )
        stage[0] = f"writing {out}"
        save_field_data(build.data, out, names=inp.radars.names, name="--out")
    return _build_result(args, out, coverage, inp, build), True


def _build_result(
    args: argparse.Namespace,
    out: Path,
    coverage: str,
    inp: RecordingInput,
    build: FieldBuild,
) -> dict[str, Any]:
    """``build``'s result document: what was read, dropped and built."""
    from optmodels.biasfield import residual_check

    radars, org_used = inp.radars, inp.org_used
    fd, diag = build.data, build.diagnostics
    chk = residual_check(diag.fits, radars.m)
    dropped = dict(inp.dropped)
    for reason, n in build.dropped.items():
        dropped[reason] = dropped.get(reason, 0) + int(n)
    seen = fd.subsets
    return {
        "out": str(Path(out).resolve()),
        "cells": fd.k,
        "radars": list(radars.names),
        "source": inp.source,
        "coverage": coverage,
        "geometry": inp.geometry,
        "plots": inp.n_read,
        "plots_used": int(sum(f.rows.size for f in diag.fits)),
        "dropped_plots": dropped,
        "cleaning": None
        if build.cleaning is None
        else build.cleaning.to_dict(max_rows=args.max_rows),
        "adsb": inp.adsb_report,
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
            if inp.origin is not None
            else None
            if org_used is None
            else "mean of the sites"
        ),
    }


def _print_biasfield_build(res: dict[str, Any]) -> None:
    print_build(res)


# --------------------------------------------------------------------------- solve
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


def _solve_flags(args: argparse.Namespace) -> tuple[tuple[float, float] | None, bool]:
    """The box (8) of ``--box-deg`` (K1 m, K2 rad) or ``None``, and whether the closed form
    (11) is asked for; the flags that cannot go together are refused."""
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
    return box, closed


def _biasfield_solve(args: argparse.Namespace) -> Outcome:
    from optmodels import biasfield as bf

    box, closed = _solve_flags(args)
    out = writable_dir("--out", args.out)  # before any work
    for name in ("field.npz", "field.csv"):
        if (out / name).is_dir():
            raise ProblemError(f"--out: {out / name} is a folder; cannot write {name}")
    with _reading(str(args.file)):
        fd = bf.FieldData.load(args.file)
        names = bf.field_data_names(args.file)
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
        "lipschitz_note": LIPSCHITZ_NOTE,
        "residuals": sol.residuals,
        "cells": fd.k,
        "out": str(Path(out).resolve()),
        "radar_names": list(names),
    }
    if sol.status.ok:
        res.update(_write_field(out, fd, sol, names))
    return res, sol.status.ok


def _write_field(
    out: Path, fd: FieldData, sol: FieldSolution, names: tuple[str, ...]
) -> dict[str, Any]:
    """``solve``'s files in ``out``: ``field.npz`` (with the frame, so that ``biasfield
    correct`` can check the radar set it is applied to), ``field.csv`` and the two maps
    (fig. 4); returns the per-radar summary, the active bounds and the files written."""
    from optmodels import plots as plt_
    from optmodels.biasfield import radar_baseline
    from optmodels.io import save_npz, write_csv

    arrays: dict[str, Any] = {
        "field": sol.field,
        "eta": sol.eta,
        "centers": fd.centers,
        "radars": fd.radars,
        "active": sol.active,
        "chain": np.array("3d" if fd.is_3d else "2d"),
    }
    if fd.is_3d:
        arrays.update(geodetic=fd.geodetic, origin=fd.origin)
    if names:
        arrays["names"] = np.array(names, dtype=str)
    if fd.seen is not None:
        arrays["seen"] = fd.seen
    save_npz(out / "field.npz", name="--out", **arrays)
    write_csv(out / "field.csv", field_rows(fd, sol, names))
    radars = radar_baseline(sol.field, fd.centers, fd.radars, fd.subsets, names)
    for comp, name in ((1, "azimuth"), (0, "range")):
        plt_.bias_maps(
            out / f"{name}_map.png",
            fd.centers,
            {"estimate": sol.field},
            fd.radars,
            component=comp,
        )
    return {
        "radars": radars,
        "active_bounds": int(np.sum(sol.active != 0)),
        "files": ["field.csv", "field.npz", "azimuth_map.png", "range_map.png"],
    }


def _print_biasfield_solve(res: dict[str, Any]) -> None:
    print_solve(res)


# --------------------------------------------------------------------------- hooks
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


# --------------------------------------------------------------------------- verbs
def _build_args(bb: argparse.ArgumentParser, positive: Callable[[str], float]) -> None:
    """The flags of ``biasfield build``."""
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
    azimuth_unit_arg(bb)
    bb.add_argument(
        "--drop-out-of-range",
        action="store_true",
        help="drop plots beyond their radar's max_range instead of refusing",
    )
    bb.add_argument(
        "--no-clean",
        dest="clean",
        action="store_false",
        help="skip the cleaning of glitches, track jumps and ground traffic "
        "(default: cleaning on unless --no-clean)",
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


def _solve_args(bs: argparse.ArgumentParser) -> None:
    """The flags of ``biasfield solve``."""
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


def register(sub: Any) -> None:
    """Add ``optmodels biasfield build``, ``solve``, ``simulate``, ``correct`` and
    ``registration`` to the top-level sub-commands ``sub``."""
    positive = _positive()
    bsub = _group(sub, "biasfield", "radar bias fields (paper 001)")
    bb = _leaf(bsub, "build", "plots -> FieldData .npz (cleaning, track fits, cells, averaging)")
    _build_args(bb, positive)
    bb.set_defaults(func=_biasfield_build, printer=_print_biasfield_build)
    bs = _leaf(bsub, "solve", "the smoothest field on a FieldData .npz")
    _solve_args(bs)
    bs.set_defaults(func=_biasfield_solve, printer=_print_biasfield_solve)
    register_simulate(bsub, positive, _count, _finite())
    register_use(bsub, positive)
