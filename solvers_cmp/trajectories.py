"""Dependent linear trajectories: CVXPY solvers on the constrained and reduced
formulations against the closed forms, Q = 2..100 objects with 10..1000 points each.

Rows follow DESIGN.md's columns: one per (family, Q, N, formulation, solver), times the
median of ``repeats`` runs (build = CVXPY canonicalisation, solve = the solver's own time).
``solution_error`` is max |θ − θ_cf| / max |θ_cf|; ``max_violation`` the largest relative
violation of the family's equalities and of the normal equations (stationarity),
re-computed in NumPy.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels import trajectories as tr
from optmodels.backends.cvxpy_backend import available_solvers
from solvers_cmp.common import repeat

#: CVXPY solvers that accept an equality-constrained least-squares QP, in report order.
QP_SOLVERS = ("CLARABEL", "OSQP", "SCS", "PIQP", "PROXQP", "DAQP", "QOCO", "ECOS", "CVXOPT")
FORMULATIONS = ("constrained", "reduced")
FAMILIES = ("diverging", "parallel")
OBJECTS = (2, 10, 100)
POINTS = (10, 100, 1000)


def instance(family: str, q: int, n: int, seed: int) -> tr.TrajectoryData:
    """Q objects, N points each at jittered, object-specific times over 0..1000 s, σ = 1."""
    rng = np.random.default_rng([seed, q, n, FAMILIES.index(family)])
    times = [np.sort(rng.uniform(0, 1000, n)) for _ in range(q)]
    if family == "diverging":
        start, vel = np.full(q, 100.0), rng.uniform(-5, 5, q)
    else:
        start, vel = rng.uniform(-1e3, 1e3, q), np.full(q, 2.0)
    vals = [start[j] + vel[j] * t + rng.normal(0, 1, n) for j, t in enumerate(times)]
    return tr.TrajectoryData(times, vals, 1.0)


def rows(objects: tuple[int, ...] = OBJECTS, points: tuple[int, ...] = POINTS, *,
         seed: int = 0, repeats: int = 3, solvers: tuple[str, ...] | None = None,
         progress: bool = False) -> list[dict[str, Any]]:
    """Run every (family, Q, N) × (closed form, formulation × solver)."""
    installed = set(available_solvers())
    use = [s for s in (solvers or QP_SOLVERS) if s in installed]
    out: list[dict[str, Any]] = []
    cases = [(f, q, n) for f in FAMILIES for q in objects for n in points]
    for family, q, n in tqdm(cases, desc="trajectories comparison", disable=not progress):
        data = instance(family, q, n, seed)
        cf = repeat(lambda d=data, f=family: tr.closed_form(d, f), repeats)
        ref = cf.last
        scale = float(np.max(np.abs(ref.theta)))
        # (formulation, solver, solution, build time, solve time): closed form first
        runs: list[tuple[str, str, tr.TrajectorySolution, float, float]] = [
            ("closed_form", "numpy", ref, 0.0, cf.median)]
        for form in FORMULATIONS:
            for s in use:
                sols = repeat(lambda d=data, f=family, fo=form, so=s:
                              tr.solve(d, f, formulation=fo, solver=so), repeats).results
                runs.append((form, s, sols[-1],
                             float(np.median([x.build_time for x in sols])),
                             float(np.median([x.solve_time for x in sols]))))
        for form, solver, sol, build, solve in runs:
            ok = sol.status.ok
            out.append({
                "problem": "trajectories", "family": family, "objects": q, "points": n,
                "size": q * n, "seed": seed, "formulation": form, "solver": solver,
                "settings": "default", "status": sol.status.value,
                "objective": sol.objective,
                "objective_gap": (sol.objective - ref.objective) / ref.objective if ok
                else float("nan"),
                "solution_error": float(np.max(np.abs(sol.theta - ref.theta))) / scale if ok
                else float("nan"),
                "max_violation": sol.max_residual, "build_time": build, "solve_time": solve,
                "total_time": build + solve, "iterations": sol.iterations,
            })
    return out


def benchmark(q: int = 100, n: int = 1000, *, repeats: int = 5, seed: int = 0
              ) -> list[dict[str, Any]]:
    """The issue's benchmark: Q objects × N points, wall time of the closed form and of the
    constrained CVXPY solve (build + solve), median and best of ``repeats``."""
    res = []
    for family in FAMILIES:
        data = instance(family, q, n, seed)
        cases = [("closed form", lambda d=data, f=family: tr.closed_form(d, f))]
        cases += [(f"CVXPY {s} constrained (build + solve)",
                   lambda d=data, f=family, so=s: tr.solve(d, f, solver=so))
                  for s in ("CLARABEL", "OSQP") if s in available_solvers()]
        for name, fn in cases:
            rep = repeat(fn, repeats)
            for sol in rep.results:
                sol.require_ok()
            res.append({"case": f"{family}: {name}", "objects": q, "points": n,
                        "median_s": rep.median, "min_s": rep.best})
    return res
