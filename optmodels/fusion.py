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

from dataclasses import dataclass, field
from typing import Any, Literal

import casadi as ca
import cvxpy as cp
import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg, stats

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.core import (
    FloatArray,
    ProblemError,
    Solution,
    Status,
    as_finite_array,
    check_spd,
    timed,
)

__all__ = [
    "FusionSolution",
    "commutation_matrix",
    "fuse",
    "monte_carlo_weight",
    "sample_covariance_moments",
    "weight_covariance",
    "weight_jacobians",
    "weight_matrix",
]

MeanKind = Literal["known", "sample"]


def _cov(name: str, s: ArrayLike, m: int | None = None) -> FloatArray:
    arr = as_finite_array(name, s, ndim=2)
    if arr.shape[0] != arr.shape[1]:
        raise ProblemError(f"{name}: expected a square matrix, got shape {arr.shape}")
    if m is not None and arr.shape[0] != m:
        raise ProblemError(f"{name}: expected ({m}, {m}) like S1, got {arr.shape}")
    check_spd(name, arr)
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
    # S1 (S1+S2)^-1 = ((S1+S2)^-1 S1)^T for symmetric S1, S2
    return linalg.solve(a + b, a, assume_a="pos").T


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


def fuse(a1: ArrayLike, s1: ArrayLike, a2: ArrayLike, s2: ArrayLike, *,
         method: Literal["closed_form", "cvxpy"] = "closed_form",
         solver: str = "CLARABEL") -> FusionSolution:
    """Fuse two estimates: (1) in closed form, or the weighted least-squares problem
    min Σ_μ (α − a_μ)ᵀC_μ(α − a_μ) solved by CVXPY.

    ``residuals["gradient"]`` is the relative norm of the WLS gradient at the returned
    point (zero at the optimum), re-computed in NumPy for either method.
    """
    s1a, s2a = _pair(s1, s2)
    m = s1a.shape[0]
    x1 = as_finite_array("a1", a1, shape=(m,))
    x2 = as_finite_array("a2", a2, shape=(m,))
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
            alpha = cp.Variable(m)
            obj = (cp.quad_form(alpha - x1, cp.psd_wrap(c1))
                   + cp.quad_form(alpha - x2, cp.psd_wrap(c2)))
            prob = cp.Problem(cp.Minimize(obj))
        res = solve_problem(prob, solver)
        common = res.common()
        common["build_time"] += tb.elapsed
        est = (np.asarray(alpha.value) if res.status.ok and alpha.value is not None
               else np.full(m, np.nan))
    else:
        raise ProblemError(f"method: expected 'closed_form' or 'cvxpy', got {method!r}")
    grad = c1 @ (est - x1) + c2 @ (est - x2)
    scale = np.abs(c1) @ np.abs(x1) + np.abs(c2) @ np.abs(x2) + np.abs(c1 + c2) @ np.abs(est)
    res_grad = float(np.max(np.abs(grad) / (scale + 1e-300)))
    return FusionSolution(objective=_wls_objective(est, x1, c1, x2, c2),
                          residuals={"gradient": res_grad}, estimate=est, covariance=cov,
                          W=w, **common)


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
        w = _weight(a, b)
        i = np.eye(m)
        c1, c2 = np.linalg.inv(a), np.linalg.inv(b)
        return np.kron((c1 @ w).T, i - w), -np.kron((c2 @ (i - w)).T, w)
    if method == "ad":
        x1, x2 = ca.SX.sym("S1", m, m), ca.SX.sym("S2", m, m)
        wsym = ca.solve((x1 + x2).T, x1.T).T  # S1 (S1+S2)^-1 for general (unsymmetric) S
        vw = ca.vec(wsym)  # CasADi's vec is column-major, as the paper's '#'
        f = ca.Function("P", [x1, x2], [ca.jacobian(vw, ca.vec(x1)), ca.jacobian(vw, ca.vec(x2))])
        p1, p2 = f(a, b)
        return np.array(p1), np.array(p2)
    raise ProblemError(f"method: expected 'closed_form' or 'ad', got {method!r}")


def commutation_matrix(m: int) -> FloatArray:
    """K with K vec(A) = vec(Aᵀ) for (m, m) matrices."""
    k = np.zeros((m * m, m * m))
    for i in range(m):
        for j in range(m):
            k[i * m + j, j * m + i] = 1.0
    return k


def _check_n(name: str, n: int, m: int) -> int:
    if int(n) != n or n <= m:
        raise ProblemError(f"{name}: need an integer sample size n > m = {m} (the sample "
                           f"covariance is singular otherwise), got {n}")
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
    m = s.shape[0]
    n = _check_n("n", n, m)
    if mean == "known":
        mu, c = n / (n - 1) * s, n / (n - 1) ** 2
    elif mean == "sample":
        mu, c = s.copy(), 1.0 / (n - 1)
    else:
        raise ProblemError(f"mean: expected 'known' or 'sample', got {mean!r}")
    return mu, c * np.kron(s, s) @ (np.eye(m * m) + commutation_matrix(m))


def weight_covariance(s1: ArrayLike, s2: ArrayLike, n1: int, n2: int, *,
                      mean: MeanKind = "known") -> FloatArray:
    """Linearised Cov(vec Ŵ) (10): P1 Cov(vec Ŝ1) P1ᵀ + P2 Cov(vec Ŝ2) P2ᵀ with the
    Jacobians (13)-(14) at the true S_μ and the moments of :func:`sample_covariance_moments`.
    Valid to first order in 1/n (see :func:`monte_carlo_weight` for the exact law)."""
    a, b = _pair(s1, s2)
    p1, p2 = weight_jacobians(a, b)
    _, k1 = sample_covariance_moments(a, n1, mean=mean)
    _, k2 = sample_covariance_moments(b, n2, mean=mean)
    return p1 @ k1 @ p1.T + p2 @ k2 @ p2.T


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
    n1, n2 = _check_n("n1", n1, m), _check_n("n2", n2, m)
    if mean not in ("known", "sample"):
        raise ProblemError(f"mean: expected 'known' or 'sample', got {mean!r}")
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
    w = np.linalg.solve(sa + sb, sa).transpose(0, 2, 1)
    vw = w.transpose(0, 2, 1).reshape(trials, m * m)  # column-major vec per trial
    return WeightMonteCarlo(mean=w.mean(axis=0), cov=np.cov(vw.T), trials=int(trials))
