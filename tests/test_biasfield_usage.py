"""Using the bias field (issue 17): FieldMap.at, correct_plots, registration_error, score."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from optmodels import biasfield as bf
from optmodels.biasfield.geometry import bias_from_shift
from optmodels.biasfield.usage import (
    FieldMap,
    correct_plots,
    field_map,
    registration_error,
    score,
)
from optmodels.core import ProblemError
from optmodels.scenarios.radar_network import radar_network


@pytest.fixture(scope="module")
def network():
    sc = radar_network(3, n_aircraft=40, duration=1800.0)
    with pytest.warns(UserWarning, match="dropped"):
        fd, _ = bf.build_field_data(sc.plots, sc.radars, cells=40)
    sol = bf.closed_form(fd)
    assert sol.status.ok
    return sc, fd, sol


def _grid_centers(n: int, half: float = 50e3) -> np.ndarray:
    g = np.linspace(-half, half, n)
    return np.array([[x, y] for x in g for y in g])


def test_at_reproduces_cell_values_exactly(network):
    _, fd, sol = network
    fm = field_map(sol, fd)
    scale = np.max(np.abs(sol.field), axis=(0, 1))
    assert np.all(np.abs(fm.at(fd.centers) - sol.field) <= 1e-12 * scale)


def test_solution_at_is_the_field_map_of_its_cells(network):
    # FieldSolution.at (the name) = field_map(solution, data).at, bit for bit at the
    # centres; the map carries the 2-D frame (the sites) and refuses another network
    sc, fd, sol = network
    np.testing.assert_array_equal(sol.at(fd.centers), sol.field)
    q = np.random.default_rng(2).uniform(-150e3, 150e3, (300, 2))
    np.testing.assert_array_equal(sol.at(q), field_map(sol, fd).at(q))
    np.testing.assert_array_equal(sol.covered(q), field_map(sol, fd).covered(q))
    assert not sol.map().is_3d
    np.testing.assert_array_equal(sol.map().sites, sc.radars.sites)
    moved = bf.RadarSet(
        np.add(sc.radars.sites, [5e3, 0.0]),
        sc.radars.sigma_range,
        sc.radars.sigma_azimuth,
        sc.radars.max_range,
    )
    with pytest.raises(ProblemError, match="sites"):
        correct_plots(sc.plots, moved, sol.map())


def test_at_is_exact_on_a_linear_field_and_second_order_on_a_smooth_one():
    rng = np.random.default_rng(7)
    a = np.array([[20.0, 1e-3], [-2e-3, 1e-8]])  # range (m) and azimuth (rad) per metre

    def linear(x):
        return np.stack([5.0 + x @ a[:, 0], 1e-3 + x @ a[:, 1]], axis=-1)

    def smooth(x):
        return np.stack(
            [
                100 * np.sin(x[..., 0] / 40e3) * np.cos(x[..., 1] / 30e3),
                2e-3 * np.cos(x[..., 0] / 35e3),
            ],
            axis=-1,
        )

    q = rng.uniform(-45e3, 45e3, (400, 2))
    c = _grid_centers(8)
    fm = FieldMap(c, linear(c)[:, None, :])
    np.testing.assert_allclose(fm.at(q)[:, 0], linear(q), rtol=0, atol=1e-9)
    errs = []
    for n in (6, 12):
        c = _grid_centers(n)
        fm = FieldMap(c, smooth(c)[:, None, :])
        errs.append(np.sqrt(np.mean((fm.at(q)[:, 0] - smooth(q)) ** 2, axis=0)))
    # P1 interpolation error O(h²): halving h (≈ 2.2×) cuts it ≈ 4.8×; ask for ≥ 3×
    assert np.all(errs[0] / errs[1] >= 3.0), errs


def test_at_is_nan_outside_the_covered_area():
    c = _grid_centers(5)
    fm = FieldMap(c, np.ones((c.shape[0], 2, 2)))
    out = fm.at([[0.0, 0.0], [60e3, 0.0], [0.0, -1e6]])
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))
    np.testing.assert_array_equal(fm.covered([[0.0, 0.0], [60e3, 0.0]]), [True, False])


def test_correct_plots_with_a_zero_field_is_the_identity(network):
    sc, fd, _ = network
    fm = FieldMap(fd.centers, np.zeros((fd.k, fd.m, 2)))
    out = correct_plots(sc.plots, sc.radars, fm)
    np.testing.assert_array_equal(out.plots.range, sc.plots.range)
    np.testing.assert_array_equal(out.plots.azimuth, sc.plots.azimuth)
    np.testing.assert_array_equal(out.plots.time, sc.plots.time)
    assert out.n_uncovered > 0 and np.all(out.bias == 0.0)


def test_correct_plots_with_the_true_field_removes_the_bias(network):
    sc, _, _ = network
    c = _grid_centers(81, 300e3)  # dense map of the true field (7.5 km spacing)
    fm = FieldMap(c, np.stack([f(c) for f in sc.fields], axis=1))
    out = correct_plots(sc.plots, sc.radars, fm)
    sel = out.covered
    # corrected − (measured − true bias at the true position): interpolation error of the
    # map plus the bias's change between the measured and the true position (≤ 1 m, 1e-5 rad
    # for bumps of 150 m / 0.3° over ≥ 30 km)
    dr = out.plots.range[sel] - (sc.plots.range[sel] - sc.true_bias[sel, 0])
    da = out.plots.azimuth[sel] - (sc.plots.azimuth[sel] - sc.true_bias[sel, 1])
    assert sel.mean() > 0.8
    assert np.quantile(np.abs(dr), 0.99) < 2.0
    assert np.quantile(np.abs(da), 0.99) < 3e-5


def _shift_fields(sites: np.ndarray, shifts: np.ndarray) -> list[bf.BiasField]:
    """Polar bias fields that move every plot of radar i by the constant shift s_i (m)."""
    return [
        bf.BiasField.from_callable(
            lambda x, site=site, s=s: bias_from_shift(x, site, np.broadcast_to(s, x.shape)),
            "constant shift",
        )
        for site, s in zip(sites, shifts, strict=True)
    ]


@pytest.mark.parametrize("shifts", [[[150.0, -80.0], [-60.0, 120.0]], [[90.0, 40.0], [90.0, 40.0]]])
def test_registration_error_matches_the_true_disagreement(shifts):
    # each radar's plots shifted by a constant s_i on the plane: the systematic
    # disagreement is |s_1 − s_2| everywhere, known exactly
    sites = np.array([[-60e3, 0.0], [60e3, 0.0]])
    s = np.array(shifts)
    sc = radar_network(
        11,
        n_aircraft=40,
        duration=1800.0,
        sites=sites,
        fields=_shift_fields(sites, s),
        region=60e3,
        periods=[5.0, 6.0],
    )
    reg = registration_error(sc.plots, sc.radars, area=30e3)
    truth = float(np.linalg.norm(s[0] - s[1]))
    assert reg.pairs[("R1", "R2")] == pytest.approx(reg.overall, rel=1e-12)
    assert reg.raw_overall > reg.overall
    # the estimate's own standard error is ``noise`` (≈ 30 m here: σ ≈ 100-250 m per plot
    # over ~40 aircraft per area); |s1 − s2| = 290 m or 0
    assert 10.0 < reg.noise < 60.0
    assert abs(reg.overall - truth) <= reg.noise, (reg.overall, truth, reg.noise)


def test_correcting_with_the_smoothest_field_cuts_registration_by_80_percent(network):
    sc, fd, sol = network
    fm = field_map(sol, fd)
    before = registration_error(sc.plots, sc.radars, within=fm)
    after = registration_error(correct_plots(sc.plots, sc.radars, fm).plots, sc.radars, within=fm)
    assert after.overall <= 0.2 * before.overall
    for pair, v in before.pairs.items():
        assert after.pairs[pair] <= 0.2 * v, pair


def test_score_splits_a_common_shift_from_the_rest(network):
    _, fd, sol = network
    rng = np.random.default_rng(5)
    truth = sol.field
    _, phi1 = bf.uncertainty_sets(fd)
    eta = rng.normal(scale=50.0, size=(fd.k, 2))
    shifted = truth + (phi1 @ eta.ravel()).reshape(fd.k, fd.m, 2)
    s = score(shifted, truth, fd)
    assert s.total_m > 30.0
    assert s.rest_m <= 1e-9 * s.total_m
    np.testing.assert_allclose(s.shift, s.total, rtol=1e-9)
    # a non-shift error: radar 0 only, a range error of 10 m in every cell
    bump = truth.copy()
    bump[:, 0, 0] += 10.0
    s2 = score(bump, truth, fd)
    assert s2.total[0] == pytest.approx(10.0 / np.sqrt(fd.m), rel=1e-12)
    assert s2.rest[0] > 0.5 * s2.total[0]
    assert s2.to_dict()["total"]["range_m"] == pytest.approx(s2.total[0])


@pytest.mark.parametrize(
    "call",
    [
        lambda fd, sol: FieldMap(np.zeros((4, 2)), np.zeros((4, 2, 2))),
        lambda fd, sol: FieldMap(fd.centers, np.zeros((fd.k + 1, fd.m, 2))),
        lambda fd, sol: FieldMap(fd.centers, np.full((fd.k, fd.m, 2), np.nan)),
        lambda fd, sol: field_map(sol, "not data"),
        lambda fd, sol: score(sol.field[:-1], sol.field, fd),
        lambda fd, sol: field_map(sol, fd).at(np.zeros((3, 3))),
    ],
)
def test_bad_inputs_are_one_problem_error(network, call):
    _, fd, sol = network
    with pytest.raises(ProblemError):
        call(fd, sol)


# ----------------------------------------------------------------------------- ADS-B referee
@pytest.fixture(scope="module")
def adsb(network):
    from optmodels.biasfield.referee import adsb_field

    sc, fd, _ = network
    rng = np.random.default_rng(21)
    ref = sc.true_position + rng.normal(scale=10.0, size=sc.true_position.shape)
    return ref, {
        model: adsb_field(fd, sc.plots, sc.radars, ref, model=model)
        for model in ("cells", "interpolant")
    }


@pytest.mark.parametrize("model", ["cells", "interpolant"])
def test_adsb_field_cuts_the_absolute_error_by_80_percent(network, adsb, model):
    from optmodels.biasfield.referee import compare_fields

    sc, fd, sol = network
    ref, fields = adsb
    af = fields[model]
    assert af.status.ok and af.stationarity < 1e-9
    assert af.chi2 == pytest.approx(af.dof, rel=1e-2)  # on the discrepancy level
    out = compare_fields(
        sc.plots, sc.radars, ref, {"smoothest": field_map(sol, fd), "adsb": af.map(fd.centers)}
    )
    before = out["before"]["absolute"]["overall_m"]
    assert before > 100.0
    assert out["adsb"]["absolute"]["overall_m"] <= 0.2 * before
    reg = out["before"]["registration"]["overall_m"]
    assert out["adsb"]["registration"]["overall_m"] <= 0.2 * reg
    assert out["smoothest"]["registration"]["overall_m"] <= 0.2 * reg


def test_adsb_field_recovers_constant_biases():
    # constant biases are in the null space of J: the field is their weighted mean over all
    # plots, whose error is ≈ σ/√n per radar; 4σ bounds
    from optmodels.biasfield.referee import adsb_field

    sc = radar_network(8, n_aircraft=30, duration=1200.0, fields="constant")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # cells without data are dropped
        fd, _ = bf.build_field_data(sc.plots, sc.radars, cells=30)
    af = adsb_field(fd, sc.plots, sc.radars, sc.true_position, sigma_reference=0.0)
    assert af.status.ok
    for i, f in enumerate(sc.fields):
        truth = f(np.zeros((1, 2)))[0]
        n = int(af.counts[:, i].sum())
        se = np.array([sc.radars.sigma_range[i], sc.radars.sigma_azimuth[i]]) / np.sqrt(n)
        err = af.field[:, i] - truth
        assert np.all(np.abs(err) <= 4 * se + 1e-9 * np.abs(truth)), (i, err.max(axis=0), se)


def test_adsb_field_bad_reference_is_one_problem_error(network):
    from optmodels.biasfield.referee import adsb_field

    sc, fd, _ = network
    with pytest.raises(ProblemError, match="reference"):
        adsb_field(fd, sc.plots, sc.radars, np.zeros((3, 2)))
    with pytest.raises(ProblemError, match="reference"):
        adsb_field(fd, sc.plots, sc.radars, np.full((len(sc.plots), 2), np.nan))
    with pytest.raises(ProblemError, match="model"):
        adsb_field(fd, sc.plots, sc.radars, sc.true_position, model="kriging")
