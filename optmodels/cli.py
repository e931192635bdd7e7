"""Command line: ``optmodels <problem> <verb> ... [--json]``, ``optmodels demo``,
``optmodels compare``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from optmodels import fusion, plane, trajectories
from optmodels.core import OptModelsError, ProblemError
from optmodels.io import json_default

PROBLEMS = ("plane", "trajectories", "fusion", "biasfield", "assignment")


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


def _plane_fit(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels.io import read_plane_csv

    cols = read_plane_csv(args.file)
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
        "normal": sol.normal.tolist(),
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
    return out


def _print_plane_fit(res: dict[str, Any]) -> None:
    n = res["normal"]
    print(f"{res['file']}: N = {res['n_points']}, {res['method']} -> {res['status']}")
    print(f"  normal  = ({n[0]:.9f}, {n[1]:.9f}, {n[2]:.9f})")
    print(f"  offset  = {res['offset']:.6f} m")
    print(f"  objective (1.2) = {res['objective']:.6g}; max residual (1.3) = "
          f"{max(res['residuals'].values()):.1e}")
    t = res.get("planarity_test")
    if t:
        verdict = "planar" if t["planar"] else "NOT planar"
        print(f"  χ² test: Λ = {t['statistic']:.6g}, dof = {t['dof']}, threshold "
              f"{t['threshold']:.6g} at level {t['level']} -> {verdict} (p = {t['p_value']:.3g})")
        pv = "planar" if t["paper_planar"] else "NOT planar"
        print(f"  paper (1.17): √(2Λ) = {t['paper_statistic']:.4f} vs √(2N)+2 = "
              f"{t['paper_threshold']:.4f} -> {pv}")


def _trajectories_fit(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels.io import read_trajectory_csv

    cols = read_trajectory_csv(args.file)
    labels = cols["objects"]
    if cols["sigma2"] is not None:
        if args.sigma2 is not None:
            raise ProblemError("--sigma2: the file has a sigma2 column already")
        sigma2: Any = cols["sigma2"]
    else:
        sigma2 = 1.0 if args.sigma2 is None else args.sigma2
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
            q, shared_start=groups(args.shared_start, "--shared-start"),
            shared_velocity=groups(args.shared_velocity, "--shared-velocity"))
    else:
        if args.shared_start or args.shared_velocity:
            raise ProblemError("--shared-start/--shared-velocity need --family custom")
        family = args.family
    if args.method == "closed-form":
        sol = trajectories.closed_form(data, family)
    else:
        sol = trajectories.solve(data, family, formulation=args.formulation, solver=args.method)
    fam = sol.family
    assert fam is not None
    std = sol.std
    out: dict[str, Any] = {
        "file": str(args.file), "objects": labels, "coordinates": cols["coordinates"],
        "n_measurements": data.counts.tolist(), "family": fam.name,
        "start_groups": [[labels[i] for i in g] for g in fam.start_groups],
        "velocity_groups": [[labels[i] for i in g] for g in fam.velocity_groups],
        "epoch": args.epoch, "status": sol.status.value, "method": sol.method,
        "theta": sol.theta, "theta_std": std, "covariance": sol.covariance,
        "start": {lab: sol.start[k] for k, lab in enumerate(labels)},
        "velocity": {lab: sol.velocity[k] for k, lab in enumerate(labels)},
        "objective": sol.objective, "dof": sol.dof,
        "fit_p_value": float(stats.chi2.sf(sol.objective, sol.dof)) if sol.dof > 0 else None,
        "residuals": sol.residuals, "build_time": sol.build_time,
        "solve_time": sol.solve_time, "iterations": sol.iterations, "message": sol.message,
    }
    if sol.ok and fam.n_constraints > 0:
        out["family_test"] = trajectories.family_test(
            data, fam, level=args.level,
            sigma2="estimated" if args.sigma2_unknown else "known").to_dict()
    return out


def _print_trajectories_fit(res: dict[str, Any]) -> None:
    print(f"{res['file']}: Q = {len(res['objects'])}, N = {res['n_measurements']}, "
          f"family {res['family']}, {res['method']} -> {res['status']}")
    for lab in res["objects"]:
        print(f"  {lab}: start = {np.round(res['start'][lab], 6)}, "
              f"velocity = {np.round(res['velocity'][lab], 6)}")
    print(f"  θ std = {np.round(res['theta_std'], 6).tolist()}")
    pv = res["fit_p_value"]
    print(f"  χ² = {res['objective']:.6g} on {res['dof']} dof"
          + (f" (p = {pv:.3g})" if pv is not None else ""))
    t = res.get("family_test")
    if t:
        verdict = "REJECTED" if t["reject"] else "not rejected"
        print(f"  vs independent lines: statistic {t['statistic']:.4g}, dof {t['dof']}, "
              f"p = {t['p_value']:.3g} -> {res['family']} {verdict} at level {t['level']}")


def _matrix_arg(flag: str, text: str) -> np.ndarray:
    """A matrix given inline as JSON (``'[[1,0],[0,2]]'``) or as a path to .npy/.json."""
    path = Path(text)
    try:
        if path.suffix == ".npy" and path.is_file():
            return np.asarray(np.load(path), dtype=float)
        if path.suffix == ".json" and path.is_file():
            return np.asarray(json.loads(path.read_text()), dtype=float)
        return np.asarray(json.loads(text), dtype=float)
    except (ValueError, TypeError, OSError) as exc:
        raise ProblemError(f"{flag}: expected a JSON matrix like '[[1,0],[0,2]]' or a path "
                           f"to an existing .npy/.json file, got {text!r} ({exc})") from exc


def _fusion_weights(args: argparse.Namespace) -> dict[str, Any]:
    s1, s2 = _matrix_arg("--s1", args.s1), _matrix_arg("--s2", args.s2)
    n1 = args.n1 if args.n1 is not None else args.n
    n2 = args.n2 if args.n2 is not None else args.n
    if n1 is None or n2 is None:
        raise ProblemError("--n: give the sample size (or --n1 and --n2)")
    try:
        w = fusion.weight_matrix(s1, s2)
    except ProblemError as exc:  # name the command-line flag, not the Python argument
        msg = str(exc)
        flag = "--s2" if msg.startswith("S2") else "--s1"
        raise ProblemError(f"{flag}: {msg}") from None
    m = w.shape[0]
    try:
        s12 = _matrix_arg("--s12", args.s12) if args.s12 else None
        cov = fusion.weight_covariance(s1, s2, n1, n2, mean=args.mean, s12=s12)
    except ProblemError as exc:  # n1/n2 -> the flag the user typed
        msg = str(exc)
        if msg.startswith("s12"):
            raise ProblemError(f"--s12: {msg}") from None
        which = "n2" if msg.startswith("n2") else "n1"
        flag = f"--{which}" if getattr(args, which) is not None else "--n"
        raise ProblemError(f"{flag}: {msg}") from None
    p1, p2 = fusion.weight_jacobians(s1, s2)
    return {"W": w, "P1": p1, "P2": p2, "cov_vec_W": cov,
            "std_W": np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(m, m, order="F"),
            "n1": n1, "n2": n2, "mean": args.mean, "shared_snapshots": args.s12 is not None,
            "note": "vec stacks columns (12); Cov(vec W) is the first-order (10), "
                    "accurate to a few per cent from n ~ 100 (docs/errata.md)"}


def _print_fusion_weights(res: dict[str, Any]) -> None:
    with np.printoptions(precision=6, suppress=False, linewidth=120):
        for key in ("W", "std_W", "P1", "P2", "cov_vec_W"):
            print(f"{key} =\n{res[key]}")
    print(f"n1 = {res['n1']}, n2 = {res['n2']}, mean = {res['mean']}; {res['note']}")


def _biasfield_build(args: argparse.Namespace) -> dict[str, Any]:
    import warnings

    from optmodels import biasfield as bf

    radars, origin = bf.read_radars(args.radars)
    plots, dropped = bf.read_plots(args.plots, radars, azimuth_unit=args.azimuth_unit,
                                   drop_out_of_range=args.drop_out_of_range)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fd, diag = bf.build_field_data(plots, radars, cells=args.cells,
                                       knot_spacing=args.knot_spacing)
    fd.save(args.out)
    chk = bf.residual_check(diag.fits, radars.m)
    return {"out": str(args.out), "cells": fd.k, "radars": list(radars.names),
            "plots": len(plots), "dropped_plots": {**dropped, **diag.dropped_plots},
            "dropped_cells": diag.dropped_cells, "warnings": [str(w.message) for w in caught],
            "track_chi2_per_dof": (chk.chi2 / np.maximum(chk.dof, 1)).tolist(),
            "origin": origin}


def _print_biasfield_build(res: dict[str, Any]) -> None:
    print(f"wrote {res['out']}: {res['cells']} cells, radars {', '.join(res['radars'])}, "
          f"{res['plots']} plots; dropped plots {res['dropped_plots'] or 'none'}, "
          f"dropped cells {res['dropped_cells']}")
    print("track model χ²/dof per radar: "
          + ", ".join(f"{v:.3f}" for v in res["track_chi2_per_dof"]))


def _biasfield_solve(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels import biasfield as bf
    from optmodels import plots as plt_

    fd = bf.FieldData.load(args.file)
    box = None
    if args.box:
        try:
            k1, k2 = (float(v) for v in args.box.split(","))
        except ValueError as exc:
            raise ProblemError(f"--box: expected K1,K2 (metres, degrees), got {args.box!r}"
                               ) from exc
        box = (k1, float(np.deg2rad(k2)))
    if args.lipschitz:
        sol = bf.solve_lipschitz(fd, box=box, solver=args.solver)
    elif args.solver == "closed-form":
        if box is not None:
            raise ProblemError("--box: the closed form (11) has no box; choose a --solver")
        sol = bf.closed_form(fd)
    else:
        sol = bf.solve(fd, box=box, solver=args.solver, formulation=args.formulation)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res: dict[str, Any] = {"status": sol.status.value, "method": sol.method,
                           "message": sol.message, "objective": sol.objective,
                           "lipschitz": sol.lipschitz, "residuals": sol.residuals,
                           "cells": fd.k, "out": str(out)}
    if sol.status.ok:
        np.savez_compressed(out / "field.npz", field=sol.field, eta=sol.eta,
                            centers=fd.centers, radars=fd.radars, active=sol.active)
        with (out / "field.csv").open("w") as fh:
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
    return res


def _print_biasfield_solve(res: dict[str, Any]) -> None:
    print(f"{res['method']}: {res['status']} ({res['message']})")
    if res["status"] in ("optimal", "optimal_inaccurate"):
        lip = f", L = {res['lipschitz']:.4g}" if res["lipschitz"] is not None else ""
        print(f"J = {res['objective']:.6g}{lip}, {res.get('active_bounds', 0)} active bounds; "
              f"wrote {', '.join(res['files'])} to {res['out']}")


def _assignment_solve(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels import assignment as asg

    path = Path(args.case)
    if not path.is_file():
        raise ProblemError(f"{path}: no such file")
    try:
        case = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{path}: not valid JSON ({exc})") from None
    fields = ("means", "covs", "measurements", "meas_cov", "volume", "pd", "rho",
              "max_group_size", "group_gate")
    unknown = sorted(set(case) - set(fields))
    if unknown:
        raise ProblemError(f"{path}: unknown fields {unknown} (expected {fields})")
    missing = sorted(set(fields[:7]) - set(case))
    if missing:
        raise ProblemError(f"{path}: missing fields {missing}")
    data = asg.AssignmentData(**case)
    if args.method == "milp":
        sol = asg.solve(data, solver=args.solver, time_limit=args.time_limit)
    elif args.method == "brute-force":
        if asg.count_hypotheses(data.q, data.n) > 10_000_000:
            raise ProblemError("--method brute-force: more than 10⁷ hypotheses; use milp")
        sol = asg.brute_force(data)
    else:
        sol = asg.linear_assignment(data)
    res: dict[str, Any] = {"status": sol.status.value, "method": sol.method,
                           "message": sol.message, "partition": sol.partition,
                           "assignment": sol.assignment, "log_score": sol.log_score,
                           "mip_gap": sol.mip_gap, "solve_time": sol.solve_time,
                           "build_time": sol.build_time,
                           "hypotheses_total": asg.count_hypotheses(data.q, data.n)}
    if args.k:
        kb = asg.k_best(data, args.k, solver=args.solver)
        res["k_best"] = [{"partition": h.partition, "assignment": h.assignment,
                          "log_score": h.log_score} for h in kb.hypotheses]
        res["marginals"] = [{("background" if not k else ",".join(map(str, k))): v
                             for k, v in b.items()} for b in kb.beta]
        res["neglected_mass_bound"] = kb.neglected
    return res


def _print_assignment_solve(res: dict[str, Any]) -> None:
    print(f"{res['method']}: {res['status']} ({res['message']}); log score "
          f"{res['log_score']:.6f}; {res['hypotheses_total']} hypotheses in total")
    blocks = ["+".join(map(str, b)) for b in res["partition"]]
    print("blocks: " + ", ".join(blocks))
    for i, a in enumerate(res["assignment"]):
        print(f"  measurement {i}: {'background' if a < 0 else blocks[a]}")
    if "k_best" in res:
        print(f"{len(res['k_best'])} best hypotheses; neglected mass ≤ "
              f"{res['neglected_mass_bound']:.3g} of the listed")


def _assignment_count(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels import assignment as asg

    per = asg.count_per_variant(args.q, args.n)
    return {"q": args.q, "n": args.n, "total": asg.count_hypotheses(args.q, args.n),
            "variants": sum(v[0] for v in per.values()),
            "per_blocks": {b: {"variants": v[0], "hypotheses_each": v[1]}
                           for b, v in per.items()}}


def _print_assignment_count(res: dict[str, Any]) -> None:
    print(f"Q = {res['q']} objects, N = {res['n']} measurements: {res['variants']} unresolved "
          f"variants, {res['total']} hypotheses")
    for b, v in res["per_blocks"].items():
        print(f"  {b} blocks: {v['variants']} variants × {v['hypotheses_each']} hypotheses")


def _demo(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels.demo import (
        run_assignment_demo,
        run_biasfield_demo,
        run_fusion_demo,
        run_plane_demo,
        run_trajectories_demo,
    )

    out = Path(args.out)
    problems = [args.problem] if args.problem else list(PROBLEMS)
    t0 = time.perf_counter()
    result: dict[str, Any] = {"out": str(out), "problems": {}}
    sections = []
    for p in problems:
        if p == "plane":
            summ = run_plane_demo(out / "plane", runs=args.runs, seed=args.seed,
                                  progress=not args.json)
            result["problems"]["plane"] = summ
            sections.append("- [Plane of maneuver (paper 000)](plane/report.md): figures 1-4,"
                            " Monte Carlo vs the Cramér–Rao bound")
        elif p == "trajectories":
            summ = run_trajectories_demo(out / "trajectories", runs=args.trajectory_runs,
                                         seed=args.seed, progress=not args.json)
            result["problems"]["trajectories"] = summ
            sections.append("- [Dependent linear trajectories (paper 002)]"
                            "(trajectories/report.md): launcher and parallel scenarios, "
                            "η against Monte Carlo")
        elif p == "fusion":
            summ = run_fusion_demo(out / "fusion", trials=args.fusion_trials,
                                   positions=args.fusion_positions, seed=args.seed,
                                   progress=not args.json)
            result["problems"]["fusion"] = summ
            sections.append("- [Fusion of two estimates (paper 003)](fusion/report.md): "
                            "accuracy of Ŵ vs n, the two-site system with the joint ML")
        elif p == "assignment":
            summ = run_assignment_demo(out / "assignment", seed=args.seed,
                                       progress=not args.json)
            result["problems"]["assignment"] = summ
            sections.append("- [Joint assignment with unresolved groups (paper 004)]"
                            "(assignment/report.md): MAP by one MILP vs resolved-only "
                            "association, closely spaced space objects")
        elif p == "biasfield":
            summ = run_biasfield_demo(out / "biasfield", seed=args.seed)
            result["problems"]["biasfield"] = summ
            sections.append("- [Radar bias fields (paper 001)](biasfield/report.md): plots to "
                            "uncertainty sets, the smoothest field with and without the box, "
                            "fig. 4 maps, the parametric baseline")
    if not args.problem and not args.no_compare:
        cmp_res = _run_harness(out / "compare", PROBLEMS, sizes=args.sizes, solvers=None,
                               profile="default", seed=args.seed,
                               time_limit=args.time_limit, quick=args.sizes is None,
                               progress=not args.json)
        result["compare"] = cmp_res
        sections.append("- [Solver and formulation comparison](compare/report.md): every "
                        "problem's original form on every installed solver against the "
                        "closed form (success, time, scaling plots)")
    result["seconds"] = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    (out / "index.md").write_text(
        "# optmodels report\n\n" + "\n".join(sections)
        + f"\n\nGenerated by `optmodels demo` in {result['seconds']:.0f} s.\n"
    )
    return result


def _run_harness(out: Path, problems: Sequence[str], *, sizes: list[int] | None,
                 solvers: list[str] | None, profile: str, seed: int,
                 time_limit: float | None, quick: bool = False, progress: bool,
                 instances: list[str] | None = None) -> dict[str, Any]:
    """The comparison harness (:mod:`solvers_cmp.harness`) and its report.

    ``quick``: the main job's sweep -- each problem's two smallest default sizes."""
    from optmodels.backends.casadi_backend import probe_nlp_plugins
    from optmodels.backends.casadi_qp import probe_plugins
    from optmodels.io import write_json
    from solvers_cmp import cases as cs
    from solvers_cmp import harness, report

    for p in problems:
        if p not in cs.REGISTRY:
            raise ProblemError(f"--problems: unknown problem {p!r} (known: "
                               f"{', '.join(cs.REGISTRY)})")
    out.mkdir(parents=True, exist_ok=True)
    env = report.environment()
    write_json(out / "environment.json", env)
    plan_sizes: harness.Sizes = sizes
    if sizes is None and quick:
        plan_sizes = {p: list(cs.adapter(p).sizes[:2]) for p in problems}
    rows = harness.run_sweep(problems, out, sizes=plan_sizes, solvers=solvers,
                             profile=profile, seeds=(seed,), time_limit=time_limit,
                             instances=instances, progress=progress)
    prof = harness.PROFILES[profile]
    limit = float(time_limit or prof.time_limit)
    notes = {f"CasADi conic {k}": v for k, v in probe_plugins().items() if v != "ok"}
    notes |= {f"CasADi nlpsol {k}": v for k, v in probe_nlp_plugins().items() if v != "ok"}
    report.write_harness_report(out, rows, profile=profile, time_limit=limit,
                                error_tol=prof.error_tol, violation_tol=prof.violation_tol,
                                notes=notes, env=env)
    return {"out": str(out), "runs": len(rows),
            "successes": sum(bool(r["success"]) for r in rows),
            "failures": [{k: r[k] for k in ("problem", "instance", "size", "formulation",
                                            "solver", "status", "reason")}
                         for r in rows if not r["success"]]}


def _run_compare(out: Path, problems: Sequence[str], sizes: list[int], runs: int,
                 repeats: int, seed: int, progress: bool) -> dict[str, Any]:
    """The per-problem studies (``optmodels compare --details``): plane Monte Carlo
    accuracy, benchmarks at the issues' target sizes, problem-specific tables."""
    from optmodels.io import write_json
    from solvers_cmp import plane as cmp_plane
    from solvers_cmp import report

    out.mkdir(parents=True, exist_ok=True)
    md = ["# Solver and formulation comparison\n"]
    res: dict[str, Any] = {"out": str(out)}
    env = report.environment()
    write_json(out / "environment.json", env)
    for p in problems:
        if p == "plane":
            timing = cmp_plane.timing_rows(sizes, seed=seed, repeats=repeats, progress=progress)
            acc = cmp_plane.accuracy_rows(sizes, runs=runs, seed=seed, progress=progress)
            bench = cmp_plane.benchmark(max(sizes), repeats=repeats, seed=seed)
            md.append(report.write_plane(out, timing, acc, bench))
            res["plane"] = {"timing": timing, "accuracy": acc, "benchmark": bench}
        elif p == "trajectories":
            from solvers_cmp import trajectories as cmp_traj

            rows = cmp_traj.rows(seed=seed, repeats=max(1, min(repeats, 3)), progress=progress)
            bench = cmp_traj.benchmark(repeats=repeats, seed=seed)
            md.append(report.write_trajectories(out, rows, bench))
            res["trajectories"] = {"results": rows, "benchmark": bench}
        elif p == "fusion":
            from solvers_cmp import fusion as cmp_fusion

            rows = cmp_fusion.rows(seed=seed, repeats=max(1, min(repeats, 3)),
                                   progress=progress)
            bench = cmp_fusion.benchmark(repeats=repeats, seed=seed)
            md.append(report.write_fusion(out, rows, bench))
            res["fusion"] = {"results": rows, "benchmark": bench}
        elif p == "assignment":
            from solvers_cmp import assignment as cmp_as

            rows = cmp_as.rows(seed=seed, repeats=max(1, min(repeats, 3)), progress=progress)
            md.append(report.write_assignment(out, rows))
            res["assignment"] = {"results": rows}
        elif p == "biasfield":
            from solvers_cmp import biasfield as cmp_bf

            rows = cmp_bf.rows(seed=seed, repeats=1, progress=progress)
            md.append(report.write_biasfield(out, rows))
            res["biasfield"] = {"results": rows}
        else:
            raise ProblemError(f"--problems: unknown problem {p!r} (known: {PROBLEMS})")
    md.append(f"\nMachine: {env['cpu']}, {env['cores']} cores; Python {env['python']}.\n")
    (out / "report.md").write_text("\n".join(md))
    return res


