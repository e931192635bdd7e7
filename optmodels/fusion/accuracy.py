"""Accuracy of the estimated weight Ŵ to first order (paper 003): the Jacobians (13)-(14)
of vec W in vec S_μ (closed form as Kronecker products, or CasADi AD), the commutation
matrix, the Wishart moments (4)-(5) of the sample covariance (3) (known or sample mean),
and the linearised Cov(vec Ŵ) (10), with the cross block for correlated snapshots."""

from __future__ import annotations

from typing import Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import FloatArray, ProblemError, as_choice, as_count
from optmodels.fusion.inputs import (
    MAX_DIM,
    MeanKind,
    _check_mean,
    _check_n,
    _cov,
    _dim_guard,
    _pair,
    _where,
)
from optmodels.fusion.weights import _cross, _weight


def weight_jacobians(
    s1: ArrayLike, s2: ArrayLike, *, method: Literal["closed_form", "ad"] = "closed_form"
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
    method = as_choice(  # type: ignore[assignment]
        _where(fn, "method"), method, ("closed_form", "ad")
    )
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
    return (
        np.asarray(np.kron((c1 @ w).T, i - w), dtype=float),
        np.asarray(-np.kron((c2 @ (i - w)).T, w), dtype=float),
    )


def commutation_matrix(m: int) -> FloatArray:
    """K with K vec(A) = vec(Aᵀ) for (m, m) matrices, 1 ≤ m ≤ :data:`MAX_DIM`."""
    m = as_count("fusion.commutation_matrix m", m, minimum=1, maximum=MAX_DIM)
    k = np.zeros((m * m, m * m))
    for i in range(m):
        for j in range(m):
            k[i * m + j, j * m + i] = 1.0
    return k


def sample_covariance_moments(
    sigma: ArrayLike, n: int, *, mean: MeanKind = "known"
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


def _moments(s: FloatArray, n: int, mean: str) -> tuple[FloatArray, FloatArray]:
    """(4)-(5) or their sample-mean counterparts for validated inputs."""
    m = s.shape[0]
    if mean == "known":
        mu, c = n / (n - 1) * s, n / (n - 1) ** 2
    else:
        mu, c = s.copy(), 1.0 / (n - 1)
    return mu, c * np.kron(s, s) @ (np.eye(m * m) + commutation_matrix(m))


def weight_covariance(
    s1: ArrayLike,
    s2: ArrayLike,
    n1: int,
    n2: int,
    *,
    mean: MeanKind = "known",
    s12: ArrayLike | None = None,
) -> FloatArray:
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
            raise ProblemError(
                f"{_where(fn, 'n2')}: with s12 both sample covariances come "
                f"from the same snapshots, so n1 = n2 is required (got {n1}, "
                f"{n2})"
            )
        c, _ = _cross(s12, a, b, fn)
        _, k12 = _moments(c, n1, mean)  # same c·(X ⊗ X)(I + K) form with X = S12
        cross = p1 @ k12 @ p2.T
        out = out + cross + cross.T
    return out
