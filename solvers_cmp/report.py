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

PACKAGES = ("optmodels", "numpy", "scipy", "cvxpy", "casadi", "clarabel", "osqp", "scs", "highspy")


def environment() -> dict[str, Any]:
    """Package versions and the machine, recorded beside every result set."""
    versions = {}
    for p in PACKAGES:
        try:
            versions[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            versions[p] = None
    import os

    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "packages": versions,
    }


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


def _benchmark(
    out: Path,
    problem: str,
    bench: list[dict[str, Any]] | None,
    intro: str,
    cols: list[str],
    digits: str,
) -> str:
    """Write ``{problem}_benchmark.csv`` and return its Markdown paragraph ('' if none)."""
    if not bench:
        return ""
    write_csv(out / f"{problem}_benchmark.csv", bench)
    return f"\n{intro}\n\n" + markdown_table(bench, cols, {"median_s": digits, "min_s": digits})


# ============================================================== the harness report
_SUMMARY_COLS = [
    "kind",
    "rank",
    "formulation",
    "solver",
    "runs",
    "success_rate",
    "sgm_total_time",
    "total 95% interval (s)",
    "× leader (95%)",
    "sgm_solve_time",
    "sgm_build_time",
    "rel_total_time",
    "max_error",
    "max_violation",
    "efficiency",
]
_SUMMARY_FMT = {
    "success_rate": ".0%",
    "sgm_solve_time": ".2e",
    "rel_total_time": ".1f",
    "sgm_build_time": ".2e",
    "sgm_total_time": ".2e",
    "max_error": ".1e",
    "max_violation": ".1e",
}


def _interval(s: dict[str, Any]) -> str:
    return f"{s['sgm_total_lo']:.2e} – {s['sgm_total_hi']:.2e}"


def _ratio(s: dict[str, Any]) -> str:
    """The paired time ratio to the leader of its (problem, formulation) with its 95 %
    interval; '—' for rows outside the ranking."""
    if "ratio_to_best" not in s:
        return "—"
    return f"{s['ratio_to_best']:.2f} ({s['ratio_lo']:.2f}–{s['ratio_hi']:.2f})"


def _eff(s: dict[str, Any]) -> str:
    """Efficiency Σ CRB / Σ squared error over the draws (:func:`~solvers_cmp.harness.
    metrics.efficiency`), with the number of draws; '—' where the problem has no bound."""
    if not s.get("draws"):
        return "—"
    return f"{s['efficiency']:.2f} ({s['draws']})"


