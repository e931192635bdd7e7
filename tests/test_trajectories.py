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


def random_data(
    seed: int, *, q: int = 5, d: int | None = None, weighted: bool = False, epoch: float = 0.0
) -> tr.TrajectoryData:
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
def test_closed_form_equals_generic_solve(
    solver: str, formulation: str, family: str, d: int | None, weighted: bool
) -> None:
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
    r = [
        y - div.start[j] - div.velocity[j] * t
        for j, (t, y) in enumerate(zip(data.times, data.values, strict=True))
    ]
    assert div.objective == pytest.approx(sum(np.sum(x**2) for x in r), rel=1e-12)


def test_vector_values_are_independent_coordinates() -> None:
    data = random_data(5, d=3, weighted=True)
    sol = tr.closed_form(data, "diverging")
    assert sol.covariance.shape == (3, 6, 6)
    for k in range(3):
        one = tr.TrajectoryData(
            data.times,
            [np.asarray(v)[:, k] for v in data.values],
            [np.asarray(s)[:] for s in data.sigma2],
        )
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
        a5[1 + j, pos : pos + tj.size] = tj
        a11[j, pos : pos + tj.size] = 1.0
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
    np.testing.assert_allclose(
        tr.covariance(data, "diverging"), 4.0 * np.linalg.inv(a.T @ a), rtol=1e-10
    )


def test_psi_matches_monte_carlo() -> None:
    """Sample covariance of θ̂ over 4000 runs against Ψ (14), for both families, at unequal
    N_j and times. Each element of a sample covariance of n Gaussian vectors has standard
    error sqrt((Ψ_aa Ψ_bb + Ψ_ab²)/(n-1)); a 4.5 se bound on each of the ≤ 25 elements
    keeps the family-wise false-failure rate below 2e-4."""
    runs = 4000
    rng = np.random.default_rng(2024)
    times = [np.sort(rng.uniform(5, 60, k)) for k in (6, 11, 8, 15)]
    for family, start, vel in (
        ("diverging", np.zeros(4), np.array([-2.0, -0.5, 1.0, 3.0])),
        ("parallel", np.array([0.0, 5.0, 9.0, 20.0]), np.full(4, 0.7)),
    ):
        sigma2 = 2.5
        psi = None
        est = np.empty((runs, 5))
        for k in range(runs):
            vals = [
                start[j] + vel[j] * t + rng.normal(0, np.sqrt(sigma2), t.size)
                for j, t in enumerate(times)
            ]
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
    return [
        (np.asarray(t, float), np.asarray(y, float))
        for t, y in zip(data.times, data.values, strict=True)
    ]


def test_printed_8_9_diverging_is_right() -> None:
    """(8)-(9) typed from the paper, term by term, against the generic constrained solve."""
    data = random_data(31, q=4)
    obj = _printed_sums(data)
    a = [np.sum(y * t) for t, y in obj]  # A_j = Σ y t
    b = [np.sum(t) for t, _ in obj]  # B_j = Σ t
    c = [np.sum(t * t) for t, _ in obj]  # C_j = Σ t²
    d = sum(np.sum(y) for _, y in obj)  # D = ΣΣ y
    e = sum(t.size for t, _ in obj)  # E = Σ N_j
    a_c = sum(np.sum(a[j] / c[j] * t) for j, (t, _) in enumerate(obj))  # A_C
    b_c = sum(np.sum(b[j] / c[j] * t) for j, (t, _) in enumerate(obj))  # B_C
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
    d = sum(np.sum(y * t) for t, y in obj)  # D = ΣΣ y t
    a = [np.sum(y) for _, y in obj]  # A_j = Σ y
    b = [np.sum(t) for t, _ in obj]  # B_j = Σ t
    n = [t.size for t, _ in obj]
    a_n = sum(np.sum(a[j] * t) / n[j] for j, (t, _) in enumerate(obj))  # A_N
    b_n = sum(np.sum(b[j] * t) / n[j] for j, (t, _) in enumerate(obj))  # B_N
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
    wrong = {
        (i, j)
        for i in range(3)
        for j in range(3)
        if not np.isclose(printed[i, j], psi[i, j], rtol=1e-10, atol=0)
    }
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
        tr.covariance(shifted, "parallel")[q, q], rel=1e-10
    )
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
    for family, shared, unique in (
        ("diverging", "start", "velocity"),
        ("parallel", "velocity", "start"),
    ):
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
        res = tr.family_test(
            tr.TrajectoryData(times, vals), "diverging", level=0.95, sigma2=sigma2_mode
        )
        rej += res.reject
    assert abs(rej / runs - 0.05) < 0.022


