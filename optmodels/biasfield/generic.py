r"""The generic formulations of the smoothest bias field (paper 001, section 4, (8)-(10)),
solved in CVXPY: the QP (9)-(10) [+ box (8)] (:func:`solve`) and the Lipschitz class's SOCP
(:func:`solve_lipschitz`).

Original problem (9)-(10), optionally with the box (8):

.. math::
    \min_{\varphi,\eta}\ \varphi^T R\varphi,\quad R = Q\otimes P,\qquad
    \text{s.t.}\ \varphi = \Phi^0 + \Phi^1\eta,\quad
    |f^1_{j}| \le K^1,\ |f^2_{j}| \le K^2 .

φ stacks f(x̌_k) = [f_1; …; f_m] (range, azimuth per radar) cell by cell; η_k ∈ R² per
cell; Φ¹ is block-diagonal (see :mod:`optmodels.biasfield.data`). The objective is written
as ‖Gφ‖² with the sparse edge-difference factor G (one 2m-row block √a_ij (f_i − f_j)ᵀL
per neighbour pair, P = LLᵀ), so GᵀG = Q ⊗ P and no dense 2mK × 2mK matrix exists
(:mod:`~optmodels.biasfield.problem`).

The Lipschitz class: the smallest L with ‖f(x_i) − f(x_j)‖_P ≤ L‖x_i − x_j‖ on neighbour
pairs, an SOCP over the same sets with one second-order cone per neighbour pair, solved
with φ eliminated and re-checked through the solver's dual certificate
(:func:`optmodels.biasfield.verify.lipschitz_residuals`) in the scaled variables of
:func:`optmodels.biasfield.problem.lipschitz_data`.

Both read validate (:func:`~optmodels.biasfield.problem.check_arguments`, the box's
feasibility cell by cell) → build (the scaled CVXPY model) → run
(:func:`~optmodels.biasfield.problem.run_solver`) → finish (packed and re-checked in NumPy
by :mod:`~optmodels.biasfield.verify`, ending in its gate). The closed form (11) is
:mod:`~optmodels.biasfield.closedform`.
"""

from __future__ import annotations

from typing import Any, Literal

import cvxpy as cp
import numpy as np
from scipy import sparse

from optmodels.backends.profiles import DEFAULTS, solver_options
from optmodels.biasfield import problem
from optmodels.biasfield.data import FieldData
from optmodels.biasfield.problem import (
    check_arguments,
    edge_factor,
    lipschitz_data,
    variable_scales,
)
from optmodels.biasfield.solution import FieldSolution
from optmodels.biasfield.verify import (
    box_feasibility,
    failed_solution,
    pack_solution,
    recheck_lipschitz,
    recheck_qp,
)
from optmodels.core import ProblemError, Status, as_positive, timed

__all__ = ["SOCP_DEFAULTS", "SOLVER_DEFAULTS", "solve", "solve_lipschitz"]


#: Default solver options: the back-end's table for QPs that must agree with a closed form
#: to ~1e-8 (the same object; the reasons for each value are given there).
SOLVER_DEFAULTS: dict[str, dict[str, Any]] = DEFAULTS["qp"]

#: Default solver options of the Lipschitz SOCP: the back-end's table for SOCPs (the same
#: object).
SOCP_DEFAULTS: dict[str, dict[str, Any]] = DEFAULTS["socp"]


