"""Fusion of two estimates (paper 003): W, the fused estimate, the Jacobians (13)-(14)
against CasADi AD and finite differences, the moments (4)-(5) and the linearised
Cov(vec Ŵ) (10) against Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from optmodels import ProblemError
from optmodels import fusion as fu


def spd(rng: np.random.Generator, m: int, floor: float = 0.5) -> np.ndarray:
    a = rng.normal(size=(m, m))
    return a @ a.T + floor * np.eye(m)


def vec(a: np.ndarray) -> np.ndarray:
    return a.reshape(-1, order="F")


@pytest.mark.parametrize("m", [2, 3, 4])
def test_weight_matrix_forms_agree(m: int) -> None:
    rng = np.random.default_rng(m)
    s1, s2 = spd(rng, m), spd(rng, m)
    c1, c2 = np.linalg.inv(s1), np.linalg.inv(s2)
    w = fu.weight_matrix(s1, s2)
    # (2) and both forms of (6), through explicit inverses
    np.testing.assert_allclose(w, np.linalg.inv(c1 + c2) @ c2, atol=1e-12)
    np.testing.assert_allclose(w, np.eye(m) - np.linalg.inv(c1 + c2) @ c1, atol=1e-12)


@pytest.mark.parametrize("m", [2, 3, 4])
def test_fuse_closed_form_equals_cvxpy(m: int) -> None:
    rng = np.random.default_rng(10 + m)
    s1, s2 = spd(rng, m), spd(rng, m)
    a1, a2 = rng.normal(size=m), rng.normal(size=m)
    cf = fu.fuse(a1, s1, a2, s2)
    g = fu.fuse(a1, s1, a2, s2, method="cvxpy").require_ok()
    # Clarabel on a 2-term convex QP: 1e-8 relative is within its default tolerances
    np.testing.assert_allclose(g.estimate, cf.estimate, rtol=1e-7, atol=1e-8)
    assert cf.residuals["gradient"] < 1e-12 and g.residuals["gradient"] < 1e-7
    np.testing.assert_allclose(cf.covariance, np.linalg.inv(np.linalg.inv(s1) + np.linalg.inv(s2)),
                               rtol=1e-10)


@pytest.mark.parametrize("m", [2, 3, 4])
def test_jacobians_closed_form_vs_ad_vs_finite_differences(m: int) -> None:
    rng = np.random.default_rng(20 + m)
    s1, s2 = spd(rng, m), spd(rng, m)
    p1, p2 = fu.weight_jacobians(s1, s2)
    q1, q2 = fu.weight_jacobians(s1, s2, method="ad")
    # AD and the Kronecker forms of (13)-(14) are both exact: round-off only
    np.testing.assert_allclose(p1, q1, atol=1e-10)
    np.testing.assert_allclose(p2, q2, atol=1e-10)
    # central differences, step 1e-6: truncation O(h²) ~ 1e-12, round-off ~ 1e-10
    h = 1e-6

    def w_of(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return vec(np.linalg.solve((a + b).T, a.T).T)  # S1 (S1+S2)^-1, any matrices

    for k in range(m * m):
        e = vec(np.eye(m * m)[k]).reshape(m, m, order="F") * h
        fd1 = (w_of(s1 + e, s2) - w_of(s1 - e, s2)) / (2 * h)
        fd2 = (w_of(s1, s2 + e) - w_of(s1, s2 - e)) / (2 * h)
        np.testing.assert_allclose(p1[:, k], fd1, atol=1e-6)
        np.testing.assert_allclose(p2[:, k], fd2, atol=1e-6)


def test_printed_13_14_elementwise() -> None:
    """(13)-(14) typed as printed, column by column: d vec(W)/d (S_μ)_ij."""
    rng = np.random.default_rng(5)
    m = 3
    s1, s2 = spd(rng, m), spd(rng, m)
    w = fu.weight_matrix(s1, s2)
    c1, c2 = np.linalg.inv(s1), np.linalg.inv(s2)
    p1, p2 = fu.weight_jacobians(s1, s2, method="ad")
    for i in range(m):
        for j in range(m):
            e = np.zeros((m, m))
            e[i, j] = 1.0
            col = i + j * m  # vec order of (12)
            np.testing.assert_allclose(p1[:, col], vec((np.eye(m) - w) @ e @ c1 @ w), atol=1e-12)
            np.testing.assert_allclose(p2[:, col], vec(-w @ e @ c2 @ (np.eye(m) - w)),
                                       atol=1e-12)


@pytest.mark.parametrize("mean", ["known", "sample"])
def test_sample_covariance_moments_by_monte_carlo(mean: str) -> None:
    """Estimator (3) from 40 000 independent draws of n = 6 snapshots. Each element of a
    sample mean/covariance over T draws has a standard error of sd/√T and
    sd·√(2/(T−1))·(1 + kurtosis term); 4 standard errors (computed from the draws)."""
    rng = np.random.default_rng(7)
    m, n, trials = 3, 6, 40_000
    sigma = spd(rng, m)
    x = rng.multivariate_normal(np.zeros(m), sigma, size=(trials, n))
    dev = x if mean == "known" else x - x.mean(axis=1, keepdims=True)
    s_hat = np.einsum("tsi,tsj->tij", dev, dev) / (n - 1)
    v = s_hat.transpose(0, 2, 1).reshape(trials, m * m)
    mu, cov = fu.sample_covariance_moments(sigma, n, mean=mean)  # type: ignore[arg-type]
    se_mu = v.std(axis=0, ddof=1) / np.sqrt(trials)
    assert np.all(np.abs(v.mean(axis=0) - vec(mu)) < 4 * se_mu)
    c = v - v.mean(axis=0)
    prod = np.einsum("ta,tb->tab", c, c)
    se_cov = prod.std(axis=0, ddof=1) / np.sqrt(trials)
    assert np.all(np.abs(prod.mean(axis=0) - cov) < 4 * se_cov + 1e-12)


def test_paper_4_5_describe_the_known_mean_estimator() -> None:
    """(4)-(5): mean n/(n−1)σ and covariance n/(n−1)²(...) are the known-mean moments; the
    usual sample-mean estimator is unbiased with covariance (...)/(n−1)."""
    sigma = np.array([[2.0, 0.3], [0.3, 1.0]])
    n = 8
    mu_k, cov_k = fu.sample_covariance_moments(sigma, n, mean="known")
    mu_s, cov_s = fu.sample_covariance_moments(sigma, n, mean="sample")
    np.testing.assert_allclose(mu_k, n / (n - 1) * sigma)
    np.testing.assert_allclose(mu_s, sigma)
    # (5): Var(Ŝ_ij) = n/(n−1)² (σ_ij² + σ_ii σ_jj), for (i, j) = (0, 1) → vec index 2
    assert cov_k[2, 2] == pytest.approx(n / (n - 1) ** 2 * (0.3**2 + 2.0), rel=1e-12)
    assert cov_s[2, 2] == pytest.approx((0.3**2 + 2.0) / (n - 1), rel=1e-12)


def test_weight_covariance_approaches_monte_carlo() -> None:
    """The linearisation (10) is first order in 1/n. Measured relative error of the
    diagonal against 10⁵ Monte Carlo draws: 0.46 (n = 5), 0.22 (10), 0.07 (30), 0.024
    (100). Monte Carlo se of a variance at 10⁵ draws is ≈ 0.5 %, so at n = 100 the bound
    0.06 holds with margin, and the error must shrink with n."""
    s1 = np.diag([1.0, 2.0, 3.0])
    s2 = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 1.5]])
    errs = []
    for n in (10, 30, 100):
        mc = fu.monte_carlo_weight(s1, s2, n, n, trials=100_000, seed=n)
        lin = fu.weight_covariance(s1, s2, n, n)
        errs.append(float(np.max(np.abs(np.diag(lin) / np.diag(mc.cov) - 1))))
    assert errs[2] < 0.06
    assert errs[0] > errs[1] > errs[2]


def test_bad_input() -> None:
    ok = np.eye(2)
    with pytest.raises(ProblemError, match="S2"):
        fu.weight_matrix(ok, np.eye(3))
    with pytest.raises(ProblemError, match=r"S1.*symmetric"):
        fu.weight_matrix([[1.0, 0.5], [0.0, 1.0]], ok)
    with pytest.raises(ProblemError, match=r"S2.*positive definite"):
        fu.weight_matrix(ok, [[1.0, 0.0], [0.0, -1.0]])
    with pytest.raises(ProblemError, match="NaN"):
        fu.weight_matrix([[np.nan, 0.0], [0.0, 1.0]], ok)
    with pytest.raises(ProblemError, match="n > m"):
        fu.sample_covariance_moments(ok, 2)
    with pytest.raises(ProblemError, match="n2"):
        fu.monte_carlo_weight(ok, ok, 5, 1)
    with pytest.raises(ProblemError, match="a2"):
        fu.fuse([0.0, 0.0], ok, [0.0], ok)
