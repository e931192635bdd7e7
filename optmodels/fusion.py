r"""Fusion of two estimates and the accuracy of its weight matrix (paper 003, Kulyavets et al.).

Paper: ``shared/papers/003_081094e0fa70fc4e.txt``, equations (1)-(14).

Problem as posed
----------------
Two independent measurers estimate the same state :math:`\alpha \in R^m`:
:math:`\hat a_\mu` with error covariance :math:`S_\mu = C_\mu^{-1}` (:math:`C_\mu` the
precision). The fused estimate (1)-(2) is the weighted least-squares solution

.. math::
    \hat a_p = \arg\min_\alpha \sum_\mu (\alpha - \hat a_\mu)^T C_\mu (\alpha - \hat a_\mu)
             = \hat a_1 + W(\hat a_2 - \hat a_1),\qquad
    W = (C_1 + C_2)^{-1} C_2 = I - C_p^{-1} C_1 \;(6) = S_1 (S_1 + S_2)^{-1}.

When :math:`S_\mu` are replaced by sample covariances :math:`\hat S_\mu` of :math:`n_\mu`
snapshots (3), :math:`\hat W` is random. The paper linearises :math:`\mathrm{vec}\,\hat W`
in :math:`\mathrm{vec}\,\hat S_\mu` (7)-(8) with the Jacobians (13)-(14)

.. math::
    \partial W/\partial (S_1)_{ij} = (I - W) E_{ij} C_1 W,\qquad
    \partial W/\partial (S_2)_{ij} = -W E_{ij} C_2 (I - W),

i.e. :math:`P_1 = (C_1W)^T \otimes (I - W)`, :math:`P_2 = -(C_2(I-W))^T \otimes W` with
``vec`` stacking columns, and propagates the Wishart moments (4)-(5) of :math:`\hat S_\mu`
through them (10).

Entry points: :func:`weight_matrix`, :func:`fuse` (closed form or CVXPY),
:func:`weight_jacobians` (closed form (13)-(14) or CasADi AD), :func:`sample_covariance_moments`
((4)-(5), known or sample mean), :func:`weight_covariance` ((10)) and
:func:`monte_carlo_weight`. Errata: ``docs/errata.md``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Literal

import casadi as ca
import cvxpy as cp
import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg, stats

from optmodels.backends.casadi_backend import BuiltNlp, build_nlpsol, check_options, run_nlpsol
from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.core import (
    MAX_MAGNITUDE,
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
    check_spd,
    timed,
    verified_status,
)

__all__ = [
    "FusionSolution",
    "JointMLSolution",
    "TwoSiteSystem",
    "clear_joint_cache",
    "commutation_matrix",
    "fuse",
    "fused_covariance",
    "monte_carlo_weight",
    "sample_covariance_moments",
    "weight_covariance",
    "weight_from_samples",
    "weight_jacobians",
    "weight_matrix",
    "weight_matrix_correlated",
]

MeanKind = Literal["known", "sample"]

#: Largest state dimension m for the functions that build (m², m²) matrices
#: (:func:`weight_jacobians`, :func:`sample_covariance_moments`, :func:`weight_covariance`,
#: :func:`monte_carlo_weight`, :func:`commutation_matrix`): at m = 30 these are 900 × 900
#: (6.5 MB) and (10) costs ~m⁶ = 7e8 flops, about a second.
MAX_DIM = 30
#: Largest trials · m² accepted by :func:`monte_carlo_weight` (measured 1e-7..8e-7 s per
#: trial·m² on a shared 2-core VM: at most ~15 s). The draws are made in chunks of at most
#: :data:`MC_CHUNK` trial·m² values, so memory is bounded whatever ``trials``.
MAX_MC_WORK = 20_000_000
MC_CHUNK = 1 << 20


def _where(fn: str, arg: str) -> str:
    """Argument name in messages: '<module>.<function> <argument>'."""
    return f"fusion.{fn} {arg}"


def _dim_guard(fn: str, m: int) -> None:
    if m > MAX_DIM:
        raise ProblemError(f"{_where(fn, 'S1')}: dimension m = {m} above {MAX_DIM} (this "
                           f"function builds (m², m²) matrices: {m * m}² entries)")


def _cov(name: str, s: ArrayLike, m: int | None = None) -> FloatArray:
    arr = as_finite_array(name, s, ndim=2, max_abs=MAX_MAGNITUDE)
    if arr.shape[0] != arr.shape[1]:
        raise ProblemError(f"{name}: expected a square matrix, got shape {arr.shape}")
    if m is not None and arr.shape[0] != m:
        raise ProblemError(f"{name}: expected ({m}, {m}) like S1, got {arr.shape}")
    check_spd(name, arr)
    low = float(np.linalg.eigvalsh(0.5 * (arr + arr.T))[0])
    if low < 1 / MAX_MAGNITUDE:
        # found by the robustness sweep: C = S⁻¹ at 1e151 times estimates at 1e149
        # overflowed; variances below 1e-100 are a units problem, not a fusion one
        raise ProblemError(f"{name}: smallest eigenvalue {low:.3g} below 1e-100 (its inverse "
                           "overflows against the estimates); change units")
    return 0.5 * (arr + arr.T)


def _pair(s1: ArrayLike, s2: ArrayLike, fn: str = "") -> tuple[FloatArray, FloatArray]:
    pre = f"fusion.{fn} " if fn else ""
    a = _cov(pre + "S1", s1)
    return a, _cov(pre + "S2", s2, a.shape[0])


def _vec(a: FloatArray) -> FloatArray:
    """Stack the columns (the paper's '#')."""
    return a.reshape(-1, order="F")


def weight_matrix(s1: ArrayLike, s2: ArrayLike) -> FloatArray:
    """W = (C1 + C2)⁻¹C2 (2), (6), computed as S1(S1 + S2)⁻¹ (no inverse of S_μ).

    The result is re-checked in NumPy: a bound on its relative forward error from the
    residual of W(S1 + S2) = S1 and the conditioning of S1 + S2 (see
    :func:`_weight_error`) must not exceed :data:`optmodels.core.REJECT_TOL`.

    Raises
    ------
    ProblemError
        Non-square, mismatched, non-finite, non-symmetric or non-PD S1/S2, or S1 + S2 so
        ill-conditioned that W cannot be computed to REJECT_TOL.
    """
    a, b = _pair(s1, s2, "weight_matrix")
    w = _weight(a, b)
    _refuse_inaccurate("weight_matrix", _weight_error(w, a + b, a), "S1 + S2")
    return w


_EPS = float(np.finfo(float).eps)


def _bounded_error(mat: FloatArray, sol: FloatArray, rhs: FloatArray, inv: FloatArray
                   ) -> FloatArray:
    """LAPACK-style (xGERFS) forward error bound of a computed ``sol`` of
    ``mat @ sol = rhs``: |inv| (|r| + γ(|mat||sol| + |rhs|)) elementwise, r the residual,
    γ = (m + 2) eps, ``inv`` the (pseudo-)inverse of ``mat``. Componentwise, so a
    badly scaled but well-conditioned system (diagonal S) is not penalised."""
    gamma = (mat.shape[0] + 2) * _EPS
    r = rhs - mat @ sol
    return np.abs(inv) @ (np.abs(r) + gamma * (np.abs(mat) @ np.abs(sol) + np.abs(rhs)))


def _weight_bound(w: FloatArray, mat: FloatArray, rhs: FloatArray,
                  inv: FloatArray | None = None) -> FloatArray:
    """Elementwise forward error bound |δW| of W solving W·mat = rhs (mat symmetric, i.e.
    mat·Wᵀ = rhsᵀ): S1 + S2 and S1 for the paper's W (2), D and S1 − S12 for the
    correlated one (``inv`` = D⁺ there); inf where W is not finite."""
    if not np.all(np.isfinite(w)):
        return np.full_like(w, np.inf)
    if inv is None:
        inv = np.linalg.inv(mat)
    return _bounded_error(mat, w.T, rhs.T, inv).T


def _weight_error(w: FloatArray, mat: FloatArray, rhs: FloatArray,
                  inv: FloatArray | None = None) -> float:
    """Relative forward error bound max|δW| / max|W| (see :func:`_weight_bound`)."""
    err = _weight_bound(w, mat, rhs, inv)
    return float(np.max(err) / max(float(np.max(np.abs(w))), np.finfo(float).tiny))


def _combination_bound(w: FloatArray, dw: FloatArray, x1: FloatArray, x2: FloatArray
                       ) -> FloatArray:
    """Elementwise error bound of a1 + W(a2 − a1) given |δW| ≤ dw: dw|a2 − a1| plus the
    round-off of the product and the sum."""
    spread = np.abs(x2 - x1)
    return dw @ spread + (x1.size + 2) * _EPS * (np.abs(x1) + np.abs(w) @ spread)


def _refuse_inaccurate(fn: str, err: float, what: str) -> None:
    """Functions that return a bare matrix cannot downgrade a status: refuse instead."""
    if not np.isfinite(err) or err > REJECT_TOL:
        raise ProblemError(f"fusion.{fn}: {what} is too ill-conditioned: the result's "
                           f"relative forward error bound {err:.2g} exceeds {REJECT_TOL:g} "
                           "(NumPy re-check)")


def _weight(a: FloatArray, b: FloatArray) -> FloatArray:
    """S1(S1 + S2)⁻¹ = ((S1 + S2)⁻¹S1)ᵀ for symmetric S1, S2; stacks (..., m, m) too."""
    if a.ndim == 2:
        return linalg.solve(a + b, a, assume_a="pos").T
    return np.swapaxes(np.linalg.solve(a + b, a), -1, -2)


@dataclass
class FusionSolution(Solution):
    """Fused estimate (1): ``estimate`` (m,), ``covariance`` (C1 + C2)⁻¹, ``W``."""

    estimate: FloatArray = field(default_factory=lambda: np.empty(0))
    covariance: FloatArray = field(default_factory=lambda: np.empty(0))
    W: FloatArray = field(default_factory=lambda: np.empty(0))


def _wls_objective(x: FloatArray, a1: FloatArray, c1: FloatArray, a2: FloatArray,
                   c2: FloatArray) -> float:
    d1, d2 = x - a1, x - a2
    return float(d1 @ c1 @ d1 + d2 @ c2 @ d2)


def _cross(s12: ArrayLike, a: FloatArray, b: FloatArray, fn: str = "fuse"
           ) -> tuple[FloatArray, FloatArray]:
    """Validate a cross-covariance S12 = Cov(a1, a2): finite (m, m) and the joint covariance
    [[S1, S12], [S12ᵀ, S2]] positive semidefinite. Returns (S12, D) with
    D = S1 + S2 − S12 − S12ᵀ = Cov(a1 − a2) (positive semidefinite, possibly singular)."""
    m = a.shape[0]
    name = _where(fn, "s12")
    c = as_finite_array(name, s12, shape=(m, m), max_abs=MAX_MAGNITUDE)
    joint = np.block([[a, c], [c.T, b]])
    lam = np.linalg.eigvalsh(joint)
    if lam[0] < -1e-10 * max(lam[-1], np.finfo(float).tiny):
        raise ProblemError(f"{name}: the joint covariance [[S1, S12], [S12ᵀ, S2]] is not positive "
                           f"semidefinite (smallest eigenvalue {lam[0]:.3g}); S12 cannot be the "
                           "cross-covariance of these estimates")
    d = a + b - c - c.T
    return c, 0.5 * (d + d.T)


#: Relative eigenvalue threshold below which D = Cov(a1 − a2) is treated as singular.
PINV_RTOL = 1e-10


def _correlated_weight(s1: FloatArray, s12: FloatArray, d: FloatArray) -> FloatArray:
    """(S1 − S12) D⁺ for stacks (..., m, m); D⁺ the pseudo-inverse (eigenvalues below
    :data:`PINV_RTOL` × the largest are dropped)."""
    return (s1 - s12) @ np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True)


