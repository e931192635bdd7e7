r"""NumPy re-checks of the section-4 answers (paper 001, (8)-(11)), and the gate.

Every result -- the closed form (11), the QP (9)-(10) [+ box (8)], the Lipschitz SOCP -- is
packed and re-checked here against the original problem, not against the solver's report:

* :func:`pack_solution` / :func:`failed_solution`: a method's φ, η as a
  :class:`~optmodels.biasfield.solution.FieldSolution` with the residuals of the sets (10)
  and of the box (8) (or, without a field, φ and η NaN);
* :func:`condition_number` / :func:`conditioning_residual`: κ₁(Φ¹ᵀRΦ¹) and the error floor
  κ₁·ε of η; :func:`identifiability`: what the data identify (that condition and the
  per-cell spread from the diagonal blocks of (Φ¹ᵀRΦ¹)⁻¹);
* :func:`kkt_residuals`: stationarity, dual signs and complementarity of the QP;
* :func:`box_feasibility`: the cells whose uncertainty set misses the box (8), exactly;
* :func:`lipschitz_residuals`: the SOCP's field against the solver's L and its dual
  certificate (weak duality);
* :func:`recheck_closed_form`, :func:`recheck_qp`, :func:`recheck_lipschitz`: each
  method's re-check, ending in the gate :func:`_finish` (the largest residual →
  :func:`optmodels.core.finish`: :data:`~optmodels.core.VERIFY_TOL` OPTIMAL_INACCURATE,
  :data:`~optmodels.core.REJECT_TOL` ERROR in the failure form
  :func:`optmodels.biasfield.solution._failure`, without a field).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg

from optmodels.biasfield import solution
from optmodels.biasfield.data import FieldData, uncertainty_sets
from optmodels.biasfield.problem import (
    Sets,
    box_bounds,
    check_graph,
    edge_factor,
    lipschitz_data,
    r_matrix,
)
from optmodels.biasfield.solution import FieldSolution
from optmodels.core import FloatArray, ProblemError, as_count, finish

__all__ = [
    "Identifiability",
    "box_feasibility",
    "identifiability",
    "kkt_residuals",
    "lipschitz_residuals",
]


# ----------------------------------------------------------------------------- packing
def failed_solution(
    data: FieldData, sets: Sets, common: dict[str, Any], bound: FloatArray | None
) -> FieldSolution:
    """The result of a method that produced no field (a failed solve, an overflow, a
    proven-infeasible box): φ and η NaN, packed and re-checked by :func:`pack_solution`."""
    phi0, phi1 = sets
    return pack_solution(
        data, sets, np.full(phi0.size, np.nan), np.full(phi1.shape[1], np.nan), common, bound, None
    )


def pack_solution(
    data: FieldData,
    sets: Sets,
    phi: FloatArray,
    eta: FloatArray,
    common: dict[str, Any],
    bound: FloatArray | None,
    duals: FloatArray | None,
    lipschitz: float | None = None,
) -> FieldSolution:
    """A method's φ, η (and box multipliers ``duals``) packed as a :class:`FieldSolution`
    with the residuals of the sets (10) and of the box (8) and the box's active set; the
    status in ``common`` is not judged here (the gate is :func:`_finish`)."""
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
    jumps = edge_factor(data) @ phi  # J(φ) = ‖Gφ‖² (9), NaN for a method without a field
    return FieldSolution(
        objective=float(jumps @ jumps),
        residuals=res,
        field=phi.reshape(k, m, 2),
        phi=phi,
        eta=eta.reshape(k, 2),
        active=active.reshape(k, m, 2),
        duals=dual.reshape(k, m, 2),
        lipschitz=lipschitz,
        centers=data.centers.copy(),
        frame=_frame(data),
        seen=None if data.seen is None else data.seen.copy(),
        **common,
    )


def _frame(data: FieldData) -> dict[str, Any]:
    """The frame a field on ``data``'s cells belongs to (see :class:`FieldSolution`)."""
    three = data.geodetic is not None and data.origin is not None
    return {
        "sites": data.radars.copy(),
        "chain": "3d" if three else "2d",
        "geodetic": None if not three else np.array(data.geodetic, dtype=float),
        "origin": None if not three else np.array(data.origin, dtype=float),
    }


# ----------------------------------------------------------------------------- conditioning
def condition_number(h: sparse.spmatrix, lu: Any = None) -> float:
    """1-norm condition number of the SPD 2K × 2K matrix H = Φ¹ᵀRΦ¹ (Hager/Higham
    estimate of ‖H⁻¹‖₁, t = 1: a few solves with its sparse factorisation ``lu``, computed
    here if not given; inf if H is singular)."""
    hc = sparse.csc_matrix(h)
    if lu is None:
        try:
            lu = splinalg.splu(hc)
        except RuntimeError:
            return float("inf")
    op = splinalg.LinearOperator(
        hc.shape,
        matvec=lu.solve,
        matmat=lu.solve,
        rmatvec=lambda v: lu.solve(v, trans="T"),
        rmatmat=lambda v: lu.solve(v, trans="T"),
        dtype=float,
    )
    with np.errstate(all="ignore"):
        kappa = float(splinalg.norm(hc, 1)) * float(splinalg.onenormest(op, t=1))
    return kappa if np.isfinite(kappa) else float("inf")


