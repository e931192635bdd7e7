"""The fused estimate (paper 003): :func:`fuse`, the weighted least-squares problem (1)-(2)
min_α Σ_μ (α − a_μ)ᵀC_μ(α − a_μ) for independent estimates and the min-trace W for
correlated ones, each in closed form or by CVXPY, re-checked in NumPy
(:mod:`optmodels.fusion.verify`)."""

from __future__ import annotations

from typing import Any, Literal

import cvxpy as cp
import numpy as np
from numpy.typing import ArrayLike

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    Status,
    as_choice,
    as_finite_array,
    timed,
)
from optmodels.fusion.inputs import _pair, _where
from optmodels.fusion.solution import FusionSolution
from optmodels.fusion.verify import (
    _EPS,
    _combination_bound,
    _finish,
    _relative_weight_error,
    _weight_bound,
    _wls_objective,
)
from optmodels.fusion.weights import (
    PINV_RTOL,
    _correlated_weight,
    _cross,
    _weight,
    fused_covariance,
)


def fuse(
    a1: ArrayLike,
    s1: ArrayLike,
    a2: ArrayLike,
    s2: ArrayLike,
    *,
    s12: ArrayLike | None = None,
    method: Literal["closed_form", "cvxpy"] = "closed_form",
    solver: str = "CLARABEL",
    **solver_options: Any,
) -> FusionSolution:
    """Fuse two estimates a1, a2 of the same α with error covariances S1, S2.

    Independent estimates (``s12=None``, the paper's assumption): (1)-(2) in closed form, or
    the weighted least-squares problem min_α Σ_μ (α − a_μ)ᵀC_μ(α − a_μ) solved by CVXPY.

    Correlated estimates (``s12`` = Cov(a1, a2)): the best linear unbiased combination
    (I − W)a1 + Wa2 with W of :func:`weight_matrix_correlated`; the generic form is
    min_W ‖[I − W, W] L‖²_F (the trace of the fused covariance, L Lᵀ the joint covariance,
    which may be singular), solved by CVXPY.

    ``covariance`` is the fused error covariance (under the stated correlation);
    ``solver_options`` go to the CVXPY solver (``method="cvxpy"``).

    Either method's result is re-checked in NumPy against the original WLS problem
    (:func:`optmodels.core.verified_status` of the largest residual):

    * ``residuals["gradient"]``: the relative norm of the optimality condition
      C1(α − a1) + C2(α − a2) = 0 (correlated: W D = S1 − S12);
    * ``residuals["estimate_error"]``: a bound on max|α − α*| / max(|α|, |a1|, |a2|), α*
      the exact optimum, from that residual and the conditioning (|(C1 + C2)⁻¹| times the
      residual and the round-off of C_μ = S_μ⁻¹, componentwise);
    * ``residuals["weight_error"]``: the same bound for W from W(S1 + S2) = S1
      (correlated: W D = S1 − S12 on range(D)).

    Above 1e-6 the status becomes OPTIMAL_INACCURATE, above 1e-3 ERROR (then
    ``estimate`` is NaN, and ``W``, ``covariance`` too if W itself fails).

    Raises
    ------
    ProblemError
        Bad shapes, NaN/inf, non-SPD S1/S2, an impossible s12, an unknown ``method``.
    """
    fn = "fuse"
    s1a, s2a = _pair(s1, s2, fn)
    m = s1a.shape[0]
    x1 = as_finite_array(_where(fn, "a1"), a1, shape=(m,), max_abs=MAX_MAGNITUDE)
    x2 = as_finite_array(_where(fn, "a2"), a2, shape=(m,), max_abs=MAX_MAGNITUDE)
    method = as_choice(  # type: ignore[assignment]
        _where(fn, "method"), method, ("closed_form", "cvxpy")
    )
    if not isinstance(solver, str):
        raise ProblemError(f"{_where(fn, 'solver')}: expected a solver name, got {solver!r}")
    if s12 is not None:
        return _fuse_correlated(x1, s1a, x2, s2a, s12, method, solver, solver_options)
    c1 = np.asarray(np.linalg.inv(s1a), dtype=float)
    c2 = np.asarray(np.linalg.inv(s2a), dtype=float)
    w = _weight(s1a, s2a)
    cov = (np.eye(m) - w) @ s1a
    cov = 0.5 * (cov + cov.T)
    if method == "closed_form":
        with timed() as tm:
            est = x1 + w @ (x2 - x1)
        common: dict[str, Any] = {
            "status": Status.OPTIMAL,
            "method": "closed_form",
            "solve_time": tm.elapsed,
            "message": "(1)-(2)",
        }
    elif method == "cvxpy":
        with timed() as tb:
            # α = a1 + d·u with d the spread of the two estimates and C_μ divided by
            # ‖C1 + C2‖: the solver sees an O(1) problem whatever the units. (The robustness
            # sweep found Clarabel returning α = 0 as 'optimal' for estimates at 1e-151:
            # its absolute tolerances swallowed the whole problem.)
            d = max(float(np.max(np.abs(x2 - x1))), 1e-300)
            cn = max(float(np.max(np.abs(c1 + c2))), 1e-300)
            delta = (x2 - x1) / d
            u = cp.Variable(m)
            obj = cp.quad_form(u, cp.psd_wrap(c1 / cn)) + cp.quad_form(
                u - delta, cp.psd_wrap(c2 / cn)
            )
            prob = cp.Problem(cp.Minimize(obj))
        res = solve_problem(prob, solver, **solver_options)
        common = res.common()
        common["build_time"] += tb.elapsed
        est = (
            x1 + d * np.asarray(u.value)
            if res.status.ok and u.value is not None
            else np.full(m, np.nan)
        )
    grad = c1 @ (est - x1) + c2 @ (est - x2)
    scale = np.abs(c1) @ np.abs(x1) + np.abs(c2) @ np.abs(x2) + np.abs(c1 + c2) @ np.abs(est)
    res_grad = float(np.max(np.abs(grad) / (scale + 1e-300)))
    # Forward error of α, two valid bounds (the smaller is kept):
    # (a) α − α* = −(C1 + C2)⁻¹ g* = −cov g*, g* the exact gradient, which differs from g
    #     by round-off in g and in C_μ = S_μ⁻¹ (|δC| ≲ γ|C||S||C|, componentwise);
    # (b) |α − α_W| + the bound of α_W = a1 + W(a2 − a1) from the bound on W (the closed
    #     form never inverts S_μ, so (b) stays sharp when S1, S2 are ill-conditioned
    #     but S1 + S2 is not).
    gamma = (m + 2) * _EPS
    g_err = np.abs(grad)
    for c_k, s_k, x_k in ((c1, s1a, x1), (c2, s2a, x2)):
        ac = np.abs(c_k)
        g_err = g_err + gamma * (ac @ np.abs(s_k) @ ac + ac) @ np.abs(est - x_k)
    dw = _weight_bound(w, s1a + s2a, s1a)
    alpha_w = x1 + w @ (x2 - x1)
    bound = np.minimum(
        np.abs(cov) @ g_err, np.abs(est - alpha_w) + _combination_bound(w, dw, x1, x2)
    )
    size = max(float(np.max(np.abs(np.concatenate([est, x1, x2])))), np.finfo(float).tiny)
    w_err = _relative_weight_error(dw, w)
    residuals = {
        "gradient": res_grad,
        "estimate_error": float(np.max(bound) / size),
        "weight_error": w_err,
    }
    sol = _finish(
        FusionSolution(
            objective=float("nan"), residuals=residuals, estimate=est, covariance=cov, W=w, **common
        )
    )
    sol.objective = _wls_objective(sol.estimate, x1, c1, x2, c2)
    return sol


