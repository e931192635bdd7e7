"""``optmodels biasfield build`` (plots -> tracks -> cells -> the FieldData of paper 001)
and ``optmodels biasfield solve`` (the smoothest field (9)-(10) with the box (8), the
closed form (11), or the Lipschitz class; field.csv/.npz and maps); and the bias-field
part of ``optmodels demo`` and ``optmodels compare --details``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.cli.args import _count, _positive
from optmodels.cli.contract import _OK_STATUSES, Outcome, _leaf, _out_dir, _out_file, _reading
from optmodels.core import ProblemError, as_positive

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = ("- [Radar bias fields (paper 001)](biasfield/report.md): plots to "
              "uncertainty sets, the smoothest field with and without the box, "
              "fig. 4 maps, the parametric baseline")


def _npz_name(path: Path) -> Path:
    """The file ``np.savez_compressed(path)`` writes (it appends ``.npz`` if missing)."""
    return path if path.name.endswith(".npz") else path.with_name(path.name + ".npz")


def _biasfield_build(args: argparse.Namespace) -> Outcome:
    import warnings

    from optmodels import biasfield as bf

    out = _out_file("--out", _npz_name(Path(args.out)))
    with _reading(str(args.radars)):
        radars, origin = bf.read_radars(args.radars)
    with _reading(str(args.plots)):
        plots, dropped = bf.read_plots(args.plots, radars, azimuth_unit=args.azimuth_unit,
                                       drop_out_of_range=args.drop_out_of_range)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fd, diag = bf.build_field_data(plots, radars, cells=args.cells,
                                       knot_spacing=args.knot_spacing)
    with _reading(f"--out {out}"):
        fd.save(out)
    chk = bf.residual_check(diag.fits, radars.m)
    return {"out": str(out), "cells": fd.k, "radars": list(radars.names),
            "plots": len(plots), "dropped_plots": {**dropped, **diag.dropped_plots},
            "dropped_cells": diag.dropped_cells, "warnings": [str(w.message) for w in caught],
            "track_chi2_per_dof": (chk.chi2 / np.maximum(chk.dof, 1)).tolist(),
            "origin": origin}, True


def _print_biasfield_build(res: dict[str, Any]) -> None:
    print(f"wrote {res['out']}: {res['cells']} cells, radars {', '.join(res['radars'])}, "
          f"{res['plots']} plots; dropped plots {res['dropped_plots'] or 'none'}, "
          f"dropped cells {res['dropped_cells']}")
    print("track model χ²/dof per radar: "
          + ", ".join(f"{v:.3f}" for v in res["track_chi2_per_dof"]))


def _parse_box(text: str) -> tuple[float, float]:
    """``--box K1,K2``: metres and degrees, both positive -> (K1 m, K2 rad)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise ProblemError(f"--box: expected K1,K2 (metres, degrees), got {text!r}")
    try:
        k1, k2 = (float(v) for v in parts)
    except ValueError:
        raise ProblemError(f"--box: expected K1,K2 (metres, degrees), got {text!r}") from None
    k1 = as_positive("--box K1 (m)", k1)
    k2 = as_positive("--box K2 (deg)", k2)
    return k1, float(np.deg2rad(k2))


