"""ML joint assignment with unresolved groups and clutter (paper 004): brute force (the
paper's enumeration (13)-(14)) = one joint MILP = per-variant MILPs; linear assignment
when merges are disallowed; hypothesis counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from optmodels import ProblemError
from optmodels import assignment as asg
from optmodels.core import Status


def case(rng: np.random.Generator, q: int, n: int, *, spread: float = 3.0,
         rho: float = 0.3, pd: float = 0.9, **kw) -> asg.AssignmentData:
    """Q predictions in a square, the first min(N, Q) measurements near objects (so merges
    and misses both happen when the square is small), the rest clutter."""
    means = rng.uniform(0, spread, (q, 2))
    covs = np.stack([np.eye(2) * rng.uniform(0.1, 0.5) for _ in range(q)])
    meas = rng.uniform(0, spread, (n, 2))
    k = min(n, q)
    meas[:k] = means[:k] + rng.normal(0, 0.5, (k, 2))
    return asg.AssignmentData(means, covs, meas, 0.25 * np.eye(2), spread**2, pd, rho, **kw)


def test_counts() -> None:
    """Closed-form counts = enumeration; Bell numbers of variants; the paper's 5 variants
    for Q = 3 and its "30 vs 8" (gated, MHT with new targets vs JPDA)."""
    bell = [1, 2, 5, 15, 52, 203]
    assert [len(list(asg.set_partitions(range(q)))) for q in range(1, 7)] == bell
    assert sum(s for s, _ in asg.count_per_variant(3, 2).values()) == 5
    rng = np.random.default_rng(0)
    for q in range(1, 5):
        for n in range(0, 5):
            d = case(rng, q, n)
            assert sum(1 for _ in asg.enumerate_hypotheses(d)) == asg.count_hypotheses(q, n)
    # per variant with B blocks: Σ_k C(B,k) N!/(N−k)! (B = 2, N = 3: 1 + 6 + 6 = 13)
    assert asg.count_per_variant(2, 3) == {1: (1, 4), 2: (1, 13)}
    gates = [[0], [0, 1], [1]]
    assert asg.count_gated(gates) == 8
    assert asg.count_gated(gates, new_target=True) == 30


def _best_per_variant(d: asg.AssignmentData) -> asg.AssignmentSolution:
    allowed = set(asg.candidate_groups(d))
    best = None
    for part in asg.set_partitions(range(d.q)):
        if any(tuple(sorted(b)) not in allowed for b in part):
            continue
        s = asg.solve(d, fixed_partition=part).require_ok()
        if best is None or s.log_score > best.log_score + 1e-12:
            best = s
    assert best is not None
    return best


def test_brute_force_equals_joint_and_per_variant_milps() -> None:
    """120 seeded cases, Q ≤ 4, N ≤ 4, three priors (ρ above, below 1 − P_D, and large):
    the same hypothesis and log score to 1e-9 from all three methods; merged groups occur
    in a good share of the cases."""
    rng = np.random.default_rng(1)
    merged = 0
    for t in range(120):
        q, n = int(rng.integers(1, 5)), int(rng.integers(0, 5))
        d = case(rng, q, n, rho=(0.3, 0.05, 0.9)[t % 3])
        bf = asg.brute_force(d)
        milp = asg.solve(d).require_ok()
        assert milp.status is Status.OPTIMAL and milp.mip_gap == 0
        assert milp.partition == bf.partition and list(milp.assignment) == list(bf.assignment)
        assert milp.log_score == pytest.approx(bf.log_score, abs=1e-9)
        assert milp.residuals["objective"] < 1e-9
        if t % 4 == 0:  # per-variant MILPs (14) are slower: every 4th case
            pv = _best_per_variant(d)
            assert pv.log_score == pytest.approx(bf.log_score, abs=1e-9)
        merged += any(len(g) > 1 for g in milp.partition)
    assert merged >= 20


@pytest.mark.parametrize("seed", range(5))
def test_milp_equals_linear_assignment_without_merges(seed: int) -> None:
    """Merges disallowed (max_group_size = 1): a linear assignment on the augmented gain
    matrix (scipy) and the MILP find the same hypothesis, Q = 25, N = 30."""
    d = case(np.random.default_rng(seed), 25, 30, spread=30.0, max_group_size=1)
    la = asg.linear_assignment(d)
    mi = asg.solve(d).require_ok()
    assert list(la.assignment) == list(mi.assignment) and la.partition == mi.partition
    assert mi.log_score == pytest.approx(la.log_score, abs=1e-9)


def test_score_by_hand() -> None:
    """One object, one measurement on it: ln P_D + ln N(x; m, K + K1)."""
    d = asg.AssignmentData([[0.0, 0.0]], [np.eye(2)], [[1.0, 0.0]], np.eye(2), 50.0, 0.8, 0.5)
    expect = math.log(0.8) - math.log(2 * math.pi * 2.0) - 0.5 * 1.0 / 2.0
    assert asg.score(d, [(0,)], [0]) == pytest.approx(expect, rel=1e-12)
    assert asg.score(d, [(0,)], [-1]) == pytest.approx(math.log(0.2) - math.log(50.0))


def test_far_measurement_does_not_underflow() -> None:
    """A measurement 10⁴ σ away: its likelihood is e^(−5·10⁷), computed in logs; it goes to
    the background."""
    d = asg.AssignmentData([[0.0, 0.0]], [np.eye(2)], [[1e4, 0.0]], np.eye(2), 1e9, 0.9, 0.1)
    ll = asg.log_likelihoods(d, [(0,)])
    assert np.isfinite(ll).all() and ll[0, 0] < -1e7
    assert list(asg.solve(d).assignment) == [-1]


def test_time_limit_is_not_optimal() -> None:
    d = case(np.random.default_rng(2), 12, 14, spread=10.0)
    s = asg.solve(d, time_limit=1e-3)
    assert s.status is not Status.OPTIMAL or s.mip_gap == 0


def test_bad_input() -> None:
    ok = dict(means=[[0.0, 0.0]], covs=[np.eye(2)], measurements=[[0.0, 0.0]],
              meas_cov=np.eye(2), volume=1.0, pd=0.9, rho=0.1)
    for key, bad, match in (("pd", 1.0, "pd"), ("rho", 0.0, "rho"), ("volume", -1.0, "volume"),
                            ("covs", [-np.eye(2)], "covs"),
                            ("measurements", [[0.0, 0.0, 0.0]], "measurements"),
                            ("meas_cov", [[1.0, 2.0], [2.0, 1.0]], "meas_cov")):
        with pytest.raises(ProblemError, match=match):
            asg.AssignmentData(**{**ok, key: bad})
    d = asg.AssignmentData(**ok)
    with pytest.raises(ProblemError, match="partition"):
        asg.score(d, [], [])


def test_k_best_and_marginals() -> None:
    """The k best by no-good cuts = the top k of the enumeration; the marginals from them
    are within the stated bound of the exact ones (all hypotheses):
    |β_exact − β_k| ≤ ε/(1 + ε), ε the reported neglected mass."""
    d = case(np.random.default_rng(3), 3, 2, spread=3.0)
    every = sorted(((asg.score(d, p, a), p, a) for p, a in asg.enumerate_hypotheses(d)),
                   key=lambda x: -x[0])
    kb = asg.k_best(d, 8)
    np.testing.assert_allclose([h.log_score for h in kb.hypotheses],
                               [x[0] for x in every[:8]], atol=1e-9)
    w = np.exp(np.array([x[0] for x in every]) - every[0][0])
    w /= w.sum()
    for i in range(d.n):
        exact: dict[tuple[int, ...], float] = {}
        for (_, p, a), wh in zip(every, w, strict=True):
            key = tuple(sorted(p[a[i]])) if a[i] >= 0 else ()
            exact[key] = exact.get(key, 0.0) + float(wh)
        eps = kb.neglected
        for key in set(exact) | set(kb.beta[i]):
            assert abs(exact.get(key, 0.0) - kb.beta[i].get(key, 0.0)) <= eps / (1 + eps) + 1e-12
    # asking for every hypothesis gives the exact marginals and no neglected mass
    full = asg.k_best(d, asg.count_hypotheses(3, 2) + 5)
    assert len(full.hypotheses) == asg.count_hypotheses(3, 2) and full.neglected == 0


def test_kalman_filter_matches_stone_soup() -> None:
    """The demo's resolved-only tracker and Stone Soup's GNN (an independent
    implementation of predictor, updater and association) give the same final estimate
    when the objects are far apart (no ambiguity): to 1e-6 m."""
    from optmodels.demo.assignment import track, track_stonesoup
    from optmodels.scenarios.space_objects import space_objects

    sc = space_objects(np.random.default_rng([0, 400, 0]), q=4, separation=400.0, clutter=0.0)
    ours = track(sc, merges=False, rng=np.random.default_rng(9))
    peer = track_stonesoup(sc, method="gnn", rng=np.random.default_rng(9))
    assert ours["correct"] == peer["correct"] == ours["total"]
    assert ours["rms_position"] == pytest.approx(peer["rms_position"], abs=1e-6)


def test_user_supplied_model() -> None:
    """The same model given as user callables (no dominance pruning then) gives the same
    MAP as the built-in one; a prior that makes merges prohibitive gives the linear
    assignment; a user likelihood of −inf forbids an assignment."""
    rng = np.random.default_rng(12)
    for _ in range(10):
        d = case(rng, 4, 4, rho=0.3)

        def ll(data: asg.AssignmentData, g: tuple[int, ...], d=d) -> np.ndarray:
            return asg.log_likelihoods(d, [g])[:, 0]

        def prior(g: tuple[int, ...], detected: bool, d=d) -> float:
            return asg.block_log_prior(d, g, detected)

        u = asg.AssignmentData(d.means, d.covs, d.measurements, d.meas_cov, d.volume, d.pd,
                               d.rho, log_likelihood=ll, block_log_prior=prior)
        a, b = asg.solve(d), asg.solve(u)
        assert a.partition == b.partition and list(a.assignment) == list(b.assignment)
        assert b.log_score == pytest.approx(a.log_score, abs=1e-9)
        no_merge = asg.AssignmentData(
            d.means, d.covs, d.measurements, d.meas_cov, d.volume, d.pd, d.rho,
            block_log_prior=lambda g, det, d=d: asg.block_log_prior(d, g, det) - 1e3 * (len(g) - 1))
        la = asg.linear_assignment(d)
        nm = asg.solve(no_merge)
        assert list(nm.assignment) == list(la.assignment) and nm.partition == la.partition
    # measurement 0 may not come from object 0
    d = case(np.random.default_rng(1), 2, 1, rho=0.05)
    forbid = asg.AssignmentData(
        d.means, d.covs, d.measurements, d.meas_cov, d.volume, d.pd, d.rho,
        log_likelihood=lambda data, g: np.where(np.array([0 in g]), -np.inf,
                                                asg.log_likelihoods(d, [g])[:, 0]))
    s = asg.solve(forbid)
    assert s.assignment[0] == -1 or 0 not in s.partition[s.assignment[0]]