def weight_matrix_correlated(s1: ArrayLike, s2: ArrayLike, s12: ArrayLike) -> FloatArray:
    """Weight of the best linear unbiased fusion of two **correlated** estimates
    (Bar-Shalom & Campo): W = (S1 − S12)D⁺, D = S1 + S2 − S12 − S12ᵀ = Cov(a1 − a2),
    S12 = Cov(a1, a2).

    With S12 = 0 this is the paper's W (2), (6), which assumes independent measurers.
    D may be singular: the two estimates then differ only inside range(D) (in the
    two-site system both lie on the bearing from A, so D has rank 1). W is then not
    unique, but (I − W)a1 + Wa2 and its covariance are; the minimum-norm W is returned.
    A valid joint covariance guarantees (S1 − S12)D⁺D = S1 − S12 (for z in null(D),
    zᵀa1 = zᵀa2, so (S1 − S12)z = Cov(a1, zᵀ(a1 − a2)) = 0).
    """
    a, b = _pair(s1, s2, "weight_matrix_correlated")
    c, d = _cross(s12, a, b, "weight_matrix_correlated")
    w = _correlated_weight(a, c, d)
    err = _weight_error(w, d, a - c, np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True))
    _refuse_inaccurate("weight_matrix_correlated", err, "D = S1 + S2 − S12 − S12ᵀ")
    return w


def fuse(a1: ArrayLike, s1: ArrayLike, a2: ArrayLike, s2: ArrayLike, *,
         s12: ArrayLike | None = None,
         method: Literal["closed_form", "cvxpy"] = "closed_form",
         solver: str = "CLARABEL", **solver_options: Any) -> FusionSolution:
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
    method = as_choice(_where(fn, "method"), method, ("closed_form", "cvxpy"))
    if not isinstance(solver, str):
        raise ProblemError(f"{_where(fn, 'solver')}: expected a solver name, got {solver!r}")
    if s12 is not None:
        return _fuse_correlated(x1, s1a, x2, s2a, s12, method, solver, solver_options)
    c1, c2 = np.linalg.inv(s1a), np.linalg.inv(s2a)
    w = _weight(s1a, s2a)
    cov = (np.eye(m) - w) @ s1a
    cov = 0.5 * (cov + cov.T)
    if method == "closed_form":
        with timed() as tm:
            est = x1 + w @ (x2 - x1)
        common: dict[str, Any] = {"status": Status.OPTIMAL, "method": "closed_form",
                                  "solve_time": tm.elapsed, "message": "(1)-(2)"}
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
            obj = (cp.quad_form(u, cp.psd_wrap(c1 / cn))
                   + cp.quad_form(u - delta, cp.psd_wrap(c2 / cn)))
            prob = cp.Problem(cp.Minimize(obj))
        res = solve_problem(prob, solver, **solver_options)
        common = res.common()
        common["build_time"] += tb.elapsed
        est = (x1 + d * np.asarray(u.value) if res.status.ok and u.value is not None
               else np.full(m, np.nan))
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
    bound = np.minimum(np.abs(cov) @ g_err,
                       np.abs(est - alpha_w) + _combination_bound(w, dw, x1, x2))
    size = max(float(np.max(np.abs(np.concatenate([est, x1, x2])))), np.finfo(float).tiny)
    w_err = float(np.max(dw) / max(float(np.max(np.abs(w))), np.finfo(float).tiny))
    residuals = {"gradient": res_grad, "estimate_error": float(np.max(bound) / size),
                 "weight_error": w_err}
    est, w, cov = _verify(common, residuals, est, w, cov)
    return FusionSolution(objective=_wls_objective(est, x1, c1, x2, c2),
                          residuals=residuals, estimate=est, covariance=cov, W=w, **common)


