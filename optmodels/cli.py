"""Command line: ``optmodels <problem> <verb> ... [--json]``, ``optmodels demo``,
``optmodels compare``, ``optmodels montecarlo``.

The contract (README, "Command line"):

- stdout carries only the result: the human text, or with ``--json`` exactly one JSON
  document (non-finite numbers written as ``null``). Everything else -- progress bars,
  warnings, solver banners printed from C (HiGHS) -- goes to stderr.
- Exit status: 0 solved (status OK: optimal or optimal_inaccurate); 1 finished but not
  OK (infeasible, unbounded, iteration/time limit, solver error, or for the multi-part
  commands a part that failed); 2 bad input or usage (a wrong flag value, an unreadable
  or malformed file, an unwritable output path, an unreachable scheduler, a solver that
  is not installed); 3 internal error (a bug: rerun with ``--debug`` for the traceback);
  130 interrupted (Ctrl-C).
- Every error is one line on stderr, ``optmodels: error: <message>``, never a traceback;
  with ``--json`` stdout then holds ``{"error": <message>, "exit_code": <code>}``.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import math
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from scipy import stats

from optmodels import fusion, plane, trajectories
from optmodels.core import (
    OptModelsError,
    ProblemError,
    SolveError,
    SolverNotAvailable,
    as_count,
    as_number,
    as_positive,
    as_probability,
)
from optmodels.io import json_default

PROBLEMS = ("plane", "trajectories", "fusion", "biasfield", "assignment")

#: Exit statuses (module docstring).
EXIT_OK, EXIT_NOT_OK, EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED = 0, 1, 2, 3, 130

#: What every handler returns: the result document and whether it is OK (exit 0 or 1).
Outcome = tuple[dict[str, Any], bool]

_OK_STATUSES = ("optimal", "optimal_inaccurate")


# ------------------------------------------------------------------ input boundaries
@contextlib.contextmanager
def _reading(label: str) -> Iterator[None]:
    """Errors raised while reading or validating the user's input are the user's: a raw
    exception from a reader or a data constructor (``float(None)``, a ragged list, a file
    that is not UTF-8, ...) becomes one :class:`ProblemError` naming ``label`` (the file
    or the flag), i.e. exit 2 instead of a traceback."""
    try:
        yield
    except OptModelsError:
        raise
    except UnicodeDecodeError as exc:
        raise ProblemError(f"{label}: not UTF-8 text (byte {exc.start}: {exc.reason}); "
                           "save it as UTF-8") from exc
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{label}: not valid JSON ({exc})") from exc
    except OSError as exc:
        raise ProblemError(f"{label}: {exc.strerror or exc}") from exc
    except (ValueError, TypeError, KeyError, IndexError, ArithmeticError,
            np.linalg.LinAlgError) as exc:
        raise ProblemError(f"{label}: {type(exc).__name__}: {exc}") from exc


def _out_dir(flag: str, path: str | Path) -> Path:
    """``--out FOLDER``: created if missing; refused (exit 2) before any work is done if
    it, or a parent, is an existing file."""
    from optmodels.io import output_dir

    try:
        return output_dir(path, name=flag)
    except ProblemError as exc:
        raise ProblemError(f"{flag}: {exc}") from None


def _out_file(flag: str, path: str | Path) -> Path:
    """``--out FILE``: missing parent folders are created; an existing directory (or a
    parent that is a file) is refused before any work is done."""
    from optmodels.io import output_file

    try:
        return output_file(path, name=flag)
    except ProblemError as exc:
        raise ProblemError(f"{flag}: {exc}") from None


# ------------------------------------------------------------ flag types (argparse)
def _flag_type(what: str, check: Callable[[Any], Any],
               parse: Callable[[str], Any] = float) -> Callable[[str], Any]:
    """An argparse ``type=``: ``parse`` the text, then ``check`` it with one of
    :mod:`optmodels.core`'s scalar checks (called with the name ``"value"``); a failure is
    a usage error (exit 2) naming the flag."""

    def convert(text: str) -> Any:
        try:
            value = parse(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            return check(value)
        except ProblemError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("value: ")) from None

    convert.__name__ = what
    return convert


def _whole(text: str) -> int | float:
    """``"12"`` → 12 exactly; ``"1e3"`` → 1000.0 (as_count then refuses ``"2.5"``)."""
    try:
        return int(text)
    except ValueError:
        return float(text)


def _positive() -> Callable[[str], float]:
    return _flag_type("a positive number", lambda v: as_positive("value", v))


def _finite() -> Callable[[str], float]:
    return _flag_type("a finite number", lambda v: as_number("value", v))


def _level() -> Callable[[str], float]:
    return _flag_type("a probability in (0, 1)", lambda v: as_probability(
        "value", v, low_open=True, high_open=True))


def _count(minimum: int) -> Callable[[str], int]:
    return _flag_type(f"a whole number >= {minimum}",
                      lambda v: as_count("value", v, minimum=minimum), _whole)


def _int_list(text: str) -> list[int]:
    """``--sizes 100,1000``: positive whole numbers."""
    try:
        vals = [as_count("value", _whole(x), minimum=1) for x in text.split(",")
                if x.strip()]
    except (ValueError, OverflowError) as exc:  # ProblemError is a ValueError
        raise argparse.ArgumentTypeError(
            f"expected positive whole numbers like 100,1000 ({str(exc).removeprefix('value: ')})"
        ) from None
    if not vals:
        raise argparse.ArgumentTypeError("expected positive whole numbers like 100,1000")
    return vals


def _names(text: str | None) -> list[str] | None:
    """A comma-separated list of names (``None`` when the flag is not given)."""
    if text is None:
        return None
    names = [x.strip() for x in text.split(",") if x.strip()]
    return names


# ---------------------------------------------------------------------------- plane
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


# --------------------------------------------------------------------- trajectories
def _trajectories_fit(args: argparse.Namespace) -> Outcome:
    from optmodels.io import read_trajectory_csv

    with _reading(str(args.file)):
        cols = read_trajectory_csv(args.file)
        labels = cols["objects"]
        if cols["sigma2"] is not None:
            if args.sigma2 is not None:
                raise ProblemError("--sigma2: the file has a sigma2 column already")
            sigma2: Any = cols["sigma2"]
        else:
            sigma2 = 1.0 if args.sigma2 is None else args.sigma2
        data = trajectories.TrajectoryData(cols["times"], cols["values"], sigma2,
                                           epoch=args.epoch)
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
    if fam is None:  # every trajectories solution carries its family
        raise RuntimeError("trajectories: the solution carries no family")
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
        "fit_p_value": float(stats.chi2.sf(sol.objective, sol.dof))
        if sol.dof > 0 and sol.ok else None,
        "residuals": sol.residuals, "build_time": sol.build_time,
        "solve_time": sol.solve_time, "iterations": sol.iterations, "message": sol.message,
    }
    if sol.ok and fam.n_constraints > 0:
        out["family_test"] = trajectories.family_test(
            data, fam, level=args.level,
            sigma2="estimated" if args.sigma2_unknown else "known").to_dict()
    return out, sol.ok


def _print_trajectories_fit(res: dict[str, Any]) -> None:
    print(f"{res['file']}: Q = {len(res['objects'])}, N = {res['n_measurements']}, "
          f"family {res['family']}, {res['method']} -> {res['status']}")
    if res["status"] not in _OK_STATUSES:
        print(f"  {res['message']}")
        return
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


# --------------------------------------------------------------------------- fusion
def _matrix_arg(flag: str, text: str) -> np.ndarray:
    """A matrix given inline as JSON (``'[[1,0],[0,2]]'``) or as a path to .npy/.json."""
    path = Path(text)
    try:
        if path.suffix == ".npy" and path.is_file():
            return np.asarray(np.load(path, allow_pickle=False), dtype=float)
        if path.suffix == ".json" and path.is_file():
            return np.asarray(json.loads(path.read_text(encoding="utf-8")), dtype=float)
        return np.asarray(json.loads(text), dtype=float)
    except (ValueError, TypeError, OSError) as exc:  # UnicodeDecodeError is a ValueError
        raise ProblemError(f"{flag}: expected a JSON matrix like '[[1,0],[0,2]]' or a path "
                           f"to an existing .npy/.json file, got {text!r:.80} ({exc})"
                           ) from None


def _fusion_weights(args: argparse.Namespace) -> Outcome:
    s1, s2 = _matrix_arg("--s1", args.s1), _matrix_arg("--s2", args.s2)
    n1 = args.n1 if args.n1 is not None else args.n
    n2 = args.n2 if args.n2 is not None else args.n
    if n1 is None or n2 is None:
        raise ProblemError("--n: give the sample size (or --n1 and --n2)")
    try:
        with _reading("--s1/--s2"):
            w = fusion.weight_matrix(s1, s2)
    except ProblemError as exc:  # name the command-line flag, not the Python argument
        msg = str(exc)
        if msg.startswith("--"):
            raise
        flag = "--s2" if "S2" in msg.split(":")[0] or msg.startswith("S2") else "--s1"
        raise ProblemError(f"{flag}: {msg}") from None
    m = w.shape[0]
    try:
        s12 = _matrix_arg("--s12", args.s12) if args.s12 else None
        with _reading("--s12/--n"):
            cov = fusion.weight_covariance(s1, s2, n1, n2, mean=args.mean, s12=s12)
    except ProblemError as exc:  # n1/n2 -> the flag the user typed
        msg = str(exc)
        head = msg.split(":")[0]
        if msg.startswith("--"):
            raise
        if "s12" in head.lower():
            raise ProblemError(f"--s12: {msg}") from None
        which = "n2" if "n2" in head else "n1"
        flag = f"--{which}" if getattr(args, which) is not None else "--n"
        raise ProblemError(f"{flag}: {msg}") from None
    p1, p2 = fusion.weight_jacobians(s1, s2)
    return {"W": w, "P1": p1, "P2": p2, "cov_vec_W": cov,
            "std_W": np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(m, m, order="F"),
            "n1": n1, "n2": n2, "mean": args.mean, "shared_snapshots": args.s12 is not None,
            "note": "vec stacks columns (12); Cov(vec W) is the first-order (10), "
                    "accurate to a few per cent from n ~ 100 (docs/errata.md)"}, True


def _print_fusion_weights(res: dict[str, Any]) -> None:
    with np.printoptions(precision=6, suppress=False, linewidth=120):
        for key in ("W", "std_W", "P1", "P2", "cov_vec_W"):
            print(f"{key} =\n{res[key]}")
    print(f"n1 = {res['n1']}, n2 = {res['n2']}, mean = {res['mean']}; {res['note']}")


# ------------------------------------------------------------------------ biasfield
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


# ----------------------------------------------------------------------- assignment
_CASE_FIELDS = ("means", "covs", "measurements", "meas_cov", "volume", "pd", "rho",
                "max_group_size", "group_gate")


def _read_case(path_text: str) -> dict[str, Any]:
    """``CASE.json``: a JSON object with the :class:`AssignmentData` fields."""
    from optmodels.io import read_text

    with _reading(path_text):
        text = read_text(path_text, what="JSON assignment case", name="case")
        try:
            case = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ProblemError(f"{path_text}: not valid JSON ({exc})") from None
    if not isinstance(case, dict):
        raise ProblemError(f"{path_text}: expected a JSON object with the fields "
                           f"{', '.join(_CASE_FIELDS[:7])}, got a JSON "
                           f"{type(case).__name__.replace('NoneType', 'null')}")
    unknown = sorted(set(case) - set(_CASE_FIELDS))
    if unknown:
        raise ProblemError(f"{path_text}: unknown fields {unknown} (expected {_CASE_FIELDS})")
    missing = sorted(set(_CASE_FIELDS[:7]) - set(case))
    if missing:
        raise ProblemError(f"{path_text}: missing fields {missing}")
    return case


def _assignment_solve(args: argparse.Namespace) -> Outcome:
    from optmodels import assignment as asg

    case = _read_case(args.case)
    with _reading(args.case):
        data = asg.AssignmentData(**case)
    total = asg.count_hypotheses(data.q, data.n)
    if args.method == "milp":
        sol = asg.solve(data, solver=args.solver, time_limit=args.time_limit)
    elif args.method == "brute-force":
        if total > 10_000_000:
            raise ProblemError(f"--method brute-force: {total:.3g} hypotheses (more than "
                               "10⁷); use milp")
        sol = asg.brute_force(data)
    else:
        sol = asg.linear_assignment(data)
    res: dict[str, Any] = {"status": sol.status.value, "method": sol.method,
                           "message": sol.message, "partition": sol.partition,
                           "assignment": sol.assignment, "log_score": sol.log_score,
                           "mip_gap": sol.mip_gap, "solve_time": sol.solve_time,
                           "build_time": sol.build_time, "hypotheses_total": total}
    if args.k and sol.ok:
        kb = asg.k_best(data, args.k, solver=args.solver)
        res["k_best"] = [{"partition": h.partition, "assignment": h.assignment,
                          "log_score": h.log_score} for h in kb.hypotheses]
        res["marginals"] = [{("background" if not k else ",".join(map(str, k))): v
                             for k, v in b.items()} for b in kb.beta]
        res["neglected_mass_bound"] = kb.neglected
    return res, sol.ok


def _print_assignment_solve(res: dict[str, Any]) -> None:
    print(f"{res['method']}: {res['status']} ({res['message']}); log score "
          f"{res['log_score']:.6f}; {res['hypotheses_total']} hypotheses in total")
    if res["status"] not in _OK_STATUSES:
        return
    blocks = ["+".join(map(str, b)) for b in res["partition"]]
    print("blocks: " + ", ".join(blocks))
    for i, a in enumerate(res["assignment"]):
        print(f"  measurement {i}: {'background' if a < 0 else blocks[a]}")
    if "k_best" in res:
        print(f"{len(res['k_best'])} best hypotheses; neglected mass ≤ "
              f"{res['neglected_mass_bound']:.3g} of the listed")


def _assignment_count(args: argparse.Namespace) -> Outcome:
    from optmodels import assignment as asg

    per = asg.count_per_variant(args.q, args.n)
    return {"q": args.q, "n": args.n, "total": asg.count_hypotheses(args.q, args.n),
            "variants": sum(v[0] for v in per.values()),
            "per_blocks": {b: {"variants": v[0], "hypotheses_each": v[1]}
                           for b, v in per.items()}}, True


def _print_assignment_count(res: dict[str, Any]) -> None:
    print(f"Q = {res['q']} objects, N = {res['n']} measurements: {res['variants']} unresolved "
          f"variants, {res['total']} hypotheses")
    for b, v in res["per_blocks"].items():
        print(f"  {b} blocks: {v['variants']} variants × {v['hypotheses_each']} hypotheses")


# ----------------------------------------------------------------------------- demo
def _demo(args: argparse.Namespace) -> Outcome:
    """Each problem's demo, then (without a problem) the quick comparison. A part that
    fails with an optmodels error is reported in ``failed`` and the others still run:
    exit 1 when some part failed, or when a closed-form reference row of the comparison
    failed (a generic solver failing is a result of the comparison, not a failure)."""
    from optmodels.demo import (
        run_assignment_demo,
        run_biasfield_demo,
        run_fusion_demo,
        run_plane_demo,
        run_trajectories_demo,
    )

    out = _out_dir("--out", args.out)
    problems = [args.problem] if args.problem else list(PROBLEMS)
    t0 = time.perf_counter()
    result: dict[str, Any] = {"out": str(out), "problems": {}, "failed": {}}
    sections = []
    progress = not args.json
    titles = {
        "plane": "- [Plane of maneuver (paper 000)](plane/report.md): figures 1-4, Monte "
                 "Carlo vs the Cramér–Rao bound",
        "trajectories": "- [Dependent linear trajectories (paper 002)]"
                        "(trajectories/report.md): launcher and parallel scenarios, η "
                        "against Monte Carlo",
        "fusion": "- [Fusion of two estimates (paper 003)](fusion/report.md): accuracy of Ŵ "
                  "vs n, the two-site system with the joint ML",
        "assignment": "- [Joint assignment with unresolved groups (paper 004)]"
                      "(assignment/report.md): MAP by one MILP vs resolved-only "
                      "association, closely spaced space objects",
        "biasfield": "- [Radar bias fields (paper 001)](biasfield/report.md): plots to "
                     "uncertainty sets, the smoothest field with and without the box, "
                     "fig. 4 maps, the parametric baseline",
    }
    runners: dict[str, Callable[[], dict[str, Any]]] = {
        "plane": lambda: run_plane_demo(out / "plane", runs=args.runs, seed=args.seed,
                                        progress=progress),
        "trajectories": lambda: run_trajectories_demo(
            out / "trajectories", runs=args.trajectory_runs, seed=args.seed,
            progress=progress),
        "fusion": lambda: run_fusion_demo(out / "fusion", trials=args.fusion_trials,
                                          positions=args.fusion_positions, seed=args.seed,
                                          progress=progress),
        "assignment": lambda: run_assignment_demo(out / "assignment", seed=args.seed,
                                                  progress=progress),
        "biasfield": lambda: run_biasfield_demo(out / "biasfield", seed=args.seed),
    }
    for p in problems:
        try:
            result["problems"][p] = runners[p]()
        except OptModelsError as exc:
            result["failed"][p] = f"{type(exc).__name__}: {exc}"
            print(f"optmodels: demo {p} failed: {exc}", file=sys.stderr)
            sections.append(f"- {p}: FAILED ({exc})")
            continue
        sections.append(titles[p])
    ok = not result["failed"]
    if not args.problem and not args.no_compare:
        cmp_res = _run_harness(out / "compare", PROBLEMS, sizes=args.sizes, solvers=None,
                               profile="default", seed=args.seed,
                               time_limit=args.time_limit, quick=args.sizes is None,
                               progress=progress)
        result["compare"] = cmp_res
        ok = ok and cmp_res["references_ok"]
        sections.append("- [Solver and formulation comparison](compare/report.md): every "
                        "problem's original form on every installed solver against the "
                        "closed form (success, time, scaling plots)")
    result["seconds"] = time.perf_counter() - t0
    with _reading(f"--out {out}"):
        (out / "index.md").write_text(
            "# optmodels report\n\n" + "\n".join(sections)
            + f"\n\nGenerated by `optmodels demo` in {result['seconds']:.0f} s.\n",
            encoding="utf-8",
        )
    return result, ok


# -------------------------------------------------------------------------- compare
def _check_selection(problems: Sequence[str], solvers: Sequence[str] | None,
                     instances: Sequence[str] | None) -> None:
    """``--problems``, ``--solvers`` and ``--instances`` against the harness registry: a
    name that selects nothing is a usage error, not an empty (successful) sweep."""
    from solvers_cmp import cases as cs

    for p in problems:
        if p not in cs.REGISTRY:
            raise ProblemError(f"--problems: unknown problem {p!r} (known: "
                               f"{', '.join(cs.REGISTRY)})")
    if not problems:
        raise ProblemError("--problems: no problem given")
    known_instances: set[str] = set()
    known_solvers: dict[str, str] = {}
    for p in problems:
        ad = cs.adapter(p)
        known_instances.update(ad.instances)
        for inst in ad.instances:
            if instances and inst not in instances:
                continue
            for r in ad.runs(inst):
                if r.formulation != "closed_form":
                    known_solvers.setdefault(r.solver.lower(), r.solver)
    if instances is not None:
        bad = [i for i in instances if i not in known_instances]
        if bad or not instances:
            raise ProblemError(f"--instances: unknown instance(s) {bad} for problems "
                               f"{', '.join(problems)} (known: "
                               f"{', '.join(sorted(known_instances))})")
    if solvers is not None:
        bad = [s for s in solvers if s.lower() not in known_solvers]
        if bad or not solvers:
            raise ProblemError(
                f"--solvers: {bad or 'none given'}: not a solver these problems run here "
                f"(available: {', '.join(sorted(known_solvers.values(), key=str.lower))}); "
                "the closed form is always kept")


def _run_harness(out: Path, problems: Sequence[str], *, sizes: list[int] | None,
                 solvers: list[str] | None, profile: str, seed: int,
                 time_limit: float | None, quick: bool = False, progress: bool,
                 instances: list[str] | None = None) -> dict[str, Any]:
    """The comparison harness (:mod:`solvers_cmp.harness`) and its report.

    ``quick``: the main job's sweep -- each problem's two smallest default sizes.
    ``references_ok``: every closed-form (reference) row succeeded."""
    from optmodels.backends.casadi_backend import probe_nlp_plugins
    from optmodels.backends.casadi_qp import probe_plugins
    from optmodels.io import write_json
    from solvers_cmp import cases as cs
    from solvers_cmp import harness, report

    _check_selection(problems, solvers, instances)
    out = _out_dir("--out", out)
    env = report.environment()
    plan_sizes: harness.Sizes = sizes
    if sizes is None and quick:
        plan_sizes = {p: list(cs.adapter(p).sizes[:2]) for p in problems}
    rows = harness.run_sweep(problems, out, sizes=plan_sizes, solvers=solvers,
                             profile=profile, seeds=(seed,), time_limit=time_limit,
                             instances=instances, progress=progress)
    # after the sweep: a second sweep refused by the folder's lock must not overwrite it
    write_json(out / "environment.json", env)
    prof = harness.PROFILES[profile]
    limit = float(prof.time_limit if time_limit is None else time_limit)
    notes = {f"CasADi conic {k}": v for k, v in probe_plugins().items() if v != "ok"}
    notes |= {f"CasADi nlpsol {k}": v for k, v in probe_nlp_plugins().items() if v != "ok"}
    report.write_harness_report(out, rows, profile=profile, time_limit=limit,
                                error_tol=prof.error_tol, violation_tol=prof.violation_tol,
                                notes=notes, env=env)
    refs = [r for r in rows if r["formulation"] == "closed_form"]
    return {"out": str(out), "runs": len(rows),
            "successes": sum(bool(r["success"]) for r in rows),
            "references_ok": all(bool(r["success"]) for r in refs)
            and not any("reference failed" in str(r.get("reason", "")) for r in rows),
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

    for p in problems:
        if p not in PROBLEMS:
            raise ProblemError(f"--problems: unknown problem {p!r} (known: "
                               f"{', '.join(PROBLEMS)})")
    out = _out_dir("--out", out)
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
    md.append(f"\nMachine: {env['cpu']}, {env['cores']} cores; Python {env['python']}.\n")
    (out / "report.md").write_text("\n".join(md), encoding="utf-8")
    return res


def _compare(args: argparse.Namespace) -> Outcome:
    """``compare``: exit 1 when a closed-form reference row failed (the comparison has no
    floor there); generic solvers failing are its results (``failures``), exit 0."""
    problems = _names(args.problems) or []
    solvers = _names(args.solvers)
    instances = _names(args.instances)
    if args.details:
        res = _run_compare(Path(args.out), problems, args.sizes or [100, 1000, 10000],
                           args.runs, args.repeats, args.seed, progress=not args.json)
        return res, True
    res = _run_harness(Path(args.out), problems, sizes=args.sizes, solvers=solvers,
                       profile=args.profile, seed=args.seed, time_limit=args.time_limit,
                       instances=instances, progress=not args.json)
    return res, res["references_ok"]


# ----------------------------------------------------------------------- montecarlo
def _montecarlo(args: argparse.Namespace) -> Outcome:
    """``montecarlo``: exit 1 when a trial's solve failed (``SolveError``; the checkpoint
    keeps the finished trials) or a per-trial value is not finite."""
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
    with _reading("--param"):
        study = mc.study(args.study, **params)
    checkpoint = _out_file("--checkpoint", args.checkpoint) if args.checkpoint else None
    out_path = _out_file("--out", args.out) if args.out else None
    res = mc.run(study, args.trials, args.seed, scheduler=args.scheduler,
                 checkpoint=checkpoint, workers=args.workers, progress=not args.json,
                 retry_failed=args.retry_failed)
    out = {"study": res.study, "seed": res.seed, "trials": int(res.trials.size),
           "requested": res.requested, "n_ok": res.n_ok,
           "failed": len(res.failures),
           "failures": [[int(i), str(m)] for i, m in res.failures[:20]],
           "skipped_lines": res.skipped_lines,
           "resumed": res.resumed, "engine": res.engine, "summary": res.summary,
           "means": {k: res.mean(k) for k in res.values},
           "standard_errors": {k: res.se(k) for k in res.values} if res.n_ok > 1
           else {}}
    if out_path is not None:
        write_json(out_path, {**out, "values": res.values})
    finite = all(bool(np.all(np.isfinite(np.asarray(v, dtype=float))))
                 for v in res.values.values())
    return out, finite and not res.failures


def _print_montecarlo(res: dict[str, Any]) -> None:
    print(f"{res['study']}: {res['trials']} trials (seed {res['seed']}, {res['resumed']} "
          f"from the checkpoint), engine {res['engine']}")
    if res["failed"]:
        print(f"  {res['failed']} of {res['requested']} trials failed (recorded; "
              "--retry-failed runs them again), e.g.")
        for i, msg in res["failures"][:3]:
            print(f"    trial {i}: {msg}")
    if res["skipped_lines"]:
        print(f"  {res['skipped_lines']} unreadable checkpoint line(s) skipped")
    for k, v in res["summary"].items():
        print(f"  {k:>22s} = {v:.6g}" if isinstance(v, int | float) else f"  {k:>22s} = {v}")
    for k, v in res["means"].items():
        se = res["standard_errors"].get(k)
        print(f"  mean {k:>17s} = {v:.6g}" + (f" ± {se:.2g}" if se is not None else ""))


def _print_written(res: dict[str, Any], name: str) -> None:
    print(f"wrote {Path(res['out']) / name}")
    for p, msg in res.get("failed", {}).items():
        print(f"  {p}: FAILED ({msg})")
    cmp_ = res.get("compare", res)
    if "runs" in cmp_:
        print(f"  comparison: {cmp_['successes']}/{cmp_['runs']} runs succeeded"
              + ("" if cmp_.get("references_ok", True) else "; a closed-form reference "
                 "FAILED"))


# --------------------------------------------------------------------------- parser
class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``optmodels plane fit: error: argument --sigma2:
    must be > 0, got -1 (see optmodels plane fit --help)``, exit 2."""

    #: set by :func:`main` when ``--json`` is on the command line: the usage error is
    #: then also the one JSON document on stdout
    json_errors = False

    def error(self, message: str) -> NoReturn:
        line = " ".join(f"{self.prog}: {message}".split())
        if _Parser.json_errors:
            _emit(_dumps({"error": line, "exit_code": EXIT_INPUT}))
        self.exit(EXIT_INPUT, f"optmodels: error: {line} (see {self.prog} --help)\n")


