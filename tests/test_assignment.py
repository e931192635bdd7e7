"""ML joint assignment with unresolved groups and clutter (paper 004): brute force (the
paper's enumeration (13)-(14)) = one joint MILP = per-variant MILPs; linear assignment
when merges are disallowed; hypothesis counts."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest

from optmodels import ProblemError
from optmodels import assignment as asg
from optmodels.assignment import groups as asg_groups
from optmodels.assignment import milp as asg_milp
from optmodels.core import REJECT_TOL, VERIFY_TOL, SolveError, Status
from solvers_cmp.assignment import instance


def case(
    rng: np.random.Generator,
    q: int,
    n: int,
    *,
    spread: float = 3.0,
    rho: float = 0.3,
    pd: float = 0.9,
    **kw,
) -> asg.AssignmentData:
    """Q predictions in a square, the first min(N, Q) measurements near objects (so merges
    and misses both happen when the square is small), the rest clutter."""
    means = rng.uniform(0, spread, (q, 2))
    covs = np.stack([np.eye(2) * rng.uniform(0.1, 0.5) for _ in range(q)])
    meas = rng.uniform(0, spread, (n, 2))
    k = min(n, q)
    meas[:k] = means[:k] + rng.normal(0, 0.5, (k, 2))
    return asg.AssignmentData(means, covs, meas, 0.25 * np.eye(2), spread**2, pd, rho, **kw)


def dense_scene(
    q: int, side_factor: float, *, gate: float | None = 3.0, max_group_size: int | None = None
) -> asg.AssignmentData:
    """The comparison's scene (solvers_cmp.assignment.instance) with a chosen density:
    Q objects in a square of side ``side_factor``·√Q, N = Q + Q//8 + 1."""
    return instance(
        q, q + q // 8 + 1, 0, gate, side_factor=side_factor, max_group_size=max_group_size
    )


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
        # HiGHS stops at mip_rel_gap = 0 or |incumbent − bound| ≤ mip_abs_gap = 1e-12 (set
        # by solve); it reports the relative gap |p − d|/|p|, which is round-off
        # (3.6e-16 seen with HiGHS 1.16), not 0: so |gap · score| ≤ 1e-12, with a factor
        # 2 for the rounding of p and d themselves
        assert milp.status is Status.OPTIMAL and milp.mip_gap is not None
        assert 0 <= milp.mip_gap and milp.mip_gap * abs(milp.log_score) <= 2e-12
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
    assert asg.score(d, [(0,)], [-1]) == pytest.approx(math.log(0.2) - math.log(50.0), rel=1e-12)


def test_far_measurement_does_not_underflow() -> None:
    """A measurement 10⁴ σ away: its likelihood is e^(−5·10⁷), computed in logs; it goes to
    the background."""
    d = asg.AssignmentData([[0.0, 0.0]], [np.eye(2)], [[1e4, 0.0]], np.eye(2), 1e9, 0.9, 0.1)
    ll = asg.log_likelihoods(d, [(0,)])
    assert np.isfinite(ll).all() and ll[0, 0] < -1e7
    assert list(asg.solve(d).assignment) == [-1]


def test_time_limit_is_not_optimal() -> None:
    """A solve stopped by its time limit is never OPTIMAL, nor returned as a solution; the
    same model without the limit is solved to optimality (so the limit, not the model, is
    what stopped it)."""
    d = case(np.random.default_rng(2), 12, 14, spread=10.0)
    s = asg.solve(d, time_limit=1e-3)
    # finished within the limit: OPTIMAL only at a closed gap, i.e. round-off of the
    # objective (mip_abs_gap 1e-12 on |score| ~ 10, see the brute-force test)
    assert s.status is not Status.OPTIMAL or s.mip_gap * max(abs(s.log_score), 1.0) <= 2e-12
    hard = dense_scene(30, 1.0)  # 70 000 binaries unpruned: HiGHS needs 1-3 s at zero gap
    stopped = asg.solve(hard, prune=False, time_limit=0.05)
    assert stopped.status is Status.ITERATION_LIMIT and not stopped.ok
    assert stopped.partition == [] and math.isnan(stopped.log_score)
    with pytest.raises(SolveError):
        stopped.require_ok()


