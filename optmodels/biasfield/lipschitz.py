r"""The Lipschitz class (paper 001, section 4): the field of smallest Lipschitz constant on
the uncertainty sets (10) [+ box (8)], an SOCP with one second-order cone per neighbour pair.

The claimed optimum is re-checked through the solver's dual certificate
(:func:`optmodels.biasfield.verify.lipschitz_residuals`) in the scaled variables of
``optmodels.biasfield.problem.lipschitz_data``.
"""

from __future__ import annotations

from typing import Any, Literal

import cvxpy as cp
import numpy as np

from optmodels.backends.profiles import DEFAULTS, solver_options
from optmodels.biasfield import problem
from optmodels.biasfield.fielddata import FieldData
from optmodels.biasfield.problem import (
    FieldSolution,
    check_arguments,
    failed_solution,
    lipschitz_data,
    pack_solution,
)
from optmodels.biasfield.verify import box_feasibility, lipschitz_residuals, verify_solution
from optmodels.core import ProblemError, as_positive, timed

__all__ = ["SOCP_DEFAULTS", "solve_lipschitz"]


#: Default solver options: the back-end's table for SOCPs (the same object).
SOCP_DEFAULTS: dict[str, dict[str, Any]] = DEFAULTS["socp"]


def solve_lipschitz(
    data: FieldData,
    *,
    box: tuple[float, float] | None = None,
    solver: str = "CLARABEL",
    cap: float | None = None,
    formulation: Literal["constrained", "reduced"] = "reduced",
    **options: Any,
) -> FieldSolution:
    r"""The field of smallest Lipschitz constant on neighbour pairs:

    min L  s.t.  ‖Lᵀ_P(f(x̌_i) − f(x̌_j))‖ ≤ L‖x̌_i − x̌_j‖ (all neighbour pairs),
                 φ = Φ⁰ + Φ¹η (10)  [, box (8)],

    an SOCP (Clarabel / SCS), one second-order cone of dimension 2m + 1 per edge.
    ``formulation="reduced"`` (default) eliminates φ = Φ⁰ + Φ¹η: the variables are η (2K)
    and L, and Clarabel's KKT factorisation stays sparse (K = 5000: ~4 s);
    ``"constrained"`` keeps φ and the 2mK equalities as written (K = 5000: ~90 s, the
    same optimum). ``cap`` (> 0, the units of L: √(F-norm²)/m) adds L ≤ cap (used by the
    minimality test: a cap below the optimum must make the problem infeasible).
    ``box`` = (K1 m, K2 rad) as in :func:`~optmodels.biasfield.selection.solve`; a box that
    misses a cell's set is a :class:`ProblemError` (proved cell by cell,
    :func:`~optmodels.biasfield.verify.box_feasibility`).

    The solution's ``lipschitz`` is computed in NumPy from the returned field, and the
    claimed optimum is re-checked against the problem (:func:`lipschitz_residuals`):
    ``set`` and ``box`` (the field on the sets), ``lipschitz`` (the field's L above the
    solver's), and the solver's dual certificate -- ``dual_stationarity``, ``dual_cone``
    and ``gap`` (the field's L minus the dual bound, which is a lower bound on the minimum
    L); all relative to the problem's own scale (the largest jump ratio at η = 0). Then
    :func:`optmodels.core.verified_status`: above VERIFY_TOL OPTIMAL_INACCURATE, above
    REJECT_TOL ERROR without a field. An INFEASIBLE status only comes with the solver's
    certificate (see :mod:`optmodels.backends.cvxpy_backend`).
    """
    fn = "biasfield.solve_lipschitz"
    n_comp, formulation, solver, bound, sets = check_arguments(fn, data, formulation, solver, box)
    cap_v = None if cap is None else as_positive(f"{fn} cap", cap)
    method = f"cvxpy:{solver}:lipschitz:{formulation}"
    phi0, phi1 = sets
    if bound is not None:
        bad = box_feasibility(data, box, sets=sets)  # type: ignore[arg-type]
        if bad.size:
            raise ProblemError(
                f"{fn} box: the box misses the uncertainty sets of cells {bad[:20].tolist()}"
            )
    prob_data = lipschitz_data(data, sets)
    sc, u0, bmat, dmat, dist, ref, lip0 = (
        prob_data[k] for k in ("sc", "u0", "bmat", "dmat", "dist", "ref", "lip0")
    )
    m2 = 2 * data.m
    with timed() as tb:
        eta = cp.Variable(phi1.shape[1])
        lip = cp.Variable()
        cons: list[Any] = []
        if formulation == "constrained":
            u: Any = cp.Variable(phi0.size)
            cons.append(u == u0 + bmat @ eta)
            w = (dmat / lip0) @ u
        else:
            u = u0 + bmat @ eta
            w = prob_data["db"] @ eta + prob_data["c"]
        soc = cp.SOC(lip * (dist / ref), cp.reshape(w, (dist.size, m2), order="C"), axis=1)
        cons.append(soc)
        box_cons = [u <= bound / sc, -u <= bound / sc] if bound is not None else []
        cap_cons = [lip <= cap_v * ref / lip0] if cap_v is not None else []
        prob = cp.Problem(cp.Minimize(lip), cons + box_cons + cap_cons)
    # the SOCP is solved to the solvers' own default accuracy (Clarabel's 1e-10 gap of the
    # QP defaults ends "inaccurate" here); the certificate is re-checked below anyway
    res = problem.run_solver(fn, prob, solver, solver_options("socp", solver, options))
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = method
    if not res.status.ok or eta.value is None:
        return failed_solution(data, sets, common, bound)
    et = np.asarray(eta.value, dtype=float) * sc[0]
    phi = phi0 + phi1 @ et if formulation == "reduced" else np.asarray(u.value) * sc
    jumps = np.linalg.norm((prob_data["jump"] @ phi).reshape(-1, m2), axis=1) / dist
    sol = pack_solution(data, sets, phi, et, common, bound, None, lipschitz=float(np.max(jumps)))
    sol.info["components"] = n_comp
    duals = {
        "soc": soc.dual_value,
        "upper": box_cons[0].dual_value if box_cons else None,
        "lower": box_cons[1].dual_value if box_cons else None,
        "cap": cap_cons[0].dual_value if cap_cons else None,
    }
    sol.info["solver_lipschitz"] = (
        float(lip.value) * lip0 / ref if lip.value is not None else float("nan")
    )
    sol.info["duals"] = duals  # the solver's multipliers: the certificate checked below
    sol.residuals.update(
        lipschitz_residuals(data, sol, duals, box=box, cap=cap_v, sets=sets, prob_data=prob_data)
    )
    return verify_solution(sol)