def _leaf(sub: Any, name: str, help_: str) -> argparse.ArgumentParser:
    """A command parser with the common flags --json and --debug."""
    p = sub.add_parser(name, help=help_)
    p.add_argument("--json", action="store_true",
                   help="print exactly one JSON document on stdout")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help="show the traceback of an internal error")
    return p


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="optmodels", description=__doc__,
                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--debug", action="store_true",
                    help="show the traceback of an internal error")
    sub = ap.add_subparsers(dest="command", required=True)
    runs, count0, count1 = _count(2), _count(0), _count(1)
    positive = _positive()

    demo = _leaf(sub, "demo", "run the papers' examples and write a report")
    demo.add_argument("problem", nargs="?", choices=PROBLEMS,
                      help="one problem only (default: all, plus the comparison)")
    demo.add_argument("--out", default="report", help="output folder (default: report)")
    demo.add_argument("--runs", type=runs, default=200,
                      help="Monte Carlo runs of the example (>= 2)")
    demo.add_argument("--seed", type=count0, default=0)
    demo.add_argument("--trajectory-runs", type=_count(40), default=4000,
                      help="Monte Carlo draws per (Q, N) of the trajectories η table (>= 40: "
                           "20 batches of at least 2)")
    demo.add_argument("--fusion-trials", type=runs, default=100_000,
                      help="Monte Carlo draws of Ŵ per (case, estimator, n) in the fusion demo")
    demo.add_argument("--fusion-positions", type=count1, default=40,
                      help="emitter positions of the fusion demo's two-site study")
    demo.add_argument("--no-compare", action="store_true", help="skip the comparison")
    demo.add_argument("--sizes", type=_int_list, default=None,
                      help="comparison sizes for every problem (default: each problem's "
                           "two smallest default sizes)")
    demo.add_argument("--time-limit", type=positive, default=5.0,
                      help="comparison time limit per run, s (default 5)")
    demo.set_defaults(func=_demo, printer=lambda r: _print_written(r, "index.md"))

    cmp_ = _leaf(sub, "compare", "compare solvers and formulations (solvers_cmp)")
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
    cmp_.add_argument("--time-limit", type=positive,
                      help="per run, s (> 0; default: the profile's)")
    cmp_.add_argument("--seed", type=count0, default=0)
    cmp_.add_argument("--out", default="report/compare")
    cmp_.add_argument("--details", action="store_true",
                      help="run the per-problem studies instead (plane Monte Carlo accuracy, "
                           "benchmarks at the issues' target sizes)")
    cmp_.add_argument("--runs", type=runs, default=200, help="--details: Monte Carlo runs")
    cmp_.add_argument("--repeats", type=count1, default=5, help="--details: timing repeats")
    cmp_.set_defaults(func=_compare, printer=lambda r: _print_written(r, "report.md"))

    mcp = _leaf(sub, "montecarlo", "run a seeded Monte Carlo study (local or Dask)")
    mcp.add_argument("study", help="plane-angle, trajectories-eta, fusion-weight, "
                                   "biasfield-recovery, assignment-separation")
    mcp.add_argument("--trials", type=count1, default=1000)
    mcp.add_argument("--seed", type=count0, default=0)
    mcp.add_argument("--param", action="append", metavar="NAME=VALUE",
                     help="study parameter (repeatable), e.g. --param n=100")
    mcp.add_argument("--scheduler", default=None,
                     help="processes (default), serial, or a Dask address tcp://host:8786")
    mcp.add_argument("--workers", type=count1, help="local processes (default: all cores)")
    mcp.add_argument("--checkpoint", help="JSON-lines file; a rerun resumes from it")
    mcp.add_argument("--retry-failed", action="store_true",
                     help="run again the trials the checkpoint records as failed")
    mcp.add_argument("--out", help="write the per-trial values and summary to this JSON")
    mcp.set_defaults(func=_montecarlo, printer=_print_montecarlo)

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

    trj = sub.add_parser("trajectories", help="dependent linear trajectories (paper 002)")
    tsub = trj.add_subparsers(dest="verb", required=True)
    tfit = _leaf(tsub, "fit", "fit a family of lines to a CSV of measurements")
    tfit.add_argument("file", type=Path,
                      help="CSV with object,t,y or object,t,x,y[,z] [,sigma2]")
    tfit.add_argument("--family", default="diverging",
                      choices=("diverging", "parallel", "independent", "custom"))
    tfit.add_argument("--shared-start", action="append", metavar="A,B,..",
                      help="custom family: objects sharing a start (repeatable)")
    tfit.add_argument("--shared-velocity", action="append", metavar="A,B,..",
                      help="custom family: objects sharing a velocity (repeatable)")
    tfit.add_argument("--sigma2", type=positive,
                      help="error variance, (unit of y)² (default 1)")
    tfit.add_argument("--sigma2-unknown", action="store_true",
                      help="family test with σ² estimated (F test) instead of known (χ²)")
    tfit.add_argument("--epoch", type=_finite(), default=0.0,
                      help="time at which the start is defined, s (default 0)")
    tfit.add_argument("--method", default="closed-form",
                      help="closed-form (default) or a CVXPY solver: CLARABEL, OSQP, SCS, ...")
    tfit.add_argument("--formulation", choices=("constrained", "reduced"),
                      default="constrained", help="generic formulation (with --method SOLVER)")
    tfit.add_argument("--level", type=_level(), default=0.95,
                      help="family test level, in (0, 1)")
    tfit.set_defaults(func=_trajectories_fit, printer=_print_trajectories_fit)

    fus = sub.add_parser("fusion", help="fusion of two estimates (paper 003)")
    fsub = fus.add_subparsers(dest="verb", required=True)
    fw = _leaf(fsub, "weights", "W, the Jacobians P1, P2 (13)-(14) and Cov(vec W) (10)")
    fw.add_argument("--s1", required=True,
                    help="error covariance of estimate 1: JSON '[[..],[..]]' or .npy/.json path")
    fw.add_argument("--s2", required=True, help="error covariance of estimate 2 (as --s1)")
    fw.add_argument("--n", type=count1, help="snapshots behind both sample covariances")
    fw.add_argument("--n1", type=count1, help="snapshots behind S1 (overrides --n)")
    fw.add_argument("--n2", type=count1, help="snapshots behind S2 (overrides --n)")
    fw.add_argument("--mean", choices=("sample", "known"), default="sample",
                    help="sample covariances about the sample mean (default) or the known "
                         "mean (the paper's literal (3))")
    fw.add_argument("--s12", help="Cov(a1, a2) when both sample covariances come from the "
                                   "same snapshots of correlated estimators (adds the cross "
                                   "block to (10); needs n1 = n2)")
    fw.set_defaults(func=_fusion_weights, printer=_print_fusion_weights)

    asp = sub.add_parser("assignment", help="joint assignment with merges (paper 004)")
    asub = asp.add_subparsers(dest="verb", required=True)
    aso = _leaf(asub, "solve", "the MAP hypothesis of a CASE.json")
    aso.add_argument("case", help="JSON with means, covs, measurements, meas_cov, volume, pd, "
                                  "rho [, max_group_size, group_gate]")
    aso.add_argument("--method", choices=("milp", "brute-force", "linear"), default="milp")
    aso.add_argument("--solver", default="HIGHS", help="MILP solver (HIGHS, SCIP, ...)")
    aso.add_argument("--time-limit", type=positive, help="MILP time limit, s (> 0)")
    aso.add_argument("--k", type=count0, default=0, help="also list the k best and marginals")
    aso.set_defaults(func=_assignment_solve, printer=_print_assignment_solve)
    aco = _leaf(asub, "count", "number of hypotheses (14) for Q objects, N marks")
    aco.add_argument("q", type=count1, help="objects Q (>= 1)")
    aco.add_argument("n", type=count0, help="measurements N (>= 0)")
    aco.set_defaults(func=_assignment_count, printer=_print_assignment_count)

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
    return ap