def test_bad_input() -> None:
    ok = dict(
        means=[[0.0, 0.0]],
        covs=[np.eye(2)],
        measurements=[[0.0, 0.0]],
        meas_cov=np.eye(2),
        volume=1.0,
        pd=0.9,
        rho=0.1,
    )
    for key, bad, match in (
        ("pd", 1.0, "pd"),
        ("rho", 0.0, "rho"),
        ("volume", -1.0, "volume"),
        ("covs", [-np.eye(2)], "covs"),
        ("measurements", [[0.0, 0.0, 0.0]], "measurements"),
        ("meas_cov", [[1.0, 2.0], [2.0, 1.0]], "meas_cov"),
    ):
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
    every = sorted(
        ((asg.score(d, p, a), p, a) for p, a in asg.enumerate_hypotheses(d)), key=lambda x: -x[0]
    )
    kb = asg.k_best(d, 8)
    np.testing.assert_allclose(
        [h.log_score for h in kb.hypotheses], [x[0] for x in every[:8]], atol=1e-9
    )
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
    # (neglected is exactly 0.0 by construction when no hypothesis is left: integer count)
    assert len(full.hypotheses) == asg.count_hypotheses(3, 2) and full.neglected == 0


@pytest.mark.parametrize("seed", range(6))
def test_k_best_equals_enumeration_on_random_cases(seed: int) -> None:
    """k_best (bound-reduced model + no-good cuts) = the top k of the enumeration, scored
    by asg.score and sorted, on random dense cases with merges (Q = 3-4, N = 2-4, with and
    without a gate / size limit): the same scores to 1e-9, every returned hypothesis is an
    enumerated one with that score (ties: any of the tied ones), none twice."""
    rng = np.random.default_rng(100 + seed)
    q, n = int(rng.integers(3, 5)), int(rng.integers(2, 5))
    kw = {} if seed % 3 else {"max_group_size": 2, "group_gate": 4.0}
    d = case(
        rng,
        q,
        n,
        spread=float(rng.uniform(1.0, 2.5)),
        rho=float(rng.uniform(0.2, 0.9)),
        pd=float(rng.uniform(0.6, 0.95)),
        **kw,
    )
    every = sorted(
        ((asg.score(d, p, a), p, tuple(a)) for p, a in asg.enumerate_hypotheses(d)),
        key=lambda x: -x[0],
    )
    k = min(int(rng.integers(5, 25)), len(every))
    kb = asg.k_best(d, k)
    got = [h.log_score for h in kb.hypotheses]
    np.testing.assert_allclose(got, [x[0] for x in every[:k]], atol=1e-9)
    keys = set()
    for h in kb.hypotheses:
        key = (tuple(h.partition), tuple(int(x) for x in h.assignment))
        assert key not in keys
        keys.add(key)
        assert any(abs(s - h.log_score) <= 1e-9 and (tuple(p), a) == key for s, p, a in every)
        assert asg.score(d, h.partition, h.assignment) == pytest.approx(h.log_score, abs=1e-9)
    # the scene is dense enough that merged hypotheses are among the k best
    assert any(len(b) > 1 for x in every[:k] for b in x[1]) or seed % 3 == 0


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

        u = asg.AssignmentData(
            d.means,
            d.covs,
            d.measurements,
            d.meas_cov,
            d.volume,
            d.pd,
            d.rho,
            log_likelihood=ll,
            block_log_prior=prior,
        )
        a, b = asg.solve(d), asg.solve(u)
        assert a.partition == b.partition and list(a.assignment) == list(b.assignment)
        assert b.log_score == pytest.approx(a.log_score, abs=1e-9)
        no_merge = asg.AssignmentData(
            d.means,
            d.covs,
            d.measurements,
            d.meas_cov,
            d.volume,
            d.pd,
            d.rho,
            block_log_prior=lambda g, det, d=d: asg.block_log_prior(d, g, det) - 1e3 * (len(g) - 1),
        )
        la = asg.linear_assignment(d)
        nm = asg.solve(no_merge)
        assert list(nm.assignment) == list(la.assignment) and nm.partition == la.partition
    # measurement 0 may not come from object 0
    d = case(np.random.default_rng(1), 2, 1, rho=0.05)
    forbid = asg.AssignmentData(
        d.means,
        d.covs,
        d.measurements,
        d.meas_cov,
        d.volume,
        d.pd,
        d.rho,
        log_likelihood=lambda data, g: np.where(
            np.array([0 in g]), -np.inf, asg.log_likelihoods(d, [g])[:, 0]
        ),
    )
    s = asg.solve(forbid)
    assert s.assignment[0] == -1 or 0 not in s.partition[s.assignment[0]]


