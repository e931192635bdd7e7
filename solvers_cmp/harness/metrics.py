"""Summary metrics of a sweep: shifted geometric means (qpbenchmark), their bootstrap
intervals, the per (problem, formulation, solver) summary and the headline ranking with
ties (issue 27, item 2).

Every summary row carries ``kind``: ``original`` (a generic solve of the problem as the
paper states it), ``reduction`` (a reduced formulation, or a special case such as the
linear assignment without merges) or ``reference`` (the closed form or the exact
enumeration: the floor). The headline ranks ``original`` rows only, per problem.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

#: Shift of the shifted geometric means, s (qpbenchmark's 10 ms).
SHIFT = 0.01
#: Bootstrap resamples and level of the intervals.
N_BOOT = 2000
LEVEL = 0.95


def shifted_geometric_mean(times: Iterable[float], shift: float = SHIFT) -> float:
    """exp(mean log(t + shift)) − shift (qpbenchmark; shift 10 ms keeps sub-millisecond
    times from dominating)."""
    t = np.asarray(list(times), dtype=float)
    if t.size == 0:
        return float("nan")
    return float(np.exp(np.mean(np.log(t + shift))) - shift)


def sgm_interval(times: Sequence[float], *, shift: float = SHIFT, n_boot: int = N_BOOT,
                 level: float = LEVEL, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval (``level``) of the shifted geometric mean of
    ``times`` (s), resampling the cases with replacement (seeded: the same data give the
    same interval). One time: a zero-width interval."""
    t = np.log(np.asarray(times, dtype=float) + shift)
    if t.size == 0:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, t.size, (n_boot, t.size))
    boot = np.exp(t[idx].mean(axis=1)) - shift
    a = (1 - level) / 2
    return float(np.quantile(boot, a)), float(np.quantile(boot, 1 - a))


def formulation_kind(problem: str, formulation: str) -> str:
    """``reference``, ``reduction`` or ``original`` for a row, from its adapter's
    ``reference_formulations`` / ``reductions`` (a problem without an adapter: only
    ``closed_form`` is a reference)."""
    if formulation == "closed_form":
        return "reference"
    try:
        from solvers_cmp import cases as cs

        ad = cs.adapter(problem)
    except Exception:  # a row of a problem no longer registered
        return "original"
    if formulation in getattr(ad, "reference_formulations", ()):
        return "reference"
    if formulation in getattr(ad, "reductions", ()):
        return "reduction"
    return "original"


def summarise(rows: Sequence[dict[str, Any]], time_limit: float, *,
              n_boot: int = N_BOOT, seed: int = 0) -> list[dict[str, Any]]:
    """Per (problem, formulation, solver): runs, success rate, shifted geometric means of
    solve and build time (failures charged ``time_limit``) and of their sum ``total``
    with its bootstrap interval (``sgm_total_lo``/``_hi``), each also normalised to the
    best of its problem, worst error and violation among successes, ``kind`` and, for
    the ``original`` rows, ``rank`` within (problem, formulation) (1 = best; rows whose
    interval overlaps the best's share rank 1 and are marked ``tied``;
    :func:`rank_rows`)."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["problem"], r["formulation"], r["solver"]), []).append(r)
    out = []
    for (problem, form, solver), rs in groups.items():
        succ = [r for r in rs if r["success"]]
        solve = [r["solve_time"] if r["success"] else time_limit for r in rs]
        build = [r["build_time"] if r["success"] else time_limit for r in rs]
        total = [s + b for s, b in zip(solve, build, strict=True)] if form != "closed_form" \
            else solve
        lo, hi = sgm_interval(total, n_boot=n_boot, seed=seed)
        out.append({
            "problem": problem, "kind": formulation_kind(problem, form),
            "formulation": form, "solver": solver, "runs": len(rs),
            "success_rate": len(succ) / len(rs),
            "sgm_solve_time": shifted_geometric_mean(solve),
            "sgm_build_time": shifted_geometric_mean(build),
            "sgm_total_time": shifted_geometric_mean(total),
            "sgm_total_lo": lo, "sgm_total_hi": hi,
            "max_error": max((r["solution_error"] for r in succ), default=float("nan")),
            "max_violation": max((r["max_violation"] for r in succ), default=float("nan")),
        })
    for problem in {o["problem"] for o in out}:
        mine = [o for o in out if o["problem"] == problem]
        for key in ("sgm_solve_time", "sgm_build_time", "sgm_total_time"):
            best = min(o[key] for o in mine) + SHIFT
            for o in mine:
                o[key.replace("sgm", "rel")] = (o[key] + SHIFT) / best
        # an original formulation per sub-problem (fusion: WLS, min-trace W, ML are
        # three problems): ranks within (problem, formulation)
        for form in {o["formulation"] for o in mine if o["kind"] == "original"}:
            rank_rows([o for o in mine if o["kind"] == "original"
                       and o["formulation"] == form])
    order = {"original": 0, "reduction": 1, "reference": 2}
    out.sort(key=lambda o: (o["problem"], order[o["kind"]], o["formulation"],
                            o.get("rank", 0), -o["success_rate"], o["sgm_total_time"]))
    return out


def rank_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rank rows of one problem in place: by success rate, then ``sgm_total_time``. A row
    whose success rate equals the leader's and whose interval
    [``sgm_total_lo``, ``sgm_total_hi``] overlaps the leader's is *tied* with it (rank 1,
    ``tied=True`` for all of them when there are two or more); the others are ranked
    after (competition ranking: the next rank is the row's position), a row whose
    interval overlaps the first row of the rank before sharing that rank."""
    rows.sort(key=lambda o: (-o["success_rate"], o["sgm_total_time"]))
    head: dict[str, Any] | None = None  # the first row of the current rank
    for i, o in enumerate(rows):
        o["tied"] = False
        if head is not None and _overlap(head, o):
            o["rank"] = head["rank"]
            o["tied"] = head["tied"] = True
        else:
            o["rank"] = i + 1
            head = o
    return rows


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return (a["success_rate"] == b["success_rate"]
            and a["sgm_total_lo"] <= b["sgm_total_hi"]
            and b["sgm_total_lo"] <= a["sgm_total_hi"])


def headline(summary: Sequence[dict[str, Any]]) -> dict[str, tuple[str, ...]]:
    """Per problem and original formulation (``"problem: formulation"``), the rows of
    rank 1 (the winner and every row tied with it), as sorted solver names: what a rerun
    must reproduce."""
    out: dict[str, list[str]] = {}
    for o in summary:
        if o["kind"] == "original" and o.get("rank") == 1:
            out.setdefault(f"{o['problem']}: {o['formulation']}", []).append(o["solver"])
    return {p: tuple(sorted(v)) for p, v in out.items()}
