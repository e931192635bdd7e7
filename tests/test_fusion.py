"""Fusion of two estimates (paper 003): W, the fused estimate, the Jacobians (13)-(14)
against CasADi AD and finite differences, the moments (4)-(5) and the linearised
Cov(vec Ŵ) (10) against Monte Carlo."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from optmodels import ProblemError, Status
from optmodels import fusion as fu
from optmodels.fusion import sampling as fu_sampling
from optmodels.fusion.inputs import MAX_DIM


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
    np.testing.assert_allclose(
        cf.covariance, np.linalg.inv(np.linalg.inv(s1) + np.linalg.inv(s2)), rtol=1e-10
    )


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
            np.testing.assert_allclose(p2[:, col], vec(-w @ e @ c2 @ (np.eye(m) - w)), atol=1e-12)


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
    # Ŝ is singular unless n ≥ m (known mean) or n ≥ m + 1 (sample mean)
    with pytest.raises(ProblemError, match="n > m"):
        fu.sample_covariance_moments(ok, 2, mean="sample")
    with pytest.raises(ProblemError, match="n ≥ m"):
        fu.sample_covariance_moments(ok, 1, mean="known")
    fu.sample_covariance_moments(ok, 2, mean="known")
    with pytest.raises(ProblemError, match="n1"):
        fu.weight_covariance(ok, ok, 2, 5, mean="sample")
    with pytest.raises(ProblemError, match="mean"):
        fu.weight_covariance(ok, ok, 5, 5, mean="median")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="n2"):
        fu.monte_carlo_weight(ok, ok, 5, 1)
    with pytest.raises(ProblemError, match="a2"):
        fu.fuse([0.0, 0.0], ok, [0.0], ok)


# ---------------------------------------------------------------- correlated fusion
def joint_cov(rng: np.random.Generator, m: int, rank: int) -> np.ndarray:
    """A valid joint covariance of (a1, a2), (2m, 2m), of the given rank."""
    a = rng.normal(size=(2 * m, rank))
    return a @ a.T


@pytest.mark.parametrize(("m", "rank"), [(2, 4), (3, 6), (2, 3), (3, 4)])
def test_correlated_fusion_closed_form_equals_cvxpy(m: int, rank: int) -> None:
    """Full-rank and rank-deficient joint covariances (rank 3 of 4 is the two-site case,
    where D = Cov(a1 − a2) is singular and W is not unique): the generic minimum-trace
    problem and (S1 − S12)D⁺ give the same fused estimate and covariance."""
    rng = np.random.default_rng(30 + 10 * m + rank)
    j = joint_cov(rng, m, rank) + 1e-3 * np.eye(2 * m) * (rank == 2 * m)
    s1, s2, s12 = j[:m, :m], j[m:, m:], j[:m, m:]
    a1, a2 = rng.normal(size=m), rng.normal(size=m)
    cf = fu.fuse(a1, s1, a2, s2, s12=s12)
    g = fu.fuse(a1, s1, a2, s2, s12=s12, method="cvxpy").require_ok()
    # Clarabel's default tolerances (1e-8) on an O(1)-scaled least-squares problem
    np.testing.assert_allclose(g.estimate, cf.estimate, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(g.covariance, cf.covariance, rtol=1e-6, atol=1e-8)
    assert cf.residuals["gradient"] < 1e-10 and g.residuals["gradient"] < 1e-6
    # minimum variance: no better than either input, and the trace beats random weights
    for w in rng.normal(size=(20, m, m)):
        assert np.trace(fu.fused_covariance(w, s1, s2, s12)) >= cf.objective * (1 - 1e-12)


def test_correlated_weight_reduces_to_the_paper_weight() -> None:
    rng = np.random.default_rng(40)
    s1, s2 = spd(rng, 3), spd(rng, 3)
    np.testing.assert_allclose(
        fu.weight_matrix_correlated(s1, s2, np.zeros((3, 3))), fu.weight_matrix(s1, s2), atol=1e-12
    )
    w = fu.weight_matrix(s1, s2)
    inv = np.linalg.inv(np.linalg.inv(s1) + np.linalg.inv(s2))
    np.testing.assert_allclose(fu.fused_covariance(w, s1, s2), inv, rtol=1e-10)


def test_correlated_fusion_by_monte_carlo() -> None:
    """Draw (a1, a2) with a known joint covariance; the fused errors' covariance equals
    fused_covariance within 4 standard errors (relative se of a variance √(2/T))."""
    rng = np.random.default_rng(41)
    m, trials = 2, 50_000
    j = joint_cov(rng, m, 3)
    s1, s2, s12 = j[:m, :m], j[m:, m:], j[:m, m:]
    w = fu.weight_matrix_correlated(s1, s2, s12)
    e = rng.multivariate_normal(np.zeros(2 * m), j, size=trials, method="eigh")
    fused = e[:, :m] + (e[:, m:] - e[:, :m]) @ w.T
    pred = fu.fused_covariance(w, s1, s2, s12)
    np.testing.assert_allclose(np.var(fused, axis=0), np.diag(pred), rtol=4 * np.sqrt(2 / trials))


def test_weight_from_samples_converges() -> None:
    """Ŵ from n = 20 000 snapshots is within 5 standard deviations of (10) of W (the
    linearisation is accurate to ~1 % at this n, see the n-study)."""
    rng = np.random.default_rng(42)
    s1, s2 = spd(rng, 2), spd(rng, 2)
    n = 20_000
    a1 = rng.multivariate_normal([1.0, 2.0], s1, size=n)
    a2 = rng.multivariate_normal([1.0, 2.0], s2, size=n)
    w_hat = fu.weight_from_samples(a1, a2)
    sd = np.sqrt(np.diag(fu.weight_covariance(s1, s2, n, n, mean="sample"))).reshape(
        2, 2, order="F"
    )
    assert np.all(np.abs(w_hat - fu.weight_matrix(s1, s2)) < 5 * sd)
    with pytest.raises(ProblemError, match="snapshots"):
        fu.weight_from_samples(a1[:2], a2[:2])


# ---------------------------------------------------------------- two-site system
SYSTEM = fu.TwoSiteSystem.on_baseline()
POSITIONS = np.array(
    [[8_000.0, 30_000.0], [-25_000.0, 12_000.0], [3_000.0, 55_000.0], [30_000.0, 6_000.0]]
)


def test_two_site_model_and_estimators() -> None:
    """Jacobian against central differences (step 1 m on positions of 10-60 km: truncation
    ~(h/ρ)² ~ 1e-9 relative); both estimators invert the noise-free measurements."""
    z = SYSTEM.measure(POSITIONS)
    # azimuth clockwise from North: straight North of A is 0, East of A is +π/2
    north, east = SYSTEM.site_a + np.array([0.0, 1e3]), SYSTEM.site_a + np.array([1e3, 1.0])
    np.testing.assert_allclose(SYSTEM.measure(north)[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(SYSTEM.measure(east)[0], np.pi / 2, atol=2e-3)
    j = SYSTEM.jacobian(POSITIONS)
    h = 1.0
    for k in range(2):
        e = np.eye(2)[k] * h
        fd = (SYSTEM.measure(POSITIONS + e) - SYSTEM.measure(POSITIONS - e)) / (2 * h)
        np.testing.assert_allclose(j[..., k], fd, rtol=1e-7, atol=1e-13)
    # closed forms are exact: round-off of 1e-16 × ranges of 6e4 m
    np.testing.assert_allclose(SYSTEM.triangulate(z), POSITIONS, atol=1e-6)
    np.testing.assert_allclose(SYSTEM.azimuth_range_difference(z), POSITIONS, atol=1e-6)


def test_two_site_covariances_by_monte_carlo() -> None:
    """First-order S1, S2, S12 against 40 000 draws at 1/10 of the default noise (the
    second-order bias is then ~1e-3 relative); tolerance 4 se of each element."""
    small = fu.TwoSiteSystem.on_baseline(sigma_azimuth=3e-4, sigma_range_difference=0.3)
    rng = np.random.default_rng(43)
    x = POSITIONS[0]
    z = small.sample(x, 40_000, rng)
    a = np.hstack([small.triangulate(z), small.azimuth_range_difference(z)])
    s1, s2, s12 = small.covariances(x)
    pred = np.block([[s1, s12], [s12.T, s2]])
    c = a - a.mean(axis=0)
    prod = np.einsum("ti,tj->tij", c, c)
    se = prod.std(axis=0, ddof=1) / np.sqrt(len(a))
    assert np.all(np.abs(prod.mean(axis=0) - pred) < 4 * se + 1e-3 * np.abs(pred))
    # both estimates lie on the bearing from A: D = Cov(a1 − a2) has rank 1
    d = s1 + s2 - s12 - s12.T
    lam = np.linalg.eigvalsh(d)
    assert abs(lam[0]) < 1e-12 * lam[1]


def test_joint_ml_ipopt_equals_gauss_newton() -> None:
    """Two independent solvers of the original problem; they agree to 1e-4 m on errors of
    tens to hundreds of metres (both are converged to ~1e-10 relative stationarity)."""
    rng = np.random.default_rng(44)
    for x in POSITIONS:
        z = SYSTEM.sample(x, 300, rng)
        ip = SYSTEM.joint_ml(z).require_ok()
        gn = SYSTEM.joint_ml(z, method="gauss_newton").require_ok()
        assert ip.status is Status.OPTIMAL and ip.residuals["stationarity"] < 1e-6
        np.testing.assert_allclose(ip.estimate, gn.estimate, atol=1e-4)
        assert ip.objective == pytest.approx(gn.objective, rel=1e-9)


def test_joint_ml_and_correlated_fusion_agree_to_first_order() -> None:
    """Scale all noise by ε. The joint ML and the correlated fusion differ by O(ε²) while
    their errors are O(ε): the ratio max|ML − fused| / RMS error falls ∝ ε (expect ×0.01
    from ε = 1 to 0.01; asserted < 0.03). Fusion (1), which ignores S12, differs at first
    order: its ratio does not fall (asserted > 0.05 at both ε)."""
    rng = np.random.default_rng(45)
    ratios: dict[str, list[float]] = {"correlated": [], "paper": []}
    x = POSITIONS[1]
    for eps in (1.0, 0.01):
        sys_e = fu.TwoSiteSystem.on_baseline(
            sigma_azimuth=3e-3 * eps, sigma_range_difference=3.0 * eps
        )
        z = sys_e.sample(x, 2000, rng)
        ml = sys_e.joint_ml(z).require_ok().estimate
        rms = np.sqrt(np.mean(np.sum((ml - x) ** 2, axis=1)))
        for key, corr in (("correlated", True), ("paper", False)):
            fused = sys_e.fused(z, weights_at="true", x_true=x, correlated=corr)
            ratios[key].append(float(np.max(np.linalg.norm(fused - ml, axis=1)) / rms))
    assert ratios["correlated"][1] < 0.03 * ratios["correlated"][0]
    assert min(ratios["paper"]) > 0.05
    # first-order covariances: the correlated fusion attains the CRB exactly
    s1, s2, s12 = SYSTEM.covariances(x)
    w = fu.weight_matrix_correlated(s1, s2, s12)
    np.testing.assert_allclose(fu.fused_covariance(w, s1, s2, s12), SYSTEM.crb(x), rtol=1e-8)
    assert np.trace(fu.fused_covariance(fu.weight_matrix(s1, s2), s1, s2, s12)) > 1.01 * np.trace(
        SYSTEM.crb(x)
    )


def test_two_site_bad_input() -> None:
    with pytest.raises(ProblemError, match="site_b"):
        fu.TwoSiteSystem(np.zeros(2), np.zeros(2), 1e-3, 1.0)
    with pytest.raises(ProblemError, match="sigma_azimuth"):
        fu.TwoSiteSystem.on_baseline(sigma_azimuth=0.0)
    with pytest.raises(ProblemError, match="sigma_range_difference"):
        fu.TwoSiteSystem.on_baseline(sigma_range_difference=np.nan)
    with pytest.raises(ProblemError, match="z"):
        SYSTEM.joint_ml(np.zeros((3, 2)))
    with pytest.raises(ProblemError, match="method"):
        SYSTEM.joint_ml(SYSTEM.measure(POSITIONS), method="newton")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="x_true"):
        SYSTEM.fused(SYSTEM.measure(POSITIONS), weights_at="true")
    # a cross-covariance that no pair of estimates can have
    with pytest.raises(ProblemError, match="s12"):
        fu.fuse([0.0, 0.0], np.eye(2), [1.0, 1.0], np.eye(2), s12=2 * np.eye(2))
    # no intersection: target behind the sites on the baseline's line
    z = SYSTEM.measure(np.array([[0.0, 10_000.0]]))
    z[0, 0], z[0, 1] = 0.0, np.pi
    assert np.all(np.isnan(SYSTEM.triangulate(z)))


def test_weight_covariance_with_shared_snapshots() -> None:
    """a1 = e0 + e1, a2 = e0 + e2 with a shared error e0 (like the shared azimuth): Ŝ1, Ŝ2
    from the same n = 200 snapshot pairs. Monte Carlo (20 000 Ŵ; variance se √(2/T) = 1 %)
    agrees with (10) plus the cross block within the first-order error at n = 200 (≈ 1-2 %,
    measured) + 4 se = 7 %, while the printed, block-diagonal (10) is off by more than
    20 % on some element (measured: 29 %)."""
    rng = np.random.default_rng(46)
    m, n, trials = 2, 200, 20_000
    l0, l1, l2 = (rng.normal(size=(m, m)) for _ in range(3))
    s0 = l0 @ l0.T
    s1, s2, s12 = s0 + 0.3 * l1 @ l1.T, s0 + 0.3 * l2 @ l2.T, s0
    j = np.block([[s1, s12], [s12.T, s2]])
    x = rng.multivariate_normal(np.zeros(2 * m), j, size=(trials, n))
    dev = x - x.mean(axis=1, keepdims=True)
    cov = np.einsum("tsi,tsj->tij", dev, dev) / (n - 1)
    w = np.linalg.solve(cov[:, :m, :m] + cov[:, m:, m:], cov[:, :m, :m]).transpose(0, 2, 1)
    mc = np.diag(np.cov(w.transpose(0, 2, 1).reshape(trials, m * m).T))
    shared = np.diag(fu.weight_covariance(s1, s2, n, n, mean="sample", s12=s12))
    printed = np.diag(fu.weight_covariance(s1, s2, n, n, mean="sample"))
    assert np.max(np.abs(shared / mc - 1)) < 0.07
    assert np.max(np.abs(printed / mc - 1)) > 0.2
    with pytest.raises(ProblemError, match="n1 = n2"):
        fu.weight_covariance(s1, s2, n, n + 1, mean="sample", s12=s12)


# ---------------------------------------------------------------- issue 14: trust
def test_degenerate_geometry_is_refused_or_flagged() -> None:
    """At a site the azimuth is undefined; on the line through the sites the bearings are
    parallel (estimator 1 singular), beyond the sites Δr ≡ ±baseline (estimator 2 and the
    joint information singular). Before: covariances at a site returned three all-NaN
    matrices silently, on the baseline a raw LinAlgError."""
    sys_ = fu.TwoSiteSystem.on_baseline(20e3)
    for x in ([-10e3, 0.0], [0.0, 0.0], [30e3, 0.0], [0.0, 1e12]):
        with pytest.raises(ProblemError, match=r"covariances x = \("):
            sys_.covariances(x)
    with pytest.raises(ProblemError, match="site A"):
        sys_.covariances([-10e3, 0.0])
    # beyond B two different positions give identical noise-free measurements (to
    # round-off of 1e-16 × 4e4 m): the position along the line is not identifiable
    np.testing.assert_allclose(sys_.measure([30e3, 0.0]), sys_.measure([50e3, 0.0]), atol=1e-9)
    with pytest.raises(ProblemError, match=r"crb x = \(30000, 0\).*joint ML"):
        sys_.crb([30e3, 0.0])
    # between the sites the joint problem is regular: analytic CRB at the midpoint,
    # J = [(0, −1/h), (0, 1/h), (−2, 0)] → diag(σ_Δr²/4, h²σ_az²/2) (round-off only)
    h = 10e3
    np.testing.assert_allclose(
        sys_.crb([0.0, 0.0]), np.diag([3.0**2 / 4, h**2 * 3e-3**2 / 2]), rtol=1e-12, atol=1e-12
    )
    # far on the bisector the conditions grow ∝ ρ (estimator 1: 2ρ/b, estimator 2:
    # 2e-3 ρ/m here): 1e9 m (2e6) is accepted, 1e12 m (2e9) is not
    s1, s2, _ = sys_.covariances([0.0, 1e9])
    assert np.all(np.isfinite(s1)) and np.all(np.isfinite(s2))
    # on_degenerate="nan" flags the bad rows only (for maps)
    pts = np.array([[8e3, 30e3], [30e3, 0.0], [-10e3, 0.0], [0.0, 0.0]])
    s1, s2, s12 = sys_.covariances(pts, on_degenerate="nan")
    ref = sys_.covariances(pts[0])
    for got, want in zip((s1, s2, s12), ref, strict=True):
        np.testing.assert_allclose(got[0], want, rtol=1e-12)
    assert np.all(np.isnan(s1[1:])) and np.all(np.isnan(s12[1:]))
    assert np.all(np.isfinite(s2[3]))  # estimator 2 is regular between the sites
    crb = sys_.crb(pts, on_degenerate="nan")
    assert np.all(np.isnan(crb[1:3])) and np.all(np.isfinite(crb[[0, 3]]))


def test_joint_ml_at_a_degenerate_point_is_not_optimal() -> None:
    """Noise-free z from a point beyond B: the ML set is the whole extension (Fisher
    information singular), so no isolated optimum exists. Before: OPTIMAL. Now the
    Newton-step check (infinite in CRB units) makes it ERROR with a NaN estimate."""
    z = SYSTEM.measure(np.array([[30e3, 0.0]]))
    for method in ("ipopt", "gauss_newton"):
        sol = SYSTEM.joint_ml(z, method=method)  # type: ignore[arg-type]
        assert sol.status is Status.ERROR and np.all(np.isnan(sol.estimate))
    with pytest.raises(ProblemError, match="x0"):
        SYSTEM.joint_ml(SYSTEM.measure(POSITIONS), x0=SYSTEM.site_a)
    with pytest.raises(ProblemError, match="x0"):
        SYSTEM.joint_ml(SYSTEM.measure(POSITIONS), x0=np.zeros((3, 2)))
    with pytest.raises(ProblemError, match="no measurements"):
        SYSTEM.joint_ml(np.zeros((0, 3)))


def test_solver_options_are_checked_by_name() -> None:
    """Before: a raw CasADi RuntimeError. Now ProblemError naming the option, for unknown
    names, wrong types and values IPOPT rejects only when first called."""
    z = SYSTEM.measure(POSITIONS[:1])
    with pytest.raises(ProblemError, match="'nonsense'"):
        SYSTEM.joint_ml(z, options={"nonsense": 1})
    with pytest.raises(ProblemError, match="'tol'"):
        SYSTEM.joint_ml(z, options={"tol": "x"})
    with pytest.raises(ProblemError, match="'mu_strategy'"):
        SYSTEM.joint_ml(z, options={"max_iter": 50, "mu_strategy": "nope"})
    with pytest.raises(ProblemError, match="options"):
        SYSTEM.joint_ml(z, options=[("tol", 1e-8)])  # type: ignore[arg-type]
    # valid options still solve: 0.1 m of the truth on noise-free data (IPOPT tol 1e-8)
    sol = SYSTEM.joint_ml(z, options={"tol": 1e-8}).require_ok()
    np.testing.assert_allclose(sol.estimate, POSITIONS[:1], atol=0.1)


def test_nlp_status_tables() -> None:
    import casadi as ca

    from optmodels.backends.casadi_backend import (
        SolverNotAvailable,
        build_nlpsol,
        nlp_status,
        run_nlpsol,
    )

    st = Status
    assert nlp_status("ipopt", {"return_status": "Solve_Succeeded", "success": True}) is st.OPTIMAL
    assert nlp_status("ipopt", {"return_status": "Brand_New_Code"}) is st.ERROR
    # a table entry never overrides CasADi's failure flag
    assert (
        nlp_status("sqpmethod", {"return_status": "Solve_Succeeded", "success": False}) is st.ERROR
    )
    assert (
        nlp_status(
            "fatrop",
            {"return_status": "0", "success": True, "unified_return_status": "SOLVER_RET_SUCCESS"},
        )
        is st.OPTIMAL
    )
    assert (
        nlp_status(
            "fatrop",
            {"return_status": "7", "success": False, "unified_return_status": "SOLVER_RET_LIMITED"},
        )
        is st.ITERATION_LIMIT
    )
    assert nlp_status("blocksqp", {"return_status": "?"}) is st.ERROR
    # a real iteration cap of sqpmethod: ITERATION_LIMIT, not ERROR or OPTIMAL
    v = ca.SX.sym("v", 2)
    nlp = {"x": v, "f": (v[0] - 1) ** 4 + 10 * (v[1] - v[0] ** 2) ** 2, "g": v[0] + v[1] - 1}
    res, _ = run_nlpsol(
        build_nlpsol(nlp, plugin="sqpmethod", options={"max_iter": 1}),
        x0=np.array([3.0, -2.0]),
        p=np.zeros(0),
    )
    assert res.status is st.ITERATION_LIMIT
    with pytest.raises(ProblemError, match="'bogus'"):
        build_nlpsol(nlp, plugin="sqpmethod", options={"bogus": 1})
    with pytest.raises(SolverNotAvailable, match="ipotp"):
        build_nlpsol(nlp, plugin="ipotp")


def test_casadi_conic_bad_option_names_the_option() -> None:
    """Before: a raw CasADi RuntimeError from inside CVXPY. casadi_qp now raises
    ProblemError naming the option; cvxpy_backend either re-raises it or reports a failed
    solve (Status.ERROR, NaN estimate) carrying that message -- never a traceback."""
    try:
        sol = fu.fuse(
            [0.0, 0.0],
            np.eye(2),
            [1.0, 1.0],
            2 * np.eye(2),
            method="cvxpy",
            solver="CASADI_OSQP",
            bogus=1,
        )
    except ProblemError as exc:
        assert "'bogus'" in str(exc)
    else:
        assert sol.status is Status.ERROR and "'bogus'" in sol.message
        assert np.all(np.isnan(sol.estimate))


@pytest.mark.parametrize("bad", [np.nan, np.inf, 2.5, "5", True, None])
def test_scalar_arguments_are_checked(bad: object) -> None:
    """Before: weight_covariance(n1=nan) raised ValueError, inf OverflowError,
    on_baseline('x') ValueError, monte_carlo_weight(seed='x') TypeError. Counts refuse
    all six values; real-valued arguments accept 2.5; seed=None is a valid seed."""
    ok = np.eye(2)
    counts: dict[str, Any] = {
        "n1": lambda: fu.weight_covariance(ok, ok, bad, 5),
        "n2": lambda: fu.monte_carlo_weight(ok, ok, 5, bad, trials=10),
        "trials": lambda: fu.monte_carlo_weight(ok, ok, 5, 5, trials=bad),
        "moments n": lambda: fu.sample_covariance_moments(ok, bad),
        "sample trials": lambda: SYSTEM.sample(POSITIONS[0], bad, np.random.default_rng(0)),
        "matrix m": lambda: fu.commutation_matrix(bad),
        "mean": lambda: fu.weight_covariance(ok, ok, 5, 5, mean=bad),
        "method": lambda: fu.fuse([0.0, 0.0], ok, [1.0, 1.0], ok, method=bad),
        "weights_at": lambda: SYSTEM.fused(SYSTEM.measure(POSITIONS), weights_at=bad),
    }
    if bad is not None:
        counts["seed"] = lambda: fu.monte_carlo_weight(ok, ok, 5, 5, trials=10, seed=bad)
    reals: dict[str, Any] = {
        "baseline": lambda: fu.TwoSiteSystem.on_baseline(bad),
        "sigma_azimuth": lambda: fu.TwoSiteSystem.on_baseline(sigma_azimuth=bad),
        "sigma_range_difference": lambda: fu.TwoSiteSystem.on_baseline(sigma_range_difference=bad),
    }
    for arg, call in counts.items():
        with pytest.raises(ProblemError, match=arg.split()[-1]):
            call()
    for arg, call in reals.items():
        if bad == 2.5:
            assert call().baseline > 0  # a valid real number
        else:
            with pytest.raises(ProblemError, match=arg):
                call()


def test_monte_carlo_weight_is_chunked_and_guarded(monkeypatch: pytest.MonkeyPatch) -> None:
    """Before: trials=1e9 ran for > 78 s without returning (one 1e9 × m × m draw). Now
    trials·m² above MAX_MC_WORK is refused at once, and the draws are made in chunks:
    forced here to 64·m² values, i.e. 313 chunks of 64 trials for 20 000 trials. The
    chunked moments agree with (10) at n = 400 (first-order error ~1/n = 0.3 %) within
    the Monte Carlo se of a variance √(2/T) = 1 % times 4, plus 1 %: 5 %."""
    s1 = np.array([[1.0, 0.3], [0.3, 2.0]])
    s2 = np.array([[2.0, -0.4], [-0.4, 1.0]])
    with pytest.raises(ProblemError, match=r"trials.*above the limit"):
        fu.monte_carlo_weight(s1, s2, 10, 10, trials=10**9)
    with pytest.raises(ProblemError, match="dimension"):
        fu.monte_carlo_weight(np.eye(MAX_DIM + 1), np.eye(MAX_DIM + 1), 40, 40, trials=10)
    monkeypatch.setattr(fu_sampling, "MC_CHUNK", 64 * 4)
    n, trials = 400, 20_000
    mc = fu.monte_carlo_weight(s1, s2, n, n, trials=trials, seed=3, mean="sample")
    lin = fu.weight_covariance(s1, s2, n, n, mean="sample")
    assert mc.trials == trials
    np.testing.assert_allclose(np.diag(mc.cov), np.diag(lin), rtol=0.05)
    # E Ŵ = W + O(1/n): within 5 se of the mean plus the 1/n bias scale × sd
    sd = np.sqrt(np.diag(mc.cov)).reshape(2, 2, order="F")
    assert np.all(
        np.abs(mc.mean - fu.weight_matrix(s1, s2)) < 5 * sd / np.sqrt(trials) + sd / np.sqrt(n)
    )


def _exact_weight(s1: np.ndarray, s2: np.ndarray) -> np.ndarray:
    """W = S1(S1 + S2)⁻¹ in exact rational arithmetic (2 × 2), from the float inputs."""
    from fractions import Fraction as Fr

    a = [[Fr(float(s1[i, j])) for j in range(2)] for i in range(2)]
    s = [[a[i][j] + Fr(float(s2[i, j])) for j in range(2)] for i in range(2)]
    det = s[0][0] * s[1][1] - s[0][1] * s[1][0]
    inv = [[s[1][1] / det, -s[0][1] / det], [-s[1][0] / det, s[0][0] / det]]
    return np.array(
        [[float(sum(a[i][k] * inv[k][j] for k in range(2))) for j in range(2)] for i in range(2)]
    )


def test_fuse_closed_form_is_rechecked_against_its_conditioning() -> None:
    """S1, S2 sharing a near-null direction (eigenvalues 1, c): S1 + S2 has condition
    ~1/c. Against W in exact arithmetic, the closed form's error grows like cond·eps
    (measured 4e-8 at c = 1e-9, 3.7e-6 at 1e-11); before, every case was OPTIMAL
    (gradient residual ≤ 3.2e-7). Now the forward error bound (valid: ≥ the true error)
    gives OPTIMAL, OPTIMAL_INACCURATE, ERROR, and weight_matrix refuses the last.
    S1 + S2 well conditioned while S1, S2 are not (opposite rotations): OPTIMAL, exact."""
    th = 0.3
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    a1, a2 = np.array([1.0, 2.0]), np.array([2.0, 3.0])
    expect = {1e-9: Status.OPTIMAL, 1e-11: Status.OPTIMAL_INACCURATE, 1e-13: Status.ERROR}
    for c, status in expect.items():
        s1 = rot @ np.diag([1.0, c]) @ rot.T
        s2 = rot @ np.diag([2.0, 3 * c]) @ rot.T
        s1, s2 = 0.5 * (s1 + s1.T), 0.5 * (s2 + s2.T)
        sol = fu.fuse(a1, s1, a2, s2)
        assert sol.status is status
        w_true = _exact_weight(s1, s2)
        if sol.ok:
            true_err = np.max(np.abs(sol.W - w_true)) / np.max(np.abs(w_true))
            assert true_err <= sol.residuals["weight_error"]
            est_true = a1 + w_true @ (a2 - a1)
            assert np.max(np.abs(sol.estimate - est_true)) / 3.0 <= sol.residuals["estimate_error"]
        else:
            assert np.all(np.isnan(sol.estimate))
            with pytest.raises(ProblemError, match="ill-conditioned"):
                fu.weight_matrix(s1, s2)
    # S1 = S2 nearly singular: W = I/2 exactly, computed W off by 1.8e-3 (before: OPTIMAL)
    s = np.array([[1.0, 1.0], [1.0, 1.0 + 1e-13]])
    assert fu.fuse([0.0, 0.0], s, [1.0, 1.0], s).status is Status.ERROR
    for c in (1e-6, 1e-13):
        s1 = rot @ np.diag([1.0, c]) @ rot.T
        s2 = rot.T @ np.diag([1.0, c]) @ rot
        s1, s2 = 0.5 * (s1 + s1.T), 0.5 * (s2 + s2.T)
        for method in ("closed_form", "cvxpy"):
            sol = fu.fuse(a1, s1, a2, s2, method=method)  # type: ignore[arg-type]
            assert sol.status is Status.OPTIMAL
            # exact W; 1e-8 covers Clarabel's relative tolerance on the O(1) problem
            np.testing.assert_allclose(
                sol.estimate, a1 + _exact_weight(s1, s2) @ (a2 - a1), rtol=1e-8
            )
    with pytest.raises(ProblemError, match=r"S2.*positive definite"):
        fu.fuse(a1, np.eye(2), a2, np.diag([1.0, -1e-3]))