def _verify(common: dict[str, Any], residuals: dict[str, float], est: FloatArray,
            w: FloatArray, cov: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A solver's (or a closed form's) 'optimal' is not taken on trust:
    :func:`optmodels.core.verified_status` with the largest NumPy-recomputed residual.
    A result that is not OK keeps no estimate (NaN), and no W/covariance if W failed."""
    worst_key = max(residuals, key=lambda k: -1.0 if np.isnan(residuals[k])
                    else residuals[k])
    worst = residuals[worst_key]
    if any(np.isnan(v) for v in residuals.values()):
        worst = float("nan")
    new = verified_status(common["status"], worst)
    if new != common["status"]:
        verdict = "fails the NumPy check" if new == Status.ERROR else "(NumPy check)"
        common["status"] = new
        common["message"] = f"{common.get('message', '')}; {worst_key} " \
            f"{worst:.1e} {verdict}"
    if not new.ok:
        est = np.full_like(est, np.nan)
        if not residuals["weight_error"] <= REJECT_TOL:
            w, cov = np.full_like(w, np.nan), np.full_like(cov, np.nan)
    return est, w, cov


def _fuse_correlated(x1: FloatArray, a: FloatArray, x2: FloatArray, b: FloatArray,
                     s12: ArrayLike, method: str, solver: str,
                     solver_options: dict[str, Any]) -> FusionSolution:
    c, d = _cross(s12, a, b, "fuse")
    m = a.shape[0]
    eye = np.eye(m)
    if method == "closed_form":
        with timed() as tm:
            w = _correlated_weight(a, c, d)
        common: dict[str, Any] = {"status": Status.OPTIMAL, "method": "closed_form",
                                  "solve_time": tm.elapsed, "message": "Bar-Shalom-Campo"}
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
        w = (np.asarray(wv.value) if res.status.ok and wv.value is not None
             else np.full((m, m), np.nan))
    est = x1 + w @ (x2 - x1)
    # optimality: d tr(cov)/dW = 2(W D − (S1 − S12)) = 0
    cov = fused_covariance(w, a, b, c)
    grad = w @ d - (a - c)
    res_grad = float(np.max(np.abs(grad)) / (np.max(np.abs(d)) * max(1.0, np.max(np.abs(w)))))
    dw = _weight_bound(w, d, a - c, np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True))
    w_err = float(np.max(dw) / max(float(np.max(np.abs(w))), np.finfo(float).tiny))
    # |δα| ≤ |δW||a2 − a1| + round-off of a1 + W(a2 − a1)
    size = max(float(np.max(np.abs(np.concatenate([est, x1, x2])))), np.finfo(float).tiny)
    bound = float(np.max(_combination_bound(w, dw, x1, x2))) / size
    residuals = {"gradient": res_grad, "estimate_error": bound, "weight_error": w_err}
    est, w, cov = _verify(common, residuals, est, w, cov)
    return FusionSolution(objective=float(np.trace(cov)), residuals=residuals,
                          estimate=est, covariance=cov, W=w, **common)


def fused_covariance(w: ArrayLike, s1: ArrayLike, s2: ArrayLike,
                     s12: ArrayLike | None = None) -> FloatArray:
    """Error covariance of (I − W)a1 + Wa2 for **any** W (stacks (..., m, m) broadcast):
    (I − W)S1(I − W)ᵀ + WS2Wᵀ + (I − W)S12Wᵀ + WS12ᵀ(I − W)ᵀ.

    With the paper's W and S12 = 0 this is (C1 + C2)⁻¹; with the paper's W applied to
    correlated estimates it is the covariance one actually gets (larger than
    (C1 + C2)⁻¹, and possibly larger than S1 itself). Inputs are not validated (an
    internal building block; the public fusion functions validate)."""
    wm, a, b = (np.asarray(v, dtype=float) for v in (w, s1, s2))
    v = np.eye(wm.shape[-1]) - wm
    tr = np.swapaxes
    cov = v @ a @ tr(v, -1, -2) + wm @ b @ tr(wm, -1, -2)
    if s12 is not None:
        c = np.asarray(s12, dtype=float)
        cov = cov + v @ c @ tr(wm, -1, -2) + wm @ tr(c, -1, -2) @ tr(v, -1, -2)
    return 0.5 * (cov + tr(cov, -1, -2))


def weight_jacobians(s1: ArrayLike, s2: ArrayLike, *,
                     method: Literal["closed_form", "ad"] = "closed_form"
                     ) -> tuple[FloatArray, FloatArray]:
    """P1 = d vec(W)/d vec(S1), P2 = d vec(W)/d vec(S2), each (m², m²), all m² entries of
    S_μ treated as independent, columns in the order of vec (12) (column-major).

    ``"closed_form"``: (13)-(14) as Kronecker products, P1 = (C1W)ᵀ ⊗ (I − W),
    P2 = −(C2(I − W))ᵀ ⊗ W. ``"ad"``: CasADi automatic differentiation of
    W = S1(S1 + S2)⁻¹ with symbolic, unsymmetrised S_μ. m ≤ :data:`MAX_DIM`.
    """
    fn = "weight_jacobians"
    a, b = _pair(s1, s2, fn)
    m = a.shape[0]
    _dim_guard(fn, m)
    method = as_choice(_where(fn, "method"), method, ("closed_form", "ad"))
    if method == "closed_form":
        return _jacobians(a, b)
    if method == "ad":
        x1, x2 = ca.SX.sym("S1", m, m), ca.SX.sym("S2", m, m)
        wsym = ca.solve((x1 + x2).T, x1.T).T  # S1 (S1+S2)^-1 for general (unsymmetric) S
        vw = ca.vec(wsym)  # CasADi's vec is column-major, as the paper's '#'
        f = ca.Function("P", [x1, x2], [ca.jacobian(vw, ca.vec(x1)), ca.jacobian(vw, ca.vec(x2))])
        p1, p2 = f(a, b)
        return np.array(p1), np.array(p2)
    raise ProblemError(f"method: expected 'closed_form' or 'ad', got {method!r}")


def _jacobians(a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(13)-(14) as Kronecker products, for validated S1 = a, S2 = b."""
    w = _weight(a, b)
    i = np.eye(a.shape[0])
    c1, c2 = np.linalg.inv(a), np.linalg.inv(b)
    return np.kron((c1 @ w).T, i - w), -np.kron((c2 @ (i - w)).T, w)


def commutation_matrix(m: int) -> FloatArray:
    """K with K vec(A) = vec(Aᵀ) for (m, m) matrices, 1 ≤ m ≤ :data:`MAX_DIM`."""
    m = as_count("fusion.commutation_matrix m", m, minimum=1, maximum=MAX_DIM)
    k = np.zeros((m * m, m * m))
    for i in range(m):
        for j in range(m):
            k[i * m + j, j * m + i] = 1.0
    return k


def _check_n(name: str, n: int, m: int, mean: str = "sample") -> int:
    """n snapshots give a nonsingular Ŝ (3) a.s. iff n ≥ m with the known mean and
    n ≥ m + 1 with the sample mean (one degree of freedom spent on it); the divisor
    n − 1 needs n ≥ 2."""
    least = max(2, m if mean == "known" else m + 1)
    k = as_count(name, n)  # refuses NaN, inf, 2.5, booleans and strings
    if k < least:
        rel = "n ≥ m" if mean == "known" else "n > m"
        raise ProblemError(f"{name}: need an integer sample size {rel} = {m} with the {mean} "
                           f"mean (the sample covariance is singular otherwise), got {k}")
    return k


def sample_covariance_moments(sigma: ArrayLike, n: int, *, mean: MeanKind = "known"
                              ) -> tuple[FloatArray, FloatArray]:
    """Mean (m, m) and covariance of vec(Ŝ) (m², m²) for the estimator (3) with divisor
    n − 1 of ``n`` Gaussian snapshots with covariance ``sigma``.

    * ``mean="known"`` (the paper's literal (3), deviations from the true mean):
      E Ŝ = n/(n−1) Σ and Cov(Ŝ_ij, Ŝ_kl) = n/(n−1)² (σ_ik σ_jl + σ_il σ_jk) -- the
      paper's (4)-(5) (with its index q read as k);
    * ``mean="sample"`` (deviations from the sample mean, the usual estimator):
      E Ŝ = Σ and Cov = (σ_ik σ_jl + σ_il σ_jk)/(n − 1).

    In matrix form Cov(vec Ŝ) = c (Σ ⊗ Σ)(I + K), K the commutation matrix.
    """
    fn = "sample_covariance_moments"
    s = _cov(_where(fn, "sigma"), sigma)
    _dim_guard(fn, s.shape[0])
    mean = _check_mean(fn, mean)
    return _moments(s, _check_n(_where(fn, "n"), n, s.shape[0], mean), mean)


