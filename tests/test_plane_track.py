"""Plane of maneuver along a track (paper 000, issue 19): sliding windows with removal,
resolved/unresolved steps, the plane-change detector (its χ²(3) null, false-alarm rate,
detection delay, power figure) and the ``plane.track`` API."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from optmodels import ProblemError, plane
from optmodels.plane import detector as det
from optmodels.plane.general import fit_general
from optmodels.plane.simulate import detection_runs, false_alarm_runs, plane_change_track
from optmodels.plane.tracking import track
from optmodels.plane.windows import direct_moments, range_moments, track_spread
from optmodels.scenarios import radar_covariances

# closed form per window vs the sliding sums: both are eigenvectors of the same 3x3 pencil
# built from sums that agree to ~1e-14 relative; the issue asks for ~1e-10 rad.
WINDOW_ANGLE_TOL = 1e-10


def _long_track(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 1 Hz level turn of 7 km radius 100 km from the origin, σ = 30 m."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    ph = 200.0 / 7000.0 * t
    truth = np.column_stack([1e5 + 7000 * np.cos(ph), 5e4 + 7000 * np.sin(ph), 9000.0 + 0 * t])
    return t, truth + 30.0 * rng.normal(size=truth.shape)


# --------------------------------------------------------------------------- windows
def test_window_moments_match_from_scratch_and_naive_removal_does_not() -> None:
    # 2e4 points of a weaving flight over 4000 km, weights α⁻² in [0.5, 2], windows of
    # 100 points (naive removal: 1.8e-7 relative; the epochs: 1e-14)
    rng = np.random.default_rng(2)
    t = np.arange(20000.0)
    pts = np.column_stack(
        [1e5 + 200 * t, 3e4 + 5000 * np.sin(t / 30), 8000 + 30 * rng.normal(size=len(t))]
    )
    w = 1.0 / rng.uniform(0.5, 2.0, len(t))
    hi = np.arange(10, len(t))
    lo = np.maximum(hi - 99, 0)
    mom = range_moments(pts, w, lo, hi)
    ref = direct_moments(pts, w, lo, hi, mom.spread)
    scale = np.max(np.abs(ref.q), axis=(1, 2))[:, None, None]
    ours = float(np.max(np.abs(mom.q - ref.q) / scale))
    assert ours <= 1e-12
    assert float(np.max(np.abs(mom.mean - ref.mean))) <= 1e-8 * 4e6  # m, at 4e6 m
    # the plain running sums with removal (cumsum about one origin, differenced) lose
    # ~eps·(track/window)²: the reason for the epochs
    y = (pts - pts[0]) / mom.spread
    c0 = np.concatenate([[0.0], np.cumsum(w)])
    c1 = np.concatenate([np.zeros((1, 3)), np.cumsum(w[:, None] * y, axis=0)])
    c2 = np.concatenate(
        [np.zeros((1, 3, 3)), np.cumsum(w[:, None, None] * y[:, :, None] * y[:, None, :], axis=0)]
    )
    a0, a1, a2 = c0[hi + 1] - c0[lo], c1[hi + 1] - c1[lo], c2[hi + 1] - c2[lo]
    naive = a2 - a1[:, :, None] * a1[:, None, :] / a0[:, None, None]
    assert float(np.max(np.abs(naive - ref.q) / scale)) > 1e5 * max(ours, 1e-16)


def test_window_moments_recompute_when_the_prefix_dominates() -> None:
    # a 3-point window near its epoch's reference point, 220 points into an epoch of 500:
    # the prefix it subtracts is > 1e3 times larger, so it is recomputed from scratch
    t, pts = _long_track(2000, 3)
    # (the circle's period is 220 s: points 1219-1221 pass the epoch's reference, 1000)
    hi = np.array([1221, 1999, 700])
    lo = np.array([1219, 1500, 201])
    mom = range_moments(pts, np.ones(len(t)), lo, hi)
    ref = direct_moments(pts, np.ones(len(t)), lo, hi, mom.spread)
    assert mom.recomputed.tolist() == [True, False, False]
    assert np.allclose(mom.q, ref.q, rtol=1e-12, atol=1e-14 * np.max(np.abs(ref.q)))


@pytest.mark.parametrize("window", ["40s", "60pts", "25.5s"])
def test_sliding_windows_equal_the_closed_form_of_each_window(window: str) -> None:
    t, pts = _long_track(400, 4)
    alpha2 = np.random.default_rng(5).uniform(0.5, 3.0, len(t))
    cov = np.diag([900.0, 400.0, 1600.0])
    tr = track(t, pts, cov, alpha2=alpha2, window=window, false_alarm_rate_per_h=3.6e-9)
    assert not tr.change.any() and tr.method == "closed_form"
    if isinstance(tr.window, int):
        assert np.all(tr.n_points[tr.window :] == tr.window)
    for k in range(0, tr.n_steps, 7):
        m = (t <= tr.times[k]) & (t >= tr.window_start[k])
        assert m.sum() == tr.n_points[k]
        if isinstance(tr.window, float):
            assert np.all(tr.times[k] - t[m] < tr.window)
        data = plane.PlaneData(pts[m], cov, alpha2[m])
        cf = plane.closed_form(data)
        pt = plane.planarity_test(data, cf, level=tr.level)
        assert tr.resolved[k] == pt.resolved
        assert tr.statistic[k] == pytest.approx(cf.info["lambda_min"], rel=1e-9)
        assert tr.line_statistic[k] == pytest.approx(pt.line_statistic, rel=1e-9)
        if tr.resolved[k]:
            assert plane.angle_error(tr.normals[k], cf.normal) <= WINDOW_ANGLE_TOL
            assert tr.offsets[k] == pytest.approx(cf.offset, abs=1e-10 * 1.2e5)
            assert tr.planar[k] == pt.planar


def test_growing_window_equals_identify_sequence() -> None:
    sc = plane_change_track(6, tilt_deg=0.0, before=150.0, after=0.0)
    tr = track(sc.times, sc.points, sc.cov, false_alarm_rate_per_h=3.6e-9)
    seq = plane.identify_sequence(sc.times, sc.points, sc.cov)
    assert np.array_equal(tr.resolved, seq.resolved)
    assert np.array_equal(tr.planar, seq.planar)
    assert np.allclose(tr.statistic, seq.statistic, rtol=1e-10)
    r = seq.resolved
    assert np.max(plane.angle_error(tr.normals[r], seq.normal[r])) <= 1e-12
    assert np.allclose(tr.offsets[r], seq.offset[r], rtol=1e-12, atol=1e-9)


# --------------------------------------------------------------------------- resolved
def _line_then_arc(
    sigma: float, rng: np.random.Generator | None = None, n_line: int = 20, n_arc: int = 30
) -> tuple[np.ndarray, np.ndarray]:
    line = np.column_stack([np.linspace(-1000.0, 0.0, n_line), np.zeros(n_line), np.zeros(n_line)])
    ph = 0.075 * np.arange(1, n_arc + 1)
    arc = np.column_stack([1000 * np.sin(ph), np.zeros(n_arc), 1000 * (1 - np.cos(ph))])
    pts = np.vstack([line, arc]) + np.array([5000.0, 2000.0, 3000.0])
    if rng is not None:
        pts = pts + sigma * rng.normal(size=pts.shape)
    return 0.1 * np.arange(len(pts)), pts


@pytest.mark.parametrize("general", [False, True])
def test_collinear_steps_are_unresolved_and_report_the_line(general: bool) -> None:
    # 20 exactly collinear points then an arc; proportional (closed form) and
    # non-proportional (fit_general) covariances
    t, pts = _line_then_arc(0.0)
    if general:
        cov = np.array([np.diag([1e-6, 2e-6 + 1e-7 * i, 3e-6]) for i in range(len(t))])
    else:
        cov = 1e-6 * np.eye(3)
    for window in (None, "12pts"):
        tr = track(t, pts, cov, window=window)
        assert tr.method == ("general" if general else "closed_form")
        line = tr.times <= t[19]
        assert line.sum() == 17
        assert not tr.resolved[line].any() and not tr.planar[line].any()
        assert np.all(np.isnan(tr.normals[line])) and np.all(np.isnan(tr.offsets[line]))
        assert np.max(plane.angle_error(tr.line_direction[line], [1.0, 0.0, 0.0])) <= 1e-9
        late = tr.times >= t[22]
        assert np.all(tr.resolved[late])
        assert np.max(plane.angle_error(tr.normals[late], [0.0, 1.0, 0.0])) <= 1e-8
        assert np.all(np.isnan(tr.line_direction[late]))


def test_noisy_straight_segment_is_unresolved_at_level() -> None:
    # σ = 1 m: on the line a step is wrongly "resolved" with probability ≤ 1 − level
    rng = np.random.default_rng(41)
    t, pts = _line_then_arc(1.0, rng, n_line=40, n_arc=30)
    tr = track(t, pts, np.eye(3), window_points=15)
    line = tr.times <= t[39]
    assert np.sum(tr.resolved[line]) <= 1
    assert not np.any(tr.planar[line & ~tr.resolved])
    assert np.all(np.isnan(tr.normals[~tr.resolved]))


# --------------------------------------------------------------------------- detector
def _regression_rss(h: np.ndarray, r: np.ndarray, v: np.ndarray) -> float:
    """Weighted least-squares residual sum of r on the columns of h (weights 1/v)."""
    sw = 1.0 / np.sqrt(v)
    beta = np.linalg.lstsq(h * sw[:, None], r * sw, rcond=None)[0]
    return float(np.sum((r - h @ beta) ** 2 / v))


@pytest.mark.parametrize("tilt", [0.0, 10.0, 30.0])
def test_chow_statistic_is_the_linear_glr_and_close_to_the_exact_one(tilt: float) -> None:
    # U = RSS(A ∪ B, one plane) − RSS(A) − RSS(B) of the regression of the residuals to
    # A's plane on h_i = (E(x_i − x_s)/ℓ, −1) (an independent lstsq), to round-off; and
    # close to the exact GLR Λ(A ∪ B) − Λ(A) − Λ(B) of (1.16): the linearisation uses
    # the noisy in-plane coordinates (errors in variables) and A's fitted plane, so it is
    # within ~12 % (H1) or 0.6 (H0, χ²(3) units) of it (measured over seeds 0-8)
    sc = plane_change_track(7, tilt_deg=tilt, before=60.0, after=20.0)
    x, cov = sc.points, sc.cov
    a_idx, b_idx = np.arange(20, 61), np.arange(61, 80)
    cf = plane.closed_form(plane.PlaneData(x[a_idx], cov))
    sp = track_spread(x)
    covs = np.broadcast_to(cov, (len(x), 3, 3))
    ell = 0.7
    ja, ba = det.score_info_points(cf.normal, cf.offset, x[60], x[a_idx], covs[a_idx], sp, ell)
    jb, bb = det.score_info_points(cf.normal, cf.offset, x[60], x[b_idx], covs[b_idx], sp, ell)
    u = float(det.chow_statistic(ja[None], ba[None], jb[None], bb[None])[0])
    e = plane.verify._tangent_basis(cf.normal[None])[0]

    def design(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h = np.column_stack([(x[idx] - x[60]) @ e.T / (sp * ell), -np.ones(len(idx))])
        r = (x[idx] @ cf.normal - cf.offset) / sp
        return h, r, np.full(len(idx), float(cf.normal @ cov @ cf.normal) / sp**2)

    both = np.concatenate([a_idx, b_idx])
    lin = (
        _regression_rss(*design(both))
        - _regression_rss(*design(a_idx))
        - _regression_rss(*design(b_idx))
    )
    assert u == pytest.approx(lin, rel=1e-8, abs=1e-9)
    lam = [
        plane.closed_form(plane.PlaneData(x[i], cov)).info["lambda_min"]
        for i in (both, a_idx, b_idx)
    ]
    exact = lam[0] - lam[1] - lam[2]
    assert abs(u - exact) <= 0.12 * exact + 0.6
    # the moments route (the closed-form path of track) gives the same J, b and U
    w = np.ones(len(x))
    ma = range_moments(x, w, a_idx[:1], a_idx[-1:], spread=sp)
    mb = range_moments(x, w, b_idx[:1], b_idx[-1:], spread=sp)
    args = (cf.normal[None], np.array([cf.offset]), x[60][None])
    ja2, ba2 = det.score_info_moments(*args, ma, cov, np.full(1, ell))
    jb2, bb2 = det.score_info_moments(*args, mb, cov, np.full(1, ell))
    assert np.allclose(ja2[0], ja, rtol=1e-9) and np.allclose(jb2[0], jb, rtol=1e-9)
    assert float(det.chow_statistic(ja2, ba2, jb2, bb2)[0]) == pytest.approx(u, rel=1e-8, abs=1e-9)


def test_detector_statistic_is_chi2_3_on_planar_tracks() -> None:
    # 300 planar tracks (level turn, σ = 50 m, 40 s window, one scale of 10 s): U at one
    # step per track, independent across tracks. χ²(3): mean 3 (se √6/√300 = 0.14),
    # P(U > χ²₃(0.95)) = 0.05 (se 0.013); KS against χ²(3).
    rng = np.random.default_rng(8)
    u = []
    for _ in range(300):
        sc = plane_change_track(rng, tilt_deg=0.0, before=60.0, after=0.0)
        tr = track(
            sc.times,
            sc.points,
            sc.cov,
            window_seconds=40.0,
            scales=[10.0],
            false_alarm_rate_per_h=3.6e-9,
        )
        u.append(tr.detector[-1])
    u = np.asarray(u)
    assert np.all(np.isfinite(u))
    assert abs(u.mean() - 3.0) <= 3 * np.sqrt(6.0 / len(u))
    tail = np.mean(u > stats.chi2.ppf(0.95, 3))
    assert abs(tail - 0.05) <= 3 * np.sqrt(0.05 * 0.95 / len(u))
    assert stats.kstest(u, stats.chi2(3).cdf).pvalue > 1e-3


def _arc(n_pts: int, seconds: float) -> np.ndarray:
    """Noise-free points of a 200 m/s level turn of 7 km radius over ``seconds`` (m)."""
    ph = 200.0 / 7000.0 * np.linspace(0.0, seconds, n_pts)
    return np.column_stack([7000 * np.sin(ph), 7000 * (1 - np.cos(ph)), np.full(n_pts, 3e3)])


@pytest.mark.parametrize(("n_pts", "seconds"), [(100, 10.0), (400, 40.0), (40, 40.0)])
def test_reference_information_matches_the_scatter_of_the_fitted_plane(
    n_pts: int, seconds: float
) -> None:
    # The ML plane (closed form) of 400 noisy copies of an arc (σ = 50 m): the RMS angle
    # between its normal and the true one against the tilt standard deviation that the
    # detector assumes for its reference, √tr((K⁻¹)_tt), K = S J⁻¹ S, S = J − N (errors in
    # variables), and against √tr((J⁻¹)_tt), which it assumed before. 100 points over
    # 10 s (10 Hz): the arc's curvature (sagitta 71 m) hardly beats the noise of the
    # in-plane coordinates; measured 0.51 rad, J⁻¹ claims 0.09 (under the 0.1 rad
    # firmness gate: such references were tested, 24 false alarms per hour at a bound of
    # 1), K⁻¹ 0.51. Over 40 s the two agree (1 Hz or 10 Hz).
    rng = np.random.default_rng(31)
    sig = 50.0
    x0 = _arc(n_pts, seconds)
    covs = np.repeat(sig**2 * np.eye(3)[None], n_pts, axis=0)
    err2, sd_j, sd_k = [], [], []
    for _ in range(400):
        x = x0 + sig * rng.normal(size=x0.shape)
        cf = plane.closed_form(plane.PlaneData(x, sig**2 * np.eye(3)), level=None)
        n, a = (cf.normal, cf.offset) if cf.normal[2] > 0 else (-cf.normal, -cf.offset)
        ja, _ = det.score_info_points(n, a, x[-1], x, covs, 1e3, 1.0)
        noise = det.noise_info_points(n, covs, 1e3, 1.0)
        k, valid = det.reference_information(ja[None], noise[None])
        err2.append(1.0 - n[2] ** 2)  # sin² of the angle to the true normal (0, 0, 1)
        sd_j.append(np.sqrt(np.trace(np.linalg.inv(ja)[:2, :2])))
        sd_k.append(np.sqrt(np.trace(np.linalg.inv(k[0])[:2, :2])) if valid[0] else np.inf)
    rms = float(np.sqrt(np.mean(err2)))
    assert float(np.median(sd_k)) == pytest.approx(rms, rel=0.15)
    if seconds < 20:
        assert rms > 3.0 * float(np.median(sd_j))  # what J⁻¹ alone claimed
        assert np.mean(np.isinf(sd_k)) < 0.2  # S not positive definite: no test
    else:
        assert float(np.median(sd_j)) == pytest.approx(rms, rel=0.15)


def test_noise_information_of_moments_and_points_agree() -> None:
    # N under (1.4) from the count (moments) and from the stacked D_i = α_i² D (points)
    rng = np.random.default_rng(32)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    a = rng.normal(size=(3, 3))
    d = a @ a.T + np.eye(3)
    alpha2 = rng.uniform(0.5, 2.0, size=25)
    nm = det.noise_info_moments(n[None], np.array([25.0]), d, np.array([0.7]), 1e3)[0]
    npt = det.noise_info_points(n, alpha2[:, None, None] * d, 1e3, 0.7)
    assert np.allclose(nm, npt, rtol=1e-12, atol=0.0)
    assert np.all(nm[2] == 0.0) and np.all(nm[:, 2] == 0.0)
    assert np.all(np.linalg.eigvalsh(nm[:2, :2]) > 0)


def test_change_statistic_without_in_plane_noise_is_the_chow_statistic() -> None:
    # (b_B − J_B β̂_A)ᵀ (J_B + J_B J_A⁻¹ J_B)⁻¹ (…) with β̂_A = J_A⁻¹ b_A equals the Chow
    # statistic (the GLR of the linear model, checked against lstsq above) for any b_A,
    # and F = S_B G⁺ S_B equals (J_A⁻¹ + J_B⁻¹)⁻¹: the errors-in-variables forms extend it
    rng = np.random.default_rng(33)
    m = rng.normal(size=(6, 3, 3))
    ja = m @ np.swapaxes(m, -1, -2) + 0.1 * np.eye(3)
    m = rng.normal(size=(6, 3, 3))
    jb = m @ np.swapaxes(m, -1, -2) + 0.1 * np.eye(3)
    ba, bb = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    beta_a = np.linalg.solve(ja, ba[..., None])[..., 0]
    u0 = det.chow_statistic(ja, ba, jb, bb)
    assert np.allclose(det.change_statistic(ja, beta_a, jb, bb, jb), u0, rtol=1e-10, atol=0)
    f = np.linalg.inv(np.linalg.inv(ja) + np.linalg.inv(jb))
    assert np.allclose(det.change_information(ja, jb, jb), f, rtol=1e-9, atol=1e-12)
    assert np.allclose(det.change_information(ja, jb), f, rtol=1e-9, atol=1e-12)


def test_detector_statistic_is_chi2_3_on_densely_sampled_tracks() -> None:
    # 10 Hz, a 200-point window (20 s of a 7 km turn, σ = 50 m), one scale of 50 points:
    # the reference's in-plane noise is ~40 % of its information J. U at one step per
    # track, 300 independent tracks, against χ²(3) (mean 3, se 0.14; tail 0.05, se
    # 0.013). With J_A alone (before the errors-in-variables information): mean 4.3,
    # P(U > χ²₃(0.95)) = 0.16, KS p ~ 1e-13; now 3.3, 0.07.
    rng = np.random.default_rng(8)
    u = []
    for _ in range(300):
        sc = plane_change_track(rng, tilt_deg=0.0, before=22.0, after=0.0, rate_hz=10.0)
        tr = track(
            sc.times,
            sc.points,
            sc.cov,
            window="200pts",
            scales=[50],
            false_alarm_rate_per_h=3.6e-9,
        )
        u.append(tr.detector[-1])
    u = np.asarray(u)
    assert np.mean(np.isfinite(u)) > 0.9
    u = u[np.isfinite(u)]
    assert abs(u.mean() - 3.0) <= 3 * np.sqrt(6.0 / len(u))
    tail = np.mean(u > stats.chi2.ppf(0.95, 3))
    assert abs(tail - 0.05) <= 3 * np.sqrt(0.05 * 0.95 / len(u))
    assert stats.kstest(u, stats.chi2(3).cdf).pvalue > 1e-3


def test_change_statistic_is_chi2_3_where_the_in_plane_noise_dominates() -> None:
    # 20 Hz, σ = 50 m: a 300-point reference over 15 s of a 7 km turn and the 150 points
    # after it (the largest scale of "300pts"), 2000 independent draws, the tests the
    # tracker would make (firm reference). The reference's error reaches B's score through
    # B's true positions (S_B), not J_B: with K_A but the Chow form (J_B) the mean was 3.71
    # and P(U > χ²₃(0.99)) = 0.046 (6.5 false alarms per hour at a bound of 1 on such
    # tracks); with S_B 3.06 and 0.012 (the information of the true positions in place of
    # the estimates S = J − N: 2.95 and 0.0096).
    rng = np.random.default_rng(34)
    sig, hz = 50.0, 20.0
    x0 = _arc(450, 449 / hz)
    cov = sig**2 * np.eye(3)
    covs = np.repeat(cov[None], 450, axis=0)
    u = []
    for _ in range(2000):
        x = x0 + sig * rng.normal(size=x0.shape)
        xa, xb = x[:300], x[300:]
        cf = plane.closed_form(plane.PlaneData(xa, cov), level=None)
        ell = float(np.sqrt(np.mean(np.sum((xa - xa.mean(0)) ** 2, 1)))) / 1e3
        args = (cf.normal, cf.offset, xa[-1])
        ja, ba = det.score_info_points(*args, xa, covs[:300], 1e3, ell)
        jb, bb = det.score_info_points(*args, xb, covs[300:], 1e3, ell)
        ka, ok = det.reference_information(
            ja[None], det.noise_info_points(cf.normal, covs[:300], 1e3, ell)[None]
        )
        if not ok[0] or det.reference_tilt_sd(ka, np.array([ell]))[0] > 0.1:
            continue
        sb = jb - det.noise_info_points(cf.normal, covs[300:], 1e3, ell)
        beta_a = np.linalg.solve(ja, ba)
        u.append(det.change_statistic(ka, beta_a[None], jb[None], bb[None], sb[None])[0])
    u = np.asarray(u)
    assert len(u) > 1500
    assert abs(u.mean() - 3.0) <= 3 * np.sqrt(6.0 / len(u))
    tail = np.mean(u > stats.chi2.ppf(0.99, 3))
    assert tail <= 0.01 + 3 * np.sqrt(0.01 * 0.99 / len(u))


def test_no_test_where_the_window_cannot_fix_the_plane() -> None:
    # "100pts" at 10 Hz is 10 s of a 7 km turn: the reference's tilt about its chord is
    # known to ~0.5 rad (see the test above), so no test is made (detector NaN, as at the
    # start of a track) instead of tests against a plane that the noise chose; the
    # same window at 1 Hz (100 s) is tested nearly everywhere
    for hz, tested in ((10.0, False), (1.0, True)):
        sc = plane_change_track(4, tilt_deg=0.0, before=300.0, after=0.0, rate_hz=hz)
        tr = track(sc.times, sc.points, sc.cov, window="100pts")
        frac = float(np.mean(np.isfinite(tr.detector)))
        assert (frac > 0.6) if tested else (frac == 0.0), (hz, frac)
        assert np.all(np.isnan(tr.detectable_tilt[~np.isfinite(tr.detector)]))
        assert not np.any(tr.change)


@pytest.mark.parametrize(
    ("window", "rate_hz"), [("40s", 1.0), ("100pts", 1.0), ("60pts", 1.0), ("200pts", 10.0)]
)
def test_false_alarm_rate_within_its_bound_fast(window: str, rate_hz: float) -> None:
    # stated 60 per hour (1 per minute) so that a short run gives enough alarms; the union
    # bound makes the rate an upper bound: measured within [0, stated + 3 se] (Poisson
    # se). The points windows at 1 Hz (100 and 60 s) and 200 points at 10 Hz (20 s).
    hours = 2.0 if rate_hz == 1.0 else 0.5
    r = false_alarm_runs(
        hours, 12, window=window, false_alarm_rate_per_h=60.0, run_hours=0.5, rate_hz=rate_hz
    )
    assert r["alarms"] > 0
    assert r["rate"] <= r["stated"] + 3 * r["se"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("window", "rate_hz", "hours"),
    [
        ("40s", 1.0, 30.0),
        (None, 1.0, 30.0),
        ("100pts", 1.0, 30.0),
        ("200pts", 10.0, 20.0),
        ("300pts", 20.0, 10.0),
    ],
)
def test_false_alarm_rate_one_per_hour(window: str | None, rate_hz: float, hours: float) -> None:
    # the default 1 per hour over 30 hours of planar track (≈ 6 s per window kind at 1 Hz;
    # 200 points at 10 Hz, 20 h: ≈ 30 s; 300 points at 20 Hz, 10 h: ≈ 30 s). Measured (4
    # seeds × 30 h at 1 Hz): 0.63-0.75 per hour for "40s", growing, "100pts", "60pts";
    # 200 points at 10 Hz 0.40-0.53, 300 points at 20 Hz 0.53 ± 0.09 (70 h). Before the
    # errors-in-variables terms: 5-12 per hour at 10 Hz; with K_A but not S_B, 6.5 at 20 Hz.
    r = false_alarm_runs(hours, 11, window=window, rate_hz=rate_hz)
    assert r["rate"] <= r["stated"] + 3 * r["se"], (window, r)


def test_detection_of_a_turn_into_a_climbing_turn() -> None:
    # level turn (7 km, 200 m/s) → turn in a plane tilted by 30° about the velocity,
    # σ = 50 m, 1 Hz, 40 s window, one false alarm per hour: detected in ≥ 90 % of 40
    # runs within 20 s (measured: all, median 13 s, 90th percentile 15 s)
    r = detection_runs(40, 1, tilt_deg=30.0, sigma=50.0, window="40s")
    assert r["detected"] >= 0.9
    assert r["p90"] <= 20.0
    assert r["early"].sum() <= 2  # 40 × 120 s = 1.3 h before the change: ~1 allowed
    # and with 30 m, even a 10° tilt within 25 s
    r = detection_runs(20, 2, tilt_deg=10.0, sigma=30.0, window="40s")
    assert r["detected"] >= 0.9 and r["p90"] <= 25.0


@pytest.mark.slow
def test_detection_with_radar_covariances() -> None:
    # one radar 42 km away (σ_range 10 m, σ_az = σ_el = 2 mrad: 85 m across the beam),
    # the general-covariance path (fit_general per window): 30° tilt in ≥ 90 % of 20 runs
    # within 35 s (measured: all, median 21 s, 90th percentile 27 s)
    r = detection_runs(20, 2, tilt_deg=30.0, errors="radar", window="40s")
    assert r["detected"] >= 0.9 and r["p90"] <= 35.0


def test_detection_with_radar_covariances_fast() -> None:
    r = detection_runs(3, 2, tilt_deg=90.0, errors="radar", window="40s")
    assert r["detected"] == 1.0 and r["p90"] <= 35.0


@pytest.mark.parametrize("about", ["least informed", "velocity"])
def test_detectable_tilt_has_the_stated_power(about: str) -> None:
    # A 40 s reference arc and a 20 s test segment rotated by θ* (the reported detectable
    # tilt) about an axis through the junction -- in the least informed direction, or
    # about the velocity (a bank change): the detector fires with probability 0.9 (400
    # runs, se 0.015). σ = 10 m keeps θ* small (3-6°), where the linear theory holds.
    # The tracker's statistic and figure: K_A and S_B of the errors in variables (at
    # σ = 50 m, least informed direction: θ* = 41°, measured power 0.94 in 1000 runs; with
    # J_A and J_B alone θ* was 33° and its power 0.79).
    sig = 10.0
    sc = plane_change_track(0, tilt_deg=0.0, before=80.0, after=0.0, sigma=sig)
    x, cov = sc.truth, sig**2 * np.eye(3)
    a_pts, b_pts, c = x[:41], x[41:61], x[40]
    n, a = sc.normals[0], sc.offsets[0]
    covs = np.broadcast_to(cov, (61, 3, 3))
    ja, _ = det.score_info_points(n, a, c, a_pts, covs[:41], 1000.0, 1.0)
    jb, _ = det.score_info_points(n, a, c, b_pts, covs[41:], 1000.0, 1.0)
    ka, _ = det.reference_information(ja[None], det.noise_info_points(n, covs[:41], 1e3, 1.0)[None])
    sb = (jb - det.noise_info_points(n, covs[41:], 1000.0, 1.0))[None]
    thr, _ = det.detector_threshold(1.0 / 3600.0, 1.0, 3)
    lam = det.noncentrality_for_power(thr, 0.9)
    assert stats.ncx2.sf(thr, 3, lam) == pytest.approx(0.9, abs=1e-9)
    e = plane.verify._tangent_basis(n[None])[0]
    if about == "velocity":
        u = det.velocity_direction(n[None], e[None], x, np.array([40]), np.array([5]))[0]
        theta = float(det.detectable_tilt(ka, jb[None], np.ones(1), lam, u[None], sb)[0])
        # the axis k = n × (change of the normal) is the tangent, up to the lag of the 5 s
        # chord that estimates it (half its arc: 2.5 s × 0.0286 rad/s = 4°, cos = 0.9974)
        tangent = (x[41] - x[39]) / np.linalg.norm(x[41] - x[39])
        assert abs(float(np.cross(n, e.T @ u) @ tangent)) == pytest.approx(
            np.cos(2.5 * 200.0 / 7000.0), abs=1e-4
        )
    else:
        theta = float(det.detectable_tilt(ka, jb[None], np.ones(1), lam, sb=sb)[0])
        f = det.change_information(ka, jb[None], sb)[0]
        u = np.linalg.eigh(f[:2, :2])[1][:, 0]
    assert 0.03 < theta < 0.15
    k = np.cross(n, e.T @ u)
    k /= np.linalg.norm(k)
    v = b_pts - c
    b_rot = c + (
        v * np.cos(theta)
        + np.cross(k, v) * np.sin(theta)
        + np.outer(v @ k, k) * (1 - np.cos(theta))
    )
    rng = np.random.default_rng(3)
    hits = 0
    runs = 400
    for _ in range(runs):
        an = a_pts + sig * rng.normal(size=a_pts.shape)
        bn = b_rot + sig * rng.normal(size=b_rot.shape)
        cf = plane.closed_form(plane.PlaneData(an, cov))
        j1, b1 = det.score_info_points(cf.normal, cf.offset, an[-1], an, covs[:41], 1e3, 1.0)
        j2, b2 = det.score_info_points(cf.normal, cf.offset, an[-1], bn, covs[41:], 1e3, 1.0)
        k1, _ = det.reference_information(
            j1[None], det.noise_info_points(cf.normal, covs[:41], 1e3, 1.0)[None]
        )
        s2 = j2 - det.noise_info_points(cf.normal, covs[41:], 1e3, 1.0)
        u_ = det.change_statistic(k1, np.linalg.solve(j1, b1)[None], j2[None], b2[None], s2[None])
        hits += bool(u_[0] > thr)
    assert abs(hits / runs - 0.9) <= 3 * np.sqrt(0.09 / runs)


def test_track_reports_both_power_figures() -> None:
    sc = plane_change_track(15, tilt_deg=0.0, before=120.0, after=0.0, sigma=30.0)
    tr = track(sc.times, sc.points, sc.cov, window_seconds=40.0)
    ok = np.isfinite(tr.detectable_tilt_any)
    assert ok.sum() > 50
    assert np.all(tr.detectable_tilt[ok] <= tr.detectable_tilt_any[ok] + 1e-12)
    # σ = 30 m, 40 s window, 1/h: a bank change of ~10° (measured: 10° is detected in all
    # of 50 runs within 22 s), any rotation of ~17°
    assert np.deg2rad(5.0) < np.median(tr.detectable_tilt[ok]) < np.deg2rad(15.0)


def test_detectable_tilt_grows_with_the_noise() -> None:
    # The power figure scales with σ: the linear information J ∝ 1/σ² (sin θ* ∝ σ), less
    # its part due to the in-plane noise (N, the same for every σ in units of v = nᵀDn;
    # errors in variables), so sin θ* grows with σ slightly faster than σ -- exactly as σ
    # where N/J is negligible. Step by step, on the steps tested at both σ, away from
    # saturation (sin θ* < 0.5).
    sc = plane_change_track(9, tilt_deg=0.0, before=100.0, after=0.0, sigma=1.0)

    def ratios(s1: float, s2: float) -> np.ndarray:
        out = []
        for sig in (s1, s2):
            tr = track(
                sc.times,
                sc.truth,
                sig**2 * np.eye(3),
                window_seconds=40.0,
                false_alarm_rate_per_h=3.6e-9,
            )
            out.append(np.sin(np.where(np.isfinite(tr.detectable_tilt), tr.detectable_tilt, 0)))
        ok = (out[0] > 0) & (out[1] > 0) & (out[1] < 0.5)
        assert ok.sum() > 30
        return out[1][ok] / out[0][ok]

    assert np.median(ratios(0.25, 1.0)) == pytest.approx(4.0, rel=1e-4)  # N/J ~ 1e-5
    r = np.median(ratios(10.0, 40.0))  # N/J ~ 1e-3 (measured 4.08)
    assert 4.01 < r < 4.2


def test_restart_forgets_the_old_plane() -> None:
    sc = plane_change_track(10, tilt_deg=45.0, sigma=30.0)
    tr = track(sc.times, sc.points, sc.cov, window=None)
    k = int(np.flatnonzero(tr.change)[0])
    assert sc.change_time < tr.times[k] <= sc.change_time + 20.0
    assert np.isfinite(tr.change_time[k]) and np.isnan(tr.change_time[~tr.change]).all()
    after = np.arange(tr.n_steps) > k
    assert np.all(tr.window_start[after] > tr.change_time[k])
    # the last step's plane is the new one (CRB-sized error, σ = 30 m, 60 s of arc)
    assert plane.angle_error(tr.normals[-1], sc.normals[1]) <= np.deg2rad(3.0)
    assert plane.angle_error(tr.normals[k - 1], sc.normals[0]) <= np.deg2rad(3.0)


# --------------------------------------------------------------------------- general D_i
def test_general_covariances_use_fit_general_per_window() -> None:
    sc = plane_change_track(11, tilt_deg=0.0, before=90.0, after=0.0, errors="radar")
    tr = track(sc.times, sc.points, sc.cov, window_points=30, false_alarm_rate_per_h=3.6e-9)
    assert tr.method == "general"
    for k in (5, 40, tr.n_steps - 1):
        m = (sc.times <= tr.times[k]) & (sc.times >= tr.window_start[k])
        assert m.sum() == 30 or k < 30
        ref = plane.solve(plane.PlaneData(sc.points[m], sc.cov[m]), "reduced")
        fit = fit_general(sc.points[m], sc.cov[m], level=tr.level)
        assert tr.resolved[k] == fit.resolved
        if tr.resolved[k]:
            assert plane.angle_error(tr.normals[k], ref.normal) <= 1e-7
            assert tr.statistic[k] == pytest.approx(ref.objective, rel=1e-7)


def test_radar_covariance_builder_agrees_with_simulation() -> None:
    sc = plane_change_track(12, errors="radar", before=20.0, after=0.0)
    cov = radar_covariances(sc.truth, np.array([-30e3, -30e3, 0.0]), 10.0, 2e-3, 2e-3)
    assert np.allclose(sc.cov, cov)


# --------------------------------------------------------------------------- API
def test_rows_and_json() -> None:
    sc = plane_change_track(13, tilt_deg=60.0, sigma=40.0, before=60.0, after=30.0)
    tr = track(sc.times, sc.points, sc.cov, window_seconds=40.0)
    rows = tr.to_rows()
    assert len(rows) == tr.n_steps
    assert {
        "time",
        "nx",
        "ny",
        "nz",
        "offset",
        "statistic",
        "threshold",
        "resolved",
        "planar",
        "change",
        "detector",
        "detectable_tilt",
    } <= set(rows[0])
    assert [r["change"] for r in rows] == tr.change.tolist()
    d = tr.to_dict()
    text = json.dumps(d, allow_nan=False)
    back = json.loads(text)
    assert len(back["normals"]) == tr.n_steps and len(back["normals"][0]) == 3
    assert back["change_times"] == tr.change_times.tolist()
    nan_rows = ~tr.resolved
    assert all(
        v is None for row in np.asarray(back["normals"], dtype=object)[nan_rows] for v in row
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"window": True}, "plane.track window"),
        ({"window_points": 3}, "plane.track window_points"),
        ({"window_points": 40.0}, "plane.track window_points"),
        ({"window_seconds": -5.0}, "plane.track window_seconds"),
        ({"window_seconds": 1e-3}, "plane.track window_seconds"),
        ({"window_seconds": 40.0, "scales": [30.0]}, "plane.track scales"),
        ({"window": "40s", "window_points": 40}, "give one window"),
        ({"window": "40"}, "does not say its unit"),
        ({"window": "3pts"}, r"plane.track window \(points\)"),
        ({"level": 1.0}, "plane.track level"),
        ({"false_alarm_rate_per_h": 0.0}, "plane.track false_alarm_rate_per_h"),
        ({"false_alarm_rate_per_h": 36000.0}, "plane.track false_alarm_rate_per_h"),
        ({"scales": []}, "plane.track scales"),
        ({"scales": [5.0, -1.0]}, r"plane.track scales\[1\]"),
        ({"window_points": 40, "scales": [2.5]}, r"plane.track scales\[0\]"),
        ({"start": 1e9}, "plane.track start"),
        ({"power": 0.0}, "plane.track power"),
        ({"min_reference": 2}, "plane.track min_reference"),
        ({"max_reference_sd": 0.0}, "plane.track max_reference_sd"),
    ],
)
def test_bad_arguments_are_problem_errors(kwargs: dict, match: str) -> None:
    sc = plane_change_track(14, before=30.0, after=0.0)
    with pytest.raises(ProblemError, match=match):
        track(sc.times, sc.points, sc.cov, **kwargs)


@pytest.mark.parametrize("window", [40, 40.0, np.int64(40), np.float64(40.0)])
def test_a_bare_number_window_is_refused_saying_what_to_write(window: float) -> None:
    """Issue 26: ``window=40`` (points) and ``window=40.0`` (seconds) read alike; both are
    refused, and the message names the two keywords that say the unit."""
    sc = plane_change_track(14, before=30.0, after=0.0)
    with pytest.raises(ProblemError, match=r"window_seconds=40\.0.*window_points=100"):
        track(sc.times, sc.points, sc.cov, window=window)


def test_window_keywords_and_text_are_the_same_window() -> None:
    sc = plane_change_track(14, before=60.0, after=0.0)
    a = track(sc.times, sc.points, sc.cov, window_seconds=20.0)
    b = track(sc.times, sc.points, sc.cov, window="20 s")
    c = track(sc.times, sc.points, sc.cov, window_points=41)
    d = track(sc.times, sc.points, sc.cov, window="41pts")
    assert a.window == 20.0 and c.window == 41
    np.testing.assert_array_equal(a.n_points, b.n_points)
    np.testing.assert_array_equal(c.n_points, d.n_points)
    assert a.to_dict()["window"] == "20s" and c.to_dict()["window"] == "41pts"
    # a seconds window and a points window differ (2 Hz: 20 s holds 40 or 41 points)
    assert int(np.max(a.n_points)) <= 41 and int(np.max(c.n_points)) == 41


def test_false_alarm_rate_is_per_hour_and_the_old_keyword_is_refused() -> None:
    sc = plane_change_track(14, before=30.0, after=0.0)
    tr = track(sc.times, sc.points, sc.cov, false_alarm_rate_per_h=2.0)
    assert tr.false_alarm_rate_per_h == 2.0 and tr.to_dict()["false_alarm_rate_per_h"] == 2.0
    dt = float(np.median(np.diff(sc.times)))
    # each test's level is rate (per s) · dt / scales
    assert tr.test_level == pytest.approx(2.0 / 3600.0 * dt / len(tr.scales), rel=1e-12)
    with pytest.raises(ProblemError, match="false_alarm_rate_per_h=1 "):
        track(sc.times, sc.points, sc.cov, false_alarm_rate=1.0 / 3600.0)


def test_bad_arrays_are_problem_errors() -> None:
    sc = plane_change_track(14, before=30.0, after=0.0)
    with pytest.raises(ProblemError, match=r"plane.track times"):
        track(sc.times[::-1], sc.points, sc.cov)
    with pytest.raises(ProblemError, match=r"plane.track times"):
        track(sc.times[:-1], sc.points, sc.cov)
    with pytest.raises(ProblemError, match=r"plane.track: plane.PlaneData cov"):
        track(sc.times, sc.points, np.eye(2))
    with pytest.raises(ProblemError, match=r"plane.track: plane.PlaneData points"):
        track(sc.times, sc.points[:, :2], sc.cov)


def test_score_has_mean_zero_for_anisotropic_covariances() -> None:
    # D with its long axis tilted 30° out of the plane: the in-plane error of a measured
    # point is correlated with its distance to the plane. With the measured coordinates in
    # h_i the score b would have mean Σ E D n / v ≠ 0 (radar false alarms: 1.6 per hour at
    # a bound of 1, 48 in 30 h); with the oblique projections (1.8) it is zero (0.9 per
    # hour, 27 in 30 h). 2000 draws of a
    # 20-point segment on the true plane: each mean within 4 se of 0; and the moments route
    # (1.4) equals the per-point route to 1e-9.
    rng = np.random.default_rng(16)
    sc = plane_change_track(16, tilt_deg=0.0, before=40.0, after=0.0)
    x = sc.truth[:20]
    n, a = sc.normals[0], sc.offsets[0]
    e = plane.verify._tangent_basis(n[None])[0]
    axis = np.cos(np.deg2rad(30.0)) * e[0] + np.sin(np.deg2rad(30.0)) * n
    cov = 80.0**2 * np.outer(axis, axis) + 15.0**2 * np.eye(3)
    alpha2 = rng.uniform(0.5, 2.0, len(x))
    covs = alpha2[:, None, None] * cov
    chol = np.linalg.cholesky(covs)
    c = x[0]
    bs, naive = [], []
    for _ in range(2000):
        xn = x + (chol @ rng.normal(size=(len(x), 3, 1)))[..., 0]
        _, b = det.score_info_points(n, a, c, xn, covs, 1000.0, 1.0)
        bs.append(b)
        u = (xn - c) / 1000.0
        r = (xn @ n - a) / 1000.0
        v = np.einsum("i,kij,j->k", n, covs, n) / 1e6
        naive.append(np.column_stack([u @ e.T, -np.ones(len(u))]).T @ (r / v))
    bs, naive = np.asarray(bs), np.asarray(naive)
    se = bs.std(axis=0) / np.sqrt(len(bs))
    assert np.all(np.abs(bs.mean(axis=0)) <= 4 * se)
    assert np.abs(naive.mean(axis=0)[0]) > 10 * se[0]  # what the correction removes
    xn = x + (chol @ rng.normal(size=(len(x), 3, 1)))[..., 0]
    jp, bp = det.score_info_points(n, a, c, xn, covs, 1000.0, 0.7)
    mom = range_moments(xn, 1.0 / alpha2, np.array([0]), np.array([len(x) - 1]), spread=1000.0)
    jm, bm = det.score_info_moments(n[None], np.array([a]), c[None], mom, cov, np.array([0.7]))
    assert np.allclose(jm[0], jp, rtol=1e-9, atol=1e-12 * np.abs(jp).max())
    assert np.allclose(bm[0], bp, rtol=1e-9, atol=1e-12 * np.abs(bp).max())


@pytest.mark.slow
def test_false_alarm_rate_with_radar_covariances() -> None:
    # general D_i (fit_general per window), stated 60 per hour over 1 h of planar track
    # (≈ 20 s); measured 17-27 per hour
    r = false_alarm_runs(
        1.0, 13, window="40s", errors="radar", false_alarm_rate_per_h=60.0, run_hours=0.25
    )
    assert r["alarms"] > 0
    assert r["rate"] <= r["stated"] + 3 * r["se"]