# ----------------------------------------------------------------- issue 14: any input
def test_size_guards_refuse_before_allocating(monkeypatch: pytest.MonkeyPatch) -> None:
    """Exploding candidate sets are refused with a ProblemError naming the limit and the
    remedy, before the model is built: Q = 100 at side 0.7·√Q has 5.7·10⁵ gated cliques
    (the old code built the (N × G) likelihood table and dense rows: 83 s, 0.9 GB);
    without a gate Q = 200 has 2²⁰⁰ subsets (the old code never returned). The refusals
    allocate little: tracemalloc peak under 30 MB (a 2·10⁷-entry likelihood table is
    160 MB)."""
    import tracemalloc

    dense = dense_scene(100, 0.7)
    with pytest.raises(ProblemError, match="candidate groups") as err:
        asg.solve(dense)  # at the default limit
    assert "max_group_size" in str(err.value) and str(asg.MAX_CANDIDATE_GROUPS) in str(err.value)
    monkeypatch.setattr(asg_groups, "MAX_CANDIDATE_GROUPS", 2000)  # same path, quicker to trace
    for data in (dense, dense_scene(200, 3.0, gate=None)):
        tracemalloc.start()
        with pytest.raises(ProblemError, match="candidate groups"):
            asg.solve(data)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        assert peak < 30e6, peak
    # the model-column guard, checked after pruning and before the build
    d = dense_scene(30, 1.5)
    n_groups = len(asg.candidate_groups(d))
    monkeypatch.setattr(asg_milp, "MAX_MODEL_COLUMNS", n_groups * d.n // 2)
    with pytest.raises(ProblemError, match="prune=False"):
        asg.solve(d, prune=False)
    assert asg.solve(d).status is Status.OPTIMAL  # pruned, it fits


def test_sparse_model_is_small_and_same_answer() -> None:
    """The unpruned model (k_best's) at Q = 40, side 1.5·√Q: the constraint matrices are
    sparse, O(columns) nonzeros (the dense block-capacity rows alone would be G × K × 8
    bytes, computed here from the model's own sizes); the Python-side peak (tracemalloc)
    is a small fraction of that; and the pruned and unpruned models find the same MAP
    (exact pruning), to 1e-9 in the score (the MILP objective's round-off is ~1e-13)."""
    import tracemalloc

    d = dense_scene(40, 1.5)
    pruned = asg.solve(d).require_ok()
    tracemalloc.start()
    full = asg.solve(d, prune=False).require_ok()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    g, k = full.info["candidate_groups"], full.info["assignment_variables"]
    dense_bytes = 8.0 * g * k
    assert dense_bytes > 50e6  # the case is big enough for the comparison to mean something
    assert peak < dense_bytes / 5, (peak, dense_bytes)
    assert full.partition == pruned.partition
    assert list(full.assignment) == list(pruned.assignment)
    assert full.log_score == pytest.approx(pruned.log_score, abs=1e-9)


def test_brute_force_size_guard() -> None:
    """brute_force refuses above max_hypotheses (default 10⁷: Q = 8, N = 9 has 1.37·10⁸),
    saying how many and what to use; at the limit it runs and agrees with the MILP."""
    d = case(np.random.default_rng(5), 8, 9)
    total = asg.count_hypotheses(8, 9)
    assert total > asg.BRUTE_FORCE_LIMIT
    with pytest.raises(ProblemError, match=r"assignment\.solve") as err:
        asg.brute_force(d)
    assert f"{float(total):.3g}" in str(err.value)
    small = case(np.random.default_rng(6), 3, 2)
    m = asg.count_hypotheses(3, 2)
    with pytest.raises(ProblemError, match="max_hypotheses"):
        asg.brute_force(small, max_hypotheses=m - 1)
    bf = asg.brute_force(small, max_hypotheses=m)
    assert bf.info["hypotheses"] == m
    assert bf.log_score == pytest.approx(asg.solve(small).log_score, abs=1e-9)
    for bad in (0, 2.5, np.nan, "10"):
        with pytest.raises(ProblemError, match="max_hypotheses"):
            asg.brute_force(small, max_hypotheses=bad)


OK_FIELDS = dict(
    means=[[0.0, 0.0], [1.0, 0.0]],
    covs=[np.eye(2), np.eye(2)],
    measurements=[[0.0, 0.1]],
    meas_cov=np.eye(2),
    volume=100.0,
    pd=0.9,
    rho=0.1,
)


@pytest.mark.parametrize(
    ("key", "bad"),
    [
        ("pd", None),
        ("pd", np.nan),
        ("pd", 0.0),
        ("pd", 1.0),
        ("pd", "0.9"),
        ("pd", True),
        ("volume", None),
        ("volume", 0.0),
        ("volume", np.inf),
        ("volume", -1.0),
        ("rho", 0.0),
        ("rho", -0.5),
        ("rho", 1.5),
        ("rho", np.inf),
        ("rho", np.nan),
        ("rho", None),
        ("group_gate", 0.0),
        ("group_gate", -1.0),
        ("group_gate", np.nan),
        ("group_gate", "3"),
        ("max_group_size", 0),
        ("max_group_size", 2.5),
        ("max_group_size", np.nan),
        ("max_group_size", True),
        ("means", [[0.0, np.nan], [1.0, 0.0]]),
        ("measurements", [[1j, 0.0]]),
        ("measurements", "x"),
        ("log_likelihood", 3.0),
    ],
)
def test_bad_scalars_in_data(key: str, bad: object) -> None:
    """Every field through the core checks: a ProblemError naming the argument."""
    with pytest.raises(ProblemError, match=f"AssignmentData {key}"):
        asg.AssignmentData(**{**OK_FIELDS, key: bad})


def test_bad_arguments_of_entry_points() -> None:
    """Scalars of solve / k_best / count_* / score: ProblemError naming the function and
    the argument; integral floats (3.0) are accepted and give the same counts as ints."""
    d = asg.AssignmentData(**OK_FIELDS)
    bad_calls = [
        (lambda: asg.solve(d, mip_gap=np.nan), "solve mip_gap"),
        (lambda: asg.solve(d, mip_gap=-0.1), "solve mip_gap"),
        (lambda: asg.solve(d, mip_gap=1.0), "solve mip_gap"),
        (lambda: asg.solve(d, time_limit=np.nan), "solve time_limit"),
        (lambda: asg.solve(d, time_limit=-1.0), "solve time_limit"),
        (lambda: asg.solve(d, time_limit=0.0), "solve time_limit"),
        (lambda: asg.solve(d, solver="CLARABEL"), "solve solver"),
        (lambda: asg.solve(d, solver="OSQP"), "solve solver"),
        (lambda: asg.solve(d, solver=3), "solve solver"),
        (lambda: asg.solve(d, prune="yes"), "solve prune"),
        (lambda: asg.solve(d, fixed_partition=[(0,)]), "fixed_partition"),
        (lambda: asg.solve(d, fixed_partition=[(0, 1.5)]), "fixed_partition"),
        (lambda: asg.solve(d, fixed_partition=[(0, 7)]), "fixed_partition"),
        (lambda: asg.k_best(d, np.nan), "k_best k"),
        (lambda: asg.k_best(d, 2.5), "k_best k"),
        (lambda: asg.k_best(d, 0), "k_best k"),
        (lambda: asg.k_best(d, 2, solver="CLARABEL"), "k_best solver"),
        (lambda: asg.count_hypotheses(2.5, 3), "count_hypotheses q"),
        (lambda: asg.count_hypotheses(-1, 3), "count_hypotheses q"),
        (lambda: asg.count_hypotheses(3, -1), "count_hypotheses n"),
        (lambda: asg.count_hypotheses(3, np.nan), "count_hypotheses n"),
        (lambda: asg.count_hypotheses(asg.COUNT_LIMIT + 1, 3), "count_hypotheses q"),
        (lambda: asg.count_per_variant("3", 2), "count_per_variant q"),
        (lambda: asg.count_gated([[0], [0.5]]), "count_gated"),
        (lambda: asg.score(d, [(0,), (1,)], [2]), "score assignment"),
        (lambda: asg.score(d, [(0,), (1,)], [0.5]), "score assignment"),
        (lambda: asg.score(d, [(0,), ("a",)], [0]), "score partition"),
        (lambda: asg.score(d, [(0, 1), (1,)], [0]), "score partition"),
    ]
    for call, match in bad_calls:
        with pytest.raises(ProblemError, match=match):
            call()
    assert (
        asg.count_hypotheses(3.0, 2.0)
        == asg.count_hypotheses(3, 2)
        == sum(1 for _ in asg.enumerate_hypotheses(case(np.random.default_rng(0), 3, 2)))
    )
    with pytest.raises(ProblemError, match="time_limit"):
        asg.solve(d, time_limit=np.inf)  # no limit is None
    with pytest.raises(ProblemError, match="k_best k"):
        asg.k_best(d, asg.K_BEST_LIMIT + 1)


def test_non_milp_solver_is_refused_by_the_cli(tmp_path, capsys) -> None:
    """`optmodels assignment solve --solver CLARABEL` used to exit 0 with a solution from
    a continuous solver; now the library refuses and the CLI reports the ProblemError."""
    import json

    from optmodels.cli import main

    case_file = tmp_path / "case.json"
    case_file.write_text(json.dumps({k: np.asarray(v).tolist() for k, v in OK_FIELDS.items()}))
    try:
        code = main(["assignment", "solve", str(case_file), "--solver", "CLARABEL"])
    except SystemExit as exc:
        code = exc.code
    assert code not in (0, None)
    assert "does not solve integer programs" in capsys.readouterr().err


def _perturbed(
    monkeypatch: pytest.MonkeyPatch,
    *,
    objective: float = 0.0,
    point: Callable[[np.ndarray], np.ndarray] | None = None,
    gap: float | None = None,
) -> None:
    """Make the back-end return a perturbed objective or point (a faulty solver)."""
    real = asg_milp.solve_problem

    def fake(prob, solver, **kw):  # type: ignore[no-untyped-def]
        res = real(prob, solver, **kw)
        if point is not None:
            x = prob.variables()[0]
            x.save_value(point(np.asarray(x.value, dtype=float)))  # no CVXPY validation
        info = dict(res.info) if gap is None else {**res.info, "mip_gap": gap}
        return dataclasses.replace(res, objective=res.objective * (1 + objective), info=info)

    monkeypatch.setattr(asg_milp, "solve_problem", fake)


def _perturbed_direct(
    monkeypatch: pytest.MonkeyPatch,
    *,
    objective: float = 0.0,
    point: Callable[[np.ndarray], np.ndarray] | None = None,
    gap: float | None = None,
) -> None:
    """The same faults injected into the direct HiGHS call of the decomposed path."""
    from optmodels.assignment import decomposed

    real = decomposed._highs_solve

    def fake(*args, **kw):  # type: ignore[no-untyped-def]
        status, x, obj, g, text, t = real(*args, **kw)
        x = x if point is None else point(x)
        return status, x, obj * (1 + objective), g if gap is None else gap, text, t

    monkeypatch.setattr(decomposed, "_highs_solve", fake)


@pytest.mark.parametrize("model", ["cvxpy", "decomposed"])
def test_milp_answer_is_rechecked(monkeypatch: pytest.MonkeyPatch, model: str) -> None:
    """The MILP's point is re-checked in NumPy: honest solves have residuals ≤ 1e-9 (exact
    0/1 values; objective = recomputed score to round-off); a solver objective off by
    1e-5 (relative, between VERIFY_TOL and REJECT_TOL) is OPTIMAL_INACCURATE, off by 1e-2
    an ERROR; a point that is not a hypothesis (an object in two blocks, a fractional
    value) is refused, never returned as a solution."""
    d = case(np.random.default_rng(7), 4, 4, rho=0.3)
    if model == "decomposed":  # the component goes to HiGHS (not the small enumeration)
        from optmodels.assignment import decomposed

        monkeypatch.setattr(decomposed, "ENUMERATE_OBJECTS", 0)
    honest = asg.solve(d, model=model)
    perturb = _perturbed if model == "cvxpy" else _perturbed_direct
    assert (
        model == "cvxpy" or honest.info["contended_components"] == 1 == honest.info["components"]
    )  # the whole scene is the one HiGHS model
    assert honest.status is Status.OPTIMAL
    assert set(honest.residuals) >= {
        "integrality",
        "exact_cover",
        "one_source",
        "block_capacity",
        "objective",
    }
    assert honest.max_residual <= 1e-9
    rel = abs(honest.log_score)
    assert rel > 1.0  # so the relative objective residual is the perturbation itself
    with monkeypatch.context() as m:
        perturb(m, objective=10 * VERIFY_TOL)
        s = asg.solve(d, model=model)
        assert s.status is Status.OPTIMAL_INACCURATE
        assert s.residuals["objective"] == pytest.approx(10 * VERIFY_TOL, rel=1e-6)
        assert s.partition == honest.partition
    with monkeypatch.context() as m:
        perturb(m, objective=10 * REJECT_TOL)
        s = asg.solve(d, model=model)
        assert s.status is Status.ERROR and not s.ok and s.partition == []
        with pytest.raises(SolveError):
            s.require_ok()
    with monkeypatch.context() as m:
        perturb(m, point=lambda x: np.ones_like(x))  # every group and pair "on"
        s = asg.solve(d, model=model)
        assert s.status is Status.ERROR and "re-check failed" in s.message
        assert s.residuals["exact_cover"] >= 1.0
    with monkeypatch.context() as m:
        perturb(m, point=lambda x: np.where(x > 0.5, 1 - 1e-4, x))  # fractional
        s = asg.solve(d, model=model)
        assert s.status is Status.OPTIMAL_INACCURATE  # 1e-4: between the two tolerances
        assert s.residuals["integrality"] == pytest.approx(1e-4, rel=1e-6)
    with monkeypatch.context() as m:  # a solver that stopped at a 1e-3 relative MIP gap
        perturb(m, gap=1e-3)
        s = asg.solve(d, mip_gap=1e-2, model=model)
        assert s.status is Status.OPTIMAL_INACCURATE and "not proven optimal" in s.message
        assert s.mip_gap == pytest.approx(1e-3, rel=1e-12)


def test_linear_assignment_is_rechecked() -> None:
    """The linear assignment's total gain plus Σ ln(1 − P_D) equals the recomputed score
    (13) to round-off; the residual is recorded."""
    d = case(np.random.default_rng(8), 10, 12, spread=20.0, max_group_size=1)
    la = asg.linear_assignment(d)
    assert la.status is Status.OPTIMAL and la.residuals["objective"] <= 1e-12


def test_highs_banner_does_not_reach_stdout() -> None:
    """HiGHS prints "Running HiGHS ..." from C on fd 1 when its first object is created;
    a solve in a fresh interpreter, with fd 1 captured by the parent, writes nothing to
    stdout (only the line the child prints itself)."""
    import subprocess
    import sys

    code = (
        "from optmodels import assignment as asg\n"
        "import numpy as np\n"
        "d = asg.AssignmentData([[0.0, 0.0]], [np.eye(2)], [[0.1, 0.0]], np.eye(2),"
        " 100.0, 0.9, 0.1)\n"
        "s = asg.solve(d); s2 = asg.solve(d)\n"
        "print('STATUS', s.status.value, s2.status.value)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.splitlines() == ["STATUS optimal optimal"], out.stdout
    assert "HiGHS" not in out.stdout


def test_space_objects_bad_arguments() -> None:
    """The scenario generator's scalars through the core checks."""
    from optmodels.scenarios.space_objects import space_objects

    for kw in (
        {"q": 2.5},
        {"q": 0},
        {"sessions": np.nan},
        {"separation": -1.0},
        {"resolution": np.inf},
        {"sigma": 0.0},
        {"pd": 1.5},
        {"clutter": -1.0},
        {"dt": None},
        {"window": "big"},
    ):
        with pytest.raises(ProblemError, match=f"space_objects {next(iter(kw))}"):
            space_objects(0, **kw)
    with pytest.raises(ProblemError, match="seed"):
        space_objects("seed")
    sc = space_objects(1, q=3, sessions=2, clutter=0.0, pd=1.0)
    # all detected, no clutter: every session has one measurement per resolved block
    for s in sc.sessions:
        assert all(len(t) >= 1 for t in s.truth) and sum(len(t) for t in s.truth) == 3