def _fuse_correlated(
    x1: FloatArray,
    a: FloatArray,
    x2: FloatArray,
    b: FloatArray,
    s12: ArrayLike,
    method: str,
    solver: str,
    solver_options: dict[str, Any],
) -> FusionSolution:
    c, d = _cross(s12, a, b, "fuse")
    m = a.shape[0]
    eye = np.eye(m)
    if method == "closed_form":
        with timed() as tm:
            w = _correlated_weight(a, c, d)
        common: dict[str, Any] = {
            "status": Status.OPTIMAL,
            "method": "closed_form",
            "solve_time": tm.elapsed,
            "message": "Bar-Shalom-Campo",
        }
    elif method == "cvxpy":
        joint = np.block([[a, c], [c.T, b]])
        lam, vecs = np.linalg.eigh(0.5 * (joint + joint.T))
        root = vecs * np.sqrt(np.clip(lam, 0.0, None))  # L with L Lᵀ = joint (PSD)
        scale = float(np.sqrt(np.trace(joint)))
        with timed() as tb:
            wv = cp.Variable((m, m))
            expr = cp.hstack([eye - wv, wv]) @ (root / scale)
            prob = cp.Problem(cp.Minimize(cp.sum_squares(expr)))
        res = solve_problem(prob, solver, **solver_options)
        common = res.common()
        common["build_time"] += tb.elapsed
        w = (
            np.asarray(wv.value)
            if res.status.ok and wv.value is not None
            else np.full((m, m), np.nan)
        )
    est = x1 + w @ (x2 - x1)
    # optimality: d tr(cov)/dW = 2(W D − (S1 − S12)) = 0
    cov = fused_covariance(w, a, b, c)
    grad = w @ d - (a - c)
    res_grad = float(np.max(np.abs(grad)) / (np.max(np.abs(d)) * max(1.0, np.max(np.abs(w)))))
    dw = _weight_bound(
        w, d, a - c, np.asarray(np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True), dtype=float)
    )
    w_err = _relative_weight_error(dw, w)
    # |δα| ≤ |δW||a2 − a1| + round-off of a1 + W(a2 − a1)
    size = max(float(np.max(np.abs(np.concatenate([est, x1, x2])))), np.finfo(float).tiny)
    bound = float(np.max(_combination_bound(w, dw, x1, x2))) / size
    residuals = {"gradient": res_grad, "estimate_error": bound, "weight_error": w_err}
    sol = _finish(
        FusionSolution(
            objective=float("nan"), residuals=residuals, estimate=est, covariance=cov, W=w, **common
        )
    )
    sol.objective = float(np.trace(sol.covariance))
    return sol