def conditioning_residual(kappa: float) -> float:
    """κ·ε: the relative error of η that no method avoids in double precision (a backward
    stable solve of H η = −b has forward error about κ(H)·ε); it enters the re-check like a
    residual, so H with κ > 4.5e9 gives OPTIMAL_INACCURATE and κ > 4.5e12 ERROR."""
    return float(kappa * np.finfo(float).eps)


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
    check_graph(data)
    _, phi1 = uncertainty_sets(data)
    h = (phi1.T @ r_matrix(data) @ phi1).tocsc()
    try:
        lu = splinalg.splu(h)
    except RuntimeError as exc:
        raise ProblemError(
            f"biasfield.identifiability data: Φ1ᵀRΦ1 is singular ({exc}); "
            "the field is not identifiable on these cells"
        ) from None
    n = h.shape[0]
    diag = np.empty((n // 2, 2, 2))
    for start in range(0, n, batch):
        cols = np.arange(start, min(start + batch, n))
        rhs = np.zeros((n, cols.size))
        rhs[cols, np.arange(cols.size)] = 1.0
        x = lu.solve(rhs)
        for c_i, c in enumerate(cols):
            diag[c // 2, :, c % 2] = x[2 * (c // 2) : 2 * (c // 2) + 2, c_i]
    spread = np.sqrt(np.maximum(np.trace(diag, axis1=1, axis2=2), 0.0))
    lam_max = float(splinalg.eigsh(h, k=1, which="LA", return_eigenvectors=False)[0])
    inv_max = float(
        splinalg.eigsh(
            splinalg.LinearOperator(h.shape, matvec=lu.solve, dtype=float),
            k=1,
            which="LA",
            return_eigenvectors=False,
        )[0]
    )
    return Identifiability(lam_max * inv_max, spread, np.argsort(-spread))


# ----------------------------------------------------------------------------- QP
def kkt_residuals(
    data: FieldData,
    sol: FieldSolution,
    box: tuple[float, float] | None = None,
    *,
    sets: Sets | None = None,
) -> dict[str, float]:
    """KKT of the QP in η: Φ¹ᵀ(2Rφ + μ) = 0 with μ the box multipliers (μ_j ≥ 0 at an upper
    bound, ≤ 0 at a lower one, 0 inside), relative to the gradient at η = 0 (or ‖Φ¹ᵀμ‖ if
    larger); complementarity
    |μ_j|·slack_j relative to the objective."""
    phi0, phi1 = uncertainty_sets(data) if sets is None else sets
    r = r_matrix(data)
    mu = sol.duals.reshape(-1)
    g1 = phi1.T @ (2 * (r @ sol.phi))
    g2 = phi1.T @ mu
    g0 = phi1.T @ (2 * (r @ phi0))  # the gradient at η = 0: the problem's own scale
    scale = max(float(np.max(np.abs(g0))), float(np.max(np.abs(g2))), 1e-300)
    out = {"stationarity": float(np.max(np.abs(g1 + g2))) / scale}
    bound = box_bounds(data, box, "biasfield.kkt_residuals")
    if bound is not None:
        slack = bound - np.abs(sol.phi)
        # interior-point duals of inactive bounds are tiny but not exactly 0: allow 1e-7
        tiny = 1e-7 * float(np.max(np.abs(mu))) + 1e-300
        # at φ_j = 0 (a zero bound, both sides active) either sign is a valid multiplier;
        # the robustness sweep found box = (0, 0) flagged as a sign error
        sign_ok = np.where(sol.phi > 0, mu >= -tiny, np.where(sol.phi < 0, mu <= tiny, True))
        out["dual_sign"] = float(np.mean(~sign_ok))
        out["complementarity"] = float(np.max(np.abs(mu) * np.maximum(slack, 0))) / max(
            sol.objective, 1e-300
        )
    return out


def box_feasibility(
    data: FieldData, box: tuple[float, float] | None, *, sets: Sets | None = None
) -> np.ndarray:
    """Cells whose uncertainty set misses the box (8). The box and the sets are per cell,
    so each cell is a 2-variable feasibility problem: the polygon ∩_j {η : |Φ⁰_j + a_jᵀη| ≤
    b_j}. It is non-empty iff one of the pairwise intersections of its boundary lines is
    feasible (a bounded polygon -- two radars at different sites give two independent
    directions -- has its vertices among them); all cells are checked at once.
    Returns the indices of the infeasible cells."""
    bound = box_bounds(data, box, "biasfield.box_feasibility")
    if bound is None:
        raise ProblemError(
            "biasfield.box_feasibility box: expected a pair (K1 m, K2 rad), got None"
        )
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
    eta = np.stack(
        [
            (rhs[..., 0] * mat[..., 1, 1] - mat[..., 0, 1] * rhs[..., 1]) / det,
            (mat[..., 0, 0] * rhs[..., 1] - rhs[..., 0] * mat[..., 1, 0]) / det,
        ],
        -1,
    )
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
def lipschitz_residuals(
    data: FieldData,
    sol: FieldSolution,
    duals: dict[str, Any],
    *,
    box: tuple[float, float] | None = None,
    cap: float | None = None,
    sets: Sets | None = None,
    prob_data: dict[str, Any] | None = None,
) -> dict[str, float]:
    r"""Re-check of a Lipschitz SOCP solution against the problem, in NumPy.

    In the scaled variables of :func:`~optmodels.biasfield.generic.solve_lipschitz`
    (φ = sc·u, u = u0 + Bη̃, cone e: (ℓ d_e/ref, w_e = D̃_e u)), the Lagrangian with the
    solver's multipliers (λ_e, μ_e) of the cones, α, β ≥ 0 of the box u ≤ b, −u ≤ b and
    γ ≥ 0 of ℓ ≤ cap gives the dual

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
    pd_ = lipschitz_data(data, sets) if prob_data is None else prob_data
    bound = box_bounds(data, box, "biasfield.lipschitz_residuals")
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


# ----------------------------------------------------------------------------- the gate
def recheck_closed_form(
    sol: FieldSolution,
    sets: Sets,
    r: sparse.csr_matrix,
    h: sparse.spmatrix,
    lu: Any,
) -> FieldSolution:
    """The closed form's re-check: ``residuals["stationarity"]`` (Φ¹ᵀRφ relative to
    Φ¹ᵀRΦ⁰, the gradient at η = 0) and ``["conditioning"]`` = κ₁(H)·ε of H = Φ¹ᵀRΦ¹ (with
    the factorisation ``lu`` of H the closed form used; ``info["condition"]`` gives κ₁),
    then the gate."""
    phi0, phi1 = sets
    grad = phi1.T @ (r @ sol.phi)
    sol.residuals["stationarity"] = float(np.max(np.abs(grad))) / max(
        float(np.max(np.abs(phi1.T @ (r @ phi0)))), 1e-300
    )
    kappa = condition_number(h, lu)
    sol.info["condition"] = kappa
    sol.residuals["conditioning"] = conditioning_residual(kappa)
    return _finish(sol)


def recheck_qp(
    data: FieldData, sol: FieldSolution, box: tuple[float, float] | None, sets: Sets
) -> FieldSolution:
    """The QP's re-check: :func:`kkt_residuals` and the conditioning term κ₁(Φ¹ᵀRΦ¹)·ε (an
    upper bound for the reduced Hessian of any active set; one sparse factorisation), then
    the gate."""
    sol.residuals.update(kkt_residuals(data, sol, box, sets=sets))
    phi1 = sets[1]
    kappa = condition_number(phi1.T @ r_matrix(data) @ phi1)
    sol.info["condition"] = kappa
    sol.residuals["conditioning"] = conditioning_residual(kappa)
    return _finish(sol)


def recheck_lipschitz(
    data: FieldData,
    sol: FieldSolution,
    duals: dict[str, Any],
    *,
    box: tuple[float, float] | None,
    cap: float | None,
    sets: Sets,
    prob_data: dict[str, Any],
) -> FieldSolution:
    """The Lipschitz SOCP's re-check: :func:`lipschitz_residuals` (the field's L and the
    solver's dual certificate), then the gate."""
    sol.residuals.update(
        lipschitz_residuals(data, sol, duals, box=box, cap=cap, sets=sets, prob_data=prob_data)
    )
    return _finish(sol)


def _finish(sol: FieldSolution) -> FieldSolution:
    """The gate: a claimed optimum whose NumPy-recomputed residual (KKT: stationarity, box
    violation, complementarity; or the Lipschitz SOCP's certificate; conditioning) exceeds
    VERIFY_TOL is reported OPTIMAL_INACCURATE, above REJECT_TOL ERROR in the failure form
    :func:`~optmodels.biasfield.solution._failure` (without a field): the one gate
    :func:`optmodels.core.finish` (:func:`optmodels.core.verified_status`; ``dual_sign``
    is a diagnostic, not a residual). A failed solve was packed without a field already
    (:func:`failed_solution`) and is returned as it is."""
    if not sol.ok:
        return sol
    return finish(sol, ignore=("dual_sign",), reject=solution._failure)
