"""The general-covariance plane estimator (plane/general.py) and radar covariances
(plane/radar.py), issue 19 items 3 and 5."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from optmodels import plane, scenarios
from optmodels.core import ProblemError, Status
from optmodels.plane.general import GeneralFit, fit_general
from optmodels.plane.radar import from_polar, radar_covariances, to_polar
from optmodels.scenarios.maneuver import climb_turn_track

TIGHT = {"tol": 1e-14, "constr_viol_tol": 1e-14}


def _reduced(points: np.ndarray, cov: np.ndarray) -> plane.PlaneSolution:
    """The reduced NLP (1.12)-(1.13), cold (3 starts), tight tolerances: independent of
    fit_general (CasADi + IPOPT, its own starts)."""
    return plane.solve(
        plane.PlaneData(points, cov), "reduced", starts=3, ipopt_options=TIGHT
    ).require_ok()


# --------------------------------------------------------------------------- vs the NLP
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sliding_windows_agree_with_reduced_nlp(seed: int) -> None:
    """Per step of a 100-point sliding window on a radar track (non-proportional D_i),
    warm-started as a tracker would: the normal within 1e-8 rad of the reduced NLP, the
    same offset and minimum of (1.12)."""
    tr = climb_turn_track(seed)
    prev = None
    compared = 0
    for k in range(len(tr.points) - 100 + 1):
        sl = slice(k, k + 100)
        fit = fit_general(tr.points[sl], tr.cov[sl], normal0=prev)
        assert fit.ok and fit.converged
        prev = fit.normal
        if k % 25 or not fit.resolved:
            continue
        sol = _reduced(tr.points[sl], tr.cov[sl])
        assert float(plane.angle_error(fit.normal, sol.normal)) <= 1e-8
        assert fit.offset == pytest.approx(sol.offset, rel=1e-9, abs=1e-6)
        assert fit.objective == pytest.approx(
            plane.reduced_objective(
                plane.PlaneData(tr.points[sl], tr.cov[sl]), sol.normal, sol.offset
            ),
            rel=1e-9,
        )
        assert fit.numerical_error <= 1e-8
        compared += 1
    assert compared >= 5


@pytest.mark.parametrize("geometry", ["broadside", "edge-on"])
def test_cold_fit_agrees_with_reduced_nlp(geometry: str) -> None:
    for seed in range(3):
        sc = scenarios.radar_plane(150, seed, geometry=geometry)
        fit = fit_general(sc.points, sc.cov)
        sol = _reduced(sc.points, sc.cov)
        assert fit.status == Status.OPTIMAL and fit.resolved
        assert float(plane.angle_error(fit.normal, sol.normal)) <= 1e-8
        assert fit.objective == pytest.approx(sol.objective, rel=1e-9)


def test_proportional_covariances_equal_the_closed_form() -> None:
    """Under (1.4) the minimiser of (1.12) is the closed form (1.5)-(1.8)."""
    for sc in (scenarios.paper_plane_example(3), scenarios.two_source_plane(300, 4)):
        data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
        cf = plane.closed_form(data)
        fit = fit_general(data.points, data.covs)
        assert float(plane.angle_error(fit.normal, cf.normal)) <= 1e-12
        assert fit.offset == pytest.approx(cf.offset, rel=1e-12, abs=1e-9)
        assert fit.objective == pytest.approx(cf.info["lambda_min"], rel=1e-11)
        np.testing.assert_allclose(fit.normal, cf.normal, atol=1e-12)  # same sign convention


def test_warm_start_from_a_wrong_normal_converges_to_the_same_plane() -> None:
    sc = scenarios.radar_plane(100, 7)
    cold = fit_general(sc.points, sc.cov)
    rng = np.random.default_rng(7)
    for _ in range(5):
        n0 = cold.normal + 0.3 * rng.normal(size=3)
        warm = fit_general(sc.points, sc.cov, normal0=n0)
        assert warm.converged and warm.ok
        assert float(plane.angle_error(warm.normal, cold.normal)) <= 1e-11


def test_statistic_is_chi2_n_minus_3_on_planar_radar_data() -> None:
    """Monte Carlo: min (1.12) ~ χ²(N − 3) for planar motion (mean N − 3, variance 2(N − 3));
    400 runs: the mean is within 4 standard errors."""
    n, runs = 60, 400
    vals = np.array(
        [
            fit_general(sc.points, sc.cov).objective
            for sc in (scenarios.radar_plane(n, 1000 + r) for r in range(runs))
        ]
    )
    dof = n - 3
    assert abs(vals.mean() - dof) <= 4 * np.sqrt(2 * dof / runs)


# --------------------------------------------------------------------------- resolved
def _line_track(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    site = np.zeros(3)
    d = np.array([0.6, 0.7, 0.39])
    d /= np.linalg.norm(d)
    truth = np.array([15e3, 22e3, 3e3]) + np.outer(np.linspace(0, 6000, n), d)
    cov = radar_covariances(truth, site, 20.0, 1e-3, 1.5e-3)
    pts = truth + (np.linalg.cholesky(cov) @ rng.normal(size=(n, 3, 1)))[..., 0]
    return pts, cov, d


def test_line_statistic_is_chi2_2n_minus_4_on_a_line() -> None:
    """Points on a line with radar covariances: the exact line fit (1.2) over lines is
    χ²(2N − 4); 300 runs, mean within 4 standard errors; the line direction is the true
    one to within its noise."""
    n, runs = 40, 300
    rng = np.random.default_rng(11)
    vals, angles = [], []
    for _ in range(runs):
        pts, cov, d = _line_track(rng, n)
        fit = fit_general(pts, cov)
        vals.append(fit.line_statistic)
        angles.append(float(plane.angle_error(fit.line_direction, d)))
    dof = 2 * n - 4
    assert abs(np.mean(vals) - dof) <= 4 * np.sqrt(2 * dof / runs)
    assert np.max(angles) < 0.02  # 20 m noise over 6 km: ~3 mrad


def test_line_statistic_equals_the_two_smallest_eigenvalues_under_proportional_cov() -> None:
    """Under (1.4) the minimum of (1.2) over lines is Λ₁ + Λ₂ of (Q, D) (closed form)."""
    rng = np.random.default_rng(5)
    n = 50
    d = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    base = np.array([[100.0, 20.0, 0.0], [20.0, 60.0, 10.0], [0.0, 10.0, 300.0]])
    truth = np.outer(np.linspace(0, 3000, n), d) + 3.0 * np.outer(
        np.sin(np.linspace(0, 3, n)), [0.0, 0.0, 1.0]
    )
    pts = truth + rng.multivariate_normal(np.zeros(3), base, size=n)
    data = plane.PlaneData(pts, base)
    fit = fit_general(pts, np.broadcast_to(base, (n, 3, 3)))
    cf = plane.closed_form(data)
    assert fit.line_statistic == pytest.approx(cf.info["line_statistic"], rel=1e-6)
    assert not fit.resolved  # below chi2.ppf(0.997, 96)
    assert fit.line_statistic <= stats.chi2.ppf(0.997, 2 * n - 4)


def test_collinear_windows_are_unresolved_and_arcs_resolved() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        pts, cov, d = _line_track(rng, 60)
        fit = fit_general(pts, cov)
        assert not fit.resolved
        assert float(plane.angle_error(fit.line_direction, d)) < 0.02
    for seed in range(5):
        sc = scenarios.radar_plane(60, seed)
        assert fit_general(sc.points, sc.cov).resolved


def test_resolved_at_level_matches_the_threshold() -> None:
    rng = np.random.default_rng(8)
    pts, cov, _ = _line_track(rng, 30)
    fit = fit_general(pts, cov, level=0.5)
    assert fit.line_threshold == pytest.approx(stats.chi2.ppf(0.5, 56), rel=1e-12)
    assert fit.resolved == (fit.line_statistic > fit.line_threshold)


# --------------------------------------------------------------------------- the gate
def test_not_converged_is_never_ok() -> None:
    sc = scenarios.radar_plane(100, 2)
    cold = fit_general(sc.points, sc.cov)
    bad = fit_general(sc.points, sc.cov, normal0=np.cross(cold.normal, [1.0, 0.0, 0.0]), max_iter=1)
    assert not bad.converged and not bad.ok and bad.status == Status.ITERATION_LIMIT
    assert not bad.resolved
    sol = bad.to_solution(plane.PlaneData(sc.points, sc.cov))
    assert not sol.ok and np.all(np.isnan(sol.normal))
    assert "rejected" in sol.info
    # exactly collinear points, warm start (the cold path refuses them): a flat profile,
    # given up quickly, never OK, never resolved
    line = np.outer(np.arange(10.0), [1.0, 2.0, 3.0])
    flat = fit_general(line, np.eye(3), normal0=[1.0, 0.0, 0.0])
    assert not flat.ok and not flat.resolved and flat.iterations < 20


def test_to_solution_goes_through_the_package_recheck() -> None:
    sc = scenarios.radar_plane(80, 4, geometry="edge-on")
    data = plane.PlaneData(sc.points, sc.cov)
    fit = fit_general(sc.points, sc.cov)
    sol = fit.to_solution(data)
    assert sol.status == Status.OPTIMAL
    np.testing.assert_allclose(sol.normal, fit.normal, atol=0)
    assert sol.info["verification"]["stationarity"] <= 1e-9
    # (1.2) at the projections (1.8) is the minimum of (1.12)
    assert sol.objective == pytest.approx(fit.objective, rel=1e-10)
    assert sol.residuals["plane"] <= 1e-9 * np.max(np.abs(sc.points))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"points": np.zeros((2, 3))}, "fit_general points"),
        ({"points": np.zeros((5, 2))}, "fit_general points"),
        ({"points": np.ones((5, 3))}, "identical"),
        ({"points": np.outer(np.arange(5.0), [1.0, 2.0, 3.0])}, "collinear"),
        ({"cov": np.zeros((4, 3, 3))}, "fit_general cov"),
        ({"cov": -np.eye(3)}, "fit_general cov"),
        ({"cov": np.eye(2)}, "fit_general cov"),
        ({"tol": 0.0}, "fit_general tol"),
        ({"tol": 0.1}, "fit_general tol"),
        ({"max_iter": 0}, "fit_general max_iter"),
        ({"level": 1.0}, "fit_general level"),
        ({"normal0": np.zeros(3)}, "fit_general normal0"),
        ({"normal0": [1.0, np.nan, 0.0]}, "fit_general normal0"),
    ],
)
def test_bad_input_is_one_problem_error(kwargs: dict, match: str) -> None:
    rng = np.random.default_rng(0)
    args = {"points": rng.normal(size=(5, 3)) * [100.0, 100.0, 1.0], "cov": np.eye(3)}
    args.update(kwargs)
    pts, cov = args.pop("points"), args.pop("cov")
    with pytest.raises(ProblemError, match=match):
        fit_general(pts, cov, **args)


def test_result_type_and_sign_convention() -> None:
    sc = scenarios.radar_plane(50, 9)
    fit = fit_general(sc.points, sc.cov)
    assert isinstance(fit, GeneralFit)
    assert fit.offset >= 0 and abs(np.linalg.norm(fit.normal) - 1) <= 1e-14
    assert abs(np.linalg.norm(fit.line_direction) - 1) <= 1e-14


# --------------------------------------------------------------------------- radar
def test_radar_covariances_match_monte_carlo_of_polar_noise() -> None:
    """Polar noise converted exactly (from_polar) vs J diag(σ²) Jᵀ. With M = 200 000
    samples an entry's standard error is ≤ sqrt((D_jj D_kk + D_jk²)/M) ≤ 0.0032·max D;
    the first-order error (relative σ² ≈ 4e-6) is far below it: tolerance 5 se."""
    rng = np.random.default_rng(2024)
    site = np.array([100.0, -200.0, 30.0])
    sig = np.array([25.0, 2e-3, 3e-3])
    m = 200_000
    for x in (np.array([12e3, 30e3, 4e3]), np.array([-20e3, -5e3, 9e3])):
        cov = radar_covariances(x[None, :], site, *sig)[0]
        pol = to_polar(x[None, :], site)[0]
        noisy = from_polar(pol + rng.normal(size=(m, 3)) * sig, site)
        emp = np.cov(noisy.T)
        se = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov**2) / m)
        assert np.all(np.abs(emp - cov) <= 5 * se)
        u = (x - site) / np.linalg.norm(x - site)
        assert u @ cov @ u == pytest.approx(sig[0] ** 2, rel=1e-12)


def test_polar_round_trip_and_conventions() -> None:
    site = np.array([5.0, 6.0, 7.0])
    # due east at 10 km, 0 elevation: azimuth 90° (clockwise from north)
    p = to_polar(site[None, :] + [[10e3, 0.0, 0.0]], site)[0]
    np.testing.assert_allclose(p, [10e3, np.pi / 2, 0.0], atol=1e-12)
    rng = np.random.default_rng(1)
    x = site + rng.normal(size=(50, 3)) * [2e4, 2e4, 3e3]
    np.testing.assert_allclose(from_polar(to_polar(x, site), site), x, rtol=0, atol=1e-8)


def test_scenarios_radar_covariances_is_the_plane_function() -> None:
    rng = np.random.default_rng(4)
    x = rng.normal(size=(20, 3)) * [2e4, 2e4, 3e3] + [0.0, 0.0, 5e3]
    site = np.array([1.0, 2.0, 3.0])
    np.testing.assert_array_equal(
        scenarios.radar_covariances(x, site, 10.0, 2e-3, 3e-3),
        radar_covariances(x, site, 10.0, 2e-3, 3e-3),
    )


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.zeros((2, 3)), np.zeros(3), 1.0, 1e-3, 1e-3), "coincide"),
        ((np.array([[0.0, 0.0, 5e3]]), np.zeros(3), 1.0, 1e-3, 1e-3), "above or below"),
        ((np.ones((2, 3)), np.zeros(3), -1.0, 1e-3, 1e-3), "sigma_range"),
        ((np.ones((2, 3)), np.zeros(3), 1.0, 0.0, 1e-3), "sigma_azimuth"),
        ((np.ones((2, 3)), np.zeros(2), 1.0, 1e-3, 1e-3), "site"),
        ((np.ones((2, 2)), np.zeros(3), 1.0, 1e-3, 1e-3), "points"),
    ],
)
def test_radar_bad_input(args: tuple, match: str) -> None:
    with pytest.raises(ProblemError, match=match):
        radar_covariances(*args)


def test_climb_turn_track_is_planar_per_segment() -> None:
    tr = climb_turn_track(0)
    for k in (1, 2):
        m = tr.segment == k
        assert np.max(np.abs(tr.truth[m] @ tr.normals[k] - tr.offsets[k])) <= 1e-6
    np.testing.assert_allclose(tr.tilt_deg[1:], [6.0, 0.0], atol=1e-9)
    speed = np.linalg.norm(np.diff(tr.truth, axis=0), axis=1) * 2.0
    np.testing.assert_allclose(speed, 150.0, rtol=1e-3)  # chords of 0.5 s at 3°/s


def test_track_demo_writes_figure_and_detection_table(tmp_path) -> None:
    from optmodels.demo.plane import run_track_demo

    md, summ = run_track_demo(tmp_path, seed=0)
    assert (tmp_path / "track.png").stat().st_size > 10_000
    rows = (tmp_path / "track_steps.csv").read_text().splitlines()
    assert len(rows) == summ["steps"] + 1
    t1, t2 = (r["true time, s"] for r in summ["transitions"])
    assert (t1, t2) == (60.0, 90.0)
    # the plane is reported only once the climbing turn has begun, and the change to the
    # level turn is detected after it happened (no alarm on the 6° plane before)
    assert summ["transitions"][0]["time, s"] > t1
    assert summ["alarms_before_level_turn"] == []
    assert summ["transitions"][1]["delay, s"] >= 0
    assert "| transition |" in md


def test_sequential_benchmark_runs_and_agrees() -> None:
    """The per-step benchmark (solvers_cmp/plane_sequential.py) on a short case: every
    warm step OK and within 1e-8 rad of the warm reduced NLP. (Times are reported, not
    asserted: benchmarks, not unit tests, carry timing goals.)"""
    from solvers_cmp.plane_sequential import benchmark

    res = benchmark(20, runs=1, rate_hz=1.0, nlp_steps=3)
    assert res["all_ok"] and res["steps"] == 131
    assert res["max_angle_vs_nlp"] <= 1e-8
    assert res["warm_iterations"] <= 6
    assert res["warm_ms"] > 0


def test_fixed_point_of_the_reweighted_scatter() -> None:
    """The stationarity condition derived in plane/general.py: at the ML normal,
    Q_w n = M_w n with Q_w = Σ w_i (x_i − x̄_w)(x_i − x̄_w)ᵀ, M_w = Σ w_i² r_i² D_i,
    w_i = 1/⟨D_i n, n⟩ (computed here in NumPy, independently): 1 is a generalized
    eigenvalue of (Q_w, M_w) with eigenvector n; and n is not stationary elsewhere."""
    sc = scenarios.radar_plane(120, 13, geometry="edge-on")
    fit = fit_general(sc.points, sc.cov)

    def residual(n: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        w = 1.0 / np.einsum("j,ijk,k->i", n, sc.cov, n)
        xbar = w @ sc.points / w.sum()
        y = sc.points - xbar
        r = y @ n
        qw = (y * w[:, None]).T @ y
        mw = np.einsum("i,ijk->jk", w * w * r * r, sc.cov)
        return float(np.linalg.norm(qw @ n - mw @ n) / np.linalg.norm(qw @ n)), qw, mw

    res, qw, mw = residual(fit.normal)
    assert res <= 1e-9
    ev = np.linalg.eigvals(np.linalg.solve(mw, qw))
    assert np.min(np.abs(ev - 1.0)) <= 1e-9
    tilted = fit.normal + 0.01 * np.cross(fit.normal, [0.0, 0.0, 1.0])
    assert residual(tilted / np.linalg.norm(tilted))[0] > 1e-4
