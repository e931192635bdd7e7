"""``optmodels trajectories fit``: a family of dependent lines of paper 002 (shared start,
shared velocity, or a custom grouping) fitted to a CSV of measurements, by the closed forms
(8)-(9), (12)-(13) or a CVXPY solver, with the family test against independent lines; and
the trajectories part of ``optmodels demo`` and ``optmodels compare --details``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Literal

import numpy as np

from optmodels.cli.args import _finite, _level, _positive
from optmodels.cli.contract import _OK_STATUSES, Outcome, _group, _leaf, _reading
from optmodels.core import ProblemError

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = (
    "- [Dependent linear trajectories (paper 002)]"
    "(trajectories/report.md): launcher and parallel scenarios, η "
    "against Monte Carlo"
)


def _trajectories_fit(args: argparse.Namespace) -> Outcome:
    from scipy import stats

    from optmodels import trajectories
    from optmodels.io import read_trajectory_csv

    if args.formulation is not None and args.method == "closed-form":
        raise ProblemError(
            f"--formulation {args.formulation}: the form of the generic problem solved by "
            "--method SOLVER (a CVXPY solver: CLARABEL, OSQP, SCS, ...); the closed form "
            "(--method closed-form, the default) has none: drop --formulation, or give "
            "--method CLARABEL"
        )
    with _reading(str(args.file)):
        cols = read_trajectory_csv(args.file)
        labels = cols["objects"]
        if cols["sigma2"] is not None:
            if args.sigma2 is not None:
                raise ProblemError("--sigma2: the file has a sigma2 column already")
            sigma2: Any = cols["sigma2"]
            source = "file"
        elif args.sigma2 is not None:
            sigma2, source = args.sigma2, "--sigma2"
        else:
            # no variance given: weights 1 and σ² estimated from the residuals below
            # (never a covariance silently computed with σ² = 1)
            sigma2, source = 1.0, "estimated"
        data = trajectories.TrajectoryData(cols["times"], cols["values"], sigma2, epoch=args.epoch)
    q = data.n_objects
    if args.family == "custom":
        index = {lab: k for k, lab in enumerate(labels)}

        def groups(specs: list[str] | None, flag: str) -> list[list[int]]:
            out = []
            for spec in specs or []:
                names = [x.strip() for x in spec.split(",") if x.strip()]
                unknown = [x for x in names if x not in index]
                if unknown:
                    raise ProblemError(f"{flag}: unknown object(s) {unknown} (have {labels})")
                out.append([index[x] for x in names])
            return out

        family: Any = trajectories.Family.custom(
            q,
            shared_start=groups(args.shared_start, "--shared-start"),
            shared_velocity=groups(args.shared_velocity, "--shared-velocity"),
        )
    else:
        if args.shared_start or args.shared_velocity:
            raise ProblemError("--shared-start/--shared-velocity need --family custom")
        family = args.family
    if args.method == "closed-form":
        sol = trajectories.closed_form(data, family)
    else:
        formulation: Literal["constrained", "reduced"] = args.formulation or "constrained"
        sol = trajectories.solve(data, family, formulation=formulation, solver=args.method)
    fam = sol.family
    if fam is None:  # every trajectories solution carries its family
        raise RuntimeError("trajectories: the solution carries no family")
    std = sol.std
    covariance = sol.covariance
    s2: float | None = None
    if source == "estimated" and sol.ok:
        if sol.dof <= 0:
            raise ProblemError(
                "--sigma2: no degrees of freedom left to estimate the error variance "
                "from the residuals; give --sigma2 (unit of y squared) or a sigma2 column"
            )
        s2 = float(sol.objective) / sol.dof  # unbiased σ² estimate RSS / (N - p)
        std, covariance = std * np.sqrt(s2), covariance * s2
    out: dict[str, Any] = {
        "file": str(args.file),
        "objects": labels,
        "coordinates": cols["coordinates"],
        "n_measurements": data.counts.tolist(),
        "family": fam.name,
        "start_groups": [[labels[i] for i in g] for g in fam.start_groups],
        "velocity_groups": [[labels[i] for i in g] for g in fam.velocity_groups],
        "epoch": args.epoch,
        "status": sol.status.value,
        "method": sol.method,
        "theta": sol.theta,
        "theta_std": std,
        "theta_labels": _theta_labels(fam, labels, cols["coordinates"]),
        "covariance": covariance,
        "sigma2_source": source,
        "sigma2_estimate": s2,
        "start": {lab: sol.start[k] for k, lab in enumerate(labels)},
        "velocity": {lab: sol.velocity[k] for k, lab in enumerate(labels)},
        "objective": sol.objective,
        "dof": sol.dof,
        "fit_p_value": float(stats.chi2.sf(sol.objective, sol.dof))
        if sol.dof > 0 and sol.ok and source != "estimated"
        else None,
        "residuals": sol.residuals,
        "build_time": sol.build_time,
        "solve_time": sol.solve_time,
        "iterations": sol.iterations,
        "message": sol.message,
    }
    if sol.ok and fam.n_constraints > 0:
        out["family_test"] = trajectories.family_test(
            data,
            fam,
            level=args.level,
            sigma2="estimated" if args.sigma2_unknown or source == "estimated" else "known",
        ).to_dict()
    return out, sol.ok


def _unit(coordinates: list[str]) -> str:
    """The unit of the measured values: the y column's, or the coordinates' (x, y[, z])."""
    return "unit of y" if list(coordinates) == ["y"] else f"unit of {', '.join(coordinates)}"


def _theta_labels(fam: Any, objects: list[str], coordinates: list[str]) -> list[dict[str, Any]]:
    """What each entry of θ is, in θ's order (one start per start group, then one velocity
    per velocity group, :class:`optmodels.trajectories.Family`): ``quantity`` (start or
    velocity), ``objects`` (the objects sharing it) and ``unit``."""
    unit = _unit(coordinates)
    return [
        {"quantity": quantity, "objects": [objects[i] for i in group], "unit": u}
        for quantity, groups, u in (
            ("start", fam.start_groups, unit),
            ("velocity", fam.velocity_groups, f"{unit} per s"),
        )
        for group in groups
    ]


def _print_theta(res: dict[str, Any]) -> None:
    """θ ± its standard deviation, one labelled line per entry (quantity, objects, unit)."""
    coords = res["coordinates"]
    theta = np.asarray(res["theta"], dtype=float).reshape(len(res["theta_labels"]), -1)
    std = np.asarray(res["theta_std"], dtype=float).reshape(theta.shape)
    print(f"  θ ± 1 std (θ = shared starts, then velocities; starts at t = {res['epoch']} s):")
    for lab, v, e in zip(res["theta_labels"], theta, std, strict=True):
        pairs = [f"{np.round(a, 6)} ± {b:.6g}" for a, b in zip(v, e, strict=True)]
        value = (
            pairs[0]
            if len(pairs) == 1
            else ", ".join(f"{c} = {p}" for c, p in zip(coords, pairs, strict=True))
        )
        sep = " = " if len(pairs) == 1 else ": "
        print(f"    {lab['quantity']} of {', '.join(lab['objects'])}{sep}{value} ({lab['unit']})")


def _print_trajectories_fit(res: dict[str, Any]) -> None:
    print(
        f"{res['file']}: Q = {len(res['objects'])}, N = {res['n_measurements']}, "
        f"family {res['family']}, {res['method']} -> {res['status']}"
    )
    if res["status"] not in _OK_STATUSES:
        print(f"  {res['message']}")
        return
    unit = _unit(res["coordinates"])
    print(f"  (start in the {unit} at t = {res['epoch']} s; velocity in {unit} per s)")
    for lab in res["objects"]:
        print(
            f"  {lab}: start = {np.round(res['start'][lab], 6)}, "
            f"velocity = {np.round(res['velocity'][lab], 6)}"
        )
    _print_theta(res)
    pv = res["fit_p_value"]
    if res["sigma2_source"] == "estimated":
        print(
            f"  σ² not given: estimated from the residuals, s² = {res['sigma2_estimate']:.6g} "
            f"({unit})² on {res['dof']} dof; θ std scaled by s (give --sigma2 if known)"
        )
    else:
        print(
            f"  χ² = {res['objective']:.6g} on {res['dof']} dof"
            + (f" (p = {pv:.3g})" if pv is not None else "")
        )
    t = res.get("family_test")
    if t:
        verdict = "REJECTED" if t["reject"] else "not rejected"
        print(
            f"  vs independent lines: statistic {t['statistic']:.4g}, dof {t['dof']}, "
            f"p = {t['p_value']:.3g} -> {res['family']} {verdict} at level {t['level']}"
        )


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the launcher and parallel scenarios of paper 002 and the η
    table in ``out/trajectories``."""
    from optmodels.demo import run_trajectories_demo

    return run_trajectories_demo(
        out / "trajectories", runs=args.trajectory_runs, seed=args.seed, progress=progress
    )


