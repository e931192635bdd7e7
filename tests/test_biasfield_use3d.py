"""Using the bias field in 3-D (issue 17): FieldSolution.at, correct_plots, registration
error and the ADS-B referee on the exact 3-D chain (slant ranges, each radar's own north)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.spatial import Delaunay

from optmodels import biasfield as bf
from optmodels.biasfield.referee import absolute_error, adsb_field, compare_fields
from optmodels.biasfield.tables import RadarSet
from optmodels.biasfield.usage import FieldMap, correct_plots, field_map, registration_error
from optmodels.core import ProblemError, Status
from optmodels.scenarios.radar_network import radar_network

SIGMA_ADSB = 10.0  # m, 1σ per horizontal axis (95 % radial 24 m: NACp 9)


def _build(sc, cells: int = 40):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # cells without all radars dropped
        fd, _ = bf.build_field_data(sc.plots, sc.radars, cells=cells)
    return fd


@pytest.fixture(scope="module")
def net3d():
    """3-D traffic at 3-12 km, four radars at their own heights, the smooth field."""
    sc = radar_network(1, n_aircraft=40, duration=1800.0, geometry="3d")
    fd = _build(sc)
    assert fd.is_3d
    sol = bf.closed_form(fd)
    assert sol.status.ok
    ref = sc.adsb_positions(21, sigma=SIGMA_ADSB)
    return sc, fd, sol, ref


# ----------------------------------------------------------------------------- FieldSolution.at
def test_solution_at_reproduces_the_cells_exactly_and_carries_the_3d_frame(net3d):
    sc, fd, sol, _ = net3d
    np.testing.assert_array_equal(sol.at(fd.centers), sol.field)  # bit for bit
    np.testing.assert_array_equal(sol.centers, fd.centers)
    fm = sol.map(names=sc.radars.names)
    assert fm.is_3d and fm.names == sc.radars.names
    np.testing.assert_array_equal(fm.origin, sc.radars.origin)
    np.testing.assert_array_equal(fm.geodetic, sc.radars.geodetic)
    # the same interpolant as field_map(solution, data)
    q = np.random.default_rng(3).uniform(-100e3, 100e3, (500, 2))
    np.testing.assert_array_equal(np.isnan(sol.at(q)), np.isnan(field_map(sol, fd).at(q)))
    np.testing.assert_allclose(sol.at(q), field_map(sol, fd).at(q), rtol=0, atol=0)


def _analytic_fields(m: int):
    """Known smooth fields with an analytic Hessian bound: range A sin(x/a) cos(y/b), azimuth
    B cos(x/c) sin(y/d); ‖∇²f‖₂ ≤ ‖∇²f‖_F ≤ A (1/a² + 1/b²) (and likewise for B)."""
    pars = [
        (120.0, 80e3, 110e3, 4e-3, 120e3, 70e3),
        (-80.0, 100e3, 60e3, -3e-3, 90e3, 140e3),
        (150.0, 70e3, 130e3, 5e-3, 76e3, 104e3),
        (60.0, 140e3, 80e3, 2e-3, 60e3, 88e3),
    ]
    pars = pars[:m]

    def value(x: np.ndarray) -> np.ndarray:
        out = np.empty((*x.shape[:-1], m, 2))
        for i, (ra, a, b, az, c, d) in enumerate(pars):
            out[..., i, 0] = ra * np.sin(x[..., 0] / a) * np.cos(x[..., 1] / b)
            out[..., i, 1] = az * np.cos(x[..., 0] / c) * np.sin(x[..., 1] / d)
        return out

    bound = np.array(
        [
            [abs(ra) * (1 / a**2 + 1 / b**2), abs(az) * (1 / c**2 + 1 / d**2)]
            for ra, a, b, az, c, d in pars
        ]
    )  # (m, 2)
    return value, bound


def test_solution_at_off_the_centres_matches_a_known_smooth_field_3d(net3d):
    # a FieldSolution whose cell values are a known smooth field, evaluated at the true
    # plane positions of the 3-D plots: the P1 error at x in a triangle of longest edge h
    # is at most ½ M h² (Taylor at x: Πf(x) − f(x) = Σ λ_j R_j, |R_j| ≤ ½ M |v_j − x|²)
    sc, fd, sol, _ = net3d
    value, bound = _analytic_fields(fd.m)
    known = dataclasses.replace(sol, field=value(fd.centers))
    x = sc.true_position
    got = known.at(x)
    cov = known.covered(x)
    assert cov.mean() > 0.3
    np.testing.assert_array_equal(np.isfinite(got).all(axis=(1, 2)), cov)
    tri = Delaunay(fd.centers)  # independent point location (scipy's walk)
    simplex = tri.find_simplex(x[cov])
    assert np.all(simplex >= 0)
    v = fd.centers[tri.simplices[simplex]]
    h = np.max(np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2), axis=1)  # longest edge
    err = np.abs(got[cov] - value(x[cov]))  # (n, m, 2)
    limit = 0.5 * bound[None] * (h**2)[:, None, None]
    assert np.all(err <= limit * (1 + 1e-9) + 1e-12), float(np.max(err / limit))
    # and the bound is not vacuous: on fields smooth over ≥ 60 km (the cells are ≈ 30 km
    # apart) the error is small against the field itself
    rms_err = np.sqrt(np.mean(err**2, axis=0))
    rms_f = np.sqrt(np.mean(value(x[cov]) ** 2, axis=0))
    assert np.all(rms_err <= 0.1 * rms_f), rms_err / rms_f


def test_solution_at_is_nan_outside_the_covered_area(net3d):
    _, fd, sol, _ = net3d
    far = np.array([[0.0, 2e6], fd.centers.max(axis=0) + 80e3])
    assert np.all(np.isnan(sol.at(far))) and not sol.covered(far).any()
    failed = dataclasses.replace(sol, status=Status.ERROR)
    with pytest.raises(ProblemError, match="status"):
        failed.at(fd.centers)


# ----------------------------------------------------------------------------- the frame
def test_field_map_frame_is_saved_and_checked(net3d, tmp_path):
    sc, fd, sol, _ = net3d
    fm = sol.map(names=sc.radars.names)
    fm.save(tmp_path / "field.npz")
    back = FieldMap.load(tmp_path / "field.npz")
    assert back.names == fm.names and back.is_3d
    np.testing.assert_array_equal(back.origin, fm.origin)
    np.testing.assert_array_equal(back.at(fd.centers), sol.field)
    back.check_radars(sc.radars)  # its own network: accepted
    flat = RadarSet(
        sc.radars.sites,
        sc.radars.sigma_range,
        sc.radars.sigma_azimuth,
        sc.radars.max_range,
        names=sc.radars.names,
    )
    moved = RadarSet(
        None,
        sc.radars.sigma_range,
        sc.radars.sigma_azimuth,
        sc.radars.max_range,
        names=sc.radars.names,
        geodetic=sc.radars.geodetic,
        origin=np.add(sc.radars.origin, [0.01, 0.0, 0.0]),
    )
    renamed = dataclasses.replace(sc.radars, names=("A", "B", "C", "D"))
    for other, what in ((flat, "3-D chain"), (moved, "origin"), (renamed, "estimated for")):
        with pytest.raises(ProblemError, match=what):
            correct_plots(sc.plots, other, back)


def test_a_field_file_without_its_frame_is_checked_on_the_sites_only(net3d, tmp_path):
    # what `optmodels biasfield solve` writes today (field, eta, centers, radars = the
    # sites, active): the chain is unknown, so a 3-D radar set with the same plane sites is
    # accepted and the correction is the same as with the full frame; a field marked as
    # the 2-D chain's is refused on a 3-D set
    sc, fd, sol, _ = net3d
    np.savez_compressed(
        tmp_path / "field.npz",
        field=sol.field,
        eta=sol.eta,
        centers=fd.centers,
        radars=fd.radars,
        active=sol.active,
    )
    bare = FieldMap.load(tmp_path / "field.npz")
    assert bare.chain == "" and not bare.is_3d
    a = correct_plots(sc.plots, sc.radars, bare)
    b = correct_plots(sc.plots, sc.radars, sol.map())
    np.testing.assert_array_equal(a.plots.range, b.plots.range)
    np.testing.assert_array_equal(a.plots.azimuth, b.plots.azimuth)
    flat2d = FieldMap(fd.centers, sol.field, sites=fd.radars, chain="2d")
    with pytest.raises(ProblemError, match="2-D chain"):
        correct_plots(sc.plots, sc.radars, flat2d)
    with pytest.raises(ProblemError, match="sites"):
        FieldMap(fd.centers, sol.field, sites=fd.radars + 5e3).check_radars(sc.radars)


# ----------------------------------------------------------------------------- correct_plots
def test_correct_plots_with_a_zero_field_is_the_identity_3d(net3d):
    sc, _, sol, _ = net3d
    zero = dataclasses.replace(sol, field=np.zeros_like(sol.field)).map()
    out = correct_plots(sc.plots, sc.radars, zero)
    for col in ("range", "azimuth", "time", "radar", "object", "height"):
        np.testing.assert_array_equal(getattr(out.plots, col), getattr(sc.plots, col))
    assert np.all(out.bias == 0.0) and 0 < out.n_uncovered < len(sc.plots)


def test_correct_plots_with_the_true_field_removes_the_bias_3d(net3d):
    sc, _, _, _ = net3d
    g = np.linspace(-300e3, 300e3, 81)  # dense map of the true field (7.5 km spacing)
    c = np.array([[x, y] for x in g for y in g])
    fm = FieldMap(
        c,
        np.stack([f(c) for f in sc.fields], axis=1),
        names=sc.radars.names,
        sites=sc.radars.sites,
        geodetic=sc.radars.geodetic,
        origin=sc.radars.origin,
    )
    out = correct_plots(sc.plots, sc.radars, fm)
    sel = out.covered
    # interpolation error of the dense map plus the bias's change between the measured and
    # the true position (≤ 1 m, 1e-5 rad for bumps of 150 m / 0.3° over ≥ 75 km)
    dr = out.plots.range[sel] - (sc.plots.range[sel] - sc.true_bias[sel, 0])
    da = out.plots.azimuth[sel] - (sc.plots.azimuth[sel] - sc.true_bias[sel, 1])
    assert sel.mean() > 0.95
    assert np.quantile(np.abs(dr), 0.99) < 2.0
    assert np.quantile(np.abs(da), 0.99) < 3e-5
    np.testing.assert_array_equal(out.plots.height, sc.plots.height)


# ----------------------------------------------------------------------------- registration
def test_registration_error_uses_the_exact_3d_geometry():
    # no bias: the 3-D chain registers the radars to within the noise of the per-area
    # means (the squared estimate has mean 0 and sd ≈ √(2/A)·noise² over A ≈ 30 areas, so
    # its root stays below ≈ 0.9·noise at 3σ); the flat 2-D chain on the same plots shows
    # the slant-range and meridian-convergence errors as a disagreement of kilometres
    sc = radar_network(4, n_aircraft=30, duration=1200.0, geometry="3d", fields="zero")
    reg = registration_error(sc.plots, sc.radars)
    assert reg.overall <= reg.noise, (reg.overall, reg.noise)
    assert reg.raw_overall > 2 * reg.noise  # the per-plot noise is far larger
    flat = RadarSet(
        sc.radars.sites, sc.radars.sigma_range, sc.radars.sigma_azimuth, sc.radars.max_range
    )
    assert registration_error(sc.plots, flat).overall > 1000.0
    ab = absolute_error(sc.plots, sc.radars, sc.adsb_positions(5, sigma=SIGMA_ADSB))
    assert ab.overall <= ab.noise


def test_registration_and_absolute_error_read_a_known_site_offset_3d():
    # radar R1's site given 224 m off its true place (same height): its plots are placed
    # shifted by that offset (to ≈ d·|δ|/R ≈ 5 m from the rotation of its north), so the
    # pairs with R1 disagree by |δ| and the others by 0; the estimates must read that
    # within their own reported noise (and the absolute error against ADS-B of R1 too).
    # For |μ| ≫ noise the figure's error is ≈ noise/√areas (≈ 8 m here); for μ = 0 the
    # clipped root stays below ≈ 0.9 × noise at 3σ (see the zero-field test)
    from optmodels.biasfield import geometry3d as g3

    sc = radar_network(6, n_aircraft=30, duration=1200.0, geometry="3d", fields="zero")
    delta = np.array([200.0, -100.0])
    geo = np.array(sc.radars.geodetic, dtype=float)
    lat, lon = g3.plane_to_geodetic(sc.radars.sites[:1] + delta, sc.radars.origin)
    geo[0, :2] = [lat[0], lon[0]]
    told = RadarSet(
        None,
        sc.radars.sigma_range,
        sc.radars.sigma_azimuth,
        sc.radars.max_range,
        geodetic=geo,
        origin=sc.radars.origin,
    )
    reg = registration_error(sc.plots, told)
    size = float(np.linalg.norm(delta))
    for (a, b), v in reg.pairs.items():
        want = size if "R1" in (a, b) else 0.0
        tol = reg.noise_pairs[(a, b)] + 5.0
        assert abs(v - want) <= tol, ((a, b), v, want, tol)
    ab = absolute_error(sc.plots, told, sc.adsb_positions(7, sigma=SIGMA_ADSB))
    assert abs(ab.radars["R1"] - size) <= ab.noise + 5.0, ab.radars
    assert all(v <= ab.noise for k, v in ab.radars.items() if k != "R1"), ab.radars


def test_correcting_with_the_smoothest_field_cuts_registration_by_80_percent_3d(net3d):
    sc, _, sol, _ = net3d
    fm = sol.map()
    before = registration_error(sc.plots, sc.radars, within=fm)
    after = registration_error(correct_plots(sc.plots, sc.radars, fm).plots, sc.radars, within=fm)
    assert before.overall > 5 * before.noise  # a disagreement well above the noise floor
    assert after.overall <= 0.2 * before.overall
    assert set(after.pairs) == set(before.pairs) and len(before.pairs) == 6
    for pair, v in before.pairs.items():
        assert after.pairs[pair] <= 0.2 * v, (pair, after.pairs[pair], v)


# ----------------------------------------------------------------------------- ADS-B referee
@pytest.fixture(scope="module")
def referee(net3d):
    sc, fd, sol, ref = net3d
    af = adsb_field(fd, sc.plots, sc.radars, ref, sigma_reference=SIGMA_ADSB)
    out = compare_fields(sc.plots, sc.radars, ref, {"smoothest": sol.map(), "adsb": af.map(fd)})
    return af, out


def test_adsb_field_cuts_the_absolute_error_by_80_percent_3d(referee):
    af, out = referee
    assert af.status.ok and af.stationarity < 1e-9
    assert af.chi2 == pytest.approx(af.dof, rel=1e-2)  # on the discrepancy level
    before, after = out["before"]["absolute"], out["adsb"]["absolute"]
    assert before["overall_m"] > 5 * before["noise_m"]
    assert after["overall_m"] <= 0.2 * before["overall_m"]
    # the smoothest field and the ADS-B field both register the radars
    reg = out["before"]["registration"]["overall_m"]
    assert out["smoothest"]["registration"]["overall_m"] <= 0.2 * reg
    assert out["adsb"]["registration"]["overall_m"] <= 0.2 * reg


def test_adsb_field_least_squares_level_fits_the_means(net3d):
    # level="means": the field is the weighted least-squares fit of the data, so χ² is at
    # its minimum, below the discrepancy level, and the smoothness only fills the cells
    # without ADS-B data; with an exact reference (σ_ref = 0) every plot of radar i has the
    # weight V_i⁻¹ and the fit is the plain per-cell mean
    sc, fd, _, _ = net3d
    ref = sc.true_position
    ls = adsb_field(fd, sc.plots, sc.radars, ref, level="means", sigma_reference=0.0)
    dp = adsb_field(fd, sc.plots, sc.radars, ref, sigma_reference=0.0)
    assert ls.status.ok and ls.stationarity < 1e-9
    assert ls.chi2 < dp.chi2 and dp.objective < ls.objective
    seen = ls.counts > 0
    np.testing.assert_allclose(ls.field[seen], ls.mean[seen], rtol=1e-6, atol=1e-6)


def test_adsb_positions_are_truth_plus_the_stated_noise(net3d):
    sc, _, _, ref = net3d
    d = ref - sc.true_position
    n = d.size
    # sample sd of n normal draws: relative standard error 1/√(2n); 4 standard errors
    assert abs(np.std(d) / SIGMA_ADSB - 1.0) < 4 / np.sqrt(2 * n)
    assert abs(np.mean(d)) < 4 * SIGMA_ADSB / np.sqrt(n)
    np.testing.assert_array_equal(sc.adsb_positions(21, sigma=SIGMA_ADSB), ref)  # seeded
    np.testing.assert_array_equal(sc.adsb_positions(0, sigma=0.0), sc.true_position)


def test_adsb_reference_interpolates_the_reports_at_the_plot_times(net3d):
    # ADS-B reports = the simulator's path samples (1 s, geodetic), as a recording's
    # CAT021 would give them; the plots' true positions are the same path interpolated
    # linearly in latitude/longitude/height, so the two agree to the plane map's curvature
    # over one 1 s step (≤ s²/2R ≈ 4 mm for s = 230 m); a 60 s gap in one aircraft's
    # reports is not bridged
    from optmodels.biasfield.recording import AdsbReports
    from optmodels.biasfield.referee import adsb_reference

    sc, _, _, _ = net3d
    cols: dict[str, list[np.ndarray]] = {"t": [], "o": [], "lat": [], "lon": [], "h": []}
    for a in range(len(sc.paths)):
        t, _, geo = sc.paths.track(a)
        if a == 3:  # a gap of 60 s in the middle of aircraft 3's reports
            mid = t[t.size // 2]
            keep = np.abs(t - mid) > 30.0
            t, geo = t[keep], geo[keep]
        for key, v in zip(
            cols, (t, np.full(t.size, a), geo[:, 0], geo[:, 1], geo[:, 2]), strict=True
        ):
            cols[key].append(v)
    c = {k: np.concatenate(v) for k, v in cols.items()}
    reports = AdsbReports(
        c["t"],
        c["o"],
        np.full(c["t"].size, -1),
        c["lat"],
        c["lon"],
        c["h"],
        np.full(c["t"].size, np.nan),
    )
    ref = adsb_reference(sc.plots, reports, sc.radars.origin, max_gap=10.0)
    has = np.all(np.isfinite(ref), axis=1)
    t3, _, _ = sc.paths.track(3)
    in_gap = (sc.plots.object == 3) & (np.abs(sc.plots.time - t3[t3.size // 2]) < 29.0)
    assert in_gap.any() and not has[in_gap].any()
    assert has[~in_gap].mean() > 0.999
    err = np.linalg.norm(ref[has] - sc.true_position[has], axis=1)
    assert np.max(err) < 5e-3, np.max(err)
    with pytest.raises(ProblemError, match="adsb"):
        adsb_reference(sc.plots, sc.plots, sc.radars.origin)


# ----------------------------------------------------------------------------- baseline 3-D
def test_parametric_baseline_recovers_constant_azimuth_biases_3d():
    sc = radar_network(
        10,
        n_aircraft=30,
        duration=1800.0,
        turn_rate=(0.0, 0.0),
        fields="constant",
        geometry="3d",
        holding=0.0,
    )
    res = bf.azimuth_bias_baseline(sc.plots, sc.radars)
    true = np.array([f(np.zeros((1, 2)))[0, 1] for f in sc.fields])
    z = (res.estimate - true) / res.std
    assert np.all(np.abs(z) < 4.0), z
    # χ²/dof of a right model: 1 ± √(2/dof) (dof ≈ 10⁴: ± 0.014); the polyline's error in
    # the climbs and descents adds a little
    assert 0.95 < res.chi2_per_dof < 1.1, res.chi2_per_dof
    assert np.all(np.abs(true) > 20 * res.std)  # biases of 0.1-0.3° against se ≈ 0.002°


def test_3d_inputs_are_one_problem_error(net3d):
    sc, fd, sol, ref = net3d
    with pytest.raises(ProblemError, match="level"):
        adsb_field(fd, sc.plots, sc.radars, ref, level="gcv")
    with pytest.raises(ProblemError, match="origin"):
        FieldMap(fd.centers, sol.field, geodetic=sc.radars.geodetic)
    with pytest.raises(ProblemError, match="names"):
        FieldMap(fd.centers, sol.field, names=("A",))
    with pytest.raises(ProblemError, match="sigma"):
        sc.adsb_positions(1, sigma=-1.0)
