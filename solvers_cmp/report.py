"""Write comparison results: tidy CSV, Markdown tables, environment description.

The helpers every per-problem section uses (:func:`_results_csv`, :func:`_benchmark`),
the environment record and the harness report (:func:`write_harness_report`). Each
problem's ``compare --details`` section is ``write_report`` in its own face file
``solvers_cmp/<problem>.py``; ``report.write_<problem>`` still names it, found by the
problem's name through :mod:`optmodels.registry` (module :func:`__getattr__`, no list).
"""

from __future__ import annotations

import platform
from importlib import metadata
from pathlib import Path
from typing import Any

from optmodels.io import markdown_table, write_csv
from solvers_cmp.common import cpu_name

PACKAGES = ("optmodels", "numpy", "scipy", "cvxpy", "casadi", "clarabel", "osqp", "scs",
            "highspy")


def environment() -> dict[str, Any]:
    """Package versions and the machine, recorded beside every result set."""
    versions = {}
    for p in PACKAGES:
        try:
            versions[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            versions[p] = None
    import os

    return {"python": platform.python_version(), "platform": platform.platform(),
            "cpu": cpu_name(), "cores": os.cpu_count(), "packages": versions}


def __getattr__(name: str) -> Any:
    """``write_<problem>`` for a problem of :func:`optmodels.registry.names`: that
    problem's section writer ``solvers_cmp.<problem>.write_report`` (imported on first
    use; the old names of the sections, kept without a list)."""
    problem = name.removeprefix("write_")
    if problem != name:
        from optmodels import registry

        if problem in registry.names():
            found = getattr(registry.face_module("solvers_cmp", problem), "write_report", None)
            if found is not None:
                return found
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _results_csv(out: Path, problem: str, rows: list[dict[str, Any]]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / f"{problem}_results.csv", rows)


def _benchmark(out: Path, problem: str, bench: list[dict[str, Any]] | None, intro: str,
               cols: list[str], digits: str) -> str:
    """Write ``{problem}_benchmark.csv`` and return its Markdown paragraph ('' if none)."""
    if not bench:
        return ""
    write_csv(out / f"{problem}_benchmark.csv", bench)
    return (f"\n{intro}\n\n"
            + markdown_table(bench, cols, {"median_s": digits, "min_s": digits}))


# ============================================================== the harness report
_SUMMARY_COLS = ["formulation", "solver", "runs", "success_rate", "sgm_solve_time",
                 "rel_solve_time", "sgm_build_time", "rel_build_time", "max_error",
                 "max_violation"]
_SUMMARY_FMT = {"success_rate": ".0%", "sgm_solve_time": ".2e", "rel_solve_time": ".1f",
                "sgm_build_time": ".2e", "rel_build_time": ".1f", "max_error": ".1e",
                "max_violation": ".1e"}


def _failure_lines(rows: list[dict[str, Any]]) -> list[str]:
    """One line per (formulation, solver, reason kind): the sizes/instances it hit and the
    first message, so that every failed row is explained without a wall of repeats."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        if r["success"]:
            continue
        kind = str(r["reason"]).split(" ")[0] + " " + str(r["status"])
        groups.setdefault((r["formulation"], r["solver"], kind), []).append(r)
    lines = []
    for (form, solver, _), rs in sorted(groups.items()):
        where = ", ".join(f"{r['instance']}/{r['size']}" for r in rs)
        msg = str(rs[0]["message"] or "").replace("|", "/").replace("\n", " ")[:160]
        lines.append(f"- **{solver}** ({form}) at {where}: {rs[0]['reason']}"
                     + (f" — `{msg}`" if msg else ""))
    return lines


def write_harness_report(out: Path, rows: list[dict[str, Any]], *, profile: str,
                         time_limit: float, error_tol: float, violation_tol: float,
                         notes: dict[str, str] | None = None,
                         env: dict[str, Any] | None = None) -> str:
    """Write ``report.md``, one scaling plot per problem (``<problem>_scaling.png``) and
    ``summary.csv`` for a harness sweep; return the Markdown."""
    from optmodels import plots
    from solvers_cmp import cases as cs
    from solvers_cmp.harness import summarise

    out.mkdir(parents=True, exist_ok=True)
    summary = summarise(rows, time_limit)
    write_csv(out / "summary.csv", summary)
    env = env or environment()
    problems = [p for p in cs.REGISTRY if any(r["problem"] == p for r in rows)]
    problems += sorted({r["problem"] for r in rows} - set(problems))
    md = [
        "# Solver and formulation comparison\n",
        f"Profile **{profile}**: success = status OK **and** solution error ≤ "
        f"{error_tol:.0e} against the reference **and** re-computed violation of the "
        f"original problem ≤ {violation_tol:.0e}. Time limit {time_limit:g} s per run; a "
        "failure is charged the time limit. Times are shifted geometric means (shift "
        "10 ms) over the problem's cases; `rel_*` divides by the best of the problem "
        "(1.0 = fastest). Build = CVXPY canonicalisation or CasADi construction; solve = "
        "the solver's own time. Full rows: `results.csv`; this table: `summary.csv`.\n",
        f"Machine: {env['cpu']}, {env['cores']} cores; Python {env['python']}; "
        + ", ".join(f"{k} {v}" for k, v in env["packages"].items() if v) + ".\n",
    ]
    n_ok = sum(r["success"] for r in rows)
    md.append(f"{len(rows)} runs, {n_ok} successes, {len(rows) - n_ok} failures, each "
              "explained under its problem.\n")
    headline = []
    for p in problems:
        generic = [s for s in summary if s["problem"] == p and s["formulation"] != "closed_form"]
        best = min(generic, key=lambda s: (-s["success_rate"], s["sgm_solve_time"]
                                           + s["sgm_build_time"]), default=None)
        cf = next((s for s in summary if s["problem"] == p
                   and s["formulation"] == "closed_form"), None)
        if best is not None:
            headline.append({"problem": p, "best generic": f"{best['solver']} "
                             f"({best['formulation']})",
                             "success": best["success_rate"],
                             "solve (sgm, s)": best["sgm_solve_time"],
                             "build (sgm, s)": best["sgm_build_time"],
                             "closed form (sgm, s)": cf["sgm_solve_time"] if cf else "—",
                             "max error": best["max_error"]})
    md.append("## Headline\n")
    md.append(markdown_table(headline, ["problem", "best generic", "success",
                                        "solve (sgm, s)", "build (sgm, s)",
                                        "closed form (sgm, s)", "max error"],
                             {"success": ".0%", "solve (sgm, s)": ".2e",
                              "build (sgm, s)": ".2e", "closed form (sgm, s)": ".2e",
                              "max error": ".1e"}))
    for p in problems:
        mine = [r for r in rows if r["problem"] == p]
        try:
            ad = cs.adapter(p)
            doc = " ".join((type(ad).__doc__ or "").split())
            size_label = ad.size_meaning or "size"
        except Exception:  # a user adapter that no longer imports
            doc, size_label = "", "size"
        fig = plots.scaling(out / f"{p}_scaling.png", mine, title=p, size_label=size_label,
                            time_limit=time_limit)
        md.append(f"\n## {p}\n\n{doc}\n")
        md.append(markdown_table([s for s in summary if s["problem"] == p], _SUMMARY_COLS,
                                 _SUMMARY_FMT))
        md.append(f"\n![{p} scaling]({fig.name})\n")
        fails = _failure_lines(mine)
        if fails:
            md.append("\nFailures:\n\n" + "\n".join(fails) + "\n")
    if notes:
        md.append("\n## Solvers left out\n\n" + "\n".join(f"- {k}: {v}"
                                                        for k, v in notes.items()) + "\n")
    text = "\n".join(md)
    (out / "report.md").write_text(text)
    return text
