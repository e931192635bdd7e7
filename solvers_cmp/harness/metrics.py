"""Summary metrics of a sweep: shifted geometric means (qpbenchmark) and the per
(problem, formulation, solver) summary."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np


def shifted_geometric_mean(times: Iterable[float], shift: float = 0.01) -> float:
    """exp(mean log(t + shift)) − shift (qpbenchmark; shift 10 ms keeps sub-millisecond
    times from dominating)."""
    t = np.asarray(list(times), dtype=float)
    if t.size == 0:
        return float("nan")
    return float(np.exp(np.mean(np.log(t + shift))) - shift)


def summarise(rows: Sequence[dict[str, Any]], time_limit: float) -> list[dict[str, Any]]:
    """Per (problem, formulation, solver): runs, success rate, shifted geometric means of
    solve and build time (failures charged ``time_limit``), each also normalised to the
    best of its problem, worst error and violation among successes."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["problem"], r["formulation"], r["solver"]), []).append(r)
    out = []
    for (problem, form, solver), rs in groups.items():
        succ = [r for r in rs if r["success"]]
        solve = [r["solve_time"] if r["success"] else time_limit for r in rs]
        build = [r["build_time"] if r["success"] else time_limit for r in rs]
        out.append({
            "problem": problem, "formulation": form, "solver": solver, "runs": len(rs),
            "success_rate": len(succ) / len(rs),
            "sgm_solve_time": shifted_geometric_mean(solve),
            "sgm_build_time": shifted_geometric_mean(build),
            "max_error": max((r["solution_error"] for r in succ), default=float("nan")),
            "max_violation": max((r["max_violation"] for r in succ), default=float("nan")),
        })
    for problem in {o["problem"] for o in out}:
        mine = [o for o in out if o["problem"] == problem]
        for key in ("sgm_solve_time", "sgm_build_time"):
            best = min(o[key] for o in mine) + 0.01
            for o in mine:
                o[key.replace("sgm", "rel")] = (o[key] + 0.01) / best
    out.sort(key=lambda o: (o["problem"], -o["success_rate"], o["sgm_solve_time"]))
    return out