def _check_mean(fn: str, mean: Any) -> MeanKind:
    return as_choice(_where(fn, "mean"), mean, ("known", "sample"))  # type: ignore[return-value]


def _moments(s: FloatArray, n: int, mean: str) -> tuple[FloatArray, FloatArray]:
    """(4)-(5) or their sample-mean counterparts for validated inputs."""
    m = s.shape[0]
    if mean == "known":
        mu, c = n / (n - 1) * s, n / (n - 1) ** 2
    else:
        mu, c = s.copy(), 1.0 / (n - 1)
    return mu, c * np.kron(s, s) @ (np.eye(m * m) + commutation_matrix(m))


def weight_covariance(s1: ArrayLike, s2: ArrayLike, n1: int, n2: int, *,
                      mean: MeanKind = "known", s12: ArrayLike | None = None) -> FloatArray:
    """Linearised Cov(vec Ŵ) (10): P C_C Pᵀ with P = [P1 P2] the Jacobians (13)-(14) at
    the true S_μ and C_C the covariance of (vec Ŝ1, vec Ŝ2) from
    :func:`sample_covariance_moments`.

    ``s12=None`` (the paper): Ŝ1 and Ŝ2 from independent snapshots, C_C block-diagonal,
    (10) as printed. ``s12`` = Cov(a1, a2): both sample covariances come from the **same**
    n1 = n2 snapshot pairs of correlated estimators, and C_C gets the off-diagonal block
    Cov(vec Ŝ1, vec Ŝ2) = c (S12 ⊗ S12)(I + K) (c as in the diagonal blocks) -- the case
    of the paper's own two-site example, where the printed (10) is off by factors of
    2-4 even at n = 100 (see ``docs/errata.md``). Valid to first order in 1/n (see
    :func:`monte_carlo_weight` for the exact law with independent snapshots)."""
    fn = "weight_covariance"
    a, b = _pair(s1, s2, fn)
    mean = _check_mean(fn, mean)
    m = a.shape[0]
    _dim_guard(fn, m)
    n1 = _check_n(_where(fn, "n1"), n1, m, mean)
    n2 = _check_n(_where(fn, "n2"), n2, m, mean)
    p1, p2 = _jacobians(a, b)
    _, k1 = _moments(a, n1, mean)
    _, k2 = _moments(b, n2, mean)
    out = p1 @ k1 @ p1.T + p2 @ k2 @ p2.T
    if s12 is not None:
        if n1 != n2:
            raise ProblemError(f"{_where(fn, 'n2')}: with s12 both sample covariances come "
                               f"from the same snapshots, so n1 = n2 is required (got {n1}, "
                               f"{n2})")
        c, _ = _cross(s12, a, b, fn)
        _, k12 = _moments(c, n1, mean)  # same c·(X ⊗ X)(I + K) form with X = S12
        cross = p1 @ k12 @ p2.T
        out = out + cross + cross.T
    return out


@dataclass(frozen=True)
class WeightMonteCarlo:
    """``mean`` (m, m) and ``cov`` (m², m²) of vec(Ŵ) over ``trials`` draws."""

    mean: FloatArray
    cov: FloatArray
    trials: int