def run_details(
    out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int, progress: bool
) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: :mod:`solvers_cmp.trajectories`' rows and
    benchmark; the report section and the result entry."""
    from solvers_cmp import trajectories as cmp_traj

    rows = cmp_traj.rows(seed=seed, repeats=max(1, min(repeats, 3)), progress=progress)
    bench = cmp_traj.benchmark(repeats=repeats, seed=seed)
    md = cmp_traj.write_report(out, rows, bench)
    return md, {"results": rows, "benchmark": bench}


def register(sub: Any) -> None:
    """Add ``optmodels trajectories fit`` to the top-level sub-commands ``sub``."""
    positive = _positive()
    tsub = _group(sub, "trajectories", "dependent linear trajectories (paper 002)")
    tfit = _leaf(tsub, "fit", "fit a family of lines to a CSV of measurements")
    tfit.add_argument("file", type=Path, help="CSV with object,t,y or object,t,x,y[,z] [,sigma2]")
    tfit.add_argument(
        "--family",
        default="diverging",
        choices=("diverging", "parallel", "independent", "custom"),
        help="the family of lines: shared start (diverging), shared velocity "
        "(parallel), none, or --shared-start/--shared-velocity groups",
    )
    tfit.add_argument(
        "--shared-start",
        action="append",
        metavar="A,B,..",
        help="custom family: objects sharing a start (repeatable)",
    )
    tfit.add_argument(
        "--shared-velocity",
        action="append",
        metavar="A,B,..",
        help="custom family: objects sharing a velocity (repeatable)",
    )
    tfit.add_argument(
        "--sigma2",
        type=positive,
        help="error variance, (unit of y)²; when neither this nor a sigma2 column is given, σ² "
        "is estimated from the residuals (RSS/dof) and the F test is used",
    )
    tfit.add_argument(
        "--sigma2-unknown",
        action="store_true",
        help="family test with σ² estimated (F test) instead of known (χ²)",
    )
    tfit.add_argument(
        "--epoch", type=_finite(), default=0.0, help="time at which the start is defined, s"
    )
    tfit.add_argument(
        "--method",
        default="closed-form",
        help="closed-form (8)-(9)/(12)-(13), or a CVXPY solver: CLARABEL, OSQP, SCS, ...",
    )
    tfit.add_argument(
        "--formulation",
        choices=("constrained", "reduced"),
        help="the generic problem's form, with --method SOLVER only (default: "
        "constrained; refused with the closed form)",
    )
    tfit.add_argument("--level", type=_level(), default=0.95, help="family test level, in (0, 1)")
    tfit.set_defaults(func=_trajectories_fit, printer=_print_trajectories_fit)
