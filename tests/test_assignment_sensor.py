"""Joint assignment for a real sensor (issue 18 items 1, 2): the resolution model
(:mod:`optmodels.assignment.sensor`) against Monte Carlo estimates and exact enumerations,
per-measurement covariances, and brute force (the paper's enumeration (13)-(14)) = the
MILP = k-best with both, plus the constant-ρ special case and the input errors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from optmodels import assignment as asg
from optmodels.assignment.data import AssignmentData
from optmodels.assignment.merge_prior import connected_probability
from optmodels.assignment.polar import (
    cartesian_to_polar,
    polar_measurement_covs,
    polar_to_cartesian,
)
from optmodels.assignment.sensor import Resolution
from optmodels.core import ProblemError

SITE = np.array([0.0, 0.0])


def _mc_tol(p: float, n: int) -> float:
    """5 binomial standard deviations of a Monte Carlo frequency (plus 1e-4 for the
    first-order polar linearisation at ~10 km, (σ/r)² ≈ 1e-3 relative at most)."""
    return 5.0 * math.sqrt(max(p * (1 - p), 1.0 / n) / n) + 1e-4


# ----------------------------------------------------------------- pair probability
@pytest.mark.parametrize("geometry", ["radar_far", "radar_near_correlated", "wrap", "3d"])
def test_pair_probability_polar_cell_matches_monte_carlo(geometry: str) -> None:
    """u_ij = P(|Δr| < Δr_res, |Δaz| < Δaz_res) of the predicted positions, against the
    frequency over 2·10⁵ seeded draws of the two true positions, converted to polar
    exactly (no linearisation in the reference)."""
    rng = np.random.default_rng(11)
    if geometry == "radar_far":  # issue 18's radar: 90 km, 500 m × 1.4°
        res = Resolution(range=500.0, azimuth=math.radians(1.4), site=SITE)
        m = np.array([[90e3, 0.0], [90.2e3, 1500.0]])
        k = np.stack([[[2e4, 5e3], [5e3, 4e4]], [[3e4, -1e4], [-1e4, 2e4]]])
    elif geometry == "radar_near_correlated":  # elongated, correlated predictions
        res = Resolution(range=150.0, azimuth=math.radians(1.0), site=[1000.0, -500.0])
        m = np.array([[11e3, 3e3], [11.05e3, 3.1e3]])
        k = np.stack([[[9e4, 8.5e4], [8.5e4, 9e4]], [[4e3, 0.0], [0.0, 1e3]]])
    elif geometry == "3d":  # 3-D positions: range over all coordinates, azimuth in x-y
        res = Resolution(range=200.0, azimuth=math.radians(1.2), site=[0.0, 0.0, 100.0])
        m = np.array([[12e3, 4e3, 3e3], [12.1e3, 4.05e3, 2.9e3]])
        k = np.stack([np.diag([4e3, 9e3, 2e4]), np.diag([1e4, 2e3, 5e3])])
    else:  # azimuth near ±π: the difference must be wrapped
        res = Resolution(range=300.0, azimuth=math.radians(2.0), site=SITE)
        m = np.array([[-10e3, 180.0], [-10e3, -180.0]])
        k = np.stack([np.eye(2) * 2500.0, np.eye(2) * 900.0])
    u = res.unresolved_probability(m, k)
    n = 200_000
    x1 = rng.multivariate_normal(m[0], k[0], n)
    x2 = rng.multivariate_normal(m[1], k[1], n)
    site = SITE if res.site is None else res.site
    p1, p2 = cartesian_to_polar(x1, site), cartesian_to_polar(x2, site)
    daz = (p1[:, 1] - p2[:, 1] + math.pi) % (2 * math.pi) - math.pi
    mc = float(np.mean((np.abs(p1[:, 0] - p2[:, 0]) < res.range) & (np.abs(daz) < res.azimuth)))
    assert 0.01 < mc < 0.99  # a case where the answer is not trivially 0 or 1
    assert u == pytest.approx(mc, abs=_mc_tol(mc, n))


@pytest.mark.parametrize("d", [2, 3])
def test_pair_probability_ellipse_matches_monte_carlo(d: int) -> None:
    """Cartesian resolution ellipse: u = P(Δpᵀ E⁻¹ Δp < 1), Δp ~ N(m_i − m_j, K_i + K_j),
    against 2·10⁵ seeded draws, in 2-D and 3-D (the nested quadrature)."""
    rng = np.random.default_rng(12 + d)
    a = rng.normal(size=(d, d))
    e = a @ a.T * 1e5 + np.eye(d) * 2e5
    m = np.vstack([np.zeros(d), rng.uniform(100, 400, d)])
    k = np.stack([np.diag(rng.uniform(5e3, 4e4, d)) for _ in range(2)])
    u = Resolution(ellipse=e).unresolved_probability(m, k)
    n = 200_000
    dx = rng.multivariate_normal(m[0], k[0], n) - rng.multivariate_normal(m[1], k[1], n)
    mc = float(np.mean(np.einsum("ni,ij,nj->n", dx, np.linalg.inv(e), dx) < 1.0))
    assert 0.01 < mc < 0.99
    assert u == pytest.approx(mc, abs=_mc_tol(mc, n))


def test_pair_probability_tails_and_limits() -> None:
    """Far apart: u at the floor (no cancellation to a negative or NaN); certain points
    (tiny covariance) inside / outside the cell: u → 1 / 0; the cell's box in closed form
    for independent coordinates: the product of two normal interval probabilities."""
    res = Resolution(range=100.0, azimuth=0.01, site=SITE)
    tiny = np.stack([np.eye(2) * 1e-6] * 2)
    inside = res.pair_probabilities(np.array([[10e3, 0.0], [10.05e3, 0.0]]), tiny)[0, 1]
    outside = res.pair_probabilities(np.array([[10e3, 0.0], [10.2e3, 0.0]]), tiny)[0, 1]
    far = res.pair_probabilities(np.array([[10e3, 0.0], [30e3, 0.0]]), np.stack([np.eye(2)] * 2))[
        0, 1
    ]
    assert inside == pytest.approx(1.0, abs=1e-9)
    assert outside == far == pytest.approx(1e-100, rel=1e-12)
    # box with independent coordinates: Δ ~ N(μ, diag(s²)) (an ellipse with E = I m², in
    # the coordinates' frame, is a disc; use the box directly)
    from optmodels.assignment.quadrature import _box_probability, _interval_prob

    mu, s = np.array([[30.0, -0.004]]), np.array([60.0, 0.006])
    got = _box_probability(mu, np.diag(s**2)[None], np.array([100.0, 0.01]))[0]
    want = float(
        _interval_prob(-100.0, 100.0, mu[0, 0], s[0]) * _interval_prob(-0.01, 0.01, mu[0, 1], s[1])
    )
    assert got == pytest.approx(want, rel=1e-10)


# ----------------------------------------------------------------- group prior
def _exact_connectivity(u: np.ndarray) -> tuple[float, float]:
    """By enumeration of every edge subset of the group (edges independent, P(edge) = u_ij):
    P(connected) and P(the edges form exactly a spanning tree)."""
    k = u.shape[0]
    edges = list(itertools.combinations(range(k), 2))
    conn = tree = 0.0
    for mask in itertools.product((0, 1), repeat=len(edges)):
        p = math.prod(u[e] if on else 1 - u[e] for e, on in zip(edges, mask, strict=True))
        parent = list(range(k))

        def find(a: int, parent: list[int] = parent) -> int:
            while parent[a] != a:
                a = parent[a]
            return a

        for (i, j), on in zip(edges, mask, strict=True):
            if on:
                parent[find(i)] = find(j)
        if len({find(i) for i in range(k)}) == 1:
            conn += p
            if sum(mask) == k - 1:
                tree += p
    return conn, tree


@pytest.mark.parametrize("k", [3, 4, 6])
def test_group_probability_is_the_chain_probability(k: int) -> None:
    """unresolved_probability of a group of k = the probability that the unresolved pairs
    (independent, the sensor's own u_ij) connect the group, by enumeration of every edge
    subset (independent of the recursion); the variant prior P(π) = C + Σ ln w(S) sums
    to 1 over every π, and the all-merged variant's prior is P_conn."""
    rng = np.random.default_rng(20 + k)
    res = Resolution(range=200.0, azimuth=math.radians(1.5), site=SITE)
    m = np.column_stack([rng.uniform(8e3, 8.3e3, k), rng.uniform(-150, 150, k)])
    cov = np.stack([np.eye(2) * rng.uniform(1e3, 1e4) for _ in range(k)])
    u = res.pair_probabilities(m, cov)
    conn, _ = _exact_connectivity(u)
    assert 1e-3 < conn < 0.999  # neither trivially merged nor resolved
    assert res.unresolved_probability(m, cov) == pytest.approx(conn, rel=1e-10)
    d = AssignmentData(m, cov, np.zeros((0, 2)), np.eye(2), 1e6, 0.9, sensor=res)
    s = asg.score(d, [tuple(range(k))], []) - math.log1p(-0.9)
    assert s + d.log_prior_constant == pytest.approx(math.log(conn), abs=1e-10)
    total = sum(
        math.exp(
            d.log_prior_constant
            + sum(asg.block_log_prior(d, b, False) - math.log1p(-0.9) for b in p)
        )
        for p in asg.set_partitions(range(k))
    )
    assert total == pytest.approx(1.0, abs=1e-12)


def test_group_probability_without_cancellation() -> None:
    """Almost surely resolved triples and quadruples (pairs down to 1e-9; one strong pair
    with weak links): P_conn to 1e-6 relative, by enumeration, where 1 − Σ (the
    recursion) alone would have lost its digits; and a triangle of certain pairs gives 1
    (where the spanning-tree bound alone would give ~0)."""
    for vals in (
        [1e-9, 2e-9, 3e-9],
        [0.999, 1e-8, 2e-8],
        [1e-4, 1e-9, 0.3, 1e-7, 1e-8, 0.5],
        [1 - 1e-12] * 3,
    ):
        k = 3 if len(vals) == 3 else 4
        u = np.eye(k)
        u[np.triu_indices(k, 1)] = vals
        u = np.maximum(u, u.T)
        conn, _ = _exact_connectivity(u)
        got = connected_probability(u, tuple(range(k)))
        assert got == pytest.approx(conn, rel=1e-6)
    assert conn == pytest.approx(1.0, abs=1e-9)
    # six members (the recursion): almost surely resolved, the max-tree lower bound, within
    # the number of trees (Cayley: 6⁴) of the truth; a middling case: exact to 1e-9
    rng = np.random.default_rng(6)
    for scale in (1e-9, 0.3):
        u = np.eye(6)
        u[np.triu_indices(6, 1)] = scale * rng.uniform(0.5, 1.0, 15)
        u = np.maximum(u, u.T)
        conn, _ = _exact_connectivity(u)
        got = connected_probability(u, tuple(range(6)))
        if scale < 1e-3:
            assert got <= conn * (1 + 1e-9) and conn <= 6**4 * got
        else:
            assert got == pytest.approx(conn, rel=1e-9)


class _ConstantPairs(Resolution):
    """A sensor whose pairs are all unresolved with the same probability u (the paper's
    constant ρ = u/(1 − u))."""

    def __init__(self, u: float) -> None:
        super().__init__(ellipse=np.eye(2))
        self.u = u

    def pair_probabilities(self, means, covs):  # type: ignore[no-untyped-def]
        q = len(means)
        out = np.full((q, q), self.u)
        np.fill_diagonal(out, 1.0)
        return out


def _case(
    rng: np.random.Generator, q: int, n: int, *, spread: float = 2.0, per_meas: bool = False
) -> dict:
    """A dense random scene (as tests/test_assignment.case) as AssignmentData keywords."""
    means = rng.uniform(0, spread, (q, 2))
    covs = np.stack([np.eye(2) * rng.uniform(0.1, 0.5) for _ in range(q)])
    meas = rng.uniform(0, spread, (n, 2))
    kk = min(n, q)
    meas[:kk] = means[:kk] + rng.normal(0, 0.5, (kk, 2))
    if per_meas:
        a = rng.normal(0, 0.3, (n, 2, 2))
        r = a @ a.transpose(0, 2, 1) + 0.05 * np.eye(2)
    else:
        r = 0.25 * np.eye(2)
    return dict(means=means, covs=covs, measurements=meas, meas_cov=r, volume=spread**2, pd=0.9)


def test_constant_rho_is_the_special_case() -> None:
    """Pairs only (max_group_size = 2) and every pair odds u/(1 − u) = ρ: every
    hypothesis scores as with the constant prior ρ (to 1e-12), hence the same MAP; one R
    given as N equal copies scores as the single R; a triple weighs 3ρ² + ρ³ (every
    connected graph on three) where the constant model has ρ²."""
    rng = np.random.default_rng(3)
    for rho in (0.05, 0.3, 1.0):
        kw = _case(rng, 4, 3)
        u = rho / (1 + rho)
        old = AssignmentData(**kw, rho=rho, max_group_size=2)
        new = AssignmentData(**kw, sensor=_ConstantPairs(u), max_group_size=2)
        stack = AssignmentData(
            **{**kw, "meas_cov": np.stack([kw["meas_cov"]] * 3)}, rho=rho, max_group_size=2
        )
        count = 0
        for p, a in asg.enumerate_hypotheses(old):
            s = asg.score(old, p, a)
            assert asg.score(new, p, a) == pytest.approx(s, abs=1e-12 * max(1, abs(s)))
            assert asg.score(stack, p, a) == pytest.approx(s, abs=1e-12 * max(1, abs(s)))
            count += 1
        assert count == asg.count_hypotheses(4, 3) - sum(  # triples and more left out
            1
            for p, a in asg.enumerate_hypotheses(AssignmentData(**kw, rho=rho))
            if max(map(len, p)) > 2
        )
        a_old, a_new = asg.solve(old), asg.solve(new)
        assert a_old.partition == a_new.partition
        assert list(a_old.assignment) == list(a_new.assignment)
        full_old = AssignmentData(**kw, rho=rho)
        full_new = AssignmentData(**kw, sensor=_ConstantPairs(u))
        p, a = [(0, 1, 2), (3,)], [0, -1, 1]
        assert asg.score(full_new, p, a) - asg.score(full_old, p, a) == pytest.approx(
            math.log(3.0 + rho), abs=1e-12
        )


# ----------------------------------------------------------------- likelihoods
@pytest.mark.parametrize("per_meas", [True, False])
def test_merged_likelihood_by_hand(per_meas: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """ln φ_iS = ln N(x_i; Σ w_j m_j, Σ w_j² K_j + R_i), with amplitude weights and one
    R_i per measurement (or one R), against scipy's multivariate_normal; batched in
    chunks of 2 groups (the chunk boundary of the batched likelihood)."""
    from optmodels.assignment import data as asg_data

    monkeypatch.setattr(asg_data, "_CHUNK", 2)
    rng = np.random.default_rng(5)
    kw = _case(rng, 3, 4, per_meas=per_meas)
    amps = np.array([1.0, 3.0, 0.5])
    d = AssignmentData(
        **kw, sensor=Resolution(range=1.0, azimuth=0.5, site=[-5.0, -5.0], weights=amps)
    )
    groups = [(0,), (0, 1), (1, 2), (0, 1, 2), (2,)]
    ll = asg.log_likelihoods(d, groups)
    for c, g in enumerate(groups):
        w = amps[list(g)] / amps[list(g)].sum()
        mean = sum(wj * kw["means"][j] for wj, j in zip(w, g, strict=True))
        cov = sum(wj**2 * kw["covs"][j] for wj, j in zip(w, g, strict=True))
        for i in range(4):
            r = kw["meas_cov"][i] if per_meas else kw["meas_cov"]
            want = multivariate_normal(mean, cov + r).logpdf(kw["measurements"][i])
            assert ll[i, c] == pytest.approx(want, abs=1e-10)


# ----------------------------------------------------------------- brute force = MILP
def _radar_case(seed: int) -> AssignmentData:
    """A random radar scene ~9 km out: Q = 2-4 objects within a few resolution cells,
    N = 1-4 measurements with their own polar covariances (σ_r 30 m, σ_az 0.3°), a polar
    cell (150 m × 1.5°) or a Cartesian ellipse, equal or amplitude weights."""
    rng = np.random.default_rng(300 + seed)
    q, n = int(rng.integers(2, 5)), int(rng.integers(1, 5))
    means = np.column_stack([rng.uniform(9000, 9500, q), rng.uniform(-250, 250, q)])
    covs = np.stack([np.diag(rng.uniform(200, 3000, 2)) for _ in range(q)])
    meas = rng.uniform([9000, -250], [9500, 250], (n, 2))
    k = min(n, q)
    meas[:k] = means[:k] + rng.normal(0, 40, (k, 2))
    r = polar_measurement_covs(meas, SITE, 30.0, math.radians(0.3))
    weights = "equal" if seed % 2 else rng.uniform(0.5, 2.0, q)
    if seed % 3 == 2:
        sensor = Resolution(ellipse=np.diag([150.0**2, 200.0**2]), weights=weights)
    else:
        sensor = Resolution(range=150.0, azimuth=math.radians(1.5), site=SITE, weights=weights)
    return AssignmentData(
        means,
        covs,
        meas,
        r,
        500.0**2,
        float(rng.uniform(0.7, 0.95)),
        sensor=sensor,
        max_group_size=None if seed % 4 else 2,
    )


@pytest.mark.parametrize("seed", range(12))
def test_brute_force_equals_milp_with_sensor(seed: int) -> None:
    """The enumeration (13)-(14) and the pruned MILP give the same hypothesis and score
    (to 1e-9) with per-measurement covariances and the resolution prior; so does the
    unpruned MILP (the pruning rules, re-derived for any block prior, remove no MAP)."""
    d = _radar_case(seed)
    bf, milp, full = asg.brute_force(d), asg.solve(d), asg.solve(d, prune=False)
    assert milp.ok and full.ok
    for s in (milp, full):
        assert s.partition == bf.partition and list(s.assignment) == list(bf.assignment)
        assert s.log_score == pytest.approx(bf.log_score, abs=1e-9 * max(1, abs(bf.log_score)))


@pytest.mark.parametrize("seed", range(8))
def test_brute_force_equals_milp_per_measurement_covs(seed: int) -> None:
    """The existing random cases (constant ρ) with one random R_i per measurement."""
    rng = np.random.default_rng(400 + seed)
    q, n = int(rng.integers(2, 5)), int(rng.integers(1, 5))
    d = AssignmentData(
        **_case(rng, q, n, spread=float(rng.uniform(1.0, 3.0)), per_meas=True),
        rho=float(rng.uniform(0.1, 0.9)),
    )
    bf, milp = asg.brute_force(d), asg.solve(d)
    assert milp.partition == bf.partition and list(milp.assignment) == list(bf.assignment)
    assert milp.log_score == pytest.approx(bf.log_score, abs=1e-9 * max(1, abs(bf.log_score)))


@pytest.mark.parametrize("seed", range(4))
def test_k_best_equals_enumeration_with_sensor(seed: int) -> None:
    """k_best with the resolution model = the top k of the enumeration (scores to 1e-9;
    each returned hypothesis enumerated with that score, none twice)."""
    d = _radar_case(seed + 1)
    every = sorted(
        ((asg.score(d, p, a), p, tuple(a)) for p, a in asg.enumerate_hypotheses(d)),
        key=lambda x: -x[0],
    )
    k = min(8, len(every))
    kb = asg.k_best(d, k)
    np.testing.assert_allclose(
        [h.log_score for h in kb.hypotheses], [x[0] for x in every[:k]], atol=1e-9
    )
    keys = {(tuple(h.partition), tuple(int(x) for x in h.assignment)) for h in kb.hypotheses}
    assert len(keys) == k
    for h in kb.hypotheses:
        key = (tuple(h.partition), tuple(int(x) for x in h.assignment))
        assert any(abs(s - h.log_score) <= 1e-9 and (tuple(p), a) == key for s, p, a in every)


@pytest.mark.parametrize("seed", range(4))
def test_linear_assignment_equals_milp_with_sensor(seed: int) -> None:
    """Merges disallowed (max_group_size = 1) with R_i and a sensor: the linear assignment
    (scipy) = the MILP = brute force (hypothesis and score)."""
    d0 = _radar_case(seed)
    d = AssignmentData(
        d0.means,
        d0.covs,
        d0.measurements,
        d0.meas_cov,
        d0.volume,
        d0.pd,
        sensor=d0.sensor,
        max_group_size=1,
    )
    lin, milp, bf = asg.linear_assignment(d), asg.solve(d), asg.brute_force(d)
    assert lin.ok and milp.ok
    for s in (lin, milp):
        assert s.partition == bf.partition and list(s.assignment) == list(bf.assignment)
        assert s.log_score == pytest.approx(bf.log_score, abs=1e-9 * max(1, abs(bf.log_score)))


# ----------------------------------------------------------------- polar covariances
def test_polar_measurement_covs_match_monte_carlo() -> None:
    """R_i from each measurement's own Jacobian against the sample covariance of 2·10⁵
    seeded polar noise draws (σ_r 50 m, σ_az 0.1°, issue 18's radar) converted exactly;
    tolerance 5 standard errors of a sample covariance entry, √((σ_aa σ_bb + σ_ab²)/n)."""
    rng = np.random.default_rng(7)
    truth_pol = np.array([[90e3, 0.3], [60e3, -2.0], [20e3, 3.1]])
    site = np.array([1000.0, -2000.0])
    pts = polar_to_cartesian(truth_pol, site)
    sr, sa = 50.0, math.radians(0.1)
    r = polar_measurement_covs(pts, site, sr, sa)
    r_pol = polar_measurement_covs(truth_pol, site, sr, sa, coordinates="polar")
    np.testing.assert_allclose(r, r_pol, rtol=1e-9)
    n = 200_000
    for i, (rg, az) in enumerate(truth_pol):
        noisy = np.column_stack([rg + rng.normal(0, sr, n), az + rng.normal(0, sa, n)])
        sample = np.cov(polar_to_cartesian(noisy, site).T)
        se = np.sqrt((np.outer(np.diag(r[i]), np.diag(r[i])) + r[i] ** 2) / n)
        assert np.all(np.abs(sample - r[i]) <= 5 * se + 1e-6 * np.abs(r[i]).max())
    # the azimuth error dominates across the beam: σ_cross = r σ_az
    ev = np.linalg.eigvalsh(r[0])
    assert math.sqrt(ev[1]) == pytest.approx(90e3 * sa, rel=1e-9)
    assert math.sqrt(ev[0]) == pytest.approx(sr, rel=1e-9)


# ----------------------------------------------------------------- input errors
def test_bad_input_is_one_problem_error() -> None:
    rng = np.random.default_rng(9)
    kw = _case(rng, 3, 2)
    polar = Resolution(range=100.0, azimuth=0.02, site=[0.0, 0.0])
    not_spd = np.stack([np.eye(2), np.array([[1.0, 2.0], [2.0, 1.0]])])
    bad: list[tuple[object, str]] = [
        (
            lambda: AssignmentData(**{**kw, "meas_cov": np.stack([np.eye(2)] * 3)}, rho=0.3),
            r"meas_cov: expected \(2, 2\) or one per measurement \(2, 2, 2\)",
        ),
        (lambda: AssignmentData(**{**kw, "meas_cov": np.ones((2, 3))}, rho=0.3), "meas_cov"),
        (lambda: AssignmentData(**{**kw, "meas_cov": not_spd}, rho=0.3), r"meas_cov\[1\]"),
        (
            lambda: AssignmentData(**{**kw, "meas_cov": [[1.0, np.nan], [0, 1]]}, rho=0.3),
            "meas_cov",
        ),
        (lambda: AssignmentData(**kw), "rho: required without a sensor"),
        (lambda: AssignmentData(**kw, rho=0.3, sensor=polar), "rho: give rho"),
        (
            lambda: AssignmentData(**kw, sensor=polar, block_log_prior=lambda s, d: 0.0),
            "sensor: give sensor or your own block_log_prior",
        ),
        (lambda: AssignmentData(**kw, sensor="radar"), "sensor: expected a Resolution"),
        (
            lambda: AssignmentData(**kw, sensor=Resolution(ellipse=np.eye(3))),
            r"ellipse \(m²\) has shape \(3, 3\)",
        ),
        (
            lambda: AssignmentData(
                **kw, sensor=Resolution(range=1.0, azimuth=0.1, site=[0.0, 0.0, 0.0])
            ),
            "site",
        ),
        (
            lambda: AssignmentData(
                **kw, sensor=Resolution(range=1.0, azimuth=0.1, weights=[1.0, 2.0])
            ),
            "weights has 2 amplitudes, expected one per object",
        ),
        (lambda: Resolution(range=-5.0, azimuth=0.1), r"Resolution range \(m\)"),
        (lambda: Resolution(range=5.0, azimuth=0.0), r"Resolution azimuth \(rad\)"),
        (lambda: Resolution(range=5.0, azimuth=10.0), "degrees given as radians"),
        (lambda: Resolution(range=5.0), "needs both range"),
        (lambda: Resolution(), "give range and azimuth"),
        (lambda: Resolution(range=5.0, azimuth=0.1, ellipse=np.eye(2)), "not both"),
        (lambda: Resolution(ellipse=np.eye(2), site=[0, 0]), "site: only for a polar"),
        (lambda: Resolution(ellipse=[[1.0, 0.0], [0.0, -1.0]]), "ellipse"),
        (lambda: Resolution(range=5.0, azimuth=0.1, weights="amplitude"), "weights"),
        (lambda: Resolution(range=5.0, azimuth=0.1, weights=[1.0, -1.0]), "weights"),
        (
            lambda: polar.unresolved_probability(
                [[0.0, 0.0], [1.0, 1.0]], np.stack([np.eye(2)] * 2)
            ),
            "at the sensor's site",
        ),
        (lambda: polar.unresolved_probability([[1.0, 0.0]], np.eye(2)), "covs"),
        (lambda: polar_measurement_covs([[1.0, 2.0]], [0, 0], -1.0, 0.1), "sigma_range"),
        (lambda: polar_measurement_covs([[1.0, 2.0]], [0, 0], 1.0, 0.0), "sigma_azimuth"),
        (lambda: polar_measurement_covs([[1.0, 2.0]], [0, 0], 1.0, 10.0), "degrees given"),
        (lambda: polar_measurement_covs([[1.0, 2.0, 3.0]], [0, 0], 1.0, 0.1), "measurements"),
        (lambda: polar_measurement_covs([[0.0, 0.0]], [0, 0], 1.0, 0.1), "range 0"),
        (
            lambda: polar_measurement_covs([[1.0, 0.0]], [0, 0], 1.0, 0.1, coordinates="geo"),
            "coordinates",
        ),
    ]
    for call, match in bad:
        with pytest.raises(ProblemError, match=match):
            call()  # type: ignore[operator]


@pytest.mark.parametrize("seed", range(3))
def test_column_bounds_from_column_generation_are_valid(seed: int) -> None:
    """k_best's column bounds U_c from the column-generated LP dual point: for every
    enumerated hypothesis H and every column c it uses, score(H) ≤ U_c (+1e-9), so
    removing the columns with U_c < L never removes a hypothesis scoring ≥ L; the same
    for the full LP's dual point."""
    from optmodels.assignment import kbest, milp
    from optmodels.assignment.groups import candidate_groups

    d = _radar_case(seed + 5)
    groups = candidate_groups(d)
    _, gain = milp._gains("test", d, groups)
    keep = np.argwhere(np.isfinite(gain)).reshape(-1, 2)
    c, a_eq, a_ub, b_ub = milp._build_model(d, groups, gain, keep, (), False)
    n_g, n_k = len(groups), len(keep)
    start = np.concatenate(
        [
            np.ones(n_g, dtype=bool),
            gain[keep[:, 0], keep[:, 1]] > -math.log(d.volume),
            np.ones(d.n, dtype=bool),
        ]
    )
    pair = {(int(i), int(k)): n_g + m for m, (i, k) in enumerate(keep)}
    index = {g: k for k, g in enumerate(groups)}
    for bound in (
        kbest._column_bounds(c, a_eq, a_ub, b_ub, start),
        kbest._column_bounds(c, a_eq, a_ub, b_ub),
    ):
        assert bound is not None and np.all(np.isfinite(bound))
        best = asg.brute_force(d).log_score
        assert np.max(bound) >= best - 1e-9  # D ≥ the LP optimum ≥ the MAP
        assert np.min(bound) < best  # some columns are provably in no near-best hypothesis
        for p, a in asg.enumerate_hypotheses(d):
            s = asg.score(d, p, a)
            cols = [index[b] for b in p] + [
                pair[(i, index[p[k]])] if k >= 0 else n_g + n_k + i for i, k in enumerate(a)
            ]
            assert np.all(s <= bound[cols] + 1e-9 * max(1.0, abs(s)))
