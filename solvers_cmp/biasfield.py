"""Bias field selection (paper 001, section 4): CVXPY QP solvers on the constrained and
reduced formulations, with and without a binding box (8), against the sparse closed form
(11) -- on synthetic uncertainty sets (:func:`optmodels.biasfield.synthetic_field_data`).

Rows follow DESIGN.md's columns. ``solution_error``: max over the two components (range,
azimuth) of max |f − f_ref| / max |f_ref|, the reference being the closed form without a
box and the best (lowest-J) optimal solve with one; ``max_violation``: the largest NumPy
KKT/feasibility residual. Times are medians of ``repeats`` runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels import biasfield as bf
from optmodels.backends.cvxpy_backend import available_solvers
from optmodels.biasfield import selection as sel
from solvers_cmp.common import repeat

QP_SOLVERS = ("CLARABEL", "OSQP", "SCS", "PIQP", "PROXQP", "QOCO")
FORMULATIONS = ("constrained", "reduced")
CELLS = (100, 500)
#: Box at this fraction of the unconstrained field's largest |f| per component: binds in a
#: few cells and stays feasible (checked per instance).
BOX_FRACTION = 0.99


def binding_box(data: bf.FieldData, cf: sel.FieldSolution) -> tuple[float, float] | None:
    """The tightest of 99 %, 99.5 %, 99.9 % of the unconstrained field's largest |f| (per
    component) that every cell's uncertainty set still meets, or None."""
    big = np.abs(cf.field).max(axis=(0, 1))
    for frac in (BOX_FRACTION, 0.995, 0.999):
        box = (frac * float(big[0]), frac * float(big[1]))
        if sel.box_feasibility(data, box).size == 0:
            return box
    return None


def _error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b).max(axis=(0, 1)) / np.abs(b).max(axis=(0, 1))))


def rows(cells: tuple[int, ...] = CELLS, *, seed: int = 0, repeats: int = 3,
         solvers: tuple[str, ...] | None = None, progress: bool = False,
         formulations: tuple[str, ...] = FORMULATIONS) -> list[dict[str, Any]]:
    """Every K × (no box, binding box) × (closed form, formulation × solver)."""
    installed = set(available_solvers())
    use = [s for s in (solvers or QP_SOLVERS) if s in installed]
    out: list[dict[str, Any]] = []
    cases = [(k, b) for k in cells for b in (False, True)]
    for k, with_box in tqdm(cases, desc="biasfield comparison", disable=not progress):
        data, _ = bf.synthetic_field_data(seed, cells=k)
        cf_rep = repeat(lambda d=data: bf.closed_form(d), repeats)
        cf = cf_rep.last
        box = binding_box(data, cf) if with_box else None
        if with_box and box is None:
            continue
        runs: list[tuple[str, str, Any, float, float]] = []
        if not with_box:
            runs.append(("closed_form", "numpy", cf, 0.0, cf_rep.median))
        for form in formulations:
            for s in use:
                sols = repeat(lambda d=data, s=s, f=form, b=box: bf.solve(
                    d, box=b, solver=s, formulation=f), repeats).results
                runs.append((form, s, sols[-1], float(np.median([x.build_time for x in sols])),
                             float(np.median([x.solve_time for x in sols]))))
        ok = [r[2] for r in runs if r[2].status.ok]
        ref = cf if not with_box else min(ok, key=lambda x: x.objective) if ok else None
        for form, solver, sol, build, solve in runs:
            good = sol.status.ok and ref is not None
            out.append({
                "problem": "biasfield", "case": "box (8) binding" if with_box else "no box",
                "size": k, "radars": data.m, "seed": seed, "formulation": form,
                "solver": solver, "settings": "default", "status": sol.status.value,
                "objective": sol.objective,
                "objective_gap": (sol.objective - ref.objective) / ref.objective if good
                else float("nan"),
                "solution_error": _error(sol.field, ref.field) if good else float("nan"),
                "max_violation": sol.max_residual,
                "active_bounds": int(np.sum(sol.active != 0)) if sol.status.ok else 0,
                "build_time": build, "solve_time": solve, "total_time": build + solve,
                "iterations": sol.iterations,
            })
    return out


def benchmark(cells: int = 10_000, *, repeats: int = 3, seed: int = 0,
              dense: bool = True) -> list[dict[str, Any]]:
    """The issue's targets at K cells, m = 4: sparse closed form (≤ 1 s, ≥ 20× a dense
    solve of the same 2K × 2K system) and the QP with a binding box (≤ 30 s with the best
    solver): wall seconds, median and best of ``repeats``."""
    data, _ = bf.synthetic_field_data(seed, cells=cells)
    cf = bf.closed_form(data)
    box = binding_box(data, cf)
    phi0, phi1 = bf.uncertainty_sets(data)
    r = sel._r_matrix(data)

    def dense_solve() -> np.ndarray:
        a = (phi1.T @ r @ phi1).toarray()
        return -np.linalg.solve(a, phi1.T @ (r @ phi0))

    cases: list[tuple[str, Any, int]] = [("sparse closed form (11)",
                                          lambda: bf.closed_form(data), repeats)]
    if dense:
        cases.append(("dense solve of the same system", dense_solve, 1))
    cases += [(f"QP + box, reduced, {s}", lambda s=s: bf.solve(data, box=box, solver=s,
                                                               formulation="reduced"), repeats)
              for s in ("CLARABEL", "OSQP") if s in available_solvers()]
    res = []
    for name, fn, n in cases:
        rep = repeat(fn, n)
        res.append({"case": name, "cells": cells, "median_s": rep.median, "min_s": rep.best})
    return res


def lipschitz_benchmark(cells: tuple[int, ...] = (1000, 5000), *, repeats: int = 3,
                        seed: int = 0, formulations: tuple[str, ...] = ("reduced",),
                        solver: str = "CLARABEL") -> list[dict[str, Any]]:
    """The Lipschitz SOCP (:func:`optmodels.biasfield.solve_lipschitz`) at K cells, m = 4:
    wall seconds (median and best of ``repeats``), build and solve time, iterations, L and
    the largest re-check residual, per formulation. ``"constrained"`` (φ, η and the 2mK
    equalities, the formulation used before issue 14) takes ~90 s at K = 5000: pass it
    explicitly. Issue 14's target: the reduced form under 10 s at K = 5000."""
    out = []
    for k in cells:
        data, _ = bf.synthetic_field_data(seed, cells=k)
        for form in formulations:
            rep = repeat(lambda d=data, f=form: bf.solve_lipschitz(d, solver=solver,
                                                                   formulation=f), repeats)
            sol = rep.last
            out.append({"case": f"Lipschitz SOCP, {form}, {solver}", "cells": k,
                        "median_s": rep.median, "min_s": rep.best,
                        "build_s": sol.build_time, "solve_s": sol.solve_time,
                        "iterations": sol.iterations, "status": sol.status.value,
                        "lipschitz": sol.lipschitz, "max_residual": sol.max_residual})
    return out
