r"""The smoothest bias field on the uncertainty sets (paper 001, section 4, (8)-(11)).

Original problem (9)-(10), optionally with the box (8):

.. math::
    \min_{\varphi,\eta}\ \varphi^T R\varphi,\quad R = Q\otimes P,\qquad
    \text{s.t.}\ \varphi = \Phi^0 + \Phi^1\eta,\quad
    |f^1_{j}| \le K^1,\ |f^2_{j}| \le K^2 .

φ stacks f(x̌_k) = [f_1; …; f_m] (range, azimuth per radar) cell by cell; η_k ∈ R² per
cell; Φ¹ is block-diagonal (see :mod:`optmodels.biasfield.cells`). The objective is written
as ‖Gφ‖² with the sparse edge-difference factor G (one 2m-row block √a_ij (f_i − f_j)ᵀL
per neighbour pair, P = LLᵀ), so GᵀG = Q ⊗ P and no dense 2mK × 2mK matrix exists.

Closed form (11), with the sign fixed: η* = −(Φ¹ᵀRΦ¹)⁻¹Φ¹ᵀRΦ⁰ (the printed (11) has no
minus sign; with (10)'s "+Φ¹η" the minimiser needs it). Solved by a sparse Cholesky-like
factorisation (scipy ``splu``) of the 2K × 2K matrix.

The Lipschitz class: the smallest L with ‖f(x_i) − f(x_j)‖_P ≤ L‖x_i − x_j‖ on neighbour
pairs, an SOCP over the same sets (:func:`solve_lipschitz`), solved with φ eliminated and
re-checked through the solver's dual certificate (:func:`lipschitz_residuals`).

Every result, the closed form included, is re-checked in NumPy and its status set by
:func:`optmodels.core.verified_status`; the conditioning of Φ¹ᵀRΦ¹ enters as κ₁·ε.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import cvxpy as cp
import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse import csgraph
from scipy.sparse import linalg as splinalg

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.biasfield.cells import FieldData, laplacian, uncertainty_sets
from optmodels.core import (  # noqa: F401 -- the tolerances are documented here too
    REJECT_TOL,
    VERIFY_TOL,
    FloatArray,
    ProblemError,
    Solution,
    Status,
    as_choice,
    as_count,
    as_finite_array,
    as_positive,
    timed,
    verified_status,
)

__all__ = ["FieldSolution", "Identifiability", "box_feasibility", "closed_form", "edge_factor",
           "identifiability", "kkt_residuals", "lipschitz_residuals", "objective", "solve",
           "solve_lipschitz"]

#: Default solver options: tight enough for the 1e-8 agreement with the closed form.
SOLVER_DEFAULTS: dict[str, dict[str, Any]] = {
    # OSQP's polish refines its KKT solve 3 times by default: on these problems that left
    # 1e-3 relative errors in φ while reporting "solved, polishing successful"; 50 reach 1e-15
    "OSQP": {"eps_abs": 1e-9, "eps_rel": 1e-9, "polishing": True, "polish_refine_iter": 50,
             "max_iter": 200_000},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 200_000},
    # Clarabel's default gap 1e-8 leaves ~2e-6 relative errors in a box-bound φ of the
    # reduced problem; 1e-10 brings them to ~3e-8 for one more iteration
    "CLARABEL": {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10,
                 "tol_ktratio": 1e-8},
}


SOCP_DEFAULTS: dict[str, dict[str, Any]] = {"SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9,
                                                     "max_iters": 200_000}}


#: (Φ⁰, Φ¹) of (10), computed once per solve and handed to the helpers below.
Sets = tuple[FloatArray, sparse.csr_matrix]


@dataclass
class FieldSolution(Solution):
    """A field on the cells: ``field`` (K, m, 2) = [range, azimuth] bias per cell and radar,
    ``phi`` (2mK,), ``eta`` (K, 2); ``active`` (K, m, 2) box constraints at their bound
    (+1 upper, −1 lower, 0 free); ``duals`` (K, m, 2) their multipliers (≥ 0, signed like
    ``active``); ``lipschitz`` L for :func:`solve_lipschitz`."""

    field: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    phi: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    eta: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    active: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0))
    duals: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    lipschitz: float | None = None

    @property
    def max_residual(self) -> float:
        """Largest KKT/feasibility residual; ``residuals["dual_sign"]`` (the share of
        box multipliers with a sign off, a diagnostic) is not a residual and is left out."""
        vals = [float(v) for k, v in self.residuals.items() if k != "dual_sign"]
        if any(np.isnan(v) for v in vals):
            return float("nan")
        return max(vals, default=0.0)


# ----------------------------------------------------------------------------- pieces
def _p_full(data: FieldData) -> FloatArray:
    m = data.m
    return np.kron(np.eye(m), data.P) if data.P.shape == (2, 2) else data.P


def _edges(data: FieldData) -> tuple[np.ndarray, np.ndarray, FloatArray]:
    upper = sparse.triu(data.adjacency, k=1).tocoo()
    i, j = upper.row, upper.col
    d2 = np.sum((data.centers[i] - data.centers[j]) ** 2, axis=1)
    return i, j, d2


def _check_graph(data: FieldData) -> tuple[int, np.ndarray]:
    """Connected components of the neighbour graph; isolated cells are refused."""
    if not isinstance(data, FieldData):
        raise ProblemError(f"biasfield data: expected a FieldData (biasfield.build_field_data "
                           f"or FieldData(...)), got {type(data).__name__}")
    n, labels = csgraph.connected_components(data.adjacency, directed=False)
    sizes = np.bincount(labels)
    lonely = np.flatnonzero(sizes[labels] == 1)
    if lonely.size:
        raise ProblemError(f"adjacency: cells {lonely[:10].tolist()} have no neighbour; their "
                           "field is not determined by the smoothness criterion (add edges "
                           "or drop them)")
    return int(n), labels


def _edge_difference(data: FieldData, weights: FloatArray) -> sparse.csr_matrix:
    """Rows weights_e · Lᵀ(f(x̌_i) − f(x̌_j)) for every neighbour pair e = (i < j), P = LLᵀ:
    (2m·E × 2mK)."""
    i, j, _ = _edges(data)
    e = np.arange(i.size)
    diff = sparse.csr_matrix((np.concatenate([weights, -weights]),
                              (np.concatenate([e, e]), np.concatenate([i, j]))),
                             shape=(i.size, data.k))
    lt = np.linalg.cholesky(_p_full(data)).T
    return sparse.kron(diff, sparse.csr_matrix(lt), format="csr")


def edge_factor(data: FieldData) -> sparse.csr_matrix:
    """Sparse G (2m·E × 2mK) with GᵀG = Q ⊗ P: for each neighbour pair (i < j) the rows
    √a_ij Lᵀ(f(x̌_i) − f(x̌_j)), a_ij = 1/‖x̌_i − x̌_j‖², P = LLᵀ."""
    return _edge_difference(data, 1.0 / np.sqrt(_edges(data)[2]))


def objective(data: FieldData, phi: ArrayLike) -> float:
    """J(φ) = φᵀ(Q ⊗ P)φ (9) (half the paper's sum over ordered pairs, see errata);
    ``phi`` (2mK,) cell by cell, radar by radar, [range m, azimuth rad]."""
    g = edge_factor(data)
    return _objective(g, as_finite_array("biasfield.objective phi", phi, shape=(g.shape[1],)))


def _objective(g: sparse.csr_matrix, phi: FloatArray) -> float:
    v = g @ phi
    return float(v @ v)


def _r_matrix(data: FieldData) -> sparse.csr_matrix:
    return sparse.kron(laplacian(data.centers, data.adjacency), sparse.csr_matrix(_p_full(data)),
                       format="csr")


def _box(data: FieldData, box: Sequence[float] | None, where: str = "biasfield.solve"
         ) -> FloatArray | None:
    """The box (8) as bounds on φ (2mK,): ``box`` = (K1 range bound, m; K2 azimuth bound,
    rad), two positive finite numbers, or None."""
    if not isinstance(data, FieldData):
        raise ProblemError(f"{where} data: expected a FieldData, got {type(data).__name__}")
    if box is None:
        return None
    if isinstance(box, str | bytes) or np.ndim(box) != 1 or np.size(box) != 2:
        raise ProblemError(f"{where} box: expected a pair (K1 range bound in m, K2 azimuth "
                           f"bound in rad), got {box!r:.80}")
    k1 = as_positive(f"{where} box[0] (K1, range bound, m)", box[0])
    k2 = as_positive(f"{where} box[1] (K2, azimuth bound, rad)", box[1])
    return np.tile([k1, k2], data.m * data.k)


def _solver_name(where: str, solver: Any) -> str:
    if not isinstance(solver, str) or not solver:
        raise ProblemError(f"{where} solver: expected a CVXPY solver name, got {solver!r:.60}")
    return solver


def _condition(h: sparse.spmatrix, lu: Any = None) -> float:
    """1-norm condition number of the SPD 2K × 2K matrix H = Φ¹ᵀRΦ¹ (Hager/Higham
    estimate of ‖H⁻¹‖₁, t = 1: a few solves with its sparse factorisation ``lu``, computed
    here if not given; inf if H is singular)."""
    hc = sparse.csc_matrix(h)
    if lu is None:
        try:
            lu = splinalg.splu(hc)
        except RuntimeError:
            return float("inf")
    op = splinalg.LinearOperator(hc.shape, matvec=lu.solve, matmat=lu.solve,
                                 rmatvec=lambda v: lu.solve(v, trans="T"),
                                 rmatmat=lambda v: lu.solve(v, trans="T"), dtype=float)
    with np.errstate(all="ignore"):
        kappa = float(splinalg.norm(hc, 1)) * float(splinalg.onenormest(op, t=1))
    return kappa if np.isfinite(kappa) else float("inf")


def _conditioning_residual(kappa: float) -> float:
    """κ·ε: the relative error of η that no method avoids in double precision (a backward
    stable solve of H η = −b has forward error about κ(H)·ε); it enters the re-check like a
    residual, so H with κ > 4.5e9 gives OPTIMAL_INACCURATE and κ > 4.5e12 ERROR."""
    return float(kappa * np.finfo(float).eps)


def _finish(data: FieldData, sets: Sets, phi: FloatArray, eta: FloatArray,
            common: dict[str, Any],
            bound: FloatArray | None, duals: FloatArray | None,
            lipschitz: float | None = None) -> FieldSolution:
    k, m = data.k, data.m
    phi0, phi1 = sets
    res: dict[str, float] = {}
    scale = max(float(np.max(np.abs(phi0))), 1e-300)
    res["set"] = float(np.max(np.abs(phi - phi0 - phi1 @ eta))) / scale
    active = np.zeros(phi.size, dtype=np.int8)
    if bound is not None:
        res["box"] = float(np.max(np.maximum(np.abs(phi) - bound, 0.0) / bound))
        tol = 1e-6 * bound
        active[phi >= bound - tol] = 1
        active[phi <= -bound + tol] = -1
    dual = np.zeros(phi.size) if duals is None else duals
    return FieldSolution(objective=_objective(edge_factor(data), phi), residuals=res,
                         field=phi.reshape(k, m, 2), phi=phi, eta=eta.reshape(k, 2),
                         active=active.reshape(k, m, 2), duals=dual.reshape(k, m, 2),
                         lipschitz=lipschitz, **common)


# ----------------------------------------------------------------------------- closed form
def closed_form(data: FieldData) -> FieldSolution:
    """(11) with sparse linear algebra: η* = −(Φ¹ᵀRΦ¹)⁻¹Φ¹ᵀRΦ⁰, φ* = Φ⁰ + Φ¹η*.

    A neighbour graph in several components is solved as one (J and the sets decouple, so
    this is the per-component solution); ``info["components"]`` gives their number.

    The result is re-checked in NumPy against the original problem (9)-(10) like a generic
    solve: ``residuals["set"]`` (φ on the sets), ``["stationarity"]`` (Φ¹ᵀRφ relative to
    Φ¹ᵀRΦ⁰, the gradient at η = 0) and ``["conditioning"]`` = κ₁(Φ¹ᵀRΦ¹)·ε (the
    double-precision error floor of η; ``info["condition"]`` gives κ₁). The status follows
    :func:`optmodels.core.verified_status`: above :data:`VERIFY_TOL` OPTIMAL_INACCURATE,
    above :data:`REJECT_TOL` ERROR without a field (an ill-determined field is refused,
    not returned).
    """
    n_comp, _ = _check_graph(data)
    with timed() as tm:
        phi0, phi1 = uncertainty_sets(data)
        r = _r_matrix(data)
        a = (phi1.T @ r @ phi1).tocsc()
        b = phi1.T @ (r @ phi0)
        try:
            lu = splinalg.splu(a)
        except RuntimeError as exc:  # exactly singular
            raise ProblemError(f"biasfield.closed_form data: Φ1ᵀRΦ1 is singular ({exc}); the "
                               "field is not identifiable on these cells") from None
        with np.errstate(all="ignore"):
            eta = -lu.solve(b)
        phi = phi0 + phi1 @ eta
    common = {"status": Status.OPTIMAL, "method": "closed_form", "solve_time": tm.elapsed,
              "message": "(11), sign corrected"}
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(eta))):
        nan = np.full(phi0.size, np.nan)
        common.update(status=Status.ERROR, message="(11): the solve overflowed (non-finite "
                      "field); Φ1ᵀRΦ1 is numerically singular")
        return _finish(data, (phi0, phi1), nan, np.full(phi1.shape[1], np.nan), common,
                       None, None)
    sol = _finish(data, (phi0, phi1), phi, eta, common, None, None)
    sol.info["components"] = n_comp
    grad = phi1.T @ (r @ phi)
    sol.residuals["stationarity"] = float(np.max(np.abs(grad))) / max(
        float(np.max(np.abs(b))), 1e-300)
    kappa = _condition(a, lu)
    sol.info["condition"] = kappa
    sol.residuals["conditioning"] = _conditioning_residual(kappa)
    return _verify(sol)


# ----------------------------------------------------------------------------- QP
def _scales(data: FieldData, phi0: FloatArray) -> FloatArray:
    """Per-component scale of φ (range, azimuth) so that the solver sees O(1) numbers."""
    v = np.abs(phi0.reshape(-1, 2))
    s = np.array([max(float(np.median(v[:, 0])), 1e-9), max(float(np.median(v[:, 1])), 1e-15)])
    return np.tile(s, data.m * data.k)


def _arguments(fn: str, data: FieldData, formulation: Any, solver: Any, box: Any
               ) -> tuple[int, Any, str, Any, Any]:
    """The checked arguments common to :func:`solve` and :func:`solve_lipschitz`: the
    number of graph components, the formulation, the solver's name, the box bound and the
    uncertainty sets (10)."""
    n_comp, _ = _check_graph(data)
    formulation = as_choice(f"{fn} formulation", formulation, ("constrained", "reduced"))
    solver = _solver_name(fn, solver)
    bound = _box(data, box, fn)
    return n_comp, formulation, solver, bound, uncertainty_sets(data)


def solve(data: FieldData, *, box: tuple[float, float] | None = None,
          solver: str = "CLARABEL", formulation: Literal["constrained", "reduced"] = "reduced",
          **options: Any) -> FieldSolution:
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
    n_comp, formulation, solver, bound, sets = _arguments(fn, data, formulation, solver, box)
    method = f"cvxpy:{solver}:{formulation}"
    phi0, phi1 = sets
    if bound is not None:
        bad = box_feasibility(data, box, sets=sets)  # type: ignore[arg-type]
        if bad.size:
            nan = np.full(phi0.size, np.nan)
            return _finish(data, sets, nan, np.full(phi1.shape[1], np.nan), {
                "status": Status.INFEASIBLE, "method": method,
                "message": f"box (8) misses the uncertainty sets of cells {bad[:20].tolist()}"
                           f"{' …' if bad.size > 20 else ''} ({bad.size} cells): no field "
                           "in these sets satisfies |f_range| ≤ K1, |f_azimuth| ≤ K2"},
                bound, None)
    sc = _scales(data, phi0)
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
            obj = (cp.quad_form(eta, cp.psd_wrap((bmat.T @ rs @ bmat).tocsc() / norm2))
                   + (2.0 / norm2) * (bmat.T @ (rs @ u0)) @ eta)
        box_cons = [u <= bound / sc, -u <= bound / sc] if bound is not None else []
        prob = cp.Problem(cp.Minimize(obj), cons + box_cons)
    opts = {**SOLVER_DEFAULTS.get(solver.upper(), {}), **options}
    res = _run(fn, prob, solver, opts)
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = method
    if not res.status.ok or eta.value is None:
        nan = np.full(phi0.size, np.nan)
        return _finish(data, sets, nan, np.full(phi1.shape[1], np.nan), common, bound, None)
    et = np.asarray(eta.value) * sc[0]
    phi = phi0 + phi1 @ et if formulation == "reduced" else np.asarray(u.value) * sc
    duals = None
    if bound is not None:
        # multipliers of the box in φ units (the scaled objective is J / norm2)
        up = np.asarray(box_cons[0].dual_value) / sc * norm2
        lo = np.asarray(box_cons[1].dual_value) / sc * norm2
        duals = up - lo
    sol = _finish(data, sets, phi, et, common, bound, duals)
    sol.info["components"] = n_comp
    sol.residuals.update(kkt_residuals(data, sol, box, sets=sets))
    kappa = _condition(phi1.T @ _r_matrix(data) @ phi1)
    sol.info["condition"] = kappa
    sol.residuals["conditioning"] = _conditioning_residual(kappa)
    return _verify(sol)


def _run(where: str, prob: cp.Problem, solver: str, opts: dict[str, Any]) -> Any:
    """:func:`solve_problem`, with a rejected option named as this function's argument."""
    try:
        return solve_problem(prob, solver, **opts)
    except ProblemError as exc:
        raise ProblemError(f"{where} options: {exc}") from None


def _verify(sol: FieldSolution) -> FieldSolution:
    """A claimed optimum whose NumPy-recomputed residual (KKT: stationarity, box violation,
    complementarity; or the Lipschitz SOCP's certificate; conditioning) exceeds VERIFY_TOL
    is reported OPTIMAL_INACCURATE, above REJECT_TOL
    ERROR (without a field): :func:`optmodels.core.verified_status`."""
    worst = sol.max_residual
    new = verified_status(sol.status, worst)
    if new == sol.status:
        return sol
    sol.status = new
    which = max((k for k in sol.residuals if k != "dual_sign"),
                key=lambda k: -np.inf if np.isnan(sol.residuals[k]) else sol.residuals[k],
                default="residual")
    if new == Status.ERROR:
        sol.message += f"; {which} residual {worst:.1e} fails the NumPy check"
        sol.field = np.full_like(sol.field, np.nan)
        sol.phi = np.full_like(sol.phi, np.nan)
        sol.eta = np.full_like(sol.eta, np.nan)
        sol.lipschitz = None if sol.lipschitz is None else float("nan")
    else:
        sol.message += f"; {which} residual {worst:.1e} (NumPy check)"
    return sol


def kkt_residuals(data: FieldData, sol: FieldSolution,
                  box: tuple[float, float] | None = None, *,
                  sets: Sets | None = None) -> dict[str, float]:
    """KKT of the QP in η: Φ¹ᵀ(2Rφ + μ) = 0 with μ the box multipliers (μ_j ≥ 0 at an upper
    bound, ≤ 0 at a lower one, 0 inside), relative to the gradient at η = 0 (or ‖Φ¹ᵀμ‖ if
    larger); complementarity
    |μ_j|·slack_j relative to the objective."""
    phi0, phi1 = uncertainty_sets(data) if sets is None else sets
    r = _r_matrix(data)
    mu = sol.duals.reshape(-1)
    g1 = phi1.T @ (2 * (r @ sol.phi))
    g2 = phi1.T @ mu
    g0 = phi1.T @ (2 * (r @ phi0))  # the gradient at η = 0: the problem's own scale
    scale = max(float(np.max(np.abs(g0))), float(np.max(np.abs(g2))), 1e-300)
    out = {"stationarity": float(np.max(np.abs(g1 + g2))) / scale}
    bound = _box(data, box, "biasfield.kkt_residuals")
    if bound is not None:
        slack = bound - np.abs(sol.phi)
        # interior-point duals of inactive bounds are tiny but not exactly 0: allow 1e-7
        tiny = 1e-7 * float(np.max(np.abs(mu))) + 1e-300
        # at φ_j = 0 (a zero bound, both sides active) either sign is a valid multiplier;
        # the robustness sweep found box = (0, 0) flagged as a sign error
        sign_ok = np.where(sol.phi > 0, mu >= -tiny, np.where(sol.phi < 0, mu <= tiny, True))
        out["dual_sign"] = float(np.mean(~sign_ok))
        out["complementarity"] = float(np.max(np.abs(mu) * np.maximum(slack, 0))) / max(
            sol.objective, 1e-300)
    return out


def box_feasibility(data: FieldData, box: tuple[float, float], *,
                    sets: Sets | None = None) -> np.ndarray:
    """Cells whose uncertainty set misses the box (8). The box and the sets are per cell,
    so each cell is a 2-variable feasibility problem: the polygon ∩_j {η : |Φ⁰_j + a_jᵀη| ≤
    b_j}. It is non-empty iff one of the pairwise intersections of its boundary lines is
    feasible (a bounded polygon -- two radars at different sites give two independent
    directions -- has its vertices among them); all cells are checked at once.
    Returns the indices of the infeasible cells."""
    bound = _box(data, box, "biasfield.box_feasibility")
    if bound is None:
        raise ProblemError("biasfield.box_feasibility box: expected a pair (K1 m, K2 rad), "
                           "got None")
    phi0, phi1 = uncertainty_sets(data) if sets is None else sets
    k, m2 = data.k, 2 * data.m
    a = _cell_blocks(phi1, k, m2)
    p0 = phi0.reshape(k, m2) / bound.reshape(k, m2)
    a = a / bound.reshape(k, m2)[..., None]
    # lines: a_jᵀη = ±1 − p0_j  (2·m2 per cell)
    lines_a = np.concatenate([a, a], axis=1)
    lines_b = np.concatenate([1 - p0, -1 - p0], axis=1)
    ii, jj = np.triu_indices(2 * m2, 1)
    mat = np.stack([lines_a[:, ii], lines_a[:, jj]], axis=2)  # (k, pairs, 2, 2)
    rhs = np.stack([lines_b[:, ii], lines_b[:, jj]], axis=2)
    det = mat[..., 0, 0] * mat[..., 1, 1] - mat[..., 0, 1] * mat[..., 1, 0]
    ok_det = np.abs(det) > 1e-12 * np.max(np.abs(mat), axis=(2, 3)) ** 2
    det = np.where(ok_det, det, 1.0)
    eta = np.stack([(rhs[..., 0] * mat[..., 1, 1] - mat[..., 0, 1] * rhs[..., 1]) / det,
                    (mat[..., 0, 0] * rhs[..., 1] - rhs[..., 0] * mat[..., 1, 0]) / det], -1)
    val = p0[:, None, :] + np.einsum("kjd,kpd->kpj", a, eta)  # (k, pairs, m2)
    inside = np.all(np.abs(val) <= 1 + 1e-9, axis=2) & ok_det
    return np.flatnonzero(~inside.any(axis=1))


def _cell_blocks(phi1: sparse.csr_matrix, k: int, m2: int) -> FloatArray:
    """The (m2, 2) diagonal blocks of the block-diagonal Φ¹, as (k, m2, 2)."""
    coo = phi1.tocoo()
    out = np.zeros((k, m2, 2))
    out[coo.row // m2, coo.row % m2, coo.col % 2] = coo.data
    return out


# ----------------------------------------------------------------------------- Lipschitz
def solve_lipschitz(data: FieldData, *, box: tuple[float, float] | None = None,
                    solver: str = "CLARABEL", cap: float | None = None,
                    formulation: Literal["constrained", "reduced"] = "reduced",
                    **options: Any) -> FieldSolution:
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
    :class:`ProblemError` (proved cell by cell, :func:`box_feasibility`).

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
    n_comp, formulation, solver, bound, sets = _arguments(fn, data, formulation, solver, box)
    cap_v = None if cap is None else as_positive(f"{fn} cap", cap)
    method = f"cvxpy:{solver}:lipschitz:{formulation}"
    phi0, phi1 = sets
    if bound is not None:
        bad = box_feasibility(data, box, sets=sets)  # type: ignore[arg-type]
        if bad.size:
            raise ProblemError(f"{fn} box: the box misses the uncertainty sets of cells "
                               f"{bad[:20].tolist()}")
    prob_data = _lipschitz_data(data, sets)
    sc, u0, bmat, dmat, dist, ref, lip0 = (prob_data[k] for k in (
        "sc", "u0", "bmat", "dmat", "dist", "ref", "lip0"))
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
    res = _run(fn, prob, solver, {**SOCP_DEFAULTS.get(solver.upper(), {}), **options})
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = method
    if not res.status.ok or eta.value is None:
        nan = np.full(phi0.size, np.nan)
        return _finish(data, sets, nan, np.full(phi1.shape[1], np.nan), common, bound, None)
    et = np.asarray(eta.value, dtype=float) * sc[0]
    phi = phi0 + phi1 @ et if formulation == "reduced" else np.asarray(u.value) * sc
    jumps = np.linalg.norm((prob_data["jump"] @ phi).reshape(-1, m2), axis=1) / dist
    sol = _finish(data, sets, phi, et, common, bound, None, lipschitz=float(np.max(jumps)))
    sol.info["components"] = n_comp
    duals = {"soc": soc.dual_value,
             "upper": box_cons[0].dual_value if box_cons else None,
             "lower": box_cons[1].dual_value if box_cons else None,
             "cap": cap_cons[0].dual_value if cap_cons else None}
    sol.info["solver_lipschitz"] = float(lip.value) * lip0 / ref if lip.value is not None \
        else float("nan")
    sol.info["duals"] = duals  # the solver's multipliers: the certificate checked below
    sol.residuals.update(lipschitz_residuals(data, sol, duals, box=box, cap=cap_v,
                                             sets=sets, prob_data=prob_data))
    return _verify(sol)


def _lipschitz_data(data: FieldData, sets: Sets) -> dict[str, Any]:
    """The scaled SOCP's matrices: φ = sc·u, u = u0 + B η̃ (η = sc_range·η̃); the jump of
    edge e is D_e u (= Lᵀ(f_i − f_j)); cone e: (ℓ d_e/ref, (D_e u)/lip0) with L = ℓ·lip0/ref,
    lip0 the largest jump ratio at η = 0 times ref = median edge length."""
    phi0, phi1 = sets
    sc = _scales(data, phi0)
    m2 = 2 * data.m
    dist = np.sqrt(_edges(data)[2])
    jump = _edge_difference(data, np.ones(dist.size))  # Lᵀ(f_i − f_j) per edge
    dmat = (jump @ sparse.diags(sc)).tocsr()
    u0 = phi0 / sc
    bmat = (sparse.diags(1 / sc) @ phi1 * sc[0]).tocsr()
    ref = float(np.median(dist))
    lip0 = float(np.max(np.linalg.norm((dmat @ u0).reshape(-1, m2), axis=1) / dist)) * ref
    if not (np.isfinite(lip0) and lip0 > 0):
        lip0 = 1.0
    return {"sc": sc, "u0": u0, "bmat": bmat, "dmat": dmat, "dist": dist, "ref": ref,
            "lip0": lip0, "jump": jump, "db": (dmat @ bmat).tocsr() / lip0,
            "c": dmat @ u0 / lip0}


def lipschitz_residuals(data: FieldData, sol: FieldSolution, duals: dict[str, Any], *,
                        box: tuple[float, float] | None = None, cap: float | None = None,
                        sets: Sets | None = None,
                        prob_data: dict[str, Any] | None = None) -> dict[str, float]:
    r"""Re-check of a Lipschitz SOCP solution against the problem, in NumPy.

    In the scaled variables of :func:`solve_lipschitz` (φ = sc·u, u = u0 + Bη̃, cone e:
    (ℓ d_e/ref, w_e = D̃_e u)), the Lagrangian with the solver's multipliers (λ_e, μ_e) of
    the cones, α, β ≥ 0 of the box u ≤ b, −u ≤ b and γ ≥ 0 of ℓ ≤ cap gives the dual

    .. math::
        g = -\sum_e \mu_e^T w_e(0) + \alpha^T(u_0 - b) - \beta^T(u_0 + b) - \gamma\,cap,
        \quad \sum_e \lambda_e d_e/ref - \gamma = 1,\quad
        -\tilde D^T\mu + B^T(\alpha - \beta) = 0 \ (\text{in } \tilde B\text{-space}),
        \quad \|\mu_e\| \le \lambda_e,

    and weak duality makes g a lower bound on the minimum ℓ. Returned, each in units of ℓ
    (the problem's own scale: ℓ = 1 at η = 0), i.e. what the error can change in the bound
    at the returned point: ``dual_stationarity`` = |1 − Σλ_e d_e/ref + γ|·ℓ + |r_η|ᵀ|η̃|
    (r_η the residual of the η equation), ``dual_cone`` = Σ_e max(‖μ_e‖ − λ_e, 0)·‖s_e‖
    plus the negative parts of α, β, γ times their slacks, ``gap`` = |ℓ(field) − g| and
    ``lipschitz`` = max(ℓ(field) − ℓ(solver), 0) (the Lipschitz inequalities at the
    solver's L), where ℓ(field) comes from ``sol.lipschitz`` (the returned field's L).
    Missing duals give NaN (not verifiable: an ERROR)."""
    sets = uncertainty_sets(data) if sets is None else sets
    pd_ = _lipschitz_data(data, sets) if prob_data is None else prob_data
    bound = _box(data, box, "biasfield.lipschitz_residuals")
    ref, lip0, dist = pd_["ref"], pd_["lip0"], pd_["dist"]
    m2 = 2 * data.m
    nan = float("nan")
    ell = float(sol.lipschitz) * ref / lip0 if sol.lipschitz is not None else nan
    ell_solver = float(sol.info.get("solver_lipschitz", nan)) * ref / lip0
    out = {"lipschitz": max(ell - ell_solver, 0.0) if np.isfinite(ell_solver) else nan}
    soc = duals.get("soc")
    if soc is None or soc[0] is None or soc[1] is None:
        out.update(dual_stationarity=nan, dual_cone=nan, gap=nan)
        return out
    lam = np.asarray(soc[0], dtype=float).reshape(-1)
    mu = np.asarray(soc[1], dtype=float).reshape(-1, m2)
    db, c, bmat = pd_["db"], pd_["c"], pd_["bmat"]
    alpha = beta = None
    if bound is not None:
        if duals.get("upper") is None or duals.get("lower") is None:
            out.update(dual_stationarity=nan, dual_cone=nan, gap=nan)
            return out
        alpha = np.asarray(duals["upper"], dtype=float).reshape(-1)
        beta = np.asarray(duals["lower"], dtype=float).reshape(-1)
    gamma = 0.0
    if cap is not None:
        if duals.get("cap") is None:
            out.update(dual_stationarity=nan, dual_cone=nan, gap=nan)
            return out
        gamma = float(np.asarray(duals["cap"], dtype=float).reshape(-1)[0])
    mu_flat = mu.reshape(-1)
    grad = -(db.T @ mu_flat)
    if alpha is not None and beta is not None:
        grad = grad + bmat.T @ (alpha - beta)
    stat_ell = 1.0 - float(lam @ dist) / ref + gamma
    # each residual is weighted by what it can change in the bound g at the returned point
    # (the Lagrangian is affine in (ℓ, η̃): a stationarity error r moves it by rᵀx), so all
    # are in units of ℓ, i.e. relative to ℓ(η = 0) = 1
    eta_s = np.asarray(sol.eta, dtype=float).reshape(-1) / pd_["sc"][0]
    out["dual_stationarity"] = abs(stat_ell) * abs(ell) + float(np.abs(grad) @ np.abs(eta_s))
    u = np.asarray(sol.phi, dtype=float) / pd_["sc"]
    w = (pd_["dmat"] @ u).reshape(-1, m2) / lip0
    s_norm = np.hypot(ell * dist / ref, np.linalg.norm(w, axis=1))
    cone = float(np.maximum(np.linalg.norm(mu, axis=1) - lam, 0.0) @ s_norm)
    if alpha is not None and beta is not None and bound is not None:
        b = bound / pd_["sc"]
        cone += float(np.maximum(-alpha, 0.0) @ np.abs(b - u))
        cone += float(np.maximum(-beta, 0.0) @ np.abs(b + u))
    if cap is not None:
        cone += max(-gamma, 0.0) * abs(float(cap) * ref / lip0 - ell)
    out["dual_cone"] = cone
    g = -float(mu_flat @ c)
    if alpha is not None and beta is not None and bound is not None:
        b = bound / pd_["sc"]
        g += float(alpha @ (pd_["u0"] - b)) - float(beta @ (pd_["u0"] + b))
    if cap is not None:
        g -= gamma * float(cap) * ref / lip0
    out["gap"] = abs(ell - g)
    return out


@dataclass(frozen=True)
class Identifiability:
    """How well the smoothness criterion pins the field down.

    ``condition``: condition number of H = Φ¹ᵀRΦ¹ (2K × 2K); ``spread`` (K,):
    √tr of the 2 × 2 diagonal blocks of H⁻¹ per cell (metres per unit √J: how far η_k,
    the per-cell common shift, can move for a given rise of J); ``worst``: cells by
    decreasing spread. What no method can recover: the common Cartesian shift in each cell
    (η_k itself) is fixed only by the smoothness prior, never by the data.
    """

    condition: float
    spread: FloatArray
    worst: np.ndarray


def identifiability(data: FieldData, *, batch: int = 512) -> Identifiability:
    """Condition of Φ¹ᵀRΦ¹ (sparse eigenvalues) and the per-cell spread from the diagonal
    blocks of its inverse (one sparse factorisation, solved in batches of columns)."""
    batch = as_count("biasfield.identifiability batch", batch, minimum=1)
    _check_graph(data)
    _, phi1 = uncertainty_sets(data)
    h = (phi1.T @ _r_matrix(data) @ phi1).tocsc()
    try:
        lu = splinalg.splu(h)
    except RuntimeError as exc:
        raise ProblemError(f"biasfield.identifiability data: Φ1ᵀRΦ1 is singular ({exc}); "
                           "the field is not identifiable on these cells") from None
    n = h.shape[0]
    diag = np.empty((n // 2, 2, 2))
    for start in range(0, n, batch):
        cols = np.arange(start, min(start + batch, n))
        rhs = np.zeros((n, cols.size))
        rhs[cols, np.arange(cols.size)] = 1.0
        x = lu.solve(rhs)
        for c_i, c in enumerate(cols):
            diag[c // 2, :, c % 2] = x[2 * (c // 2):2 * (c // 2) + 2, c_i]
    spread = np.sqrt(np.maximum(np.trace(diag, axis1=1, axis2=2), 0.0))
    lam_max = float(splinalg.eigsh(h, k=1, which="LA", return_eigenvectors=False)[0])
    inv_max = float(splinalg.eigsh(splinalg.LinearOperator(h.shape, matvec=lu.solve,
                                                           dtype=float),
                                   k=1, which="LA", return_eigenvectors=False)[0])
    return Identifiability(lam_max * inv_max, spread, np.argsort(-spread))
