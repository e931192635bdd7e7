"""``optmodels compare``: the comparison harness sweep (:mod:`solvers_cmp.harness`: every
problem's original form on every installed solver against the closed form) and its
report, the selection checks of ``--problems/--solvers/--instances``, and ``--details``
(the per-problem studies, through the ``run_details`` hook of each module in
:mod:`optmodels.cli.problems`). The demo's quick sweep runs through here too."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from optmodels.cli import problems as cli_problems
from optmodels.cli.args import _count, _int_list, _names, _positive
from optmodels.cli.contract import Outcome, _leaf, _out_dir
from optmodels.core import ProblemError
from optmodels.execution import scheduler_argument


def _check_selection(
    problems: Sequence[str], solvers: Sequence[str] | None, instances: Sequence[str] | None
) -> None:
    """``--problems``, ``--solvers`` and ``--instances`` against the harness registry: a
    name that selects nothing is a usage error, not an empty (successful) sweep."""
    from solvers_cmp import cases as cs

    for p in problems:
        if p not in cs.REGISTRY:
            raise ProblemError(
                f"--problems: unknown problem {p!r} (known: {', '.join(cs.REGISTRY)})"
            )
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
            raise ProblemError(
                f"--instances: unknown instance(s) {bad} for problems "
                f"{', '.join(problems)} (known: "
                f"{', '.join(sorted(known_instances))})"
            )
    if solvers is not None:
        bad = [s for s in solvers if s.lower() not in known_solvers]
        if bad or not solvers:
            raise ProblemError(
                f"--solvers: {bad or 'none given'}: not a solver these problems run here "
                f"(available: {', '.join(sorted(known_solvers.values(), key=str.lower))}); "
                "the closed form is always kept"
            )


def quick_sizes(sizes: Sequence[int]) -> list[int]:
    """The quick sweep's sizes: a problem's two smallest default sizes and their
    geometric midpoint -- three sizes, so that every scaling line has a slope."""
    a, b = sorted(sizes)[:2]
    mid = round((a * b) ** 0.5)
    return sorted({a, mid, b})


def _run_harness(
    out: Path,
    problems: Sequence[str],
    *,
    sizes: list[int] | None,
    solvers: list[str] | None,
    profile: str,
    seed: int,
    time_limit: float | None,
    quick: bool = False,
    progress: bool,
    instances: list[str] | None = None,
    scheduler: str | None = None,
    repeats: int = 3,
) -> dict[str, Any]:
    """The comparison harness (:mod:`solvers_cmp.harness`) and its report.

    ``quick``: the main job's sweep -- each problem's two smallest default sizes and
    their geometric midpoint (:func:`quick_sizes`), the
    runs :data:`solvers_cmp.harness.profiles.TOO_SLOW` marks too slow for their size
    left out (listed in the report, ``skipped`` here). ``repeats``: calls per run
    (the median solve time is reported).
    ``scheduler``: ``None``/``"processes"``, ``"serial"``, or a Dask address (each run a
    Dask task; :func:`optmodels.execution.as_scheduler`).
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
        plan_sizes = {p: quick_sizes(cs.adapter(p).sizes) for p in problems}
    from solvers_cmp.harness.profiles import too_slow

    skipped = []
    if quick:
        for _, case, runs in harness.plan(problems, plan_sizes, solvers, (seed,), instances):
            for run in runs:
                why = too_slow(case, run)
                if why is not None:
                    skipped.append(
                        {
                            "problem": case.problem,
                            "instance": case.instance,
                            "size": case.size,
                            "seed": case.seed,
                            "formulation": run.formulation,
                            "solver": run.solver,
                            "why": why,
                        }
                    )
    rows = harness.run_sweep(
        problems,
        out,
        sizes=plan_sizes,
        solvers=solvers,
        profile=profile,
        seeds=(seed,),
        time_limit=time_limit,
        instances=instances,
        progress=progress,
        scheduler=scheduler,
        repeats=repeats,
        skip_slow=quick,
    )
    # after the sweep: a second sweep refused by the folder's lock must not overwrite it
    write_json(out / "environment.json", env)
    prof = harness.PROFILES[profile]
    limit = float(prof.time_limit if time_limit is None else time_limit)
    notes = {f"CasADi conic {k}": v for k, v in probe_plugins().items() if v != "ok"}
    notes |= {f"CasADi nlpsol {k}": v for k, v in probe_nlp_plugins().items() if v != "ok"}
    report.write_harness_report(
        out,
        rows,
        profile=profile,
        time_limit=limit,
        error_tol=prof.error_tol,
        violation_tol=prof.violation_tol,
        notes=notes,
        env=env,
        skipped=skipped,
    )
    summary = report.harness_info(rows, limit, skipped)
    refs = [r for r in rows if r["formulation"] == "closed_form"]
    at_limit = [r for r in rows if r["status"] == "time_limit"]
    return {
        "out": str(out),
        "runs": len(rows),
        "successes": sum(bool(r["success"]) for r in rows),
        "time_limit_s": limit,
        "runs_at_time_limit": len(at_limit),
        "seconds_at_time_limit": float(sum(r["solve_time"] for r in at_limit)),
        "skipped": skipped,
        "headline": summary["headline"],
        "failure_kinds": summary["failure_kinds"],
        "references_ok": all(bool(r["success"]) for r in refs)
        and not any("reference failed" in str(r.get("reason", "")) for r in rows),
        "failures": [
            {
                k: r[k]
                for k in (
                    "problem",
                    "instance",
                    "size",
                    "formulation",
                    "solver",
                    "status",
                    "reason",
                )
            }
            for r in rows
            if not r["success"]
        ],
    }


