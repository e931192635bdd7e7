"""Dependent linear trajectories (paper 002): generic constrained LSQ vs the closed forms,
Ψ against the design matrix and Monte Carlo, the printed (16)-(20), η, the family test."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from optmodels import ProblemError, SolveError, Status, scenarios
from optmodels import trajectories as tr
from optmodels.backends.cvxpy_backend import available_solvers

SOLVERS = [s for s in ("CLARABEL", "OSQP", "SCS") if s in available_solvers()]
FAMILIES = ["diverging", "parallel", "independent", "custom"]


def _family(name: str, q: int) -> tr.Family | str:
    if name == "custom":  # objects 0-2 share a start, 3-4 share a velocity
        return tr.Family.custom(q, shared_start=[[0, 1, 2]], shared_velocity=[[3, 4]])
    return name


def random_data(seed: int, *, q: int = 5, d: int | None = None, weighted: bool = False,
                epoch: float = 0.0) -> tr.TrajectoryData:
    """Unequal N_j (3..40) and unequal, unsorted times over 0..100 s."""
    rng = np.random.default_rng(seed)
    times = [rng.permutation(rng.uniform(0, 100, rng.integers(3, 41))) for _ in range(q)]
    shape = (q,) if d is None else (q, d)
    y0, v = rng.normal(0, 10, shape), rng.normal(0, 2, shape)
    vals = []
    for j, t in enumerate(times):
        clean = y0[j] + np.multiply.outer(t, v[j]) if d else y0[j] + v[j] * t
        vals.append(clean + rng.normal(0, 1, clean.shape))
    s2 = [rng.uniform(0.3, 3.0, t.size) for t in times] if weighted else 1.0
    return tr.TrajectoryData(times, vals, s2, epoch=epoch)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


# --------------------------------------------------------------------------- (a) generic vs closed
@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("formulation", ["constrained", "reduced"])
@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize(("d", "weighted"), [(None, False), (None, True), (2, True)])
def test_closed_form_equals_generic_solve(solver: str, formulation: str, family: str,
                                          d: int | None, weighted: bool) -> None:
    data = random_data(11, d=d, weighted=weighted)
    fam = _family(family, 5)
    g = tr.solve(data, fam, solver=solver, formulation=formulation).require_ok()
    cf = tr.closed_form(data, fam)
    # The QP has equalities only; with SOLVER_DEFAULTS (Clarabel 1e-12, SCS 1e-9, OSQP polishing)
    # every solver lands on the KKT solution to ~1e-11 relative (measured ≤ 2e-11 over
    # these instances); 1e-9 is the bar.
    assert rel_err(g.theta, cf.theta) < 1e-9
    assert g.theta.shape == cf.theta.shape == (cf.family.n_params, *(() if d is None else (d,)))
    assert abs(g.objective - cf.objective) <= 1e-9 * cf.objective
    # (b) both re-checked against the original form: equalities and the normal equations
    assert cf.max_residual < 1e-10
    assert g.max_residual < 1e-8


def test_solution_fields_follow_the_papers_ordering() -> None:
    data = random_data(3, q=3)
    div = tr.closed_form(data, "diverging")
    par = tr.closed_form(data, "parallel")
    # diverging θ = (y0, V1..VQ); parallel θ = (y01..y0Q, V)
    np.testing.assert_array_equal(div.start, np.full(3, div.theta[0]))
    np.testing.assert_array_equal(div.velocity, div.theta[1:])
    np.testing.assert_array_equal(par.start, par.theta[:3])
    np.testing.assert_array_equal(par.velocity, np.full(3, par.theta[3]))
    assert div.covariance.shape == par.covariance.shape == (4, 4)
    assert div.dof == data.n_measurements - 4
    # objective is Σ w r², recomputed from the lines
    r = [y - div.start[j] - div.velocity[j] * t
         for j, (t, y) in enumerate(zip(data.times, data.values, strict=True))]
    assert div.objective == pytest.approx(sum(np.sum(x**2) for x in r), rel=1e-12)


def test_vector_values_are_independent_coordinates() -> None:
    data = random_data(5, d=3, weighted=True)
    sol = tr.closed_form(data, "diverging")
    assert sol.covariance.shape == (3, 6, 6)
    for k in range(3):
        one = tr.TrajectoryData(data.times, [np.asarray(v)[:, k] for v in data.values],
                                [np.asarray(s)[:] for s in data.sigma2])
        sk = tr.closed_form(one, "diverging")
        np.testing.assert_allclose(sol.theta[:, k], sk.theta, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(sol.covariance[k], sk.covariance, rtol=1e-12)


# --------------------------------------------------------------------------- design matrix, Ψ
def test_design_matrix_is_the_printed_5_and_11() -> None:
    data = random_data(7, q=3)
    t = [np.asarray(x) for x in data.times]
    n = data.n_measurements
    # (5): first row of Aᵀ all ones; row 1 + j holds t_j in object j's block
    a5 = np.zeros((4, n))
    a5[0] = 1.0
    # (11): row j ones in object j's block; last row all times
    a11 = np.zeros((4, n))
    a11[3] = np.concatenate(t)
    pos = 0
    for j, tj in enumerate(t):
        a5[1 + j, pos:pos + tj.size] = tj
        a11[j, pos:pos + tj.size] = 1.0
        pos += tj.size
    np.testing.assert_array_equal(tr.design_matrix(data, "diverging").toarray().T, a5)
    np.testing.assert_array_equal(tr.design_matrix(data, "parallel").toarray().T, a11)


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("weighted", [False, True])
def test_closed_form_covariance_equals_design_matrix_psi(family: str, weighted: bool) -> None:
    data = random_data(21, weighted=weighted)
    fam = _family(family, 5)
    a = tr.design_matrix(data, fam).toarray()
    w = data.w[:, 0]
    psi = np.linalg.inv(a.T @ (w[:, None] * a))  # (14), dense and independent
    np.testing.assert_allclose(tr.covariance(data, fam), psi, rtol=1e-9, atol=0)
    np.testing.assert_allclose(tr.closed_form(data, fam).covariance, psi, rtol=1e-9, atol=0)


def test_psi_scales_with_sigma2() -> None:
    base = random_data(2)
    data = tr.TrajectoryData(base.times, base.values, 4.0)
    a = tr.design_matrix(data, "diverging").toarray()
    np.testing.assert_allclose(tr.covariance(data, "diverging"), 4.0 * np.linalg.inv(a.T @ a),
                               rtol=1e-10)


def test_psi_matches_monte_carlo() -> None:
    """Sample covariance of θ̂ over 4000 runs against Ψ (14), for both families, at unequal
    N_j and times. Each element of a sample covariance of n Gaussian vectors has standard
    error sqrt((Ψ_aa Ψ_bb + Ψ_ab²)/(n-1)); a 4.5 se bound on each of the ≤ 25 elements
    keeps the family-wise false-failure rate below 2e-4."""
    runs = 4000
    rng = np.random.default_rng(2024)
    times = [np.sort(rng.uniform(5, 60, k)) for k in (6, 11, 8, 15)]
    for family, start, vel in (("diverging", np.zeros(4), np.array([-2.0, -0.5, 1.0, 3.0])),
                               ("parallel", np.array([0.0, 5.0, 9.0, 20.0]), np.full(4, 0.7))):
        sigma2 = 2.5
        psi = None
        est = np.empty((runs, 5))
        for k in range(runs):
            vals = [start[j] + vel[j] * t + rng.normal(0, np.sqrt(sigma2), t.size)
                    for j, t in enumerate(times)]
            sol = tr.closed_form(tr.TrajectoryData(times, vals, sigma2), family)
            est[k] = sol.theta
            psi = sol.covariance if psi is None else psi
        assert psi is not None
        truth = np.r_[start[0], vel] if family == "diverging" else np.r_[start, vel[0]]
        se_mean = np.sqrt(np.diag(psi) / runs)
        assert np.all(np.abs(est.mean(axis=0) - truth) < 4.5 * se_mean)
        s = np.cov(est.T)
        se = np.sqrt((np.outer(np.diag(psi), np.diag(psi)) + psi**2) / (runs - 1))
        assert np.all(np.abs(s - psi) < 4.5 * se), family


# --------------------------------------------------------------------------- (8)-(13) as printed
def _printed_sums(data: tr.TrajectoryData) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(np.asarray(t, float), np.asarray(y, float))
            for t, y in zip(data.times, data.values, strict=True)]


def test_printed_8_9_diverging_is_right() -> None:
    """(8)-(9) typed from the paper, term by term, against the generic constrained solve."""
    data = random_data(31, q=4)
    obj = _printed_sums(data)
    a = [np.sum(y * t) for t, y in obj]          # A_j = Σ y t
    b = [np.sum(t) for t, _ in obj]              # B_j = Σ t
    c = [np.sum(t * t) for t, _ in obj]          # C_j = Σ t²
    d = sum(np.sum(y) for _, y in obj)           # D = ΣΣ y
    e = sum(t.size for t, _ in obj)              # E = Σ N_j
    a_c = sum(np.sum(a[j] / c[j] * t) for j, (t, _) in enumerate(obj))   # A_C
    b_c = sum(np.sum(b[j] / c[j] * t) for j, (t, _) in enumerate(obj))   # B_C
    y0 = (d - a_c) / (e - b_c)
    v = [(a[j] - y0 * b[j]) / c[j] for j in range(4)]
    g = tr.solve(data, "diverging", solver=SOLVERS[0]).require_ok()
    assert rel_err(np.r_[y0, v], g.theta) < 1e-9


@pytest.mark.parametrize("printed_e", [True, False])
def test_printed_12_13_parallel_E_erratum(printed_e: bool) -> None:
    """(12)-(13) typed from the paper. With E = ΣΣ t as printed the estimate is wrong;
    with E = ΣΣ t² it is the generic constrained optimum."""
    data = random_data(32, q=4)
    obj = _printed_sums(data)
    d = sum(np.sum(y * t) for t, y in obj)       # D = ΣΣ y t
    a = [np.sum(y) for _, y in obj]              # A_j = Σ y
    b = [np.sum(t) for t, _ in obj]              # B_j = Σ t
    n = [t.size for t, _ in obj]
    a_n = sum(np.sum(a[j] * t) / n[j] for j, (t, _) in enumerate(obj))   # A_N
    b_n = sum(np.sum(b[j] * t) / n[j] for j, (t, _) in enumerate(obj))   # B_N
    e = sum(np.sum(t if printed_e else t * t) for t, _ in obj)
    v = (d - a_n) / (e - b_n)
    y0 = [(a[j] - v * b[j]) / n[j] for j in range(4)]
    g = tr.solve(data, "parallel", solver=SOLVERS[0]).require_ok()
    err = rel_err(np.r_[y0, v], g.theta)
    if printed_e:
        assert err > 1e-2
        # optmodels' printed=True reproduces it, and its objective is worse
        bad = tr.closed_form(data, "parallel", printed=True)
        assert rel_err(bad.theta, np.r_[y0, v]) < 1e-12
        assert bad.objective > g.objective * (1 + 1e-6)
        assert bad.residuals["stationarity"] > 1e-3
    else:
        assert err < 1e-9


# --------------------------------------------------------------------------- (16)-(20)
#: Elements of (18) and (20) that are misprinted (0-based (row, col)).
WRONG = {"diverging": {(1, 0), (2, 0), (1, 2), (2, 1)}, "parallel": {(0, 1)}}


@pytest.mark.parametrize("family", ["diverging", "parallel"])
@pytest.mark.parametrize("n", [2, 3, 5, 10, 40])
def test_paper_covariance_18_20_against_design_matrix(family: str, n: int) -> None:
    dt, sigma2 = 0.7, 3.0
    sc = scenarios.equally_spaced(0, n=n, q=2, dt=dt, family=family, sigma2=sigma2)
    psi = tr.covariance(sc.data(), family)  # σ²(AᵀA)⁻¹ from the generic design matrix
    right = tr.paper_covariance(family, n, dt, sigma2)
    np.testing.assert_allclose(right, psi, rtol=1e-10, atol=1e-14 * np.max(np.abs(psi)))
    printed = tr.paper_covariance(family, n, dt, sigma2, printed=True)
    wrong = {(i, j) for i in range(3) for j in range(3)
             if not np.isclose(printed[i, j], psi[i, j], rtol=1e-10, atol=0)}
    # (20) (1,2) = 3/(ΔT N(N+1)) coincides with 3(N-1)/(2N(N+1)) when ΔT = 2/(N-1)
    assert wrong == WRONG[family]


def test_paper_16_and_19_normal_matrices() -> None:
    """The matrices printed before inversion in (16)/(18) and (19)/(20), with C and D of
    (17), are AᵀA of the generic design matrix."""
    n, dt = 7, 0.5
    c = dt * n * (n - 1) / 2
    d = dt**2 * n * (n - 1) * (2 * n - 1) / 6
    sc = scenarios.equally_spaced(0, n=n, q=2, dt=dt)
    a1 = tr.design_matrix(sc.data(), "diverging").toarray()
    a2 = tr.design_matrix(sc.data(), "parallel").toarray()
    np.testing.assert_allclose(a1.T @ a1, [[2 * n, c, c], [c, d, 0], [c, 0, d]], rtol=1e-12)
    np.testing.assert_allclose(a2.T @ a2, [[n, 0, c], [0, n, c], [c, c, 2 * d]], rtol=1e-12)


def test_covariance_depends_on_time_origin() -> None:
    """Erratum before (17): shifting the clock changes Ψ (and, for the diverging family,
    the hypothesis itself: the common start is the instant t = 0)."""
    base = random_data(8, q=3)
    shifted = tr.TrajectoryData(base.times, base.values, epoch=-10.0)
    for family in ("diverging", "parallel", "independent"):
        p0, p1 = tr.covariance(base, family), tr.covariance(shifted, family)
        assert rel_err(p1, p0) > 1e-2, family
    # what survives a shift: velocity variances of the parallel and independent families
    q = 3
    assert tr.covariance(base, "parallel")[q, q] == pytest.approx(
        tr.covariance(shifted, "parallel")[q, q], rel=1e-10)
    # and the diverging fit itself moves (a different constraint)
    d0, d1 = tr.closed_form(base, "diverging"), tr.closed_form(shifted, "diverging")
    assert abs(d0.objective - d1.objective) > 1e-3 * d0.objective


def test_independent_variances_of_the_introduction() -> None:
    for n in (2, 3, 10, 100):
        dt, sigma2 = 0.25, 2.0
        data = tr.TrajectoryData([dt * np.arange(n)], [np.zeros(n)], sigma2)
        psi = tr.covariance(data, "independent")
        v0, vv = tr.independent_variances(n, dt, sigma2)
        assert psi[0, 0] == pytest.approx(v0, rel=1e-10)
        assert psi[1, 1] == pytest.approx(vv, rel=1e-10)


# --------------------------------------------------------------------------- η, η0
@pytest.mark.parametrize("q", [2, 3, 7])
@pytest.mark.parametrize("n", [2, 3, 10, 200])
def test_eta_against_psi_ratios(q: int, n: int) -> None:
    for family, shared, unique in (("diverging", "start", "velocity"),
                                   ("parallel", "velocity", "start")):
        sc = scenarios.equally_spaced(1, n=n, q=q, dt=0.3, family=family)
        r = tr.variance_ratios(sc.data(), family)
        np.testing.assert_allclose(r[shared], tr.eta0(q), rtol=1e-10)
        np.testing.assert_allclose(r[unique], tr.eta(n, q), rtol=1e-10)
    if q == 2:
        # the conclusions' printed η for two objects
        assert tr.eta(n, 2) == pytest.approx((5 * n - 1) / (4 * (2 * n - 1)), rel=1e-14)


def test_eta_limits_quoted_in_the_conclusions() -> None:
    assert tr.eta(3) == pytest.approx(0.7, rel=1e-14)
    assert tr.eta(10**7) == pytest.approx(0.625, abs=1e-7)
    assert tr.eta0(2) == 0.5
    # η is a ratio of variances: the RMS improves by √η only
    assert np.sqrt(tr.eta(10**7)) == pytest.approx(0.79, abs=5e-3)


def test_shared_parameter_gain_is_that_of_averaging() -> None:
    """η0 = 1/Q equals averaging the Q independent estimates of the shared parameter."""
    sc = scenarios.equally_spaced(0, n=12, q=4, family="diverging")
    ind = tr.covariance(sc.data(), "independent")
    avg = np.full(4, 0.25) @ ind[:4, :4] @ np.full(4, 0.25)
    assert tr.covariance(sc.data(), "diverging")[0, 0] == pytest.approx(avg, rel=1e-10)


# --------------------------------------------------------------------------- model choice
@pytest.mark.parametrize("sigma2_mode", ["known", "estimated"])
def test_family_test_size_by_monte_carlo(sigma2_mode: str) -> None:
    """Under a true diverging family the test rejects at rate 1 − level. 2000 runs at
    level 0.95: binomial se = sqrt(0.05·0.95/2000) = 0.0049; accept |rate − 0.05| < 0.022
    (4.5 se)."""
    rng = np.random.default_rng(99)
    runs = 2000
    times = [np.sort(rng.uniform(1, 30, k)) for k in (5, 9, 7)]
    vel = np.array([-1.0, 0.5, 2.0])
    rej = 0
    for _ in range(runs):
        vals = [vel[j] * t + rng.normal(0, 1, t.size) for j, t in enumerate(times)]
        res = tr.family_test(tr.TrajectoryData(times, vals), "diverging", level=0.95,
                             sigma2=sigma2_mode)
        rej += res.reject
    assert abs(rej / runs - 0.05) < 0.022


def test_family_test_statistic_distribution_and_power() -> None:
    sc = scenarios.launcher_release(5, family="diverging")
    data = sc.data()
    res = tr.family_test(data, "diverging")
    assert res.dof == data.n_objects - 1
    lam = (tr.closed_form(data, "diverging").objective
           - tr.closed_form(data, "independent").objective)
    assert res.statistic == pytest.approx(lam, rel=1e-12)
    assert res.p_value == pytest.approx(stats.chi2.sf(lam, res.dof), rel=1e-12)
    # the parallel hypothesis on diverging objects is rejected outright
    assert tr.family_test(data, "parallel").reject
    assert tr.family_test(scenarios.launcher_release(5, family="parallel").data(),
                          "diverging").reject


# --------------------------------------------------------------------------- invariances
@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10**6), family=st.sampled_from(["diverging", "parallel"]))
def test_permutation_of_objects(seed: int, family: str) -> None:
    data = random_data(seed, q=4)
    perm = np.random.default_rng(seed).permutation(4)
    pd = tr.TrajectoryData([data.times[k] for k in perm], [data.values[k] for k in perm])
    a, b = tr.closed_form(data, family), tr.closed_form(pd, family)
    np.testing.assert_allclose(b.start, a.start[perm], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.velocity, a.velocity[perm], rtol=1e-9, atol=1e-9)
    assert b.objective == pytest.approx(a.objective, rel=1e-9)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10**6), scale=st.floats(0.01, 100), shift=st.floats(-50, 50))
def test_affine_change_of_units(seed: int, scale: float, shift: float) -> None:
    """y → c·y + s multiplies θ by c and adds s to each start; Ψ (in units of σ²) and
    the χ² objective (with σ² scaled by c²) are unchanged."""
    data = random_data(seed, q=3)
    new = tr.TrajectoryData(data.times, [scale * np.asarray(v) + shift for v in data.values],
                            scale**2)
    for family in ("diverging", "parallel"):
        a, b = tr.closed_form(data, family), tr.closed_form(new, family)
        np.testing.assert_allclose(b.start, scale * a.start + shift, rtol=1e-8, atol=1e-8 * scale)
        np.testing.assert_allclose(b.velocity, scale * a.velocity, rtol=1e-8, atol=1e-9 * scale)
        np.testing.assert_allclose(b.covariance, scale**2 * a.covariance, rtol=1e-9)
        assert b.objective == pytest.approx(a.objective, rel=1e-7)


def test_epoch_moves_the_common_start() -> None:
    """With the clock read from epoch T, the diverging fit is the fit with common start at
    T: the same as shifting the times by hand."""
    data = random_data(4, q=3)
    by_epoch = tr.TrajectoryData(data.times, data.values, epoch=20.0)
    by_hand = tr.TrajectoryData([np.asarray(t) - 20.0 for t in data.times], data.values)
    a, b = tr.closed_form(by_epoch, "diverging"), tr.closed_form(by_hand, "diverging")
    np.testing.assert_allclose(a.theta, b.theta, rtol=1e-12)


# --------------------------------------------------------------------------- failures, bad input
def test_solver_failure_is_not_a_solution() -> None:
    data = random_data(1, q=3)
    sol = tr.solve(data, "diverging", solver="OSQP", max_iter=1, polishing=False)
    assert sol.status is Status.ITERATION_LIMIT
    assert np.all(np.isnan(sol.theta))
    with pytest.raises(SolveError):
        sol.require_ok()
    if "SCS" in SOLVERS:
        # SCS stops after one iteration and calls it "optimal_inaccurate": the
        # verification (normal equations) rejects it
        bad = tr.solve(data, "diverging", solver="SCS", max_iters=1)
        assert bad.status is Status.ERROR and "verification failed" in bad.message
        assert np.all(np.isnan(bad.theta))


@pytest.mark.parametrize(("times", "values", "sigma2", "match"), [
    ([[0.0, 1.0], [2.0, 2.0, 2.0]], [[0.0, 1.0], [1.0, 2.0, 3.0]], 1.0, "fewer than 2 distinct"),
    ([[0.0, 1.0], []], [[0.0, 1.0], []], 1.0, "no measurements"),
    ([[0.0, 1.0, 2.0]], [[0.0, np.nan, 1.0]], 1.0, "NaN"),
    ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], -1.0, "positive"),
    ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [[1.0, 0.0, 1.0]], "positive"),
    ([[0.0, 1.0, 2.0]], [[0.0, 1.0]], 1.0, "2 values for 3 times"),
    ([], [], 1.0, "no objects"),
    ([[0.0, 1.0], [0.0, 1.0]], [[0.0, 1.0]], 1.0, "1 objects"),
    ([[0.0, 1.0], [0.0, 1.0]], [[0.0, 1.0], [[0.0, 1.0], [1.0, 2.0]]], 1.0, "coordinates"),
    ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [[1.0, 1.0]], "does not match"),
])
def test_bad_input(times: list, values: list, sigma2: object, match: str) -> None:
    with pytest.raises(ProblemError, match=match):
        tr.TrajectoryData(times, values, sigma2)  # type: ignore[arg-type]


def test_bad_family_and_unidentifiable_data() -> None:
    data = random_data(0, q=3)
    with pytest.raises(ProblemError, match="family"):
        tr.closed_form(data, "converging")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="built for 4"):
        tr.closed_form(data, tr.Family.diverging(4))
    with pytest.raises(ProblemError, match="out of range"):
        tr.Family.custom(3, shared_start=[[0, 5]])
    with pytest.raises(ProblemError, match="groups 0 and 1"):
        tr.Family.custom(3, shared_velocity=[[0, 1], [1, 2]])
    with pytest.raises(ProblemError, match="no constraint"):
        tr.family_test(data, "independent")
    # two distinct times 1e-9 s apart, 1e6 s after the epoch: AᵀA is singular in floats
    far = tr.TrajectoryData([1e6 + np.array([0.0, 1e-9])] * 2, [[0.0, 1.0], [0.0, 2.0]])
    with pytest.raises(ProblemError, match="singular"):
        tr.covariance(far, "diverging")
    with pytest.raises(ProblemError, match="singular"):
        tr.solve(far, "diverging")
    with pytest.raises(ProblemError, match="formulation"):
        tr.solve(data, "diverging", formulation="dual")  # type: ignore[arg-type]
