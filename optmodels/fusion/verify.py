"""NumPy re-check of the fusion answers (paper 003): forward error bounds of the weight W
(2), (6) (and of the correlated W) from the residual of W(S1 + S2) = S1 and the
conditioning (LAPACK xGERFS style, componentwise), of the fused estimate (1), the WLS
objective (1) itself, and the status gate :func:`_finish` (via
:func:`optmodels.core.verified_status`); :func:`_refuse_inaccurate` for functions that
return a bare matrix. The end of every :func:`optmodels.fusion.fuse`, closed form or
CVXPY: :func:`_finish_independent` (1)-(2) and :func:`_finish_correlated` (the min-trace
W), the re-check's residuals, then the gate."""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np

from optmodels.core import REJECT_TOL, FloatArray, ProblemError, Solution, Status, Verdict, finish
from optmodels.fusion.solution import FusionSolution, _failure

_EPS = float(np.finfo(float).eps)


def _bounded_error(
    mat: FloatArray, sol: FloatArray, rhs: FloatArray, inv: FloatArray
) -> FloatArray:
    """LAPACK-style (xGERFS) forward error bound of a computed ``sol`` of
    ``mat @ sol = rhs``: |inv| (|r| + γ(|mat||sol| + |rhs|)) elementwise, r the residual,
    γ = (m + 2) eps, ``inv`` the (pseudo-)inverse of ``mat``. Componentwise, so a
    badly scaled but well-conditioned system (diagonal S) is not penalised."""
    gamma = (mat.shape[0] + 2) * _EPS
    r = rhs - mat @ sol
    return np.abs(inv) @ (np.abs(r) + gamma * (np.abs(mat) @ np.abs(sol) + np.abs(rhs)))


def _weight_bound(
    w: FloatArray, mat: FloatArray, rhs: FloatArray, inv: FloatArray | None = None
) -> FloatArray:
    """Elementwise forward error bound |δW| of W solving W·mat = rhs (mat symmetric, i.e.
    mat·Wᵀ = rhsᵀ): S1 + S2 and S1 for the paper's W (2), D and S1 − S12 for the
    correlated one (``inv`` = D⁺ there); inf where W is not finite."""
    if not np.all(np.isfinite(w)):
        return np.full_like(w, np.inf)
    if inv is None:
        inv = np.asarray(np.linalg.inv(mat), dtype=float)
    return _bounded_error(mat, w.T, rhs.T, inv).T


def _weight_error(
    w: FloatArray, mat: FloatArray, rhs: FloatArray, inv: FloatArray | None = None
) -> float:
    """Relative forward error bound max|δW| / max|W| (see :func:`_weight_bound`)."""
    return _relative_weight_error(_weight_bound(w, mat, rhs, inv), w)


def _relative_weight_error(dw: FloatArray, w: FloatArray) -> float:
    """max|δW| / max|W| for an elementwise bound ``dw`` on W's error."""
    return float(np.max(dw) / max(float(np.max(np.abs(w))), np.finfo(float).tiny))


def _combination_bound(w: FloatArray, dw: FloatArray, x1: FloatArray, x2: FloatArray) -> FloatArray:
    """Elementwise error bound of a1 + W(a2 − a1) given |δW| ≤ dw: dw|a2 − a1| plus the
    round-off of the product and the sum."""
    spread = np.abs(x2 - x1)
    return dw @ spread + (x1.size + 2) * _EPS * (np.abs(x1) + np.abs(w) @ spread)


def _refuse_inaccurate(fn: str, err: float, what: str) -> None:
    """Functions that return a bare matrix cannot downgrade a status: refuse instead."""
    if not np.isfinite(err) or err > REJECT_TOL:
        raise ProblemError(
            f"fusion.{fn}: {what} is too ill-conditioned: the result's "
            f"relative forward error bound {err:.2g} exceeds {REJECT_TOL:g} "
            "(NumPy re-check)"
        )


