"""The fused estimate (paper 003): :func:`fuse`, the weighted least-squares problem (1)-(2)
min_α Σ_μ (α − a_μ)ᵀC_μ(α − a_μ) for independent estimates and the min-trace W for
correlated ones, in closed form (:mod:`optmodels.fusion.closedform`) or by CVXPY (the
generic formulations here: :func:`_wls_cvxpy`, :func:`_min_trace_cvxpy`), every answer
re-checked in NumPy and gated (:mod:`optmodels.fusion.verify`).

:func:`fuse` reads validate (the arguments) → build and run (the closed form or the CVXPY
model) → finish (:func:`~optmodels.fusion.verify._finish_independent` /
:func:`~optmodels.fusion.verify._finish_correlated`).
"""

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
    as_choice,
    as_finite_array,
    timed,
)
from optmodels.fusion.closedform import _closed_form, _closed_form_correlated, _paper_weight
from optmodels.fusion.inputs import _pair, _where
from optmodels.fusion.solution import FusionSolution
from optmodels.fusion.verify import _finish_correlated, _finish_independent
from optmodels.fusion.weights import PINV_RTOL, _cross, fused_covariance


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
    return _fuse_independent(x1, s1a, x2, s2a, method, solver, solver_options)


def _fuse_independent(
    x1: FloatArray,
    s1: FloatArray,
    x2: FloatArray,
    s2: FloatArray,
    method: str,
    solver: str,
    solver_options: dict[str, Any],
) -> FusionSolution:
    """(1)-(2) for checked arguments: the closed form or CVXPY, then the re-check."""
    c1 = np.asarray(np.linalg.inv(s1), dtype=float)
    c2 = np.asarray(np.linalg.inv(s2), dtype=float)
    w, cov = _paper_weight(s1, s2)
    if method == "closed_form":
        est, common = _closed_form(x1, x2, w)
    else:
        est, common = _wls_cvxpy(x1, x2, c1, c2, solver, solver_options)
    return _finish_independent(x1, s1, x2, s2, c1, c2, w, cov, est, common)


def _wls_cvxpy(
    x1: FloatArray,
    x2: FloatArray,
    c1: FloatArray,
    c2: FloatArray,
    solver: str,
    solver_options: dict[str, Any],
) -> tuple[FloatArray, dict[str, Any]]:
    """The WLS problem (1) in CVXPY: the estimate (NaN if the solver failed) and the
    solution's common fields (status, times, message of the solver)."""
    m = x1.shape[0]
    with timed() as tb:
        # α = a1 + d·u with d the spread of the two estimates and C_μ divided by
        # ‖C1 + C2‖: the solver sees an O(1) problem whatever the units. (The robustness
        # sweep found Clarabel returning α = 0 as 'optimal' for estimates at 1e-151:
        # its absolute tolerances swallowed the whole problem.)
        d = max(float(np.max(np.abs(x2 - x1))), 1e-300)
        cn = max(float(np.max(np.abs(c1 + c2))), 1e-300)
        delta = (x2 - x1) / d
        u = cp.Variable(m)
        obj = cp.quad_form(u, cp.psd_wrap(c1 / cn)) + cp.quad_form(u - delta, cp.psd_wrap(c2 / cn))
        prob = cp.Problem(cp.Minimize(obj))
    res = solve_problem(prob, solver, **solver_options)
    common = res.common()
    common["build_time"] += tb.elapsed
    est = (
        x1 + d * np.asarray(u.value)
        if res.status.ok and u.value is not None
        else np.full(m, np.nan)
    )
    return est, common


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
    """The min-trace fusion of correlated estimates: S12 checked, W in closed form or by
    CVXPY, then the re-check."""
    c, d = _cross(s12, a, b, "fuse")
    if method == "closed_form":
        w, common = _closed_form_correlated(a, c, d)
    else:
        w, common = _min_trace_cvxpy(a, b, c, solver, solver_options)
    cov = fused_covariance(w, a, b, c)
    d_pinv = np.asarray(np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True), dtype=float)
    return _finish_correlated(x1, x2, a, c, d, d_pinv, w, cov, common)


def _min_trace_cvxpy(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    solver: str,
    solver_options: dict[str, Any],
) -> tuple[FloatArray, dict[str, Any]]:
    """min_W ‖[I − W, W] L‖²_F in CVXPY (L Lᵀ the joint covariance [[S1, S12], [S12ᵀ, S2]],
    PSD, scaled by √tr): W (NaN if the solver failed) and the common fields."""
    m = a.shape[0]
    eye = np.eye(m)
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
    w = np.asarray(wv.value) if res.status.ok and wv.value is not None else np.full((m, m), np.nan)
    return w, common