# ----------------------------------------------------------------------------- main
def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers (a solver's ``printf`` to a pipe sits there
    until exit, after fd 1 is back on stdout)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no libc symbols (non-POSIX)
        pass


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """While the work runs, every write to stdout -- Python's, a C library's (HiGHS prints
    its banner on fd 1), a child process's -- goes to stderr: fd 1 points at fd 2 and
    ``sys.stdout`` is ``sys.stderr``. Both are restored on the way out, so the result
    alone is printed on stdout."""
    for stream in (sys.stdout, sys.__stdout__, sys.stderr):
        with contextlib.suppress(Exception):
            if stream is not None:
                stream.flush()
    saved: int | None = None
    try:
        saved = os.dup(1)
        os.dup2(2, 1)
    except OSError:  # no fd 1/2 (embedded interpreter): Python-level redirection only
        if saved is not None:
            os.close(saved)
        saved = None
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        for stream in (sys.__stdout__, sys.stderr):
            with contextlib.suppress(Exception):
                if stream is not None:
                    stream.flush()
        _flush_c_stdio()
        if saved is not None:
            os.dup2(saved, 1)
            os.close(saved)


def _jsonable(value: Any) -> Any:
    """NaN/±inf -> None (strict JSON has no such numbers); containers recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def _dumps(obj: Any) -> str:
    """One strict JSON document (NumPy arrays and scalars as lists and numbers)."""
    plain = json.loads(json.dumps(obj, default=json_default))
    return json.dumps(_jsonable(plain), indent=2, allow_nan=False)


def _emit(text: str) -> None:
    """Write the result on stdout (a closed pipe, ``| head``, is not an error)."""
    try:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        with contextlib.suppress(OSError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())


def _fail(args: argparse.Namespace | None, code: int, message: str) -> int:
    """One line on stderr (and with --json the error document on stdout); the code."""
    line = " ".join(message.split())  # a message never spans lines
    print(f"optmodels: error: {line}", file=sys.stderr, flush=True)
    if args is not None and getattr(args, "json", False):
        _emit(_dumps({"error": line, "exit_code": code}))
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (module docstring). Usage errors
    raise ``SystemExit(2)`` from argparse after one line on stderr."""
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = build_parser()
    _Parser.json_errors = "--json" in argv
    args = ap.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    text, ok, code, message = "", False, EXIT_OK, ""
    result: dict[str, Any] = {}
    with _stdout_to_stderr():
        try:
            result, ok = args.func(args)
            if args.json:
                text = _dumps(result)
            else:
                buf: list[str] = []
                with contextlib.redirect_stdout(_Lines(buf)):
                    args.printer(result)
                text = "".join(buf)
        except KeyboardInterrupt as exc:
            # montecarlo.Interrupted says what was saved and where
            code, message = EXIT_INTERRUPTED, str(exc) or "interrupted"
        except (ProblemError, SolverNotAvailable) as exc:
            code, message = EXIT_INPUT, str(exc)
        except SolveError as exc:
            code, message = EXIT_NOT_OK, f"not solved: {exc}"
        except OptModelsError as exc:
            code, message = EXIT_NOT_OK, str(exc)
        except OSError as exc:  # the environment: a file, a folder, a network address
            name = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            code, message = EXIT_INPUT, f"{name}{exc.strerror or exc}"
        except Exception as exc:  # a bug: one line, the traceback on request
            if debug:
                traceback.print_exc()
            code = EXIT_INTERNAL
            message = f"internal error: {type(exc).__name__}: {exc}" + (
                "" if debug else " (rerun with --debug for the traceback)")
    if code != EXIT_OK:
        return _fail(args, code, message)
    _emit(text)
    if not ok:
        status = result.get("status")
        what = f"status {status}" if status else "some part failed (see the output)"
        extra = f" ({result['message']})" if status and result.get("message") else ""
        print(f"optmodels: not OK: {what}{extra}", file=sys.stderr, flush=True)
    return EXIT_OK if ok else EXIT_NOT_OK


class _Lines:
    """A minimal text sink collecting what a printer writes (printed in one go)."""

    def __init__(self, buf: list[str]) -> None:
        self.buf = buf

    def write(self, text: str) -> int:
        self.buf.append(text)
        return len(text)

    def flush(self) -> None:
        pass


if __name__ == "__main__":
    raise SystemExit(main())