def _display(summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Summary rows for the Markdown tables: the interval as text, ties marked (``1=``),
    no rank for reductions and references."""
    out = []
    for s in summary:
        d = dict(s)
        d["total 95% interval (s)"] = _interval(s)
        d["× leader (95%)"] = _ratio(s)
        d["efficiency"] = _eff(s)
        d["rank"] = f"{s['rank']}{'=' if s.get('tied') else ''}" if "rank" in s else "—"
        out.append(d)
    return out


#: Failure kinds of the harness rows and why they are expected (the demo's summary).
FAILURE_KINDS = {
    "time_limit": "the run passed the time limit (a solver too slow at this size, "
    "charged the limit in the means)",
    "error": "the solver failed or its answer failed the package's NumPy re-check "
    "(never counted as a solution)",
    "crashed": "the solver killed its worker process (isolated; the sweep went on)",
    "inaccurate": "the solver returned an answer outside the success bar (error or "
    "violation above the profile's tolerance)",
}


def harness_info(
    rows: list[dict[str, Any]], time_limit: float, skipped: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """The numbers a summary prints: per problem the headline (rank-1 generic solves of
    the original problem, ties included, with their interval and efficiency) and the
    failures by kind (:data:`FAILURE_KINDS`)."""
    from solvers_cmp.harness import summarise

    summary = summarise(rows, time_limit, skipped=skipped or ())
    head = {}
    for s in summary:
        if s["kind"] == "original" and s.get("rank") == 1:
            head.setdefault(f"{s['problem']}: {s['formulation']}", []).append(
                {
                    "solver": s["solver"],
                    "formulation": s["formulation"],
                    "sgm_total_s": s["sgm_total_time"],
                    "interval_s": [s["sgm_total_lo"], s["sgm_total_hi"]],
                    "success_rate": s["success_rate"],
                    "tied": bool(s.get("tied")),
                    "ratio_to_best": [
                        s.get("ratio_to_best", 1.0),
                        s.get("ratio_lo", 1.0),
                        s.get("ratio_hi", 1.0),
                    ],
                    "efficiency": s["efficiency"] if s["draws"] else None,
                }
            )
    kinds: dict[str, int] = {}
    for r in rows:
        if not r["success"]:
            k = r["status"] if r["status"] in ("time_limit", "error", "crashed") else "inaccurate"
            kinds[k] = kinds.get(k, 0) + 1
    return {"headline": head, "failure_kinds": kinds}


def _next(summary: list[dict[str, Any]], form: str) -> str:
    """The best original row of ``form`` after the rank-1 rows: its solver and paired
    ratio to the leader (interval), or '—'."""
    rest = [
        s
        for s in summary
        if s["kind"] == "original" and s["formulation"] == form and s.get("rank", 1) != 1
    ]
    if not rest:
        return "—"
    return f"{rest[0]['solver']} {_ratio(rest[0])}"


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
        lines.append(
            f"- **{solver}** ({form}) at {where}: {rs[0]['reason']}"
            + (f" — `{msg}`" if msg else "")
        )
    return lines


def _headline_rows(problems: list[str], summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The headline table: per problem and original formulation, the best generic solve
    (the tied leaders named together), its interval, the next solver's ratio, the
    efficiency, the best reduction and the floor (closed form, enumeration)."""
    headline = []
    for p in problems:
        mine_s = [s for s in summary if s["problem"] == p]
        floor = [s for s in mine_s if s["kind"] == "reference"]
        red = sorted(
            (s for s in mine_s if s["kind"] == "reduction"),
            key=lambda s: (-s["success_rate"], s["sgm_total_time"]),
        )
        forms = sorted({s["formulation"] for s in mine_s if s["kind"] == "original"})
        for form in forms:
            best = [
                s
                for s in mine_s
                if s["kind"] == "original" and s.get("rank") == 1 and s["formulation"] == form
            ]
            headline.append(
                {
                    "problem": p,
                    "original problem": form,
                    "best generic": " = ".join(s["solver"] for s in best)
                    + (" (tied)" if len(best) > 1 else ""),
                    "success": best[0]["success_rate"],
                    "total (sgm, s)": best[0]["sgm_total_time"],
                    "95% interval (s)": _interval(best[0]),
                    "next (× leader, 95%)": _next(mine_s, form),
                    "efficiency": " / ".join(_eff(s) for s in best),
                    "best reduction": (
                        f"{red[0]['solver']} ({red[0]['formulation']}): "
                        f"{red[0]['sgm_total_time']:.2e} s"
                    )
                    if red
                    else "—",
                    "floor (s)": " / ".join(
                        f"{s['formulation']} {s['sgm_total_time']:.2e}" for s in floor
                    )
                    or "—",
                }
            )
    return headline


#: The columns of the headline table, in order.
_HEADLINE_COLS = [
    "problem",
    "original problem",
    "best generic",
    "success",
    "total (sgm, s)",
    "95% interval (s)",
    "next (× leader, 95%)",
    "efficiency",
    "best reduction",
    "floor (s)",
]


def _headline(problems: list[str], summary: list[dict[str, Any]]) -> list[str]:
    """The ``Headline`` section: how the solves are ranked and tied, and the table."""
    from solvers_cmp.harness.metrics import N_BOOT, TIE_MARGIN

    return [
        "## Headline\n",
        "Generic solves of the **original** problem ranked per problem by success "
        "rate, then the shifted geometric mean of build + solve time over the "
        "problem's cases; the 95 % interval is a percentile bootstrap over the cases "
        f"({N_BOOT} resamples, seeded); solvers whose intervals overlap the leader's "
        "are **tied** (`1=`) and named together — a rerun may swap them, not the "
        "headline. Reductions (reduced formulations, the linear assignment without "
        "merges) and the floor (closed form, enumeration) have their own rows.\n",
        "Ties are decided on the cases every solver of the problem ran, *paired*: "
        "`× leader` is the ratio of a solver's shifted geometric mean to the "
        "leader's with the 95 % interval of the same bootstrap over the cases (the "
        "spread of case sizes cancels); a solver is tied with the leader when that "
        f"interval reaches below {TIE_MARGIN:g} (the run-to-run spread of the same "
        "solver on this shared machine). A run the quick sweep leaves out as too "
        "slow counts as a failure of its solver. **Efficiency** (estimation "
        "problems): Σ Cramér–Rao bound / Σ squared error of the estimate against the "
        "truth over the seeded draws (number of draws in brackets); 1 = efficient "
        "(up to the draws' Monte Carlo spread, shared by every solver of the "
        "problem), below 1 = what an early stop costs the estimate.\n",
        markdown_table(
            _headline_rows(problems, summary),
            _HEADLINE_COLS,
            {"success": ".0%", "total (sgm, s)": ".2e"},
        ),
    ]


def _skipped_section(skipped: list[dict[str, Any]]) -> list[str]:
    """``Left out of this quick sweep``: the runs the profile marks as too slow, grouped
    by problem, solver and reason."""
    groups: dict[tuple[str, str, str], list[str]] = {}
    for k in skipped:
        groups.setdefault((k["problem"], k["solver"], k["why"]), []).append(
            f"{k['instance']}/{k['formulation']}/{k['size']}"
        )
    return [
        "\n## Left out of this quick sweep\n\nRuns the profile marks as too "
        "slow for their size (`solvers_cmp.harness.profiles.TOO_SLOW`, measured); "
        "a full `optmodels compare` runs them:\n",
        "\n".join(
            f"- {p}: **{sv}** at {', '.join(w)} — {why}" for (p, sv, why), w in groups.items()
        )
        + "\n",
    ]


def _problem_section(
    out: Path,
    p: str,
    rows: list[dict[str, Any]],
    summary: list[dict[str, Any]],
    instance_notes: dict[str, list[dict[str, Any]]],
    time_limit: float,
) -> list[str]:
    """Problem ``p``'s section: its adapter's description, its summary table, its
    instances' notes, its scaling plot (written to ``out``) and its failures."""
    from optmodels import plots
    from solvers_cmp import cases as cs

    mine = [r for r in rows if r["problem"] == p]
    try:
        ad = cs.adapter(p)
        doc = " ".join((type(ad).__doc__ or "").split())
        size_label = ad.size_meaning or "size"
    except Exception:  # a user adapter that no longer imports
        doc, size_label = "", "size"
    fig = plots.scaling(
        out / f"{p}_scaling.png", mine, title=p, size_label=size_label, time_limit=time_limit
    )
    md = [f"\n## {p}\n\n{doc}\n"]
    md.append(
        markdown_table(
            _display([s for s in summary if s["problem"] == p]), _SUMMARY_COLS, _SUMMARY_FMT
        )
    )
    notes_p = instance_notes.get(p)
    if notes_p:
        md.append(
            "\nInstances:\n\n"
            + markdown_table(notes_p, list(notes_p[0]), {"merge gain (ln)": ".2f"})
        )
    md.append(f"\n![{p} scaling]({fig.name})\n")
    fails = _failure_lines(mine)
    if fails:
        md.append("\nFailures:\n\n" + "\n".join(fails) + "\n")
    return md


def write_harness_report(
    out: Path,
    rows: list[dict[str, Any]],
    *,
    profile: str,
    time_limit: float,
    error_tol: float,
    violation_tol: float,
    notes: dict[str, str] | None = None,
    env: dict[str, Any] | None = None,
    skipped: list[dict[str, Any]] | None = None,
) -> str:
    """Write ``report.md``, one scaling plot per problem (``<problem>_scaling.png``) and
    ``summary.csv`` for a harness sweep; return the Markdown. ``skipped``: runs the quick
    sweep left out (problem, instance, size, formulation, solver, why)."""
    from solvers_cmp import cases as cs
    from solvers_cmp.harness import summarise

    out.mkdir(parents=True, exist_ok=True)
    summary = summarise(rows, time_limit, skipped=skipped or ())
    write_csv(out / "summary.csv", summary)
    instance_notes = _instance_notes(rows)
    env = env or environment()
    problems = [p for p in cs.REGISTRY if any(r["problem"] == p for r in rows)]
    problems += sorted({r["problem"] for r in rows} - set(problems))
    n_ok = sum(r["success"] for r in rows)
    md = [
        "# Solver and formulation comparison\n",
        f"Profile **{profile}**: success = status OK **and** solution error ≤ "
        f"{error_tol:.0e} against the reference **and** re-computed violation of the "
        f"original problem ≤ {violation_tol:.0e}. Time limit {time_limit:g} s per run; a "
        "failure is charged the time limit. Times are shifted geometric means (shift "
        "10 ms) over the problem's cases; `rel_*` divides by the best of the problem "
        "(1.0 = fastest). Build = CVXPY canonicalisation or CasADi construction; solve = "
        "the solver's own time (median of the run's repetitions; build = the first "
        "call's, measured for every row, the closed forms' included). Full rows: "
        "`results.csv` (each with its time limit, options and solver version: a rerun "
        "recomputes any row whose key differs); this table: `summary.csv`.\n",
        f"Machine: {env['cpu']}, {env['cores']} cores; Python {env['python']}; "
        + ", ".join(f"{k} {v}" for k, v in env["packages"].items() if v)
        + ".\n",
        f"{len(rows)} runs, {n_ok} successes, {len(rows) - n_ok} failures, each "
        "explained under its problem.\n",
    ]
    md += _headline(problems, summary)
    if skipped:
        md += _skipped_section(skipped)
    for p in problems:
        md += _problem_section(out, p, rows, summary, instance_notes, time_limit)
    if notes:
        md.append(
            "\n## Solvers left out\n\n" + "\n".join(f"- {k}: {v}" for k, v in notes.items()) + "\n"
        )
    text = "\n".join(md)
    (out / "report.md").write_text(text)
    return text


def _instance_notes(rows: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Per problem, what its adapter says about each case of the sweep
    (:meth:`solvers_cmp.cases.Adapter.notes`, e.g. the assignment MAP's merges and
    merge gain); computed here, once per case."""
    from solvers_cmp import cases as cs

    out: dict[str, list[dict[str, Any]]] = {}
    seen = set()
    for r in rows:
        key = (r["problem"], r["instance"], r["size"], r["seed"])
        if key in seen:
            continue
        seen.add(key)
        try:
            ad = cs.adapter(r["problem"])
            if type(ad).notes is cs.Adapter.notes:
                continue
            data = ad.make(r["instance"], r["size"], r["seed"])
            note = ad.notes(r["instance"], data, None)  # type: ignore[arg-type]
        except Exception:  # a note is optional: never fail a report for it
            continue
        if note:
            out.setdefault(r["problem"], []).append(
                {"instance": r["instance"], "size": r["size"], "seed": r["seed"], **note}
            )
    return out
