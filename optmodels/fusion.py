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

from optmodels.backends.casadi_backend import BuiltNlp, build_nlpsol, run_nlpsol
from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    Solution,
    Status,
    as_finite_array,
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


def _pair(s1: ArrayLike, s2: ArrayLike) -> tuple[FloatArray, FloatArray]:
    a = _cov("S1", s1)
    return a, _cov("S2", s2, a.shape[0])


def _vec(a: FloatArray) -> FloatArray:
    """Stack the columns (the paper's '#')."""
    return a.reshape(-1, order="F")


def weight_matrix(s1: ArrayLike, s2: ArrayLike) -> FloatArray:
    """W = (C1 + C2)⁻¹C2 (2), (6), computed as S1(S1 + S2)⁻¹ (no inverse of S_μ).

    Raises
    ------
    ProblemError
        Non-square, mismatched, non-finite, non-symmetric or non-PD S1/S2.
    """
    a, b = _pair(s1, s2)
    return _weight(a, b)


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


def _cross(s12: ArrayLike, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Validate a cross-covariance S12 = Cov(a1, a2): finite (m, m) and the joint covariance
    [[S1, S12], [S12ᵀ, S2]] positive semidefinite. Returns (S12, D) with
    D = S1 + S2 − S12 − S12ᵀ = Cov(a1 − a2) (positive semidefinite, possibly singular)."""
    m = a.shape[0]
    c = as_finite_array("s12", s12, shape=(m, m))
    joint = np.block([[a, c], [c.T, b]])
    lam = np.linalg.eigvalsh(joint)
    if lam[0] < -1e-10 * max(lam[-1], np.finfo(float).tiny):
        raise ProblemError(f"s12: the joint covariance [[S1, S12], [S12ᵀ, S2]] is not positive "
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
    a, b = _pair(s1, s2)
    c, d = _cross(s12, a, b)
    return _correlated_weight(a, c, d)


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
    ``residuals["gradient"]`` is the relative norm of the optimality condition at the
    returned point, re-computed in NumPy for either method. ``solver_options`` go to the
    CVXPY solver (``method="cvxpy"``).
    """
    s1a, s2a = _pair(s1, s2)
    m = s1a.shape[0]
    x1 = as_finite_array("a1", a1, shape=(m,), max_abs=MAX_MAGNITUDE)
    x2 = as_finite_array("a2", a2, shape=(m,), max_abs=MAX_MAGNITUDE)
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
    else:
        raise ProblemError(f"method: expected 'closed_form' or 'cvxpy', got {method!r}")
    grad = c1 @ (est - x1) + c2 @ (est - x2)
    scale = np.abs(c1) @ np.abs(x1) + np.abs(c2) @ np.abs(x2) + np.abs(c1 + c2) @ np.abs(est)
    res_grad = float(np.max(np.abs(grad) / (scale + 1e-300)))
    _verify(common, res_grad)
    return FusionSolution(objective=_wls_objective(est, x1, c1, x2, c2),
                          residuals={"gradient": res_grad}, estimate=est, covariance=cov,
                          W=w, **common)


def _verify(common: dict[str, Any], res_grad: float) -> None:
    """A solver's 'optimal' is not taken on trust: :func:`optmodels.core.verified_status`
    with the NumPy-recomputed optimality residual."""
    new = verified_status(common["status"], res_grad)
    if new != common["status"]:
        verdict = "fails the NumPy check" if new == Status.ERROR else "(NumPy check)"
        common["status"] = new
        common["message"] = f"{common.get('message', '')}; optimality residual " \
            f"{res_grad:.1e} {verdict}"


def _fuse_correlated(x1: FloatArray, a: FloatArray, x2: FloatArray, b: FloatArray,
                     s12: ArrayLike, method: str, solver: str,
                     solver_options: dict[str, Any]) -> FusionSolution:
    c, d = _cross(s12, a, b)
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
    else:
        raise ProblemError(f"method: expected 'closed_form' or 'cvxpy', got {method!r}")
    est = x1 + w @ (x2 - x1)
    # optimality: d tr(cov)/dW = 2(W D − (S1 − S12)) = 0
    cov = fused_covariance(w, a, b, c)
    grad = w @ d - (a - c)
    res_grad = float(np.max(np.abs(grad)) / (np.max(np.abs(d)) * max(1.0, np.max(np.abs(w)))))
    _verify(common, res_grad)
    return FusionSolution(objective=float(np.trace(cov)), residuals={"gradient": res_grad},
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
    W = S1(S1 + S2)⁻¹ with symbolic, unsymmetrised S_μ.
    """
    a, b = _pair(s1, s2)
    m = a.shape[0]
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
    """K with K vec(A) = vec(Aᵀ) for (m, m) matrices."""
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
    if int(n) != n or n < least:
        rel = "n ≥ m" if mean == "known" else "n > m"
        raise ProblemError(f"{name}: need an integer sample size {rel} = {m} with the {mean} "
                           f"mean (the sample covariance is singular otherwise), got {n}")
    return int(n)


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
    s = _cov("sigma", sigma)
    _check_mean(mean)
    return _moments(s, _check_n("n", n, s.shape[0], mean), mean)


def _check_mean(mean: str) -> None:
    if mean not in ("known", "sample"):
        raise ProblemError(f"mean: expected 'known' or 'sample', got {mean!r}")


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
    a, b = _pair(s1, s2)
    _check_mean(mean)
    m = a.shape[0]
    n1, n2 = _check_n("n1", n1, m, mean), _check_n("n2", n2, m, mean)
    p1, p2 = _jacobians(a, b)
    _, k1 = _moments(a, n1, mean)
    _, k2 = _moments(b, n2, mean)
    out = p1 @ k1 @ p1.T + p2 @ k2 @ p2.T
    if s12 is not None:
        if n1 != n2:
            raise ProblemError(f"n2: with s12 both sample covariances come from the same "
                               f"snapshots, so n1 = n2 is required (got {n1}, {n2})")
        c, _ = _cross(s12, a, b)
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
    divided by n − 1. Vectorised over trials.
    """
    a, b = _pair(s1, s2)
    m = a.shape[0]
    _check_mean(mean)
    n1, n2 = _check_n("n1", n1, m, mean), _check_n("n2", n2, m, mean)
    if int(trials) != trials or trials < 2:
        raise ProblemError(f"trials: need an integer >= 2, got {trials}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    lost = 0 if mean == "known" else 1
    draws = []
    for s, n in ((a, n1), (b, n2)):
        x = stats.wishart(df=n - lost, scale=s).rvs(size=trials, random_state=rng)
        draws.append(np.asarray(x).reshape(trials, m, m) / (n - 1))
    sa, sb = draws
    # Ŵ = Ŝ1 (Ŝ1+Ŝ2)^-1 = ((Ŝ1+Ŝ2)^-1 Ŝ1)^T (symmetric draws)
    w = _weight(sa, sb)
    vw = w.transpose(0, 2, 1).reshape(trials, m * m)  # column-major vec per trial
    return WeightMonteCarlo(mean=w.mean(axis=0), cov=np.cov(vw.T), trials=int(trials))


def weight_from_samples(a1: ArrayLike, a2: ArrayLike, *, correlated: bool = False
                        ) -> FloatArray:
    """Ŵ from n snapshots of the two estimators, rows of ``a1`` and ``a2`` (n, m): the
    sample covariances (3) with the sample mean and divisor n − 1, then W of (2), or of
    :func:`weight_matrix_correlated` with the sample cross-covariance if ``correlated``.

    Raises :class:`ProblemError` if n ≤ m (singular sample covariance) or the snapshots
    are degenerate.
    """
    x1 = as_finite_array("a1", a1, ndim=2)
    x2 = as_finite_array("a2", a2, shape=x1.shape)
    n, m = x1.shape
    _check_n("a1 rows (snapshots)", n, m)
    full = np.cov(np.hstack([x1, x2]).T)
    s1, s2, s12 = full[:m, :m], full[m:, m:], full[:m, m:]
    for name, s in (("a1", s1), ("a2", s2)):
        try:
            check_spd(f"sample covariance of {name}", s)
        except ProblemError as exc:
            raise ProblemError(f"{name}: the snapshots are degenerate ({exc})") from None
    if correlated:
        return weight_matrix_correlated(s1, s2, s12)
    return _weight(s1, s2)


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
    """

    site_a: FloatArray
    site_b: FloatArray
    sigma_azimuth: float
    sigma_range_difference: float

    def __post_init__(self) -> None:
        a = as_finite_array("site_a", self.site_a, shape=(2,))
        b = as_finite_array("site_b", self.site_b, shape=(2,))
        if np.linalg.norm(b - a) == 0:
            raise ProblemError("site_b: coincides with site_a (zero baseline)")
        for name in ("sigma_azimuth", "sigma_range_difference"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v <= 0:
                raise ProblemError(f"{name}: need a positive finite standard deviation, got {v}")
            object.__setattr__(self, name, v)
        object.__setattr__(self, "site_a", a)
        object.__setattr__(self, "site_b", b)

    @classmethod
    def on_baseline(cls, baseline: float = 20_000.0, sigma_azimuth: float = 3e-3,
                    sigma_range_difference: float = 3.0) -> TwoSiteSystem:
        """Sites at (∓baseline/2, 0). Defaults: a 20 km baseline, σ_az = 3 mrad (0.17°),
        σ_Δr = 3 m (10 ns) -- both estimators then matter over the region of the demo."""
        h = 0.5 * float(baseline)
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
        arr = as_finite_array(name, x)
        if arr.shape[-1:] != (2,):
            raise ProblemError(f"{name}: expected positions (..., 2), got shape {arr.shape}")
        return arr

    def measure(self, x: ArrayLike) -> FloatArray:
        """Noise-free z(x) = (azimuth A, azimuth B, Δr), (..., 3)."""
        p = self._pos(x)
        da, db = p - self.site_a, p - self.site_b
        return np.stack([np.arctan2(da[..., 0], da[..., 1]), np.arctan2(db[..., 0], db[..., 1]),
                         np.hypot(db[..., 0], db[..., 1]) - np.hypot(da[..., 0], da[..., 1])],
                        axis=-1)

    def jacobian(self, x: ArrayLike) -> FloatArray:
        """∂z/∂x, (..., 3, 2). For azimuth atan2(dx, dy): ∂/∂x = (dy, −dx)/ρ²."""
        p = self._pos(x)
        rows = []
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
        z = self.measure(self._pos(x)) + rng.normal(size=(int(trials), 3)) * np.sqrt(
            np.diag(self.noise_cov))
        z[:, :2] = np.angle(np.exp(1j * z[:, :2]))
        return z

    # ------------------------------------------------------------------ estimators
    def _z(self, z: ArrayLike) -> FloatArray:
        arr = as_finite_array("z", z)
        if arr.shape[-1:] != (3,):
            raise ProblemError(f"z: expected measurements (..., 3) = {MEASUREMENTS}, "
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

    def covariances(self, x: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """First-order S1, S2 and S12 = Cov(a1, a2) at position(s) x, each (..., 2, 2).

        a_k = x + G_k e_k with G_k = (∂z_k/∂x)⁻¹; e_1 = (e_azA, e_azB), e_2 = (e_azA, e_Δr),
        so S12 = G_1 Cov(e_1, e_2) G_2ᵀ with Cov(e_1, e_2) = diag(σ_az², 0).
        """
        j = self.jacobian(x)
        g1 = np.linalg.inv(j[..., [0, 1], :])
        g2 = np.linalg.inv(j[..., [0, 2], :])
        r = self.noise_cov
        r1, r2 = r[np.ix_([0, 1], [0, 1])], r[np.ix_([0, 2], [0, 2])]
        r12 = np.diag([self.sigma_azimuth**2, 0.0])
        tr = np.swapaxes
        return g1 @ r1 @ tr(g1, -1, -2), g2 @ r2 @ tr(g2, -1, -2), g1 @ r12 @ tr(g2, -1, -2)

    def crb(self, x: ArrayLike) -> FloatArray:
        """(Jᵀ R⁻¹ J)⁻¹, (..., 2, 2): first-order covariance of the joint ML (the CRB)."""
        j = self.jacobian(x)
        info = np.swapaxes(j, -1, -2) @ np.linalg.inv(self.noise_cov) @ j
        return np.linalg.inv(info)

    def residuals(self, z: ArrayLike, x: ArrayLike) -> FloatArray:
        """Whitened residuals R^{-1/2}(z − z(x)), azimuth differences wrapped, (..., 3)."""
        d = self._z(z) - self.measure(x)
        d[..., :2] = np.angle(np.exp(1j * d[..., :2]))
        return d / np.sqrt(np.diag(self.noise_cov))

    # ------------------------------------------------------------------ joint ML
    def joint_ml(self, z: ArrayLike, *, x0: ArrayLike | None = None,
                 method: Literal["ipopt", "gauss_newton"] = "ipopt",
                 options: dict[str, Any] | None = None) -> JointMLSolution:
        """ML position from all three measurements (the original problem):
        min_x Σ_k ((z_k − z_k(x)) / σ_k)² for every row of z.

        ``method="ipopt"``: CasADi/IPOPT. The T rows are independent problems, solved as
        one block-separable NLP (2T variables, block-diagonal exact Hessian), each row's
        position scaled by its CRB RMS around the start. ``method="gauss_newton"``:
        vectorised Gauss-Newton with step halving in NumPy (an independent
        implementation, used to cross-check IPOPT).

        Start: the triangulation (``x0`` to override). Each row's stationarity
        J_tᵀR⁻¹r_t, relative to ‖J_t‖‖r_t‖ + 1 in whitened units, is re-checked in NumPy;
        above 1e-6 the status is downgraded to OPTIMAL_INACCURATE, above 1e-3 to ERROR.
        IPOPT stopping at its precision limit (Search_Direction_Becomes_Too_Small) is
        reported as OPTIMAL_INACCURATE if the check passes at 1e-6, as ERROR otherwise.
        """
        zz = np.atleast_2d(self._z(z))
        t = zz.shape[0]
        if method not in ("ipopt", "gauss_newton"):
            raise ProblemError(f"method: expected 'ipopt' or 'gauss_newton', got {method!r}")
        if x0 is None:
            start = self.triangulate(zz)
            fallback = self.azimuth_range_difference(zz)
            start = np.where(np.isnan(start), fallback, start)
            mid = 0.5 * (self.site_a + self.site_b)
            start = np.where(np.isnan(start), mid + np.array([0.0, self.baseline]), start)
        else:
            start = np.broadcast_to(self._pos(x0, "x0"), (t, 2)).astype(float)
        if method == "gauss_newton":
            est, common = self._gauss_newton(zz, start)
        else:
            # variables: x_t = start_t + L_t u_t with L_t the CRB RMS at the start, so that
            # the whitened objective has O(1) curvature in u whatever the noise level
            length = np.sqrt(np.trace(self.crb(start), axis1=-2, axis2=-1))
            length = np.where(np.isfinite(length) & (length > 0), length, self.baseline)
            built, _ = _joint_nlp(t, tuple(sorted((options or {}).items())))
            params = np.concatenate([zz.reshape(-1, order="F"), start.reshape(-1, order="F"),
                                     length, self.site_a, self.site_b,
                                     [self.sigma_azimuth, self.sigma_range_difference]])
            res, u = run_nlpsol(built, x0=np.zeros(2 * t), p=params)
            est = start + length[:, None] * u.reshape(t, 2, order="F")
            common = res.common()
        _, wr, _, stat = self._whitened(zz, est)
        worst = float(np.max(stat)) if t else 0.0
        if common["message"] == "Search_Direction_Becomes_Too_Small" and worst <= 1e-6:
            # IPOPT's precision limit (tiny noise makes the whitened problem stiff): accept
            # the point only because the NumPy stationarity check passes
            common["status"] = Status.OPTIMAL_INACCURATE
            common["message"] += f" (stationarity {worst:.1e} verified in NumPy)"
        if not common["status"].ok:
            est = np.full_like(est, np.nan)
        elif not np.isfinite(worst) or worst > 1e-3:
            common["status"] = Status.ERROR
            common["message"] += f"; stationarity {worst:.2g} fails the NumPy check"
            est = np.full_like(est, np.nan)
        elif common["status"] == Status.OPTIMAL and worst > 1e-6:
            common["status"] = Status.OPTIMAL_INACCURATE
        obj = float(np.sum(wr**2)) if common["status"].ok else float("nan")
        return JointMLSolution(objective=obj, residuals={"stationarity": worst},
                               estimate=est, stationarity=stat, **common)

    def _whitened(self, z: FloatArray, x: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Whitened Jacobian (T, 3, 2), residuals (T, 3), gradient J_tᵀR⁻¹r_t (T, 2) and the
        relative stationarity ‖g_t‖ / (‖J_t‖‖r_t‖ + 1) per row, at positions x."""
        jw = self.jacobian(x) / np.sqrt(np.diag(self.noise_cov))[:, None]
        r = self.residuals(z, x)
        g = np.einsum("tki,tk->ti", jw, r)
        stat = np.linalg.norm(g, axis=1) / (
            np.linalg.norm(jw, axis=(1, 2)) * np.linalg.norm(r, axis=1) + 1.0)
        return jw, r, g, stat

    def _gauss_newton(self, z: FloatArray, start: FloatArray, max_iter: int = 50
                      ) -> tuple[FloatArray, dict[str, Any]]:
        """Vectorised Gauss-Newton with step halving; stops when every row's full step is
        below 1e-10 of the baseline or its relative stationarity (as in :meth:`joint_ml`)
        below 1e-10 (GN converges only linearly on non-zero residuals), or no step along
        its direction lowers the cost any more (round-off floor)."""
        t0 = time.perf_counter()
        x = start.copy()
        cost = np.sum(self.residuals(z, x) ** 2, axis=1)
        it, converged = 0, False
        stalled = np.zeros(len(x), dtype=bool)
        for it in range(1, max_iter + 1):  # noqa: B007 (reported below)
            jw, _, g, stat = self._whitened(z, x)
            step = np.linalg.solve(np.swapaxes(jw, 1, 2) @ jw, g[..., None])[..., 0]
            done = (np.max(np.abs(step), axis=1) < 1e-10 * self.baseline) | (stat < 1e-10) \
                | stalled
            if done.all():
                converged = True
                break
            lam = np.ones(len(x))
            for _ in range(30):
                trial = x + lam[:, None] * step
                new = np.sum(self.residuals(z, trial) ** 2, axis=1)
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
        the first-order covariances at ``x_true`` (``weights_at="true"``) or at the
        triangulated position of each row (``"estimated"``), independent (2) or, with
        ``correlated``, the correlated fusion of :func:`weight_matrix_correlated`.
        """
        zz = np.atleast_2d(self._z(z))
        a1, a2 = self.triangulate(zz), self.azimuth_range_difference(zz)
        if w is not None:
            wm = as_finite_array("w", w, shape=(2, 2))
            return a1 + (a2 - a1) @ wm.T
        if weights_at == "true":
            if x_true is None:
                raise ProblemError("x_true: needed with weights_at='true'")
            at = np.broadcast_to(self._pos(x_true, "x_true"), a1.shape)
        elif weights_at == "estimated":
            at = a1
        else:
            raise ProblemError(f"weights_at: expected 'true' or 'estimated', got {weights_at!r}")
        out = np.full_like(a1, np.nan)
        ok = np.all(np.isfinite(a1) & np.isfinite(a2), axis=1)
        s1, s2, s12 = self.covariances(at[ok])
        if correlated:
            wts = _correlated_weight(s1, s12, s1 + s2 - s12 - np.swapaxes(s12, -1, -2))
        else:
            wts = _weight(s1, s2)
        out[ok] = a1[ok] + np.einsum("tij,tj->ti", wts, a2[ok] - a1[ok])
        return out


_JOINT_CACHE: dict[tuple[Any, ...], BuiltNlp] = {}


def _joint_nlp(t: int, options: tuple[Any, ...]) -> tuple[BuiltNlp, bool]:
    """Block-separable NLP of T joint-ML problems, variables u with x = start + L u
    (cached per T)."""
    key = (t, options)
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
    built = build_nlpsol(nlp, options=dict(options))
    if len(_JOINT_CACHE) >= 8:
        _JOINT_CACHE.pop(next(iter(_JOINT_CACHE)))
    _JOINT_CACHE[key] = built
    return built, True


def clear_joint_cache() -> None:
    """Forget the built joint-ML NLPs (the next solve pays the CasADi construction again;
    used by benchmarks that measure cold build + solve)."""
    _JOINT_CACHE.clear()
