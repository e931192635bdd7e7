"""Exact 3-D geometry of the bias-field chain (issue 16, item 1): slant ranges, each radar's
own north, targets at their heights above the WGS-84 ellipsoid, the common plane.

Reference values come from pymap3d directly (geodetic2enu, geodetic2ecef, geodetic2aer,
vincenty.vreckon) or from closed-form geometry, never from the code under test."""

from __future__ import annotations

import warnings

import numpy as np
import pymap3d
import pytest
from pymap3d import vincenty

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.cells import build_field_data
from optmodels.biasfield.closedform import closed_form
from optmodels.biasfield.data import FieldData, uncertainty_sets
from optmodels.biasfield.paths import AircraftPaths
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import ProblemError, Status
from optmodels.scenarios.radar_network import radar_network

ORIGIN = np.array([55.0, 83.0, 150.0])  # lat, lon (deg), h (m above the ellipsoid)
WGS84_A, WGS84_F = 6378137.0, 1 / 298.257223563


def _meridian_radius(lat_deg: float) -> float:
    e2 = WGS84_F * (2 - WGS84_F)
    s = np.sin(np.deg2rad(lat_deg))
    return WGS84_A * (1 - e2) / (1 - e2 * s**2) ** 1.5


def test_curvature_drop_at_100_km() -> None:
    """A target on the ellipsoid 100 km north of a radar lies 784 m below the radar's
    horizontal plane (pymap3d ENU; the sphere of the meridian radius gives d²/2M to 1 m),
    and locate() puts it back on its geodetic position to 1 mm from the slant range and
    azimuth that pymap3d's geodetic2aer gives."""
    site = np.array([55.0, 83.0, 0.0])
    lat, lon = vincenty.vreckon(site[0], site[1], 100e3, 0.0)
    _, n, u = pymap3d.geodetic2enu(lat, lon, 0.0, *site)
    assert u == pytest.approx(-(100e3**2) / (2 * _meridian_radius(55.45)), abs=1.5)
    assert -790 < u < -780  # the ~785 m of the issue
    az, _, rng = pymap3d.geodetic2aer(lat, lon, 0.0, *site)
    la, lo, e_, n_ = g3.locate(site, rng, np.deg2rad(az), 0.0, site)
    assert abs(la - lat) * 111e3 < 1e-3 and abs(lo - lon) * 64e3 < 1e-3
    assert abs(n_ - n) < 1e-3 and abs(e_) < 1e-3
    # the radar's own measurement of the same target, against pymap3d's aer
    r, a = g3.measure(site, lat, lon, 0.0)
    assert r == pytest.approx(rng, abs=1e-6) and abs(a - np.deg2rad(az)) < 1e-12


@pytest.mark.parametrize("east", [60e3, -60e3])
def test_each_radar_has_its_own_north(east: float) -> None:
    """A radar 60 km east (west) of the common origin at 55°N: its north is turned on the
    common plane by the meridian convergence γ ≈ Δλ·sin φ (0.77° here; (d/R)·tan φ, i.e.
    0.3° at 29°N), measured with pymap3d's ENU of the origin. measure() reports azimuth 0
    for a target due north of the radar along its meridian, and the plane direction of
    that target from the site (our common_plane) is the pymap3d one."""
    lat_r, lon_r = vincenty.vreckon(ORIGIN[0], ORIGIN[1], abs(east), 90.0 if east > 0 else 270.0)
    site = np.array([lat_r, lon_r, 300.0])
    lat_t, lon_t = vincenty.vreckon(lat_r, lon_r, 50e3, 0.0)
    e0, n0, _ = pymap3d.geodetic2enu(lat_r, lon_r, 0.0, *ORIGIN)
    e1, n1, _ = pymap3d.geodetic2enu(lat_t, lon_t, 0.0, *ORIGIN)
    gamma = np.arctan2(e1 - e0, n1 - n0)
    expected = -np.deg2rad(lon_r - ORIGIN[1]) * np.sin(np.deg2rad(lat_r))
    assert gamma == pytest.approx(expected, rel=0.01)
    assert abs(np.rad2deg(gamma)) > 0.7  # the size of the azimuth biases themselves
    _, az = g3.measure(site, lat_t, lon_t, 9000.0)
    assert abs(az) < 1e-9
    p = g3.common_plane(np.array([lat_r, lat_t]), np.array([lon_r, lon_t]), ORIGIN)
    assert np.arctan2(*(p[1] - p[0])) == pytest.approx(gamma, abs=1e-12)


