"""``optmodels plane fit``: the ML plane of maneuver (1.2)-(1.3) of paper 000 fitted to a
CSV of positions (IPOPT on the full or reduced (1.12) form, or the closed form
(1.5)-(1.8)) with the χ² planarity test; and the plane part of ``optmodels demo`` and
``optmodels compare --details``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from optmodels import plane
from optmodels.cli.args import _level, _positive
from optmodels.cli.contract import _OK_STATUSES, Outcome, _leaf, _reading
from optmodels.core import ProblemError

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = ("- [Plane of maneuver (paper 000)](plane/report.md): figures 1-4, Monte "
              "Carlo vs the Cramér–Rao bound")


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


def _plane_fit(args: argparse.Namespace) -> Outcome:
    from optmodels.io import read_plane_csv

    with _reading(str(args.file)):
        cols = read_plane_csv(args.file)
        if "cov" in cols:
            if args.sigma2 is not None or args.cov is not None:
                raise ProblemError("--sigma2/--cov: the file has per-point covariances "
                                   "already")
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
    if args.formulation == "closed-form":
        sol = plane.closed_form(data)
    else:
        sol = plane.solve(data, args.formulation)
    out: dict[str, Any] = {
        "file": str(args.file),
        "n_points": data.n_points,
        "formulation": args.formulation,
        "status": sol.status.value,
        "method": sol.method,
        "normal": np.asarray(sol.normal, dtype=float).tolist(),
        "offset": sol.offset,
        "objective": sol.objective,
        "residuals": sol.residuals,
        "build_time": sol.build_time,
        "solve_time": sol.solve_time,
        "iterations": sol.iterations,
        "message": sol.message,
    }
    if sol.ok and data.n_points >= 4:
        out["planarity_test"] = plane.planarity_test(data, sol, level=args.level).to_dict()
    return out, sol.ok


def _print_plane_fit(res: dict[str, Any]) -> None:
    n = res["normal"]
    print(f"{res['file']}: N = {res['n_points']}, {res['method']} -> {res['status']}")
    if res["status"] not in _OK_STATUSES:
        print(f"  {res['message']}")
        return
    print(f"  normal  = ({n[0]:.9f}, {n[1]:.9f}, {n[2]:.9f})")
    print(f"  offset  = {res['offset']:.6f} m")
    print(f"  objective (1.2) = {res['objective']:.6g}; max residual (1.3) = "
          f"{max(res['residuals'].values(), default=0.0):.1e}")
    t = res.get("planarity_test")
    if t:
        verdict = "planar" if t["planar"] else "NOT planar"
        print(f"  χ² test: Λ = {t['statistic']:.6g}, dof = {t['dof']}, threshold "
              f"{t['threshold']:.6g} at level {t['level']} -> {verdict} (p = {t['p_value']:.3g})")
        pv = "planar" if t["paper_planar"] else "NOT planar"
        print(f"  paper (1.17): √(2Λ) = {t['paper_statistic']:.4f} vs √(2N)+2 = "
              f"{t['paper_threshold']:.4f} -> {pv}")


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the example of paper 000 in ``out/plane``."""
    from optmodels.demo import run_plane_demo

    return run_plane_demo(out / "plane", runs=args.runs, seed=args.seed, progress=progress)


def run_details(out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int,
                progress: bool) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: timing and Monte Carlo accuracy per size and the
    benchmark (:mod:`solvers_cmp.plane`); the report section and the result entry."""
    from solvers_cmp import plane as cmp_plane

    timing = cmp_plane.timing_rows(sizes, seed=seed, repeats=repeats, progress=progress)
    acc = cmp_plane.accuracy_rows(sizes, runs=runs, seed=seed, progress=progress)
    bench = cmp_plane.benchmark(max(sizes), repeats=repeats, seed=seed)
    md = cmp_plane.write_report(out, timing, acc, bench)
    return md, {"timing": timing, "accuracy": acc, "benchmark": bench}


def register(sub: Any) -> None:
    """Add ``optmodels plane fit`` to the top-level sub-commands ``sub``."""
    positive = _positive()
    pl = sub.add_parser("plane", help="plane of maneuver (paper 000)")
    plsub = pl.add_subparsers(dest="verb", required=True)
    fit = _leaf(plsub, "fit", "fit the ML plane to a CSV of positions")
    fit.add_argument("file", type=Path, help="CSV with x,y,z [,t] [,alpha2] [,cxx..czz]")
    g = fit.add_mutually_exclusive_group()
    g.add_argument("--sigma2", type=positive, help="error variance per axis, m² (D = σ² I)")
    g.add_argument("--cov", help="common D, m²: cxx,cxy,cxz,cyy,cyz,czz (or 9 numbers)")
    fit.add_argument("--formulation", choices=("full", "reduced", "closed-form"),
                     default="full")
    fit.add_argument("--level", type=_level(), default=0.997,
                     help="χ² test level, in (0, 1)")
    fit.set_defaults(func=_plane_fit, printer=_print_plane_fit)