# ----------------------------------------------------------------------------- QP
def solve(
    data: FieldData,
    *,
    box: tuple[float, float] | None = None,
    solver: str = "CLARABEL",
    formulation: Literal["constrained", "reduced"] = "reduced",
    **options: Any,
) -> FieldSolution:
    """The QP (9)-(10) [+ box (8)] in CVXPY.

    ``formulation="constrained"``: the original problem as written -- variables φ and η,
    the equality φ = Φ⁰ + Φ¹η, objective φᵀRφ. ``"reduced"`` (default): φ eliminated,
    min over η of (Φ⁰ + Φ¹η)ᵀR(Φ⁰ + Φ¹η) with the box on Φ⁰ + Φ¹η; the same minimiser,
    a 2K-variable quadratic form instead of 2(m + 1)K variables and 2mK equalities (at
    K = 10⁴ Clarabel needs ~2 s instead of ~45 s). R enters as a sparse ``psd_wrap``-ed
    quadratic form (CVXPY's own PSD check of a large matrix takes minutes). φ is rescaled
    per component (metres and radians differ by 10⁵) and η by the range scale before the
    solver sees them.

    Box infeasibility is diagnosed cell by cell
    (:func:`~optmodels.biasfield.verify.box_feasibility`) and reported as INFEASIBLE with
    the offending cells in ``message``; a solver failure is never returned as a field. KKT
    residuals are re-computed in NumPy (:func:`~optmodels.biasfield.verify.recheck_qp`),
    with the conditioning term κ₁(Φ¹ᵀRΦ¹)·ε of the closed form (an upper bound for the
    reduced Hessian of any active set; one extra sparse factorisation), and a claimed
    optimum failing them is downgraded (:data:`~optmodels.core.VERIFY_TOL`,
    :data:`~optmodels.core.REJECT_TOL`). ``box`` = (K1 m, K2 rad), two positive numbers; a
    solver option the solver rejects is a :class:`~optmodels.core.ProblemError` naming it.
    """
    fn = "biasfield.solve"
    n_comp, formulation, solver, bound, sets = check_arguments(fn, data, formulation, solver, box)
    method = f"cvxpy:{solver}:{formulation}"
    phi0, phi1 = sets
    if bound is not None:
        bad = box_feasibility(data, box, sets=sets)
        if bad.size:
            return failed_solution(
                data,
                sets,
                {
                    "status": Status.INFEASIBLE,
                    "method": method,
                    "message": f"box (8) misses the uncertainty sets of cells {bad[:20].tolist()}"
                    f"{' …' if bad.size > 20 else ''} ({bad.size} cells): no field "
                    "in these sets satisfies |f_range| ≤ K1, |f_azimuth| ≤ K2",
                },
                bound,
            )
    sc = variable_scales(data, phi0)
    with timed() as tb:
        gs = (edge_factor(data) @ sparse.diags(sc)).tocsr()
        rs = (gs.T @ gs).tocsc()
        u0 = phi0 / sc
        norm2 = max(float(np.sum((gs @ u0) ** 2)), 1e-300)
        # η (metres) in units of the range scale: the constraint matrix is then O(1)
        bmat = (sparse.diags(1 / sc) @ phi1 * sc[0]).tocsr()
        eta = cp.Variable(phi1.shape[1])
        if formulation == "constrained":
            u: Any = cp.Variable(phi0.size)
            cons = [u == u0 + bmat @ eta]
            obj = cp.quad_form(u, cp.psd_wrap(rs / norm2))
        else:
            u = u0 + bmat @ eta
            cons = []
            obj = (
                cp.quad_form(eta, cp.psd_wrap((bmat.T @ rs @ bmat).tocsc() / norm2))
                + (2.0 / norm2) * (bmat.T @ (rs @ u0)) @ eta
            )
        box_cons = [u <= bound / sc, -u <= bound / sc] if bound is not None else []
        prob = cp.Problem(cp.Minimize(obj), cons + box_cons)
    opts = solver_options("qp", solver, options)
    res = problem.run_solver(fn, prob, solver, opts)
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = method
    if not res.status.ok or eta.value is None:
        return failed_solution(data, sets, common, bound)
    et = np.asarray(eta.value) * sc[0]
    phi = phi0 + phi1 @ et if formulation == "reduced" else np.asarray(u.value) * sc
    duals = None
    if bound is not None:
        # multipliers of the box in φ units (the scaled objective is J / norm2)
        up = np.asarray(box_cons[0].dual_value) / sc * norm2
        lo = np.asarray(box_cons[1].dual_value) / sc * norm2
        duals = up - lo
    sol = pack_solution(data, sets, phi, et, common, bound, duals)
    sol.info["components"] = n_comp
    return recheck_qp(data, sol, box, sets)


# ----------------------------------------------------------------------------- Lipschitz
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
    ``box`` = (K1 m, K2 rad) as in :func:`solve`; a box that misses a cell's set is a
    :class:`ProblemError` (proved cell by cell,
    :func:`~optmodels.biasfield.verify.box_feasibility`).

    The solution's ``lipschitz`` is computed in NumPy from the returned field, and the
    claimed optimum is re-checked against the problem
    (:func:`~optmodels.biasfield.verify.lipschitz_residuals`):
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
        bad = box_feasibility(data, box, sets=sets)
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
    sol.info["duals"] = duals  # the solver's multipliers: the certificate checked there
    return recheck_lipschitz(data, sol, duals, box=box, cap=cap_v, sets=sets, prob_data=prob_data)