def test_family_test_statistic_distribution_and_power() -> None:
    sc = scenarios.launcher_release(5, family="diverging")
    data = sc.data()
    res = tr.family_test(data, "diverging")
    assert res.dof == data.n_objects - 1
    lam = (
        tr.closed_form(data, "diverging").objective - tr.closed_form(data, "independent").objective
    )
    assert res.statistic == pytest.approx(lam, rel=1e-12)
    assert res.p_value == pytest.approx(stats.chi2.sf(lam, res.dof), rel=1e-12)
    # the parallel hypothesis on diverging objects is rejected outright
    assert tr.family_test(data, "parallel").reject
    assert tr.family_test(
        scenarios.launcher_release(5, family="parallel").data(), "diverging"
    ).reject


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
    new = tr.TrajectoryData(
        data.times, [scale * np.asarray(v) + shift for v in data.values], scale**2
    )
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


@pytest.mark.parametrize(
    ("times", "values", "sigma2", "match"),
    [
        (
            [[0.0, 1.0], [2.0, 2.0, 2.0]],
            [[0.0, 1.0], [1.0, 2.0, 3.0]],
            1.0,
            "fewer than 2 distinct",
        ),
        ([[0.0, 1.0], []], [[0.0, 1.0], []], 1.0, "no measurements"),
        ([[0.0, 1.0, 2.0]], [[0.0, np.nan, 1.0]], 1.0, "NaN"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], -1.0, "positive"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [[1.0, 0.0, 1.0]], "positive"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0]], 1.0, "2 values for 3 times"),
        ([], [], 1.0, "no objects"),
        ([[0.0, 1.0], [0.0, 1.0]], [[0.0, 1.0]], 1.0, "1 objects"),
        ([[0.0, 1.0], [0.0, 1.0]], [[0.0, 1.0], [[0.0, 1.0], [1.0, 2.0]]], 1.0, "coordinates"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [[1.0, 1.0]], "does not match"),
    ],
)
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


# --------------------------------------------------------------------------- issue 14: any input
#: POSIX-like clock offset (s). Times below lie on a 1/1024 s grid, so t + SHIFT is exact in
#: float64 (41 significant bits): the shifted data are the same numbers, and any difference
#: in the estimates is the package's own rounding.
SHIFT = 1.7e9


def grid_data(
    seed: int, *, q: int = 5, offset: float = 0.0, epoch: float = 0.0, d: int | None = None
) -> tr.TrajectoryData:
    rng = np.random.default_rng(seed)
    times = [np.round(rng.uniform(0, 100, rng.integers(3, 41)) * 1024) / 1024 for _ in range(q)]
    shape = (q,) if d is None else (q, d)
    y0, v = rng.normal(0, 10, shape), rng.normal(0, 2, shape)
    vals = [
        y0[j] + np.multiply.outer(t, v[j]) + rng.normal(0, 1, (t.size, *shape[1:]))
        for j, t in enumerate(times)
    ]
    return tr.TrajectoryData([t + offset for t in times], vals, 1.0, epoch=epoch)


METHODS = [("closed_form", None)] + [
    (s, f) for s in SOLVERS if s != "SCS" for f in ("constrained", "reduced")
]


def _fit(
    data: tr.TrajectoryData, fam: tr.Family | str, method: str, form: str | None
) -> tr.TrajectorySolution:
    if method == "closed_form":
        return tr.closed_form(data, fam)
    return tr.solve(data, fam, solver=method, formulation=form)  # type: ignore[arg-type]


