"""Fusion of two estimates (paper 003): CVXPY solvers on the generic fusion problems
against the closed forms, IPOPT against Gauss-Newton on the two-site joint ML, and the
Monte Carlo benchmark of Ŵ.

Rows follow DESIGN.md's columns. Fusion: ``solution_error`` is max |α − α_cf| / max |α_cf|
(independent estimates: the WLS min Σ(α − a_μ)ᵀC_μ(α − a_μ); correlated: the
minimum-trace weight), ``max_violation`` the relative optimality residual re-computed in
NumPy. Joint ML: ``solution_error`` is the largest distance to the Gauss-Newton solution in
units of the CRB RMS. Times are medians of ``repeats`` runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels import fusion as fu
from optmodels.backends.cvxpy_backend import available_solvers
from solvers_cmp.common import repeat

#: CVXPY solvers that accept the (unconstrained) least-squares fusion problems.
QP_SOLVERS = ("CLARABEL", "OSQP", "SCS", "PIQP", "PROXQP", "DAQP", "QOCO", "ECOS", "CVXOPT")
DIMENSIONS = (2, 3, 6, 20)
ROWS_ML = (1, 100, 1000)


def instance(m: int, seed: int, correlated: bool) -> dict[str, np.ndarray]:
    """Two estimates of an m-vector with random SPD covariances; with ``correlated`` a
    joint covariance of rank 2m − 1 (singular D, as in the two-site system)."""
    rng = np.random.default_rng([seed, m, int(correlated)])
    rank = 2 * m - 1 if correlated else 2 * m
    a = rng.normal(size=(2 * m, rank))
    joint = a @ a.T + (0.0 if correlated else 0.1) * np.eye(2 * m)
    out = {"a1": rng.normal(size=m), "a2": rng.normal(size=m), "s1": joint[:m, :m],
           "s2": joint[m:, m:]}
    if correlated:
        out["s12"] = joint[:m, m:]
    return out


def _fusion_rows(dimensions: tuple[int, ...], use: list[str], seed: int, repeats: int,
                 progress: bool) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    cases = [(c, m) for c in (False, True) for m in dimensions]
    for corr, m in tqdm(cases, desc="fusion comparison", disable=not progress):
        d = instance(m, seed, corr)
        kw = {"s12": d["s12"]} if corr else {}
        cf = repeat(lambda d=d, kw=kw: fu.fuse(d["a1"], d["s1"], d["a2"], d["s2"], **kw),
                    repeats)
        ref = cf.last
        scale = float(np.max(np.abs(ref.estimate)))
        runs = [("closed_form", "numpy", ref, 0.0, cf.median)]
        for s in use:
            sols = repeat(lambda d=d, kw=kw, s=s: fu.fuse(
                d["a1"], d["s1"], d["a2"], d["s2"], method="cvxpy", solver=s, **kw),
                repeats).results
            runs.append(("min-trace W" if corr else "weighted LSQ", s, sols[-1],
                         float(np.median([x.build_time for x in sols])),
                         float(np.median([x.solve_time for x in sols]))))
        for form, solver, sol, build, solve in runs:
            ok = sol.status.ok
            out.append({
                "problem": "fusion", "case": "correlated" if corr else "independent",
                "size": m, "seed": seed, "formulation": form, "solver": solver,
                "settings": "default", "status": sol.status.value,
                "objective": sol.objective,
                "objective_gap": (sol.objective - ref.objective) / abs(ref.objective)
                if ok else float("nan"),
                "solution_error": float(np.max(np.abs(sol.estimate - ref.estimate))) / scale
                if ok else float("nan"),
                "max_violation": sol.max_residual, "build_time": build, "solve_time": solve,
                "total_time": build + solve, "iterations": sol.iterations,
            })
    return out


def _ml_rows(ml_rows: tuple[int, ...], seed: int, repeats: int) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    system = fu.TwoSiteSystem.on_baseline()
    x = np.array([8_000.0, 30_000.0])
    crb = float(np.sqrt(np.trace(system.crb(x))))
    for t in ml_rows:
        z = system.sample(x, t, np.random.default_rng([seed, t]))
        gn = repeat(lambda z=z: system.joint_ml(z, method="gauss_newton"), repeats)
        ref = gn.last
        fu.clear_joint_cache()  # the first IPOPT run pays the CasADi build (reported)
        ip = repeat(lambda z=z: system.joint_ml(z), repeats)
        for name, rep, build in (("gauss_newton", gn, 0.0),
                                 ("casadi:ipopt", ip, ip.results[0].build_time)):
            sol = rep.last
            solve = float(np.median([r.solve_time for r in rep.results]))
            out.append({
                "problem": "fusion", "case": "two-site joint ML", "size": t, "seed": seed,
                "formulation": "ML (all 3 measurements)", "solver": name,
                "settings": "default", "status": sol.status.value,
                "objective": sol.objective,
                "objective_gap": (sol.objective - ref.objective) / ref.objective,
                "solution_error": float(np.max(np.linalg.norm(
                    sol.estimate - ref.estimate, axis=1))) / crb,
                "max_violation": sol.max_residual, "build_time": build,
                "solve_time": solve, "total_time": build + solve,
                "iterations": sol.iterations,
            })
    return out


def rows(dimensions: tuple[int, ...] = DIMENSIONS, ml_rows: tuple[int, ...] = ROWS_ML, *,
         seed: int = 0, repeats: int = 3, solvers: tuple[str, ...] | None = None,
         progress: bool = False) -> list[dict[str, Any]]:
    """Every (independent | correlated, m) × (closed form, CVXPY solver), and the two-site
    joint ML for T rows by Gauss-Newton and IPOPT."""
    installed = set(available_solvers())
    use = [s for s in (solvers or QP_SOLVERS) if s in installed]
    return (_fusion_rows(dimensions, use, seed, repeats, progress)
            + _ml_rows(ml_rows, seed, repeats))


def benchmark(*, repeats: int = 5, seed: int = 0) -> list[dict[str, Any]]:
    """The issue's target: :func:`optmodels.fusion.monte_carlo_weight`, 10⁵ trials at m = 3
    (≤ 2 s), and the first-order Cov(vec Ŵ) (10); wall seconds, median and best."""
    s1 = np.diag([1.0, 2.0, 3.0])
    s2 = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 1.5]])
    cases = [
        ("monte_carlo_weight, 10⁵ trials, m = 3",
         lambda: fu.monte_carlo_weight(s1, s2, 30, 30, trials=100_000, seed=seed)),
        ("weight_covariance (10), m = 3", lambda: fu.weight_covariance(s1, s2, 30, 30)),
        ("weight_jacobians, CasADi AD, m = 3",
         lambda: fu.weight_jacobians(s1, s2, method="ad")),
    ]
    res = []
    for name, fn in cases:
        rep = repeat(fn, repeats)
        res.append({"case": name, "median_s": rep.median, "min_s": rep.best})
    return res