def _wls_objective(
    x: FloatArray, a1: FloatArray, c1: FloatArray, a2: FloatArray, c2: FloatArray
) -> float:
    d1, d2 = x - a1, x - a2
    return float(d1 @ c1 @ d1 + d2 @ c2 @ d2)


S = TypeVar("S", bound=Solution)


def _note(v: Verdict) -> str:
    verdict = "fails the NumPy check" if v.status == Status.ERROR else "(NumPy check)"
    return f"{v.key} {v.worst:.1e} {verdict}"


def _finish(sol: S) -> S:
    """A solver's (or a closed form's) 'optimal' is not taken on trust: the one gate
    (:func:`optmodels.core.finish`, i.e. :func:`~optmodels.core.verified_status` of the
    largest NumPy-recomputed residual). A result that is not OK keeps no estimate (NaN),
    and no W/covariance if W failed."""
    return finish(sol, note=_note, reject=_failure)


# --------------------------------------------------------------------------- fuse's end
def _finish_independent(
    x1: FloatArray,
    s1: FloatArray,
    x2: FloatArray,
    s2: FloatArray,
    c1: FloatArray,
    c2: FloatArray,
    w: FloatArray,
    cov: FloatArray,
    est: FloatArray,
    common: dict[str, Any],
) -> FusionSolution:
    """The re-check of a fused estimate ``est`` of independent a1, a2 (C_μ = S_μ⁻¹, W (2)
    and the covariance ``cov`` of the closed form) against the WLS problem (1), the gate
    :func:`_finish`, and the objective (1) of what it kept.

    Residuals: ``gradient`` (the relative norm of C1(α − a1) + C2(α − a2)),
    ``estimate_error`` (the smaller of two forward error bounds of α, below) and
    ``weight_error`` (of W from W(S1 + S2) = S1)."""
    m = x1.shape[0]
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
    for c_k, s_k, x_k in ((c1, s1, x1), (c2, s2, x2)):
        ac = np.abs(c_k)
        g_err = g_err + gamma * (ac @ np.abs(s_k) @ ac + ac) @ np.abs(est - x_k)
    dw = _weight_bound(w, s1 + s2, s1)
    alpha_w = x1 + w @ (x2 - x1)
    bound = np.minimum(
        np.abs(cov) @ g_err, np.abs(est - alpha_w) + _combination_bound(w, dw, x1, x2)
    )
    size = max(float(np.max(np.abs(np.concatenate([est, x1, x2])))), np.finfo(float).tiny)
    residuals = {
        "gradient": res_grad,
        "estimate_error": float(np.max(bound) / size),
        "weight_error": _relative_weight_error(dw, w),
    }
    sol = _finish(
        FusionSolution(
            objective=float("nan"), residuals=residuals, estimate=est, covariance=cov, W=w, **common
        )
    )
    sol.objective = _wls_objective(sol.estimate, x1, c1, x2, c2)
    return sol


def _finish_correlated(
    x1: FloatArray,
    x2: FloatArray,
    s1: FloatArray,
    s12: FloatArray,
    d: FloatArray,
    d_pinv: FloatArray,
    w: FloatArray,
    cov: FloatArray,
    common: dict[str, Any],
) -> FusionSolution:
    """The re-check of a weight ``w`` of correlated a1, a2 (D = Cov(a1 − a2), ``d_pinv``
    its pseudo-inverse, ``cov`` the fused covariance under ``w``) against the min-trace
    problem: the optimality d tr(cov)/dW = 2(W D − (S1 − S12)) = 0 (``gradient``), the
    forward error bound of W on range(D) (``weight_error``) and of a1 + W(a2 − a1)
    (``estimate_error``); the gate :func:`_finish`, and the objective tr(cov)."""
    est = x1 + w @ (x2 - x1)
    grad = w @ d - (s1 - s12)
    res_grad = float(np.max(np.abs(grad)) / (np.max(np.abs(d)) * max(1.0, np.max(np.abs(w)))))
    dw = _weight_bound(w, d, s1 - s12, d_pinv)
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