def _compare(args: argparse.Namespace) -> dict[str, Any]:
    problems = [p.strip() for p in args.problems.split(",") if p.strip()]
    solvers = [x.strip() for x in args.solvers.split(",") if x.strip()] if args.solvers \
        else None
    instances = [x.strip() for x in args.instances.split(",") if x.strip()] \
        if args.instances else None
    if args.details:
        return _run_compare(Path(args.out), problems, args.sizes or [100, 1000, 10000],
                            args.runs, args.repeats, args.seed, progress=not args.json)
    return _run_harness(Path(args.out), problems, sizes=args.sizes, solvers=solvers,
                        profile=args.profile, seed=args.seed, time_limit=args.time_limit,
                        instances=instances, progress=not args.json)


def _montecarlo(args: argparse.Namespace) -> dict[str, Any]:
    from optmodels import montecarlo as mc
    from optmodels.io import write_json

    params: dict[str, Any] = {}
    for item in args.param or []:
        key, sep, val = item.partition("=")
        if not sep or not key:
            raise ProblemError(f"--param: expected NAME=VALUE, got {item!r}")
        try:
            params[key] = json.loads(val)
        except json.JSONDecodeError:
            params[key] = val
    try:
        study = mc.study(args.study, **params)
    except TypeError as exc:
        raise ProblemError(f"--param: {exc}") from exc
    res = mc.run(study, args.trials, args.seed, scheduler=args.scheduler,
                 checkpoint=args.checkpoint, workers=args.workers, progress=not args.json)
    out = {"study": res.study, "seed": res.seed, "trials": int(res.trials.size),
           "resumed": res.resumed, "engine": res.engine, "summary": res.summary,
           "means": {k: res.mean(k) for k in res.values},
           "standard_errors": {k: res.se(k) for k in res.values} if res.trials.size > 1
           else {}}
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        write_json(Path(args.out), {**out, "values": res.values})
    return out