def test_slant_range_to_a_target_at_10_km() -> None:
    """Slant range to a target 10 km above the ellipsoid, 60 km away: the ECEF distance
    (pymap3d geodetic2ecef), to 1 µm; it exceeds the geodesic ground distance by ~1 km,
    and locate() with the target's height inverts it."""
    site = np.array([55.2, 83.4, 250.0])
    lat, lon = vincenty.vreckon(site[0], site[1], 60e3, 33.0)
    a = np.array(pymap3d.geodetic2ecef(*site))
    b = np.array(pymap3d.geodetic2ecef(lat, lon, 10e3))
    r, az = g3.measure(site, lat, lon, 10e3)
    assert r == pytest.approx(float(np.linalg.norm(b - a)), abs=1e-6)
    assert np.rad2deg(az) == pytest.approx(33.0, abs=0.01)
    assert 800 < r - 60e3 < 1100
    la, lo, _, _ = g3.locate(site, r, az, 10e3, ORIGIN)
    assert abs(la - lat) * 111e3 < 1e-3 and abs(lo - lon) * 64e3 < 1e-3
    # no elevation reaches a height 10 km up with a 5 km slant range: NaN, not a guess
    assert np.isnan(g3.locate(site, 5e3, 0.0, 10e3, ORIGIN)[0])


def test_plane_and_jacobian_against_independent_chains() -> None:
    """common_plane is pymap3d's ENU of the footprint; plane_to_geodetic inverts it to
    1 mm over ±300 km; the Jacobian ∂(r, α)/∂(E, N) at fixed height (differences of
    plane → geodetic → aer) inverts the differences of locate (aer → geodetic → plane)
    to 1e-5 relative."""
    rng = np.random.default_rng(3)
    en = rng.uniform(-300e3, 300e3, (200, 2))
    lat, lon = g3.plane_to_geodetic(en, ORIGIN)
    e, n, _ = pymap3d.geodetic2enu(lat, lon, np.zeros(200), *ORIGIN)
    np.testing.assert_allclose(np.column_stack([e, n]), en, atol=1e-3)
    np.testing.assert_allclose(g3.common_plane(lat, lon, ORIGIN), en, atol=1e-6)
    site = np.array([55.4, 82.1, 400.0])
    x = rng.uniform(-150e3, 150e3, (50, 2))
    h = rng.uniform(3e3, 12e3, 50)
    jac = g3.polar_jacobian3d(x, h, site, ORIGIN)
    pol = g3.to_polar3d(x, h, site, ORIGIN)
    cols = []
    for d in (np.array([20.0, 0.0]), np.array([0.0, 2e-4])):
        hi = g3.locate(site, pol[:, 0] + d[0], pol[:, 1] + d[1], h, ORIGIN)
        lo = g3.locate(site, pol[:, 0] - d[0], pol[:, 1] - d[1], h, ORIGIN)
        cols.append(np.column_stack([hi[2] - lo[2], hi[3] - lo[3]]) / (2 * d.max()))
    inv_fd = np.stack(cols, axis=-1)  # ∂(E, N)/∂(r, α)
    # in units where both coordinates are metres (α·r), the product is I to 1e-7
    scale = np.stack([np.ones(50), pol[:, 0]], axis=-1)  # (r, α·r)
    prod = np.einsum("kab,kbc->kac", jac * scale[:, :, None], inv_fd / scale[:, None, :])
    np.testing.assert_allclose(prod, np.broadcast_to(np.eye(2), prod.shape), atol=1e-7)
    np.testing.assert_allclose(
        g3.plane_jacobian(x, h, site, ORIGIN) / scale[:, None, :],
        inv_fd / scale[:, None, :],
        atol=1e-7,
    )