@pytest.mark.parametrize(("method", "form"), METHODS)
@pytest.mark.parametrize("family", [*FAMILIES, "custom2"])
def test_shifted_clock_gives_the_same_estimates(family: str, method: str, form: str | None) -> None:
    """Issue 14: the same data on a clock shifted by 1.7e9 s (times and epoch) give the same
    θ and Ψ to 1e-9 relative. Before: closed_form(parallel) returned velocity 3.18 against
    2.50 (optimal), solve refused the data as singular."""
    fam: tr.Family | str = (
        tr.Family.custom(5, shared_start=[[0, 1], [3, 4]], shared_velocity=[[0, 1, 2]])
        if family == "custom2"
        else _family(family, 5)
    )
    a = grid_data(7, epoch=12.5)
    b = grid_data(7, offset=SHIFT, epoch=12.5 + SHIFT)
    sa, sb = _fit(a, fam, method, form).require_ok(), _fit(b, fam, method, form).require_ok()
    assert sa.status is sb.status is Status.OPTIMAL
    assert rel_err(sb.velocity, sa.velocity) < 1e-9
    assert rel_err(sb.start, sa.start) < 1e-9
    np.testing.assert_allclose(sb.covariance, sa.covariance, rtol=1e-9, atol=0)
    assert sb.objective == pytest.approx(sa.objective, rel=1e-9)
    if family != "independent" and method == "closed_form":
        ta, tb = tr.family_test(a, fam), tr.family_test(b, fam)
        assert tb.statistic == pytest.approx(ta.statistic, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize(("method", "form"), METHODS)
@pytest.mark.parametrize("family", ["parallel", "independent", "shared_velocity"])
def test_velocities_do_not_depend_on_the_epoch(family: str, method: str, form: str | None) -> None:
    """Without a shared start the velocities are origin-free: data at t ≈ 1.7e9 s with
    epoch 0 (POSIX time, the CLI default) give the velocities of the same data at t ≈ 0, and
    the starts move by −V·1.7e9 with Ψ transformed accordingly (Var(y0) ≈ T²Var(V))."""
    fam = (
        tr.Family.custom(5, shared_velocity=[[0, 1, 2], [3, 4]])
        if family == "shared_velocity"
        else family
    )
    a, b = grid_data(3), grid_data(3, offset=SHIFT)
    sa, sb = _fit(a, fam, method, form), _fit(b, fam, method, form)
    assert sa.status is sb.status is Status.OPTIMAL
    assert rel_err(sb.velocity, sa.velocity) < 1e-9
    assert rel_err(sb.start, sa.start - sa.velocity * SHIFT) < 1e-9
    # Ψ of (y0_j, V_j) moves with the Jacobian [[1, -T], [0, 1]]
    f = tr.resolve_family(fam, 5)
    jac = np.eye(f.n_params)
    for g in f.start_groups:
        jac[f.start_index[g[0]], f.velocity_index[g[0]]] = -SHIFT
    np.testing.assert_allclose(sb.covariance, jac @ sa.covariance @ jac.T, rtol=1e-8, atol=0)
    assert np.all(np.isfinite(sb.std)) and np.all(sb.std > 0)


def _exact_normal_equations(data: tr.TrajectoryData, fam: tr.Family | str) -> np.ndarray:
    """θ from the normal equations (3) in exact rational arithmetic (the float inputs are
    exact rationals; the columns t − epoch are formed exactly)."""
    from fractions import Fraction as Fr

    f = tr.resolve_family(fam, data.n_objects)
    r = f.n_params
    rows = []
    for i in range(data.n_measurements):
        row = [Fr(0)] * r
        j = data.obj[i]
        row[f.start_index[j]] += 1
        row[f.velocity_index[j]] += Fr(float(data.raw_t[i])) - Fr(data.epoch)
        rows.append(row)
    y = [Fr(float(v)) for v in data.y[:, 0]]
    m = [[sum(x[a] * x[b] for x in rows) for b in range(r)] for a in range(r)]
    rhs = [sum(x[a] * yi for x, yi in zip(rows, y, strict=True)) for a in range(r)]
    for c in range(r):  # Gauss-Jordan, exact
        piv = next(k for k in range(c, r) if m[k][c] != 0)
        m[c], m[piv], rhs[c], rhs[piv] = m[piv], m[c], rhs[piv], rhs[c]
        for k in range(r):
            if k != c and m[k][c] != 0:
                fac = m[k][c] / m[c][c]
                m[k] = [m[k][i] - fac * m[c][i] for i in range(r)]
                rhs[k] -= fac * rhs[c]
    return np.array([float(rhs[c] / m[c][c]) for c in range(r)])


@pytest.mark.parametrize("epoch", [0.0, SHIFT - 3600.0, -1e12])
@pytest.mark.parametrize("family", ["diverging", "custom"])
def test_shared_start_far_from_the_data_against_exact_arithmetic(family: str, epoch: float) -> None:
    """A shared start at an epoch far from the data (the lines meet there: a different,
    rigid hypothesis) is computed to ~1e-16 (measured ≤ 8e-16) against exact rationals;
    1e-10 leaves room for other BLAS. Before: 2-5 sigma off with status optimal."""
    data = grid_data(5, q=5, offset=SHIFT, epoch=epoch)
    fam = _family(family, 5)
    exact = _exact_normal_equations(data, fam)
    cf = tr.closed_form(data, fam)
    assert cf.ok
    assert np.max(np.abs(cf.theta - exact) / np.abs(exact)) < 1e-10
    for solver in SOLVERS[:2]:
        g = tr.solve(data, fam, solver=solver)
        if g.ok:
            # the re-check is the exact distance to the optimum, relative to max(|θ|, σ):
            # an OK status must mean what it says
            ns = len(g.family.start_groups)
            size = np.r_[
                np.full(ns, np.max(np.abs(exact[:ns]))),
                np.full(exact.size - ns, np.max(np.abs(exact[ns:]))),
            ]
            err = float(np.max(np.abs(g.theta - exact) / np.maximum(size, cf.std)))
            limit = 1e-6 if g.status is Status.OPTIMAL else 1e-3
            assert err < limit, (solver, g.status, err)
            # above its rounding floor (~cond·eps, measured ≤ 1e-11 here) the stationarity
            # is that distance
            if err > 1e-9:
                assert g.residuals["stationarity"] == pytest.approx(err, rel=0.05)
            else:
                assert g.residuals["stationarity"] < 1e-9


@pytest.mark.parametrize("offset", [1e10, 1e12])
def test_nan_std_never_with_an_ok_status(offset: float) -> None:
    """Before: at t ≈ 1e10 s the closed form's std was NaN with status optimal. Now the
    velocities equal those of the unshifted data (1e-9; the integer times shift exactly)
    and the standard deviations are finite, positive and transformed correctly."""
    rng = np.random.default_rng(0)
    t = np.arange(100.0)
    vals = [10 + 2.0 * t + rng.normal(0, 1, 100), 10 + 3.0 * t + rng.normal(0, 1, 100)]
    ref = tr.closed_form(tr.TrajectoryData([t, t], vals), "independent")
    for family in ("diverging", "parallel", "independent"):
        for method in ("closed_form", SOLVERS[0]):
            data = tr.TrajectoryData([t + offset, t + offset], vals)
            sol = _fit(data, family, method, "constrained")
            if sol.ok:
                assert np.all(np.isfinite(sol.std)) and np.all(sol.std > 0)
            if family == "independent":
                # at 1e12 s float64 resolves a 29 s spread to eps·1e12/29 = 7.7e-6 only
                assert sol.status is (
                    Status.OPTIMAL if offset < 1e11 else Status.OPTIMAL_INACCURATE
                )
                assert rel_err(sol.velocity, ref.velocity) < 1e-9
                # the velocities' σ are origin-free; the starts' are the extrapolation's
                np.testing.assert_allclose(sol.std[2:], ref.std[2:], rtol=1e-9)
                np.testing.assert_allclose(sol.std[:2], ref.std[2:] * offset, rtol=1e-6)


@pytest.mark.parametrize("method", ["closed_form", "CLARABEL"])
def test_epoch_too_far_is_downgraded_then_refused(method: str) -> None:
    """The start at an epoch 1e14 s from the data is an extrapolation whose float64 rounding
    moves the line at the data by eps·|V|·1e14·√N ≈ 0.4 σ: OPTIMAL_INACCURATE, velocities
    still right; at 1e16 s (≈ 40 σ) the epoch is refused."""
    base = grid_data(2, q=3)
    ref = tr.closed_form(base, "parallel")
    far = tr.TrajectoryData(base.times, base.values, epoch=-1e14)
    sol = _fit(far, "parallel", method, "constrained")
    assert sol.status is Status.OPTIMAL_INACCURATE
    assert "far from the data" in sol.message
    assert 1e-2 < sol.info["extrapolation"] < 1.0
    assert rel_err(sol.velocity, ref.velocity) < 1e-9
    with pytest.raises(ProblemError, match="epoch"):
        _fit(
            tr.TrajectoryData(base.times, base.values, epoch=-1e16),
            "parallel",
            method,
            "constrained",
        )


def test_times_unresolved_by_float64_are_downgraded_or_refused() -> None:
    """eps·|t|/std(t): 10 times 0.01 s apart at 1.7e9 s are resolved to 1.3e-5 only
    (OPTIMAL_INACCURATE, velocity within that of the exact answer), 1e-6 s apart not at
    all (ProblemError)."""
    t = np.arange(10.0)
    vals = [1.0 + 2.0 * t * 0.01, 3.0 - t * 0.01]
    coarse = tr.TrajectoryData([SHIFT + 0.01 * t] * 2, vals, epoch=SHIFT)
    sol = tr.closed_form(coarse, "independent")
    assert sol.status is Status.OPTIMAL_INACCURATE
    assert 1e-6 < sol.info["time_resolution"] < 1e-3
    # noise-free lines: the exact velocities are 2 and -1 (up to the times' rounding)
    assert rel_err(sol.velocity, np.array([2.0, -1.0])) < 10 * sol.info["time_resolution"]
    with pytest.raises(ProblemError, match="singular"):
        tr.closed_form(tr.TrajectoryData([SHIFT + 1e-6 * t] * 2, vals), "independent")


def test_closed_form_recheck_measures_the_distance_to_the_optimum() -> None:
    """The closed form ends in a re-check: the misprinted (13) gives status ERROR (numbers
    kept, on request), and its stationarity is exactly the relative distance to the true
    optimum, max |θ_printed − θ| / max(|θ| of its kind, σ) (the quadratic's Newton step is
    exact; 1e-6 relative covers rounding)."""
    data = random_data(32, q=4)
    good = tr.closed_form(data, "parallel")
    bad = tr.closed_form(data, "parallel", printed=True)
    assert good.status is Status.OPTIMAL and good.residuals["stationarity"] < 1e-12
    assert bad.status is Status.ERROR and not bad.ok
    size = np.r_[np.full(4, np.max(np.abs(bad.theta[:4]))), abs(bad.theta[4])]
    expect = float(np.max(np.abs(bad.theta - good.theta) / np.maximum(size, good.std)))
    assert bad.residuals["stationarity"] == pytest.approx(expect, rel=1e-6)
    with pytest.raises(SolveError):
        bad.require_ok()


def test_family_test_on_noise_free_data() -> None:
    """Before: ZeroDivisionError. With σ² estimated and lines that fit exactly the F test
    is undefined (0/0): ProblemError saying so. With σ² known, Λ = 0 to rounding."""
    t = [np.arange(6.0), np.arange(1.0, 9.0)]
    data = tr.TrajectoryData(t, [2.0 * t[0], -1.0 * t[1]])
    with pytest.raises(ProblemError, match="F test is undefined"):
        tr.family_test(data, "diverging", sigma2="estimated")
    known = tr.family_test(data, "diverging")
    assert known.statistic < 1e-20 and not known.reject
    assert known.p_value == pytest.approx(1.0, abs=1e-9)


def _scalar_calls() -> list[tuple[str, object]]:
    data = random_data(0, q=3)
    t, v = data.times, data.values
    return [
        ("epoch", lambda: tr.TrajectoryData(t, v, epoch="abc")),
        ("epoch", lambda: tr.TrajectoryData(t, v, epoch=None)),
        ("epoch", lambda: tr.TrajectoryData(t, v, epoch=np.nan)),
        ("epoch", lambda: tr.TrajectoryData(t, v, epoch=True)),
        ("epoch", lambda: tr.TrajectoryData(t, v, epoch=1 + 1j)),
        ("sigma2", lambda: tr.TrajectoryData(t, v, sigma2="abc")),
        ("sigma2", lambda: tr.TrajectoryData(t, v, sigma2=True)),
        ("sigma2", lambda: tr.TrajectoryData(t, v, sigma2=np.inf)),
        ("times", lambda: tr.TrajectoryData(5.0, v)),  # type: ignore[arg-type]
        ("level", lambda: tr.family_test(data, level="0.9")),
        ("level", lambda: tr.family_test(data, level=1.0)),
        ("level", lambda: tr.family_test(data, level=np.nan)),
        ("sigma2", lambda: tr.family_test(data, sigma2="unknown")),
        ("sigma2", lambda: tr.family_test(data, sigma2=1.0)),
        ("solver", lambda: tr.solve(data, solver=3)),
        ("formulation", lambda: tr.solve(data, formulation=None)),
        ("printed", lambda: tr.closed_form(data, "parallel", printed="yes")),
        ("q", lambda: tr.Family.custom(2.5)),
        ("q", lambda: tr.Family.diverging("3")),
        ("shared_start", lambda: tr.Family.custom(3, shared_start=[[0, 1.5]])),
        ("shared_start", lambda: tr.Family.custom(3, shared_start=[0, 1])),
        ("family", lambda: tr.closed_form(data, tr.Family("x", 3, ((0, 1),), ((0,), (1,), (2,))))),
        ("n", lambda: tr.eta(2.5)),
        ("q", lambda: tr.eta(5, q="2")),
        ("q", lambda: tr.eta0(0)),
        ("dt", lambda: tr.independent_variances(5, dt="x")),
        ("sigma2", lambda: tr.independent_variances(5, sigma2=-1.0)),
        ("dt", lambda: tr.paper_covariance("diverging", 3, np.nan)),
        ("family", lambda: tr.paper_covariance("converging", 3)),
        ("printed", lambda: tr.paper_covariance("parallel", 3, printed=1)),
        ("q", lambda: scenarios.launcher_release(0, q=2.5)),
        ("sigma", lambda: scenarios.launcher_release(0, sigma=-1.0)),
        ("family", lambda: scenarios.launcher_release(0, family="custom")),
        ("seed", lambda: scenarios.launcher_release("abc")),
        ("n", lambda: scenarios.equally_spaced(0, n=3.5)),
        ("dt", lambda: scenarios.equally_spaced(0, dt=0.0)),
        ("sigma2", lambda: scenarios.equally_spaced(0, sigma2="1")),
    ]


@pytest.mark.parametrize("case", range(len(_scalar_calls())))
def test_scalar_arguments_give_problem_error(case: int) -> None:
    name, call = _scalar_calls()[case]
    with pytest.raises(ProblemError, match=name):
        call()  # type: ignore[operator]


@pytest.mark.parametrize(
    ("times", "values", "sigma2", "match"),
    [
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0 + 1j, 1.0]], 1.0, "complex"),
        ([[0.0, 1.0 + 0j, 2.0]], [[0.0, 1.0, 1.0]], 1.0, "complex"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [[1.0, 1.0 + 2j, 1.0]], "complex"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], 1.0 + 2j, "complex"),
        ([[0.0, np.inf, 2.0]], [[0.0, 1.0, 1.0]], 1.0, "infinite"),
        ([[0.0, 1.0, 2.0]], [[0.0, -np.inf, 1.0]], 1.0, "infinite"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [[1.0, np.nan, 1.0]], "NaN"),
        ([[0.0, 1.0, 2e100]], [[0.0, 1.0, 1.0]], 1.0, "above 1e"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, -2e100]], 1.0, "above 1e"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], 1e101, "positive"),
        ([[0.0, 1.0, 2.0]], [[0.0, 1.0, 1.0]], [["a", "b", "c"]], "numeric"),
    ],
)
def test_bad_numbers_give_problem_error(
    times: list, values: list, sigma2: object, match: str
) -> None:
    with pytest.raises(ProblemError, match=match):
        tr.TrajectoryData(times, values, sigma2)  # type: ignore[arg-type]


@pytest.mark.parametrize("scale", [1e-45, 1e-15, 1e15, 1e45])
def test_large_and_small_magnitudes(scale: float) -> None:
    """Times and values multiplied by c (σ² by c²): velocities unchanged, starts and σ
    scaled by c, status optimal, to 1e-12 relative (power-of-ten scalings round once)."""
    base = random_data(4, q=3)
    data = tr.TrajectoryData(
        [scale * np.asarray(t) for t in base.times],
        [scale * np.asarray(v) for v in base.values],
        scale**2,
    )
    for family in ("diverging", "parallel"):
        a, b = tr.closed_form(base, family), tr.closed_form(data, family)
        assert b.status is Status.OPTIMAL
        assert rel_err(b.velocity, a.velocity) < 1e-12
        assert rel_err(b.start, scale * a.start) < 1e-12
        assert (
            rel_err(
                b.std,
                a.std
                * np.r_[
                    np.full(len(b.family.start_groups), scale),
                    np.ones(b.theta.size - len(b.family.start_groups)),
                ],
            )
            < 1e-12
        )
        g = tr.solve(data, family)
        assert g.status is Status.OPTIMAL and rel_err(g.theta, b.theta) < 1e-9