def monte_carlo_weight(s1: ArrayLike, s2: ArrayLike, n1: int, n2: int, *,
                       trials: int = 100_000, seed: int | np.random.Generator | None = None,
                       mean: MeanKind = "known") -> WeightMonteCarlo:
    """Monte Carlo law of Ŵ = Ŝ1(Ŝ1 + Ŝ2)⁻¹ with Ŝ_μ from (3).

    Σ_s (x_s − m)(x_s − m)ᵀ is Wishart(n, S) with the true mean, Wishart(n − 1, S) with the
    sample mean; both are drawn by :func:`scipy.stats.wishart` (Bartlett decomposition) and
    divided by n − 1. Vectorised over chunks of at most :data:`MC_CHUNK` / m² trials, the
    moments accumulated around the true W, so memory is bounded whatever ``trials``.

    ``seed``: None, a non-negative integer or a :class:`numpy.random.Generator`.
    Size guard: trials · m² ≤ :data:`MAX_MC_WORK` = 2e7 (about 15 s here; 10⁵ trials at
    m = 3 take ~0.5 s) and m ≤ :data:`MAX_DIM`; larger requests raise ProblemError
    rather than run for minutes.
    """
    fn = "monte_carlo_weight"
    a, b = _pair(s1, s2, fn)
    m = a.shape[0]
    _dim_guard(fn, m)
    mean = _check_mean(fn, mean)
    n1 = _check_n(_where(fn, "n1"), n1, m, mean)
    n2 = _check_n(_where(fn, "n2"), n2, m, mean)
    trials = as_count(_where(fn, "trials"), trials, minimum=2)
    if trials * m * m > MAX_MC_WORK:
        raise ProblemError(f"{_where(fn, 'trials')}: {trials} trials at m = {m} is "
                           f"trials·m² = {trials * m * m:.3g}, above the limit {MAX_MC_WORK:.0e} "
                           f"(≈ 15 s); use at most {MAX_MC_WORK // (m * m)} trials (the "
                           "Monte Carlo standard error falls only as 1/√trials)")
    rng = _rng(_where(fn, "seed"), seed)
    lost = 0 if mean == "known" else 1
    w0 = _vec(_weight(a, b))  # shift: moments accumulated around the true W (stable sums)
    total = np.zeros(m * m)
    outer = np.zeros((m * m, m * m))
    chunk = max(1, MC_CHUNK // (m * m))
    done = 0
    while done < trials:
        k = min(chunk, trials - done)
        draws = []
        for s, n in ((a, n1), (b, n2)):
            x = stats.wishart(df=n - lost, scale=s).rvs(size=k, random_state=rng)
            draws.append(np.asarray(x).reshape(k, m, m) / (n - 1))
        # Ŵ = Ŝ1 (Ŝ1+Ŝ2)^-1 = ((Ŝ1+Ŝ2)^-1 Ŝ1)^T (symmetric draws)
        w = _weight(draws[0], draws[1])
        dv = w.transpose(0, 2, 1).reshape(k, m * m) - w0  # column-major vec per trial
        total += dv.sum(axis=0)
        outer += dv.T @ dv
        done += k
    mean_dv = total / trials
    cov = (outer - trials * np.outer(mean_dv, mean_dv)) / (trials - 1)
    return WeightMonteCarlo(mean=(w0 + mean_dv).reshape(m, m, order="F"),
                            cov=0.5 * (cov + cov.T), trials=trials)


def _rng(name: str, seed: Any) -> np.random.Generator:
    """None, a non-negative integer or a Generator → a Generator; ProblemError otherwise."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None:
        return np.random.default_rng()
    return np.random.default_rng(as_count(name, seed))


def weight_from_samples(a1: ArrayLike, a2: ArrayLike, *, correlated: bool = False
                        ) -> FloatArray:
    """Ŵ from n snapshots of the two estimators, rows of ``a1`` and ``a2`` (n, m): the
    sample covariances (3) with the sample mean and divisor n − 1, then W of (2), or of
    :func:`weight_matrix_correlated` with the sample cross-covariance if ``correlated``.

    Raises :class:`ProblemError` if n ≤ m (singular sample covariance) or the snapshots
    are degenerate.
    """
    fn = "weight_from_samples"
    x1 = as_finite_array(_where(fn, "a1"), a1, ndim=2, max_abs=MAX_MAGNITUDE)
    x2 = as_finite_array(_where(fn, "a2"), a2, shape=x1.shape, max_abs=MAX_MAGNITUDE)
    if not isinstance(correlated, bool | np.bool_):
        raise ProblemError(f"{_where(fn, 'correlated')}: expected True or False, got "
                           f"{correlated!r}")
    n, m = x1.shape
    _check_n(_where(fn, "a1 rows (snapshots)"), n, m)
    full = np.cov(np.hstack([x1, x2]).T)
    s1, s2, s12 = full[:m, :m], full[m:, m:], full[:m, m:]
    for name, s in (("a1", s1), ("a2", s2)):
        try:
            check_spd(f"sample covariance of {name}", s)
        except ProblemError as exc:
            raise ProblemError(f"{name}: the snapshots are degenerate ({exc})") from None
    if correlated:
        return weight_matrix_correlated(s1, s2, s12)
    w = _weight(s1, s2)
    _refuse_inaccurate(fn, _weight_error(w, s1 + s2, s1), "the sample S1 + S2")
    return w


# =========================================================================== two sites
#: Reading of the measurement vector z of :class:`TwoSiteSystem`.
MEASUREMENTS = ("azimuth A", "azimuth B", "range difference")


@dataclass
class JointMLSolution(Solution):
    """Joint ML positions ``estimate`` (T, 2) from all three measurements, one per row
    of z, and the per-trial relative stationarity ``stationarity`` (T,)."""

    estimate: FloatArray = field(default_factory=lambda: np.empty((0, 2)))
    stationarity: FloatArray = field(default_factory=lambda: np.empty(0))


@dataclass(frozen=True)
class TwoSiteSystem:
    r"""The two-position passive system of the paper's introduction.

    Receiving sites A and B on a baseline (positions (2,), metres, East-North); each
    measures the azimuth of the emitter (clockwise from North, :math:`\operatorname{atan2}
    (dx, dy)`), and the pair measures the range difference
    :math:`\Delta r = \|x - B\| - \|x - A\|`. Noise is independent, Gaussian, with standard
    deviations ``sigma_azimuth`` (rad) and ``sigma_range_difference`` (m).

    Two minimal estimators of the position x (the paper's "measurers"):

    * estimator 1, :meth:`triangulate`: the two azimuths;
    * estimator 2, :meth:`azimuth_range_difference`: the azimuth at A and Δr.

    Both use the azimuth at A, so their errors are **correlated**
    (:meth:`covariances` returns S1, S2 and S12 to first order); the paper's fusion (1)
    assumes independent measurers. The original problem, ML from all three measurements,
    is :meth:`joint_ml` (CasADi/IPOPT); its first-order covariance is :meth:`crb`.

    Degenerate geometry: at a site the azimuth is undefined; on the line through the
    sites the two bearings are parallel (estimator 1 is singular everywhere on it), and on
    its extension beyond the sites Δr is constant (±baseline), so estimator 2 and the
    joint Fisher information are singular there too: the position along the line is not
    observed (infinite variance). :meth:`covariances` and :meth:`crb` refuse such
    positions (ProblemError naming the position), judged by the condition number of the
    whitened Jacobian against :data:`GEOMETRY_COND`; ``on_degenerate="nan"`` returns NaN
    matrices there instead (for maps).
    """

    site_a: FloatArray
    site_b: FloatArray
    sigma_azimuth: float
    sigma_range_difference: float

    def __post_init__(self) -> None:
        a = as_finite_array("fusion.TwoSiteSystem site_a", self.site_a, shape=(2,),
                            max_abs=MAX_MAGNITUDE)
        b = as_finite_array("fusion.TwoSiteSystem site_b", self.site_b, shape=(2,),
                            max_abs=MAX_MAGNITUDE)
        if np.linalg.norm(b - a) == 0:
            raise ProblemError("fusion.TwoSiteSystem site_b: coincides with site_a (zero "
                               "baseline)")
        for name in ("sigma_azimuth", "sigma_range_difference"):
            v = as_positive(f"fusion.TwoSiteSystem {name}", getattr(self, name))
            object.__setattr__(self, name, v)
        if self.sigma_azimuth > np.pi:
            raise ProblemError(f"fusion.TwoSiteSystem sigma_azimuth: {self.sigma_azimuth:g} "
                               "rad exceeds π (give radians)")
        object.__setattr__(self, "site_a", a)
        object.__setattr__(self, "site_b", b)

    @classmethod
    def on_baseline(cls, baseline: float = 20_000.0, sigma_azimuth: float = 3e-3,
                    sigma_range_difference: float = 3.0) -> TwoSiteSystem:
        """Sites at (∓baseline/2, 0), metres. Defaults: a 20 km baseline, σ_az = 3 mrad
        (0.17°), σ_Δr = 3 m (10 ns) -- both estimators then matter over the region of the
        demo."""
        b = as_positive("fusion.TwoSiteSystem.on_baseline baseline", baseline)
        if b > MAX_MAGNITUDE:
            raise ProblemError(f"fusion.TwoSiteSystem.on_baseline baseline: {b:g} m above "
                               f"{MAX_MAGNITUDE:.0e} (change units)")
        h = 0.5 * b
        return cls(np.array([-h, 0.0]), np.array([h, 0.0]), sigma_azimuth,
                   sigma_range_difference)

    @property
    def baseline(self) -> float:
        return float(np.linalg.norm(self.site_b - self.site_a))

    @property
    def noise_cov(self) -> FloatArray:
        """R = diag(σ_az², σ_az², σ_Δr²) of z."""
        return np.diag([self.sigma_azimuth**2, self.sigma_azimuth**2,
                        self.sigma_range_difference**2])

    # ------------------------------------------------------------------ model
    def _pos(self, x: ArrayLike, name: str = "x") -> FloatArray:
        arr = as_finite_array(name, x, max_abs=MAX_MAGNITUDE)
        if arr.shape[-1:] != (2,):
            raise ProblemError(f"{name}: expected positions (..., 2), got shape {arr.shape}")
        return arr

    def _off_sites(self, p: FloatArray, name: str) -> None:
        """Refuse positions at a site (azimuth undefined there)."""
        for label, site in (("A", self.site_a), ("B", self.site_b)):
            at = np.all(p == site, axis=-1)
            if np.any(at):
                idx = _first_index(at)
                raise ProblemError(f"{_at(name, idx)} = {_xy(p[idx])} m coincides with site "
                                   f"{label}: the azimuth is undefined there")

    def measure(self, x: ArrayLike) -> FloatArray:
        """Noise-free z(x) = (azimuth A, azimuth B, Δr), (..., 3). ProblemError at a site."""
        p = self._pos(x, "fusion.TwoSiteSystem.measure x")
        self._off_sites(p, "fusion.TwoSiteSystem.measure x")
        return self._measure(p)

    def _measure(self, p: FloatArray) -> FloatArray:
        da, db = p - self.site_a, p - self.site_b
        return np.stack([np.arctan2(da[..., 0], da[..., 1]), np.arctan2(db[..., 0], db[..., 1]),
                         np.hypot(db[..., 0], db[..., 1]) - np.hypot(da[..., 0], da[..., 1])],
                        axis=-1)

    def jacobian(self, x: ArrayLike) -> FloatArray:
        """∂z/∂x, (..., 3, 2). For azimuth atan2(dx, dy): ∂/∂x = (dy, −dx)/ρ².
        ProblemError at a site (it is defined everywhere else, on the baseline too)."""
        p = self._pos(x, "fusion.TwoSiteSystem.jacobian x")
        self._off_sites(p, "fusion.TwoSiteSystem.jacobian x")
        return self._jac(p)

    def _jac(self, p: FloatArray) -> FloatArray:
        """Unchecked Jacobian (NaN at a site)."""
        rows = []
        with np.errstate(divide="ignore", invalid="ignore"):
            for s in (self.site_a, self.site_b):
                d = p - s
                r2 = d[..., 0] ** 2 + d[..., 1] ** 2
                rows.append(np.stack([d[..., 1] / r2, -d[..., 0] / r2], axis=-1))
            ua = (p - self.site_a) / np.linalg.norm(p - self.site_a, axis=-1, keepdims=True)
            ub = (p - self.site_b) / np.linalg.norm(p - self.site_b, axis=-1, keepdims=True)
        rows.append(ub - ua)
        return np.stack(rows, axis=-2)

    def sample(self, x: ArrayLike, trials: int, rng: np.random.Generator) -> FloatArray:
        """Noisy measurements (trials, 3) at one position x (2,); azimuths wrapped."""
        p = as_finite_array("fusion.TwoSiteSystem.sample x", x, shape=(2,),
                            max_abs=MAX_MAGNITUDE)
        self._off_sites(p, "fusion.TwoSiteSystem.sample x")
        k = as_count("fusion.TwoSiteSystem.sample trials", trials, minimum=1)
        if not isinstance(rng, np.random.Generator):
            raise ProblemError("fusion.TwoSiteSystem.sample rng: expected a "
                               f"numpy.random.Generator, got {type(rng).__name__}")
        z = self._measure(p) + rng.normal(size=(k, 3)) * np.sqrt(np.diag(self.noise_cov))
        z[:, :2] = np.angle(np.exp(1j * z[:, :2]))
        return z

    # ------------------------------------------------------------------ geometry
    @property
    def _harmless(self) -> FloatArray:
        """A regular position (one baseline from A, perpendicular to AB) that stands in
        for degenerate ones before their results are set to NaN."""
        d = self.site_b - self.site_a
        return self.site_a + np.array([-d[1], d[0]])
    def _conditions(self, p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Condition numbers (...,) of the whitened Jacobians of estimator 1 (azimuths A,
        B), estimator 2 (azimuth A, Δr) and the joint problem (all three); inf at a site
        or where the Jacobian is singular."""
        jw = self._jac(p) / np.sqrt(np.diag(self.noise_cov))[:, None]
        out = []
        for rows in ([0, 1], [0, 2], [0, 1, 2]):
            sub = jw[..., rows, :]
            good = np.all(np.isfinite(sub), axis=(-2, -1))
            sv = np.linalg.svd(np.where(good[..., None, None], sub, 0.0), compute_uv=False)
            with np.errstate(divide="ignore", invalid="ignore"):
                cond = sv[..., 0] / sv[..., -1]
            out.append(np.where(good & np.isfinite(cond), cond, np.inf))
        return out[0], out[1], out[2]

    def _refuse_degenerate(self, p: FloatArray, bad: FloatArray, cond: FloatArray,
                           name: str, what: str) -> None:
        if np.any(bad):
            idx = _first_index(bad)
            self._off_sites(p, name)
            raise ProblemError(
                f"{_at(name, idx)} = {_xy(p[idx])} m: degenerate geometry for {what} (condition "
                f"number {float(cond[idx]):.2g} of its whitened Jacobian, limit "
                f"{GEOMETRY_COND:.0e}): on or near the line through the sites, where the "
                "position along that line is not observed, or too far away; give "
                "on_degenerate='nan' for NaN there instead")

    def covariances(self, x: ArrayLike, *,
                    on_degenerate: Literal["raise", "nan"] = "raise"
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """First-order S1, S2 and S12 = Cov(a1, a2) at position(s) x, each (..., 2, 2), m².

        a_k = x + G_k e_k with G_k = (∂z_k/∂x)⁻¹; e_1 = (e_azA, e_azB), e_2 = (e_azA, e_Δr),
        so S12 = G_1 Cov(e_1, e_2) G_2ᵀ with Cov(e_1, e_2) = diag(σ_az², 0).

        Raises ProblemError naming the first position where estimator 1 or 2 is degenerate
        (a site; the line through the sites for estimator 1, its extension beyond the
        sites for estimator 2; condition number of the whitened Jacobian above
        :data:`GEOMETRY_COND`, so that S_k stays within what :func:`weight_matrix`
        accepts). With ``on_degenerate="nan"`` those matrices are NaN instead (S12 NaN
        where either is).
        """
        name = "fusion.TwoSiteSystem.covariances x"
        mode = as_choice("fusion.TwoSiteSystem.covariances on_degenerate", on_degenerate,
                         ("raise", "nan"))
        p = self._pos(x, name)
        c1, c2, _ = self._conditions(p)
        bad1, bad2 = ~(c1 <= GEOMETRY_COND), ~(c2 <= GEOMETRY_COND)
        if mode == "raise":
            self._refuse_degenerate(p, bad1, c1, name, "estimator 1 (azimuths A and B)")
            self._refuse_degenerate(p, bad2, c2, name, "estimator 2 (azimuth A and Δr)")
        # degenerate positions are replaced by a harmless point, then set to NaN
        q = np.where((bad1 | bad2)[..., None], self._harmless, p)
        j = self._jac(q)
        g1 = np.linalg.inv(j[..., [0, 1], :])
        g2 = np.linalg.inv(j[..., [0, 2], :])
        r = self.noise_cov
        r1, r2 = r[np.ix_([0, 1], [0, 1])], r[np.ix_([0, 2], [0, 2])]
        r12 = np.diag([self.sigma_azimuth**2, 0.0])
        tr = np.swapaxes
        s1 = g1 @ r1 @ tr(g1, -1, -2)
        s2 = g2 @ r2 @ tr(g2, -1, -2)
        s12 = g1 @ r12 @ tr(g2, -1, -2)
        nan = np.full((2, 2), np.nan)
        s1 = np.where(bad1[..., None, None], nan, s1)
        s2 = np.where(bad2[..., None, None], nan, s2)
        s12 = np.where((bad1 | bad2)[..., None, None], nan, s12)
        return s1, s2, s12

    def crb(self, x: ArrayLike, *,
            on_degenerate: Literal["raise", "nan"] = "raise") -> FloatArray:
        """(Jᵀ R⁻¹ J)⁻¹, (..., 2, 2), m²: first-order covariance of the joint ML (the CRB).

        On the extension of the baseline beyond the sites (and at the sites) the Fisher
        information JᵀR⁻¹J is singular: the bound on the position along the line is
        infinite. Such positions (condition number of the whitened Jacobian above
        :data:`GEOMETRY_COND`) raise ProblemError naming the position, or give NaN with
        ``on_degenerate="nan"``. Between the sites the joint problem is regular (Δr fixes
        the position along the baseline).
        """
        name = "fusion.TwoSiteSystem.crb x"
        mode = as_choice("fusion.TwoSiteSystem.crb on_degenerate", on_degenerate,
                         ("raise", "nan"))
        p = self._pos(x, name)
        _, _, c = self._conditions(p)
        bad = ~(c <= GEOMETRY_COND)
        if mode == "raise":
            self._refuse_degenerate(p, bad, c, name, "the joint ML (all three measurements)")
        q = np.where(bad[..., None], self._harmless, p)
        out = self._crb(q)
        return np.where(bad[..., None, None], np.full((2, 2), np.nan), out)

    def _crb(self, p: FloatArray) -> FloatArray:
        """Unchecked CRB: the closed-form 2×2 inverse (inf/NaN where singular)."""
        j = self._jac(p)
        info = np.swapaxes(j, -1, -2) @ np.linalg.inv(self.noise_cov) @ j
        a, b, d = info[..., 0, 0], info[..., 0, 1], info[..., 1, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            det = a * d - b * b
            out = np.stack([np.stack([d, -b], axis=-1), np.stack([-b, a], axis=-1)],
                           axis=-2) / det[..., None, None]
        return out

    def residuals(self, z: ArrayLike, x: ArrayLike) -> FloatArray:
        """Whitened residuals R^{-1/2}(z − z(x)), azimuth differences wrapped, (..., 3)."""
        p = self._pos(x, "fusion.TwoSiteSystem.residuals x")
        self._off_sites(p, "fusion.TwoSiteSystem.residuals x")
        return self._residuals(self._z(z), p)

    def _residuals(self, z: FloatArray, p: FloatArray) -> FloatArray:
        d = z - self._measure(p)
        d[..., :2] = np.angle(np.exp(1j * d[..., :2]))
        return d / np.sqrt(np.diag(self.noise_cov))

    # ------------------------------------------------------------------ estimators
    def _z(self, z: ArrayLike, name: str = "z") -> FloatArray:
        arr = as_finite_array(name, z, max_abs=MAX_MAGNITUDE)
        if arr.shape[-1:] != (3,):
            raise ProblemError(f"{name}: expected measurements (..., 3) = {MEASUREMENTS}, "
                               f"got shape {arr.shape}")
        return arr

    def triangulate(self, z: ArrayLike) -> FloatArray:
        """Estimator 1: intersection of the two bearings, (..., 2). NaN where the bearings
        do not intersect in front of both sites (target on the baseline's line)."""
        zz = self._z(z)
        ua = np.stack([np.sin(zz[..., 0]), np.cos(zz[..., 0])], axis=-1)
        ub = np.stack([np.sin(zz[..., 1]), np.cos(zz[..., 1])], axis=-1)
        d = self.site_b - self.site_a
        # r_a ua − r_b ub = B − A  (Cramer's rule)
        det = -ua[..., 0] * ub[..., 1] + ua[..., 1] * ub[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            ra = (-d[0] * ub[..., 1] + d[1] * ub[..., 0]) / det
            rb = (ua[..., 0] * d[1] - ua[..., 1] * d[0]) / det
        x = self.site_a + ra[..., None] * ua
        bad = ~((ra > 0) & (rb > 0) & np.isfinite(ra))
        return np.where(bad[..., None], np.nan, x)

    def azimuth_range_difference(self, z: ArrayLike) -> FloatArray:
        """Estimator 2: the bearing from A cut by the hyperbola Δr, (..., 2).

        With ρ = ‖x − A‖ along the bearing u_A: ‖A − B + ρu_A‖ = ρ + Δr gives
        ρ = (Δr² − ‖A − B‖²) / (2(u_A·(A − B) − Δr)); NaN where ρ ≤ 0 (no intersection).
        """
        zz = self._z(z)
        ua = np.stack([np.sin(zz[..., 0]), np.cos(zz[..., 0])], axis=-1)
        ab = self.site_a - self.site_b
        dr = zz[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = (dr**2 - ab @ ab) / (2.0 * (ua @ ab - dr))
        x = self.site_a + rho[..., None] * ua
        return np.where((rho > 0)[..., None] & np.isfinite(rho)[..., None], x, np.nan)

    # ------------------------------------------------------------------ joint ML
    def joint_ml(self, z: ArrayLike, *, x0: ArrayLike | None = None,
                 method: Literal["ipopt", "gauss_newton"] = "ipopt",
                 options: dict[str, Any] | None = None) -> JointMLSolution:
        """ML position from all three measurements (the original problem):
        min_x Σ_k ((z_k − z_k(x)) / σ_k)² for every row of z (T rows, T ≥ 1).

        ``method="ipopt"``: CasADi/IPOPT. The T rows are independent problems, solved as
        one block-separable NLP (2T variables, block-diagonal exact Hessian), each row's
        position scaled by its CRB RMS around the start. ``options`` go to IPOPT; an
        unknown or ill-typed one raises ProblemError naming it. ``method="gauss_newton"``:
        vectorised Gauss-Newton with step halving in NumPy (an independent
        implementation, used to cross-check IPOPT).

        Start: the triangulation (``x0``, (2,) or (T, 2), to override). Re-checked in
        NumPy per row, with :func:`optmodels.core.verified_status` of the worst row:

        * ``residuals["stationarity"]``: J_tᵀR⁻¹r_t relative to ‖J_t‖‖r_t‖ + 1 in whitened
          units;
        * ``residuals["newton_step"]``: the Gauss-Newton step to the stationary point in
          CRB units, √(gᵀ(JᵀR⁻¹J)⁻¹g), i.e. the distance to the optimum relative to the
          estimate's own standard deviation (infinite where the information is singular,
          on the baseline's extension: the estimate is then not an isolated optimum).

        Above 1e-6 the status is OPTIMAL_INACCURATE, above 1e-3 ERROR (estimate NaN).
        IPOPT stopping at its precision limit (Search_Direction_Becomes_Too_Small) is
        reported as OPTIMAL_INACCURATE if both checks pass at 1e-6, as ERROR otherwise.
        """
        fn = "fusion.TwoSiteSystem.joint_ml"
        zz = np.atleast_2d(self._z(z, f"{fn} z"))
        if zz.ndim != 2:
            raise ProblemError(f"{fn} z: expected (T, 3) measurements, got shape {zz.shape}")
        t = zz.shape[0]
        if t == 0:
            raise ProblemError(f"{fn} z: no measurements (0 rows)")
        method = as_choice(f"{fn} method", method, ("ipopt", "gauss_newton"))
        opts = check_options(options)
        if x0 is None:
            start = self.triangulate(zz)
            fallback = self.azimuth_range_difference(zz)
            start = np.where(np.isnan(start), fallback, start)
            mid = 0.5 * (self.site_a + self.site_b)
            start = np.where(np.isnan(start), mid + np.array([0.0, self.baseline]), start)
        else:
            p0 = self._pos(x0, f"{fn} x0")
            if p0.shape not in ((2,), (t, 2)):
                raise ProblemError(f"{fn} x0: expected (2,) or ({t}, 2), got {p0.shape}")
            self._off_sites(p0, f"{fn} x0")
            start = np.broadcast_to(p0, (t, 2)).astype(float)
        if method == "gauss_newton":
            est, common = self._gauss_newton(zz, start)
        else:
            # variables: x_t = start_t + L_t u_t with L_t the CRB RMS at the start, so that
            # the whitened objective has O(1) curvature in u whatever the noise level
            length = np.sqrt(np.trace(self._crb(start), axis1=-2, axis2=-1))
            length = np.where(np.isfinite(length) & (length > 0), length, self.baseline)
            built, _ = _joint_nlp(t, opts)
            params = np.concatenate([zz.reshape(-1, order="F"), start.reshape(-1, order="F"),
                                     length, self.site_a, self.site_b,
                                     [self.sigma_azimuth, self.sigma_range_difference]])
            res, u = run_nlpsol(built, x0=np.zeros(2 * t), p=params)
            est = start + length[:, None] * u.reshape(t, 2, order="F")
            common = res.common()
        jw, wr, g, stat = self._whitened(zz, est)
        step = _newton_step(jw, g)
        worst_stat = float(np.max(stat))
        worst_step = float(np.max(step))
        worst = max(worst_stat, worst_step) if np.isfinite(worst_stat + worst_step) \
            else float("inf")
        if common["message"] == "Search_Direction_Becomes_Too_Small" and worst <= VERIFY_TOL:
            # IPOPT's precision limit (tiny noise makes the whitened problem stiff): accept
            # the point only because the NumPy stationarity check passes
            common["status"] = Status.OPTIMAL_INACCURATE
            common["message"] += f" (stationarity {worst:.1e} verified in NumPy)"
        new = verified_status(common["status"], worst)
        if new == Status.ERROR and common["status"].ok:
            common["message"] += f"; stationarity {worst_stat:.2g}, Newton step " \
                f"{worst_step:.2g} (CRB units) fail the NumPy check"
        common["status"] = new
        if not new.ok:
            est = np.full_like(est, np.nan)
        obj = float(np.sum(wr**2)) if new.ok else float("nan")
        return JointMLSolution(objective=obj, residuals={"stationarity": worst_stat,
                                                         "newton_step": worst_step},
                               estimate=est, stationarity=stat, **common)

    def _whitened(self, z: FloatArray, x: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Whitened Jacobian (T, 3, 2), residuals (T, 3), gradient J_tᵀR⁻¹r_t (T, 2) and the
        relative stationarity ‖g_t‖ / (‖J_t‖‖r_t‖ + 1) per row, at positions x (NaN rows
        where x is not finite or at a site)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            jw = self._jac(x) / np.sqrt(np.diag(self.noise_cov))[:, None]
            r = self._residuals(z, x)
            g = np.einsum("tki,tk->ti", jw, r)
            stat = np.linalg.norm(g, axis=1) / (
                np.linalg.norm(jw, axis=(1, 2)) * np.linalg.norm(r, axis=1) + 1.0)
        return jw, r, g, np.where(np.isfinite(stat), stat, np.inf)

    def _gauss_newton(self, z: FloatArray, start: FloatArray, max_iter: int = 50
                      ) -> tuple[FloatArray, dict[str, Any]]:
        """Vectorised Gauss-Newton with step halving; stops when every row's full step is
        below 1e-10 of the baseline or its relative stationarity (as in :meth:`joint_ml`)
        below 1e-10 (GN converges only linearly on non-zero residuals), or no step along
        its direction lowers the cost any more (round-off floor). A singular normal matrix
        (a row on the baseline's extension) ends the run with ERROR."""
        t0 = time.perf_counter()
        x = start.copy()
        cost = np.sum(self._residuals(z, x) ** 2, axis=1)
        it, converged = 0, False
        stalled = np.zeros(len(x), dtype=bool)
        for it in range(1, max_iter + 1):
            jw, _, g, stat = self._whitened(z, x)
            normal = np.swapaxes(jw, 1, 2) @ jw
            if not np.all(np.isfinite(normal)) or np.any(np.linalg.det(normal) <= 0):
                return x, {"status": Status.ERROR, "method": "gauss_newton",
                           "solve_time": time.perf_counter() - t0, "iterations": it,
                           "message": "Gauss-Newton: singular normal matrix (degenerate "
                                      "geometry)"}
            step = np.linalg.solve(normal, g[..., None])[..., 0]
            done = (np.max(np.abs(step), axis=1) < 1e-10 * self.baseline) | (stat < 1e-10) \
                | stalled
            if done.all():
                converged = True
                break
            lam = np.ones(len(x))
            for _ in range(30):
                trial = x + lam[:, None] * step
                new = np.sum(self._residuals(z, trial) ** 2, axis=1)
                worse = ~(new <= cost * (1 + 1e-12))  # round-off allowance
                if not worse.any():
                    break
                lam = np.where(worse, 0.5 * lam, lam)
            # no decrease even for tiny steps: the row is at its round-off floor
            stalled = lam < 2.0**-20
            x, cost = trial, new
        status = Status.OPTIMAL if converged else Status.ITERATION_LIMIT
        return x, {"status": status, "method": "gauss_newton",
                   "solve_time": time.perf_counter() - t0, "iterations": it,
                   "message": "Gauss-Newton"}

    def fused(self, z: ArrayLike, w: ArrayLike | None = None, *,
              weights_at: Literal["true", "estimated"] = "estimated",
              x_true: ArrayLike | None = None, correlated: bool = False) -> FloatArray:
        """Fusion (1) of the two estimators for every row of z, (T, 2).

        ``w`` (2, 2) fixes the weight (e.g. Ŵ from snapshots); otherwise W is computed from
        the first-order covariances at ``x_true`` (``weights_at="true"``; ProblemError if
        that position is degenerate, see :meth:`covariances`) or at the triangulated
        position of each row (``"estimated"``), independent (2) or, with ``correlated``,
        the correlated fusion of :func:`weight_matrix_correlated`. Rows whose estimators
        do not intersect, or whose estimated position is degenerate, are NaN (as in
        :meth:`triangulate`).
        """
        fn = "fusion.TwoSiteSystem.fused"
        zz = np.atleast_2d(self._z(z, f"{fn} z"))
        weights_at = as_choice(f"{fn} weights_at", weights_at, ("true", "estimated"))
        if not isinstance(correlated, bool | np.bool_):
            raise ProblemError(f"{fn} correlated: expected True or False, got {correlated!r}")
        a1, a2 = self.triangulate(zz), self.azimuth_range_difference(zz)
        if w is not None:
            wm = as_finite_array(f"{fn} w", w, shape=(2, 2), max_abs=MAX_MAGNITUDE)
            return a1 + (a2 - a1) @ wm.T
        if weights_at == "true":
            if x_true is None:
                raise ProblemError(f"{fn} x_true: needed with weights_at='true'")
            xt = as_finite_array(f"{fn} x_true", x_true, shape=(2,), max_abs=MAX_MAGNITUDE)
            self.covariances(xt)  # refuses a degenerate x_true, naming it
            at = np.broadcast_to(xt, a1.shape)
        else:
            at = a1
        out = np.full_like(a1, np.nan)
        ok = np.all(np.isfinite(a1) & np.isfinite(a2), axis=1)
        s1, s2, s12 = self.covariances(np.where(ok[:, None], at, self._harmless),
                                       on_degenerate="nan")
        ok &= np.all(np.isfinite(s1) & np.isfinite(s2), axis=(1, 2))
        s1, s2, s12 = s1[ok], s2[ok], s12[ok]
        if correlated:
            wts = _correlated_weight(s1, s12, s1 + s2 - s12 - np.swapaxes(s12, -1, -2))
        else:
            wts = _weight(s1, s2)
        out[ok] = a1[ok] + np.einsum("tij,tj->ti", wts, a2[ok] - a1[ok])
        return out


#: Largest condition number of a whitened measurement Jacobian accepted by
#: :meth:`TwoSiteSystem.covariances` and :meth:`TwoSiteSystem.crb`: S = (JᵀR⁻¹J)⁻¹ then
#: has condition ≤ 1e14, the limit :func:`optmodels.core.check_spd` accepts, so the
#: matrices can be fused. For the default system (20 km baseline, 3 mrad, 3 m) the
#: conditions grow ∝ range far away (estimator 2: 2e-3 per metre), so ranges beyond about
#: 5e9 m are refused, besides the line through the sites.
GEOMETRY_COND = 1e7


def _first_index(mask: FloatArray) -> tuple[int, ...]:
    """Index of the first True entry of ``mask`` (() for a scalar mask)."""
    if np.ndim(mask) == 0:
        return ()
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _at(name: str, idx: tuple[int, ...]) -> str:
    """'x' for a single position, 'x[3]' / 'x[1, 2]' for one of many."""
    return f"{name}[{', '.join(map(str, idx))}]" if idx else name


def _xy(p: FloatArray) -> str:
    return f"({float(p[0]):.6g}, {float(p[1]):.6g})"


def _newton_step(jw: FloatArray, g: FloatArray) -> FloatArray:
    """√(gᵀ(JᵀJ)⁻¹g) per row (whitened J (T, 3, 2), g (T, 2)): the Gauss-Newton step in the
    metric of the Fisher information, i.e. in CRB standard deviations; inf where JᵀJ is
    singular or anything is not finite."""
    info = np.swapaxes(jw, 1, 2) @ jw
    a, b, d = info[:, 0, 0], info[:, 0, 1], info[:, 1, 1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        det = a * d - b * b
        q = (d * g[:, 0] ** 2 - 2 * b * g[:, 0] * g[:, 1] + a * g[:, 1] ** 2) / det
        ok = np.isfinite(q) & (det > 1e-14 * (a + d) ** 2)
        return np.where(ok, np.sqrt(np.abs(q)), np.inf)


_JOINT_CACHE: dict[tuple[Any, ...], BuiltNlp] = {}


def _joint_nlp(t: int, options: dict[str, Any]) -> tuple[BuiltNlp, bool]:
    """Block-separable NLP of T joint-ML problems, variables u with x = start + L u
    (cached per T and options)."""
    key = (t, repr(sorted(options.items())))
    if key in _JOINT_CACHE:
        return _JOINT_CACHE[key], False
    u = ca.MX.sym("u", t, 2)
    z = ca.MX.sym("z", t, 3)
    x0 = ca.MX.sym("x0", t, 2)
    length = ca.MX.sym("L", t)
    sa, sb = ca.MX.sym("A", 2), ca.MX.sym("B", 2)
    sig = ca.MX.sym("sig", 2)
    px = x0[:, 0] + length * u[:, 0]
    py = x0[:, 1] + length * u[:, 1]
    da_x, da_y = px - sa[0], py - sa[1]
    db_x, db_y = px - sb[0], py - sb[1]

    def wrap(a: Any) -> Any:
        return ca.atan2(ca.sin(a), ca.cos(a))

    ra = wrap(z[:, 0] - ca.atan2(da_x, da_y)) / sig[0]
    rb = wrap(z[:, 1] - ca.atan2(db_x, db_y)) / sig[0]
    rd = (z[:, 2] - (ca.sqrt(db_x**2 + db_y**2) - ca.sqrt(da_x**2 + da_y**2))) / sig[1]
    f = ca.sumsqr(ra) + ca.sumsqr(rb) + ca.sumsqr(rd)
    nlp = {"x": ca.vec(u), "f": f / t,
           "p": ca.vertcat(ca.vec(z), ca.vec(x0), length, sa, sb, sig)}
    built = build_nlpsol(nlp, options=options)
    if len(_JOINT_CACHE) >= 8:
        _JOINT_CACHE.pop(next(iter(_JOINT_CACHE)))
    _JOINT_CACHE[key] = built
    return built, True


def clear_joint_cache() -> None:
    """Forget the built joint-ML NLPs (the next solve pays the CasADi construction again;
    used by benchmarks that measure cold build + solve)."""
    _JOINT_CACHE.clear()