def test_radar_set_and_plot_table_3d() -> None:
    """Geodetic sites: sites = pymap3d ENU (h = 0) of each site; ids; the errors."""
    geo = np.array([[55.3, 82.0, 200.0], [54.7, 84.1, 450.0]])
    radars = RadarSet(None, 60.0, 1e-3, 3e5, geodetic=geo, origin=ORIGIN, ids=[(1, 2), (1, 3)])
    e, n, _ = pymap3d.geodetic2enu(geo[:, 0], geo[:, 1], np.zeros(2), *ORIGIN)
    np.testing.assert_allclose(radars.sites, np.column_stack([e, n]), atol=1e-6)
    assert radars.is_3d and radars.index_of_id(1, 3) == 1
    default = RadarSet(None, 60.0, 1e-3, 3e5, geodetic=geo)
    np.testing.assert_allclose(default.origin, [55.0, 83.05, 0.0])
    with pytest.raises(ProblemError, match="geodetic"):
        RadarSet(None, 60.0, 1e-3, 3e5, geodetic=geo[:, :2])
    with pytest.raises(ProblemError, match="ids"):
        RadarSet(None, 60.0, 1e-3, 3e5, geodetic=geo, ids=[(1, 2), (1, 2)])
    with pytest.raises(ProblemError, match="ids"):
        RadarSet(None, 60.0, 1e-3, 3e5, geodetic=geo, ids=[(1, 256), (1, 2)])
    with pytest.raises(ProblemError, match="sites"):
        RadarSet(None, 60.0, 1e-3, 3e5)
    with pytest.raises(ProblemError, match="height"):
        radars.cartesian_cov(0, np.array([[1e4, 2e4]]))
    # a plot of each radar on a target at a known position
    lat_t, lon_t, h_t = 55.1, 83.3, 8000.0
    rr, aa = zip(*(g3.measure(geo[i], lat_t, lon_t, h_t) for i in range(2)), strict=True)
    plots = PlotTable(
        np.array([0.0, 1.0, 2.0]),
        np.array([0, 1, 1]),
        np.array([rr[0], rr[1], 100.0]),
        np.array([aa[0], aa[1], 0.0]),
        np.array([0, 0, 0]),
        np.array([h_t, h_t, np.nan]),
    )
    np.testing.assert_array_equal(plots.locatable(radars), [True, True, False])
    with pytest.raises(ProblemError, match="height"):
        plots.cartesian(radars)
    good = plots.subset(plots.locatable(radars))
    assert good.height is not None and good.height.shape == (2,)
    z = good.cartesian(radars)
    e_t, n_t, _ = pymap3d.geodetic2enu(lat_t, lon_t, 0.0, *ORIGIN)
    np.testing.assert_allclose(z, [[e_t, n_t]] * 2, atol=1e-3)
    with pytest.raises(ProblemError, match="height"):
        PlotTable(
            np.zeros(1),
            np.zeros(1, int),
            np.ones(1),
            np.zeros(1),
            np.zeros(1, int),
            np.array([np.inf]),
        )
    # the covariance is the sandwich of the exact Jacobian
    cov = radars.cartesian_cov(1, z[1], height=h_t)
    jac = g3.polar_jacobian3d(z[1], h_t, geo[1], ORIGIN)
    np.testing.assert_allclose(
        jac @ cov @ jac.T, radars.polar_cov(1), rtol=1e-9, atol=1e-14
    )  # off-diagonal: 1e-12 of √(σ_r² σ_az²)


def test_aircraft_paths_per_aircraft() -> None:
    """from_reports: shuffled reports of two aircraft (one repeated instant) → each over
    its own span, plane positions = pymap3d ENU of the footprint, interpolation between
    samples, the dense view for old callers."""
    rng = np.random.default_rng(11)
    t_a, t_b = np.arange(0.0, 60.0, 2.0), np.arange(100.0, 130.0, 1.0)
    lat = np.concatenate([55.0 + 1e-4 * t_a, 54.5 - 2e-4 * (t_b - 100)])
    lon = np.concatenate([83.0 + 2e-4 * t_a, 82.7 + 1e-4 * (t_b - 100)])
    h = np.concatenate([9000.0 + t_a, 4000.0 - 5 * (t_b - 100)])
    obj = np.array(["4ca1f2"] * t_a.size + ["3c6444"] * t_b.size)
    t = np.concatenate([t_a, t_b])
    perm = rng.permutation(t.size)
    rows = np.concatenate([perm, perm[:1]])  # one report twice
    paths = AircraftPaths.from_reports(obj[rows], t[rows], lat[rows], lon[rows], h[rows], ORIGIN)
    assert paths.labels == ("3c6444", "4ca1f2") and paths.duplicates == 1 and len(paths) == 2
    assert paths.span(0) == (100.0, 129.0) and paths.span(1) == (0.0, 58.0)
    tt, en, geo = paths.track(1)
    np.testing.assert_array_equal(tt, t_a)
    e, n, _ = pymap3d.geodetic2enu(lat[: t_a.size], lon[: t_a.size], np.zeros(t_a.size), *ORIGIN)
    np.testing.assert_allclose(en, np.column_stack([e, n]), atol=1e-6)
    assert geo is not None and np.allclose(geo[:, 2], h[: t_a.size])
    mid = paths.at(1, [3.0])[0]
    np.testing.assert_allclose(mid, 0.5 * (en[1] + en[2]), atol=1e-9)
    assert paths.height_at(0, [110.5])[0] == pytest.approx(4000.0 - 52.5)
    assert paths.nbytes == 8 * 6 * (t_a.size + t_b.size)
    assert paths.positions.shape == (2, t_a.size + t_b.size, 2)
    assert paths.active.sum() == t_a.size + t_b.size
    with pytest.raises(ProblemError, match="objects"):
        AircraftPaths.from_reports(obj[:3], t, lat, lon, h, ORIGIN)