def _run_compare(
    out: Path,
    problems: Sequence[str],
    sizes: list[int],
    runs: int,
    repeats: int,
    seed: int,
    progress: bool,
) -> dict[str, Any]:
    """The per-problem studies (``optmodels compare --details``): plane Monte Carlo
    accuracy, benchmarks at the issues' target sizes, problem-specific tables."""
    from optmodels.io import write_json
    from solvers_cmp import report

    studies = cli_problems.with_hook("run_details")
    for p in problems:
        if p not in studies:
            raise ProblemError(f"--problems: unknown problem {p!r} (known: {', '.join(studies)})")
    out = _out_dir("--out", out)
    md = ["# Solver and formulation comparison\n"]
    res: dict[str, Any] = {"out": str(out)}
    env = report.environment()
    write_json(out / "environment.json", env)
    for p in problems:
        section, res[p] = studies[p].run_details(
            out, sizes=sizes, runs=runs, repeats=repeats, seed=seed, progress=progress
        )
        md.append(section)
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
        if args.scheduler != "processes":
            raise ProblemError("--scheduler: only for the sweep, not with --details")
        res = _run_compare(
            Path(args.out),
            problems,
            args.sizes or [100, 1000, 10000],
            args.runs,
            args.repeats or 5,
            args.seed,
            progress=not args.json,
        )
        return res, True
    res = _run_harness(
        Path(args.out),
        problems,
        sizes=args.sizes,
        solvers=solvers,
        profile=args.profile,
        seed=args.seed,
        time_limit=args.time_limit,
        instances=instances,
        progress=not args.json,
        scheduler=args.scheduler,
        repeats=args.repeats or 3,
    )
    return res, res["references_ok"]


def _print_written(res: dict[str, Any], name: str) -> None:
    print(f"wrote {Path(res['out']) / name}")
    for p, msg in res.get("failed", {}).items():
        print(f"  {p}: FAILED ({msg})")
    cmp_ = res.get("compare", res)
    if "runs" in cmp_:
        print(
            f"  comparison: {cmp_['successes']}/{cmp_['runs']} runs succeeded"
            + ("" if cmp_.get("references_ok", True) else "; a closed-form reference FAILED")
        )


def register(sub: Any) -> None:
    """Add ``optmodels compare`` to the top-level sub-commands ``sub``; ``--problems``
    defaults to every problem the harness registry knows."""
    from solvers_cmp import cases as cs

    runs, count0, count1 = _count(2), _count(0), _count(1)
    positive = _positive()

    cmp_ = _leaf(sub, "compare", "compare solvers and formulations (solvers_cmp)")
    cmp_.add_argument(
        "--problems", default=",".join(cs.known_problems()), help="comma-separated (default: all)"
    )
    cmp_.add_argument(
        "--sizes",
        type=_int_list,
        default=None,
        help="sizes for every problem (default: each problem's own; see "
        "report.md for what size means per problem)",
    )
    cmp_.add_argument(
        "--solvers",
        help="comma-separated solver names (CLARABEL, OSQP, "
        "CASADI_QPOASES, ipopt, sqpmethod, HIGHS, ...); the "
        "closed form is always kept",
    )
    cmp_.add_argument("--instances", help="comma-separated instance names (e.g. box,radar)")
    cmp_.add_argument("--profile", choices=("default", "high"), default="default")
    cmp_.add_argument(
        "--time-limit", type=positive, help="per run, s (> 0; default: the profile's)"
    )
    cmp_.add_argument("--seed", type=count0, default=0)
    cmp_.add_argument(
        "--out",
        default="report/compare-full",
        help="output FOLDER (report.md, results.csv); the demo's quick sweep "
        "writes report/compare, so the two never share rows",
    )
    cmp_.add_argument(
        "--scheduler",
        type=scheduler_argument,
        default="processes",
        help="processes (default: one isolated worker process here), serial "
        "(in this process) or a Dask scheduler address, e.g. "
        "tcp://host:8786: each run is a task on the cluster, with its "
        "time limit; results.csv and resume as locally",
    )
    cmp_.add_argument(
        "--details",
        action="store_true",
        help="run the per-problem studies instead (plane Monte Carlo accuracy, "
        "benchmarks at the issues' target sizes)",
    )
    cmp_.add_argument("--runs", type=runs, default=200, help="--details: Monte Carlo runs")
    cmp_.add_argument(
        "--repeats",
        type=count1,
        default=None,
        help="timing repeats: calls per run of the sweep (default 3, the "
        "median solve time reported, stopped after 1 s of calls), "
        "--details: per benchmark (default 5)",
    )
    cmp_.set_defaults(func=_compare, printer=lambda r: _print_written(r, "report.md"))
