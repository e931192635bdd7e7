r"""The smoothest bias field on the uncertainty sets (paper 001, section 4, (8)-(11)).

Original problem (9)-(10), optionally with the box (8):

.. math::
    \min_{\varphi,\eta}\ \varphi^T R\varphi,\quad R = Q\otimes P,\qquad
    \text{s.t.}\ \varphi = \Phi^0 + \Phi^1\eta,\quad
    |f^1_{j}| \le K^1,\ |f^2_{j}| \le K^2 .

φ stacks f(x̌_k) = [f_1; …; f_m] (range, azimuth per radar) cell by cell; η_k ∈ R² per
cell; Φ¹ is block-diagonal (see :mod:`optmodels.biasfield.fielddata`). The objective is written
as ‖Gφ‖² with the sparse edge-difference factor G (one 2m-row block √a_ij (f_i − f_j)ᵀL
per neighbour pair, P = LLᵀ), so GᵀG = Q ⊗ P and no dense 2mK × 2mK matrix exists.

Closed form (11), with the sign fixed: η* = −(Φ¹ᵀRΦ¹)⁻¹Φ¹ᵀRΦ⁰ (the printed (11) has no
minus sign; with (10)'s "+Φ¹η" the minimiser needs it): :mod:`~optmodels.biasfield.closedform`
(:func:`closed_form`, importable from here).

The Lipschitz class: the smallest L with ‖f(x_i) − f(x_j)‖_P ≤ L‖x_i − x_j‖ on neighbour
pairs, an SOCP over the same sets (:func:`solve_lipschitz`), solved with φ eliminated and
re-checked through the solver's dual certificate (:func:`lipschitz_residuals`).

Every result, the closed form included, is re-checked in NumPy and its status set by
:func:`optmodels.core.verified_status`; the conditioning of Φ¹ᵀRΦ¹ enters as κ₁·ε.

Modules (all names stay importable from here, the section's entry point):
:mod:`~optmodels.biasfield.problem` (the original problem's pieces, :class:`FieldSolution`,
:func:`objective`, :func:`edge_factor`), :mod:`~optmodels.biasfield.closedform` (closed
form (11)), this module (the QP (9)-(10) [+ (8)]),
:mod:`~optmodels.biasfield.lipschitz` (:func:`solve_lipschitz`),
:mod:`~optmodels.biasfield.verify` (the NumPy re-checks: :func:`kkt_residuals`,
:func:`box_feasibility`, :func:`lipschitz_residuals`) and
:mod:`~optmodels.biasfield.identifiability` (:func:`identifiability`).
"""

from __future__ import annotations

from typing import Any, Literal

import cvxpy as cp
import numpy as np
from scipy import sparse

from optmodels.backends.profiles import DEFAULTS, solver_options
from optmodels.biasfield import problem
from optmodels.biasfield.closedform import closed_form
from optmodels.biasfield.fielddata import FieldData
from optmodels.biasfield.identifiability import Identifiability, identifiability
from optmodels.biasfield.lipschitz import SOCP_DEFAULTS as SOCP_DEFAULTS
from optmodels.biasfield.lipschitz import solve_lipschitz
from optmodels.biasfield.problem import (
    FieldSolution,
    check_arguments,
    edge_factor,
    failed_solution,
    objective,
    pack_solution,
    r_matrix,
    variable_scales,
)

# importable from here as from the one-module selection of before (tests, solvers_cmp)
from optmodels.biasfield.problem import Sets as Sets
from optmodels.biasfield.problem import p_full as p_full
from optmodels.biasfield.verify import (
    box_feasibility,
    condition_number,
    conditioning_residual,
    kkt_residuals,
    lipschitz_residuals,
    verify_solution,
)
from optmodels.core import (  # noqa: F401 -- the tolerances are documented here too
    REJECT_TOL,
    VERIFY_TOL,
    ProblemError,
    Status,
    timed,
)

__all__ = [
    "FieldSolution",
    "Identifiability",
    "box_feasibility",
    "closed_form",
    "edge_factor",
    "identifiability",
    "kkt_residuals",
    "lipschitz_residuals",
    "objective",
    "solve",
    "solve_lipschitz",
]


#: Default solver options: the back-end's table for QPs that must agree with a closed form
#: to ~1e-8 (the same object; the reasons for each value are given there).
SOLVER_DEFAULTS: dict[str, dict[str, Any]] = DEFAULTS["qp"]


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

    Box infeasibility is diagnosed cell by cell (:func:`box_feasibility`) and reported as
    INFEASIBLE with the offending cells in ``message``; a solver failure is never returned
    as a field. KKT residuals are re-computed in NumPy (:func:`kkt_residuals`), with the
    conditioning term κ₁(Φ¹ᵀRΦ¹)·ε of :func:`closed_form` (an upper bound for the reduced
    Hessian of any active set; one extra sparse factorisation), and a claimed optimum
    failing them is downgraded (:data:`VERIFY_TOL`, :data:`REJECT_TOL`). ``box`` = (K1 m,
    K2 rad), two positive numbers; a solver option the solver rejects is a
    :class:`ProblemError` naming it.
    """
    fn = "biasfield.solve"
    n_comp, formulation, solver, bound, sets = check_arguments(fn, data, formulation, solver, box)
    method = f"cvxpy:{solver}:{formulation}"
    phi0, phi1 = sets
    if bound is not None:
        bad = box_feasibility(data, box, sets=sets)  # type: ignore[arg-type]
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
    sol.residuals.update(kkt_residuals(data, sol, box, sets=sets))
    kappa = condition_number(phi1.T @ r_matrix(data) @ phi1)
    sol.info["condition"] = kappa
    sol.residuals["conditioning"] = conditioning_residual(kappa)
    return verify_solution(sol)