def test_simulator_3d_measures_slant_range_and_own_azimuth() -> None:
    """The 3-D simulator, noise-free: each plot minus its true bias is pymap3d's slant
    range and azimuth from the radar's own frame to the true geodetic position
    (plane_to_geodetic of the truth, checked with pymap3d's ENU); heights 3-12 km with
    levels, climbs and descents; the plots carry the true height; cartesian() of the plots
    is the truth plus the exact shift."""
    sc = radar_network(
        4, n_aircraft=12, duration=900.0, geometry="3d", sigma_range=1e-6, sigma_azimuth=1e-12
    )
    p, r = sc.plots, sc.radars
    assert r.is_3d and p.height is not None
    assert 3e3 <= p.height.min() and p.height.max() <= 12e3
    lat, lon = g3.plane_to_geodetic(sc.true_position, r.origin)
    e, n, _ = pymap3d.geodetic2enu(lat, lon, np.zeros(lat.size), *r.origin)
    np.testing.assert_allclose(np.column_stack([e, n]), sc.true_position, atol=1e-3)
    for i in range(r.m):
        sel = p.radar == i
        az, _, rng = pymap3d.geodetic2aer(lat[sel], lon[sel], p.height[sel], *r.geodetic[i])
        np.testing.assert_allclose(p.range[sel] - sc.true_bias[sel, 0], rng, atol=1e-3)
        d = np.angle(np.exp(1j * (p.azimuth[sel] - sc.true_bias[sel, 1] - np.deg2rad(az))))
        assert np.abs(d).max() < 1e-9
    rates = []
    for a in range(len(sc.paths)):
        t, _, geo = sc.paths.track(a)
        assert geo is not None
        rates.append(np.abs(np.diff(geo[:, 2]) / np.diff(t)))
    allr = np.concatenate(rates)
    assert np.mean(allr == 0) > 0.3 and allr.max() <= 15.0 + 1e-9 and allr.max() > 4.0
    z = p.cartesian(r)
    np.testing.assert_allclose(z, sc.true_position + sc.true_shift(), atol=1e-3)


def _set_residual(fd: FieldData, truth: np.ndarray) -> np.ndarray:
    """f − (Φ0 + Φ1η) at the best η per cell, in the weights of P (the distance of the
    true field to the sets (10): what remains after the unobservable common shift)."""
    phi0, phi1 = uncertainty_sets(fd)
    k, m = fd.k, fd.m
    w = np.sqrt(np.diag(fd.P)) if fd.P.shape[0] == 2 * m else np.tile(np.sqrt(np.diag(fd.P)), m)
    r = (truth.reshape(-1) - phi0).reshape(k, 2 * m)
    jac = phi1.toarray()
    out = np.empty((k, 2 * m))
    for kk in range(k):
        a = jac[2 * m * kk : 2 * m * (kk + 1), 2 * kk : 2 * kk + 2] * w[:, None]
        eta = np.linalg.lstsq(a, r[kk] * w, rcond=None)[0]
        out[kk] = r[kk] - (a @ eta) / w
    return out.reshape(k, m, 2)