def _biasfield_solve(args: argparse.Namespace) -> Outcome:
    from optmodels import biasfield as bf
    from optmodels import plots as plt_

    box = _parse_box(args.box) if args.box else None
    if args.lipschitz and args.solver == "closed-form":
        raise ProblemError("--solver closed-form: the Lipschitz problem (--lipschitz) has no "
                           "closed form; choose a CVXPY conic solver (CLARABEL, SCS, ...)")
    if args.solver == "closed-form" and box is not None:
        raise ProblemError("--box: the closed form (11) has no box; choose a --solver")
    out = _out_dir("--out", args.out)
    with _reading(str(args.file)):
        fd = bf.FieldData.load(args.file)
    if args.lipschitz:
        sol = bf.solve_lipschitz(fd, box=box, solver=args.solver)
    elif args.solver == "closed-form":
        sol = bf.closed_form(fd)
    else:
        sol = bf.solve(fd, box=box, solver=args.solver, formulation=args.formulation)
    res: dict[str, Any] = {"status": sol.status.value, "method": sol.method,
                           "message": sol.message, "objective": sol.objective,
                           "lipschitz": sol.lipschitz, "residuals": sol.residuals,
                           "cells": fd.k, "out": str(out)}
    if sol.status.ok:
        with _reading(f"--out {out}"):
            np.savez_compressed(out / "field.npz", field=sol.field, eta=sol.eta,
                                centers=fd.centers, radars=fd.radars, active=sol.active)
            with (out / "field.csv").open("w", encoding="utf-8") as fh:
                fh.write("cell,x,y,radar,range_bias_m,azimuth_bias_deg,active_range,"
                         "active_azimuth\n")
                for k in range(fd.k):
                    for i in range(fd.m):
                        f = sol.field[k, i]
                        fh.write(f"{k},{fd.centers[k, 0]!r},{fd.centers[k, 1]!r},{i},"
                                 f"{float(f[0])!r},{float(np.rad2deg(f[1]))!r},"
                                 f"{int(sol.active[k, i, 0])},{int(sol.active[k, i, 1])}\n")
        for comp, name in ((1, "azimuth"), (0, "range")):
            plt_.bias_maps(out / f"{name}_map.png", fd.centers, {"estimate": sol.field},
                           fd.radars, component=comp)
        res["active_bounds"] = int(np.sum(sol.active != 0))
        res["files"] = ["field.csv", "field.npz", "azimuth_map.png", "range_map.png"]
    return res, sol.status.ok


def _print_biasfield_solve(res: dict[str, Any]) -> None:
    print(f"{res['method']}: {res['status']} ({res['message']})")
    if res["status"] in _OK_STATUSES:
        lip = f", L = {res['lipschitz']:.4g}" if res["lipschitz"] is not None else ""
        print(f"J = {res['objective']:.6g}{lip}, {res.get('active_bounds', 0)} active bounds; "
              f"wrote {', '.join(res['files'])} to {res['out']}")


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the radar-network example of paper 001 in ``out/biasfield``
    (it shows no progress bar)."""
    from optmodels.demo import run_biasfield_demo

    return run_biasfield_demo(out / "biasfield", seed=args.seed)


def run_details(out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int,
                progress: bool) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: :mod:`solvers_cmp.biasfield`'s rows; the report
    section and the result entry."""
    from solvers_cmp import biasfield as cmp_bf

    rows = cmp_bf.rows(seed=seed, repeats=1, progress=progress)
    md = cmp_bf.write_report(out, rows)
    return md, {"results": rows}


def register(sub: Any) -> None:
    """Add ``optmodels biasfield build`` and ``solve`` to the top-level sub-commands
    ``sub``."""
    positive = _positive()
    bfp = sub.add_parser("biasfield", help="radar bias fields (paper 001)")
    bsub = bfp.add_subparsers(dest="verb", required=True)
    bb = _leaf(bsub, "build", "plots -> FieldData .npz (track fits, cells, averaging)")
    bb.add_argument("plots", type=Path, help="CSV/Parquet: time,radar,range,azimuth[,object]")
    bb.add_argument("--radars", type=Path, required=True,
                    help="CSV: name,x,y|lat,lon[,alt],sigma_range,sigma_azimuth(deg),max_range")
    bb.add_argument("--cells", type=_count(2), default=200, help="number of k-means cells")
    bb.add_argument("--knot-spacing", type=positive, default=20.0, help="polyline knots, s")
    bb.add_argument("--azimuth-unit", choices=("deg", "rad"), default="deg")
    bb.add_argument("--drop-out-of-range", action="store_true")
    bb.add_argument("--out", type=Path, default=Path("fielddata.npz"))
    bb.set_defaults(func=_biasfield_build, printer=_print_biasfield_build)
    bs = _leaf(bsub, "solve", "the smoothest field on a FieldData .npz")
    bs.add_argument("file", type=Path)
    bs.add_argument("--box", help="K1,K2: |range bias| ≤ K1 m, |azimuth bias| ≤ K2 deg (8)")
    bs.add_argument("--solver", default="CLARABEL",
                    help="closed-form, or a CVXPY solver (CLARABEL, OSQP, SCS, ...)")
    bs.add_argument("--formulation", choices=("reduced", "constrained"), default="reduced")
    bs.add_argument("--lipschitz", action="store_true",
                    help="smallest Lipschitz constant instead of the quadratic criterion")
    bs.add_argument("--out", default="biasfield_out", help="folder for field.csv/.npz, maps")
    bs.set_defaults(func=_biasfield_solve, printer=_print_biasfield_solve)