def _print_montecarlo(res: dict[str, Any]) -> None:
    print(f"{res['study']}: {res['trials']} trials (seed {res['seed']}, {res['resumed']} "
          f"from the checkpoint), engine {res['engine']}")
    for k, v in res["summary"].items():
        print(f"  {k:>22s} = {v:.6g}")
    for k, v in res["means"].items():
        se = res["standard_errors"].get(k)
        print(f"  mean {k:>17s} = {v:.6g}" + (f" ± {se:.2g}" if se is not None else ""))


def _int_list(text: str) -> list[int]:
    try:
        vals = [int(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected integers like 100,1000 ({exc})") from exc
    if not vals or min(vals) < 1:
        raise argparse.ArgumentTypeError("sizes must be positive integers")
    return vals


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="optmodels", description=__doc__)
    sub = ap.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the papers' examples and write a report")
    demo.add_argument("problem", nargs="?", choices=PROBLEMS,
                      help="one problem only (default: all, plus the comparison)")
    demo.add_argument("--out", default="report", help="output folder (default: report)")
    demo.add_argument("--runs", type=int, default=200, help="Monte Carlo runs of the example")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--trajectory-runs", type=int, default=4000,
                      help="Monte Carlo draws per (Q, N) of the trajectories η table")
    demo.add_argument("--fusion-trials", type=int, default=100_000,
                      help="Monte Carlo draws of Ŵ per (case, estimator, n) in the fusion demo")
    demo.add_argument("--fusion-positions", type=int, default=40,
                      help="emitter positions of the fusion demo's two-site study")
    demo.add_argument("--no-compare", action="store_true", help="skip the comparison")
    demo.add_argument("--sizes", type=_int_list, default=None,
                      help="comparison sizes for every problem (default: each problem's "
                           "two smallest default sizes)")
    demo.add_argument("--time-limit", type=float, default=5.0,
                      help="comparison time limit per run, s (default 5)")
    demo.add_argument("--json", action="store_true", help="machine-readable output")
    demo.set_defaults(func=_demo)

    cmp_ = sub.add_parser("compare", help="compare solvers and formulations (solvers_cmp)")
    cmp_.add_argument("--problems", default=",".join(PROBLEMS),
                      help="comma-separated (default: all)")
    cmp_.add_argument("--sizes", type=_int_list, default=None,
                      help="sizes for every problem (default: each problem's own; see "
                           "report.md for what size means per problem)")
    cmp_.add_argument("--solvers", help="comma-separated solver names (CLARABEL, OSQP, "
                                        "CASADI_QPOASES, ipopt, sqpmethod, HIGHS, ...); the "
                                        "closed form is always kept")
    cmp_.add_argument("--instances", help="comma-separated instance names (e.g. box,radar)")
    cmp_.add_argument("--profile", choices=("default", "high"), default="default")
    cmp_.add_argument("--time-limit", type=float, help="per run, s (default: the profile's)")
    cmp_.add_argument("--seed", type=int, default=0)
    cmp_.add_argument("--out", default="report/compare")
    cmp_.add_argument("--details", action="store_true",
                      help="run the per-problem studies instead (plane Monte Carlo accuracy, "
                           "benchmarks at the issues' target sizes)")
    cmp_.add_argument("--runs", type=int, default=200, help="--details: Monte Carlo runs")
    cmp_.add_argument("--repeats", type=int, default=5, help="--details: timing repeats")
    cmp_.add_argument("--json", action="store_true")
    cmp_.set_defaults(func=_compare)

    mcp = sub.add_parser("montecarlo", help="run a seeded Monte Carlo study (local or Dask)")
    mcp.add_argument("study", help="plane-angle, trajectories-eta, fusion-weight, "
                                   "biasfield-recovery, assignment-separation")
    mcp.add_argument("--trials", type=int, default=1000)
    mcp.add_argument("--seed", type=int, default=0)
    mcp.add_argument("--param", action="append", metavar="NAME=VALUE",
                     help="study parameter (repeatable), e.g. --param n=100")
    mcp.add_argument("--scheduler", default=None,
                     help="processes (default), serial, or a Dask address tcp://host:8786")
    mcp.add_argument("--workers", type=int, help="local processes (default: all cores)")
    mcp.add_argument("--checkpoint", help="JSON-lines file; a rerun resumes from it")
    mcp.add_argument("--out", help="write the per-trial values and summary to this JSON")
    mcp.add_argument("--json", action="store_true")
    mcp.set_defaults(func=_montecarlo, printer=_print_montecarlo)

    pl = sub.add_parser("plane", help="plane of maneuver (paper 000)")
    plsub = pl.add_subparsers(dest="verb", required=True)
    fit = plsub.add_parser("fit", help="fit the ML plane to a CSV of positions")
    fit.add_argument("file", type=Path, help="CSV with x,y,z [,t] [,alpha2] [,cxx..czz]")
    g = fit.add_mutually_exclusive_group()
    g.add_argument("--sigma2", type=float, help="error variance per axis, m² (D = σ² I)")
    g.add_argument("--cov", help="common D: cxx,cxy,cxz,cyy,cyz,czz (or 9 numbers)")
    fit.add_argument("--formulation", choices=("full", "reduced", "closed-form"),
                     default="full")
    fit.add_argument("--level", type=float, default=0.997, help="χ² test level")
    fit.add_argument("--json", action="store_true")
    fit.set_defaults(func=_plane_fit, printer=_print_plane_fit)

    trj = sub.add_parser("trajectories", help="dependent linear trajectories (paper 002)")
    tsub = trj.add_subparsers(dest="verb", required=True)
    tfit = tsub.add_parser("fit", help="fit a family of lines to a CSV of measurements")
    tfit.add_argument("file", type=Path,
                      help="CSV with object,t,y or object,t,x,y[,z] [,sigma2]")
    tfit.add_argument("--family", default="diverging",
                      choices=("diverging", "parallel", "independent", "custom"))
    tfit.add_argument("--shared-start", action="append", metavar="A,B,..",
                      help="custom family: objects sharing a start (repeatable)")
    tfit.add_argument("--shared-velocity", action="append", metavar="A,B,..",
                      help="custom family: objects sharing a velocity (repeatable)")
    tfit.add_argument("--sigma2", type=float, help="error variance (default 1)")
    tfit.add_argument("--sigma2-unknown", action="store_true",
                      help="family test with σ² estimated (F test) instead of known (χ²)")
    tfit.add_argument("--epoch", type=float, default=0.0,
                      help="time at which the start is defined (default 0)")
    tfit.add_argument("--method", default="closed-form",
                      help="closed-form (default) or a CVXPY solver: CLARABEL, OSQP, SCS, ...")
    tfit.add_argument("--formulation", choices=("constrained", "reduced"),
                      default="constrained", help="generic formulation (with --method SOLVER)")
    tfit.add_argument("--level", type=float, default=0.95, help="family test level")
    tfit.add_argument("--json", action="store_true")
    tfit.set_defaults(func=_trajectories_fit, printer=_print_trajectories_fit)

    fus = sub.add_parser("fusion", help="fusion of two estimates (paper 003)")
    fsub = fus.add_subparsers(dest="verb", required=True)
    fw = fsub.add_parser("weights", help="W, the Jacobians P1, P2 (13)-(14) and Cov(vec W) (10)")
    fw.add_argument("--s1", required=True,
                    help="error covariance of estimate 1: JSON '[[..],[..]]' or .npy/.json path")
    fw.add_argument("--s2", required=True, help="error covariance of estimate 2 (as --s1)")
    fw.add_argument("--n", type=int, help="snapshots behind both sample covariances")
    fw.add_argument("--n1", type=int, help="snapshots behind S1 (overrides --n)")
    fw.add_argument("--n2", type=int, help="snapshots behind S2 (overrides --n)")
    fw.add_argument("--mean", choices=("sample", "known"), default="sample",
                    help="sample covariances about the sample mean (default) or the known "
                         "mean (the paper's literal (3))")
    fw.add_argument("--s12", help="Cov(a1, a2) when both sample covariances come from the "
                                   "same snapshots of correlated estimators (adds the cross "
                                   "block to (10); needs n1 = n2)")
    fw.add_argument("--json", action="store_true")
    fw.set_defaults(func=_fusion_weights, printer=_print_fusion_weights)

    asp = sub.add_parser("assignment", help="joint assignment with merges (paper 004)")
    asub = asp.add_subparsers(dest="verb", required=True)
    aso = asub.add_parser("solve", help="the MAP hypothesis of a CASE.json")
    aso.add_argument("case", help="JSON with means, covs, measurements, meas_cov, volume, pd, "
                                  "rho [, max_group_size, group_gate]")
    aso.add_argument("--method", choices=("milp", "brute-force", "linear"), default="milp")
    aso.add_argument("--solver", default="HIGHS", help="MILP solver (HIGHS, SCIP, ...)")
    aso.add_argument("--time-limit", type=float, help="MILP time limit, s")
    aso.add_argument("--k", type=int, default=0, help="also list the k best and marginals")
    aso.add_argument("--json", action="store_true")
    aso.set_defaults(func=_assignment_solve, printer=_print_assignment_solve)
    aco = asub.add_parser("count", help="number of hypotheses (14) for Q objects, N marks")
    aco.add_argument("q", type=int)
    aco.add_argument("n", type=int)
    aco.add_argument("--json", action="store_true")
    aco.set_defaults(func=_assignment_count, printer=_print_assignment_count)

    bfp = sub.add_parser("biasfield", help="radar bias fields (paper 001)")
    bsub = bfp.add_subparsers(dest="verb", required=True)
    bb = bsub.add_parser("build", help="plots -> FieldData .npz (track fits, cells, averaging)")
    bb.add_argument("plots", type=Path, help="CSV/Parquet: time,radar,range,azimuth[,object]")
    bb.add_argument("--radars", type=Path, required=True,
                    help="CSV: name,x,y|lat,lon[,alt],sigma_range,sigma_azimuth(deg),max_range")
    bb.add_argument("--cells", type=int, default=200, help="number of k-means cells")
    bb.add_argument("--knot-spacing", type=float, default=20.0, help="polyline knots, s")
    bb.add_argument("--azimuth-unit", choices=("deg", "rad"), default="deg")
    bb.add_argument("--drop-out-of-range", action="store_true")
    bb.add_argument("--out", type=Path, default=Path("fielddata.npz"))
    bb.add_argument("--json", action="store_true")
    bb.set_defaults(func=_biasfield_build, printer=_print_biasfield_build)
    bs = bsub.add_parser("solve", help="the smoothest field on a FieldData .npz")
    bs.add_argument("file", type=Path)
    bs.add_argument("--box", help="K1,K2: |range bias| ≤ K1 m, |azimuth bias| ≤ K2 deg (8)")
    bs.add_argument("--solver", default="CLARABEL",
                    help="closed-form, or a CVXPY solver (CLARABEL, OSQP, SCS, ...)")
    bs.add_argument("--formulation", choices=("reduced", "constrained"), default="reduced")
    bs.add_argument("--lipschitz", action="store_true",
                    help="smallest Lipschitz constant instead of the quadratic criterion")
    bs.add_argument("--out", default="biasfield_out", help="folder for field.csv/.npz, maps")
    bs.add_argument("--json", action="store_true")
    bs.set_defaults(func=_biasfield_solve, printer=_print_biasfield_solve)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    try:
        result = args.func(args)
    except OptModelsError as exc:
        print(f"optmodels: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, default=json_default, indent=2))
    elif hasattr(args, "printer"):
        args.printer(result)
    elif args.command in ("demo", "compare"):
        name = "index.md" if args.command == "demo" else "report.md"
        print(f"wrote {Path(result['out']) / name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