@pytest.mark.parametrize("fields", ["constant", "linear"])
def test_true_field_lies_in_the_exact_3d_sets(fields: str) -> None:
    """Near-zero noise, straight 3-D paths at 3-12 km: the true f at each cell lies in its
    exact 3-D set (10) up to the linearisation of p_i and the field's variation across a
    cell. In metres on the plane (range residual; azimuth residual × range), against the
    largest shift |∇p_i⁻¹f|: in 90 % of the (cell, radar) pairs below 1 %, everywhere
    below 10 %, as in 2-D (measured: constant 0.06 % / 0.6 %, linear 0.37 % / 4.4 %)."""
    sc = radar_network(
        2,
        n_aircraft=40,
        duration=1800.0,
        sigma_range=1e-3,
        sigma_azimuth=1e-8,
        fields=fields,
        turn_rate=(0.0, 0.0),
        geometry="3d",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fd, _ = build_field_data(sc.plots, sc.radars, cells=30)
    assert fd.jacobians is not None
    mean = fd.xi.mean(axis=1)
    f = np.stack([sc.fields[i](mean) for i in range(fd.m)], axis=1)
    r = np.abs(_set_residual(fd, f))
    shift = np.linalg.solve(fd.jacobians, f[..., None])[..., 0]
    big = np.linalg.norm(shift, axis=-1).max()
    dist = np.linalg.norm(mean[:, None] - fd.radars[None], axis=-1)
    metres = np.stack([r[..., 0], r[..., 1] * dist], axis=-1)
    assert np.all(np.quantile(metres, 0.9, axis=(0, 1)) < 0.01 * big)
    assert np.all(metres.max(axis=(0, 1)) < 0.1 * big)


def chain_errors(
    seed: int, *, n_aircraft: int, duration: float, cells: int
) -> tuple[np.ndarray, np.ndarray, FieldData]:
    """RMS [range (m), azimuth (rad)] distance of the true field to the sets (10) from the
    exact 3-D chain and from the 2-D chain (today's code fed the same slant ranges and
    own-north azimuths as ground ranges on the flat plane of the sites)."""
    sc = radar_network(seed, n_aircraft=n_aircraft, duration=duration, geometry="3d")
    r3 = sc.radars
    r2 = RadarSet(r3.sites, r3.sigma_range, r3.sigma_azimuth, r3.max_range)
    p2 = PlotTable(sc.plots.time, sc.plots.radar, sc.plots.range, sc.plots.azimuth, sc.plots.object)
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cells without all radars are dropped
        fd3, _ = build_field_data(sc.plots, r3, cells=cells)
        fd2, _ = build_field_data(p2, r2, cells=cells)
    for fd in (fd3, fd2):
        mean = fd.xi.mean(axis=1)
        truth = np.stack([sc.fields[i](mean) for i in range(fd.m)], axis=1)
        e = _set_residual(fd, truth)
        out.append(np.sqrt(np.mean(e**2, axis=(0, 1))))
    return out[0], out[1], fd3


def test_3d_chain_recovers_the_field_5x_better_than_2d() -> None:
    """Simulated 3-D traffic at 3-12 km, smooth imposed field (range ±150 m, azimuth
    ±0.3°), four radars 90-130 km from the origin at 55°N: the distance of the true field
    to the sets (10) (the error left after removing the per-cell common shift) from the
    exact 3-D chain is ≥ 5× smaller than from the 2-D chain, in range and in azimuth
    (measured 35-62× and 50-97× over seeds 0-4 with 40 aircraft, 30 min, 30 cells;
    this fast variant: one seed, 25 aircraft, 20 min), and within 25 m / 0.03° (noise:
    σ_r = 60 m, σ_az = 0.08°)."""
    e3, e2, fd3 = chain_errors(1, n_aircraft=25, duration=1200.0, cells=20)
    ratio = e2 / e3
    assert ratio[0] >= 5 and ratio[1] >= 5, (e3, e2)
    assert e3[0] < 25.0 and np.rad2deg(e3[1]) < 0.03
    assert fd3.jacobians is not None and fd3.heights is not None
    assert 3e3 < fd3.heights.min() and fd3.heights.max() < 12e3


@pytest.mark.slow
def test_3d_chain_ratio_over_seeds() -> None:
    """The figure of the note: median over seeds 0-4 (40 aircraft, 30 min, 30 cells) of
    the 2-D/3-D error ratio ≥ 5 in range and azimuth (measured ≈ 54 and 80)."""
    ratios = np.array(
        [
            np.divide(*chain_errors(s, n_aircraft=40, duration=1800.0, cells=30)[1::-1])
            for s in range(5)
        ]
    )
    assert np.all(np.median(ratios, axis=0) >= 5)


def test_field_data_3d_saved_loaded_and_2d_files_still_load(tmp_path) -> None:
    """FieldData of the 3-D chain keeps its Jacobians, heights, sites and origin through
    save/load (the same sets (10)); the same data without them is a 2-D file; Jacobians
    alone give Φ0 linearised, within the second-order term |ξ̂_i − ξ̂|²/r of the exact."""
    sc = radar_network(2, n_aircraft=20, duration=900.0, geometry="3d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fd, _ = build_field_data(sc.plots, sc.radars, cells=12)
    assert fd.is_3d
    fd.save(tmp_path / "fd3.npz")
    back = FieldData.load(tmp_path / "fd3.npz")
    for name in ("jacobians", "heights", "geodetic", "origin"):
        np.testing.assert_array_equal(getattr(back, name), getattr(fd, name))
    phi0, phi1 = uncertainty_sets(fd)
    b0, b1 = uncertainty_sets(back)
    np.testing.assert_array_equal(b0, phi0)
    assert abs(b1 - phi1).max() == 0
    # the selection runs on the 3-D sets: the closed form (11) is verified and its field
    # lies on them (φ = Φ0 + Φ1η to 1e-9 of |φ|)
    sol = closed_form(back)
    assert sol.status is Status.OPTIMAL
    np.testing.assert_allclose(
        sol.phi, b0 + b1 @ sol.eta.reshape(-1), atol=1e-9 * np.abs(sol.phi).max()
    )
    # the exact Jacobians are those of the 3-D map at (ξ̂_(k), h_k), not the 2-D ones
    mean = fd.xi.mean(axis=1)
    for i in range(fd.m):
        ref = g3.polar_jacobian3d(mean, fd.heights, fd.geodetic[i], fd.origin)
        np.testing.assert_allclose(fd.jacobians[:, i], ref, rtol=1e-9, atol=1e-15)
    only_jac = FieldData(fd.radars, fd.centers, fd.xi, fd.adjacency, fd.P, fd.xi_cov, fd.jacobians)
    lin0, _ = uncertainty_sets(only_jac)
    d = np.linalg.norm(fd.xi - mean[:, None, :], axis=2)  # (K, m)
    rng_ = np.linalg.norm(mean[:, None, :] - fd.radars[None], axis=2)
    bound = (d**2 / rng_).reshape(-1)  # second-order term (m) in range, /r in azimuth
    diff = (lin0 - phi0).reshape(-1, 2)
    assert np.all(np.abs(diff[:, 0]) <= bound + 1e-6)
    assert np.all(np.abs(diff[:, 1]) <= bound / rng_.reshape(-1) + 1e-12)
    flat = FieldData(fd.radars, fd.centers, fd.xi, fd.adjacency, fd.P, fd.xi_cov)
    flat.save(tmp_path / "fd2.npz")
    back2 = FieldData.load(tmp_path / "fd2.npz")
    assert not back2.is_3d and back2.jacobians is None and back2.heights is None
    with pytest.raises(ProblemError, match="heights"):
        FieldData(
            fd.radars,
            fd.centers,
            fd.xi,
            fd.adjacency,
            fd.P,
            None,
            None,
            None,
            fd.geodetic,
            fd.origin,
        )
    with pytest.raises(ProblemError, match="jacobians"):
        FieldData(
            fd.radars, fd.centers, fd.xi, fd.adjacency, fd.P, None, np.zeros((fd.k, fd.m, 2, 2))
        )


def test_build_field_data_passes_the_scheduler_through() -> None:
    """``scheduler="serial"`` reaches fit_tracks and gives the same FieldData (3-D) as the
    default; an unknown scheduler is refused there, by name."""
    sc = radar_network(5, n_aircraft=12, duration=900.0, geometry="3d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a, _ = build_field_data(sc.plots, sc.radars, cells=8)
        b, _ = build_field_data(sc.plots, sc.radars, cells=8, scheduler="serial")
    np.testing.assert_allclose(b.xi, a.xi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.jacobians, a.jacobians, rtol=1e-12, atol=0)
    with pytest.raises(ProblemError, match="scheduler"):
        build_field_data(sc.plots, sc.radars, cells=8, scheduler=3.5)
