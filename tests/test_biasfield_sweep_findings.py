"""Regression tests of the defects the property sweep found in the bias-field readers and
pipeline (tests/test_property_sweep.py with tests/sweep_recipes_biasfield.py; issue 28
item 5): each bad value is one ProblemError naming the argument, and the good path still
gives the right numbers (checked against an independent computation)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from optmodels import biasfield as bf
from optmodels.assignment import connected_probability
from optmodels.core import ProblemError
from tests import sweep_recipes_biasfield as rec
from tests.sweep_support import Ctx

RAGGED = [[0.0], [1.0, 1.0]]


@pytest.fixture(scope="module")
def c(tmp_path_factory: pytest.TempPathFactory) -> Ctx:
    """The sweep's tiny 3-D network (4 radars, 4 aircraft, 2 min) and its files."""
    return Ctx(tmp_path_factory.mktemp("bf-findings"))


# ------------------------------------------------------------------ connected_probability
def test_connected_probability_checks_the_table_and_the_group() -> None:
    u = np.array([[1.0, 0.3, 0.2], [0.3, 1.0, 0.5], [0.2, 0.5, 1.0]])
    # a list of ragged rows was a raw TypeError; a mapping as the group a silent 1.0
    with pytest.raises(ProblemError, match=r"connected_probability u: a ragged"):
        connected_probability(RAGGED, (0, 1))  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match=r"connected_probability group: a ragged"):
        connected_probability(u, RAGGED)  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match=r"connected_probability group"):
        connected_probability(u, {"a": 1.0})  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match=r"connected_probability group: expected"):
        connected_probability(u, (0, 3))
    with pytest.raises(ProblemError, match=r"connected_probability group: repeated"):
        connected_probability(u, (0, 1, 1))
    with pytest.raises(ProblemError, match=r"connected_probability u: pair probabilities"):
        connected_probability(3.0 * u, (0, 1))
    with pytest.raises(ProblemError, match=r"connected_probability u: .*symmetric"):
        connected_probability(np.triu(u), (0, 1, 2))
    # the good path: a triangle is connected when at least two of its edges are
    a, b, d = 0.3, 0.2, 0.5
    want = a * b + a * d + b * d - 2 * a * b * d
    assert connected_probability(u, (0, 1, 2)) == pytest.approx(want, rel=1e-12)
    assert connected_probability(u, [2, 0]) == pytest.approx(0.2, rel=1e-12)
    # u_ij = 0 (a pair always resolved) was a raw "math domain error": now the sensor's
    # floor U_FLOOR = 1e-100, i.e. P_conn = 0 to any precision
    z = u.copy()
    z[0, 1] = z[1, 0] = 0.0
    assert connected_probability(z, (0, 1)) < 1e-99


# ------------------------------------------------------------------ tables and cleaning
def test_aircraft_paths_active_ragged_is_refused() -> None:
    t = np.arange(4.0)
    pos = np.arange(16.0).reshape(2, 4, 2)
    with pytest.raises(ProblemError, match=r"AircraftPaths active: a ragged"):
        bf.AircraftPaths(t, pos, RAGGED)
    p = bf.AircraftPaths(t, pos, np.ones((2, 4), dtype=bool))
    np.testing.assert_allclose(p.at(1, [0.5, 2.5]), [[9.0, 10.0], [13.0, 14.0]], rtol=0)


def test_clean_reports_checks_labels_heights_and_sigma() -> None:
    rng = np.random.default_rng(20261210)
    n = 40
    t = np.arange(n, dtype=float)
    x = np.column_stack([200.0 * t, np.zeros(n), np.full(n, 9e3)]) + rng.normal(0, 5, (n, 3))
    obj = np.repeat([7, 9], n // 2)
    for kw, name in (
        ({"objects": RAGGED}, "objects"),
        ({"objects": [None] * n}, "objects"),
        ({"heights": RAGGED}, "heights"),
        ({"sigma": RAGGED}, "sigma"),
        ({"sigma": np.ones(3)}, "sigma"),
    ):
        args = {"objects": obj, "times": t, "positions": x, **kw}
        with pytest.raises(ProblemError, match=rf"clean_reports {name}"):
            bf.clean_reports(**args)
    # the good path: heights as a list with NaN (unknown) and sigma per report give the
    # same as without heights and one sigma: two clean segments, nothing dropped
    h = [float("nan")] * n
    seg, rep = bf.clean_reports(obj, t, x, sigma=np.full(n, 10.0), heights=h)
    seg0, _ = bf.clean_reports(obj, t, x)
    np.testing.assert_array_equal(seg, seg0)
    np.testing.assert_array_equal(seg, np.repeat([0, 1], n // 2))
    assert rep.total == 0 and rep.segments == 2


def test_adsb_height_spikes_checks_every_argument(c: Ctx) -> None:
    obj, t, h = rec._spiky(c)
    for kw, name in (
        ({"obj": RAGGED}, "obj"),
        ({"t": RAGGED}, "t"),
        ({"height": RAGGED}, "height"),
        ({"t": t[:-1]}, "t"),
        ({"neighbours": "x"}, "neighbours"),
        ({"neighbours": 0}, "neighbours"),
        ({"tolerance": "x"}, "tolerance"),
        ({"vertical_rate": -1.0}, "vertical_rate"),
    ):
        args = {"obj": obj, "t": t, "height": h, **kw}
        with pytest.raises(ProblemError, match=rf"adsb_height_spikes {name}"):
            bf.adsb_height_spikes(**args)
    # the good path: the one +7.8 km spike is the only report flagged (smooth true tracks)
    got = bf.adsb_height_spikes(obj, t, h)
    assert np.flatnonzero(got).tolist() == [10]
    h2 = h.copy()
    h2[20] = np.nan  # an absent height is not a spike and does not hide the other one
    assert np.flatnonzero(bf.adsb_height_spikes(obj, t, h2)).tolist() == [10]


def test_azimuth_bias_baseline_objects_ragged_is_refused(c: Ctx) -> None:
    p, r = rec._plots(c), rec._radars(c)
    with pytest.raises(ProblemError, match=r"azimuth_bias_baseline objects: a ragged"):
        bf.azimuth_bias_baseline(p, r, objects=RAGGED)  # type: ignore[arg-type]
    # found with a smaller scene: an id without plots was a raw IndexError, and a repeated
    # id counted the object twice in the GLS (a wrong estimate and covariance, no error)
    for bad, why in (([0, 9], r"\[9\] without plots"), ([-1], r"\[-1\]"), ([0, 0], "repeated")):
        with pytest.raises(ProblemError, match=rf"azimuth_bias_baseline objects: .*{why}"):
            bf.azimuth_bias_baseline(p, r, objects=bad)
    every = bf.azimuth_bias_baseline(p, r, objects=[0, 1, 2, 3])
    default = bf.azimuth_bias_baseline(p, r)
    np.testing.assert_allclose(every.estimate, default.estimate, rtol=1e-12, atol=0)
    assert every.objects == 4 and every.plots + every.dropped == len(p)


def test_residual_check_fits_must_be_a_list(c: Ctx) -> None:
    fits = rec._build(c).diagnostics.fits
    for bad in ("", "x", {"a": 1.0}):
        with pytest.raises(ProblemError, match=r"residual_check fits: expected a list"):
            bf.residual_check(bad, 4)  # type: ignore[arg-type]
    chk = bf.residual_check(tuple(fits), 4)  # type: ignore[arg-type]
    want = [sum(f.chi2 for f in fits if f.radar == i) for i in range(4)]
    np.testing.assert_allclose(chk.chi2, want, rtol=1e-12)


# ------------------------------------------------------------------ the pipeline
def test_build_field_data_cells_and_progress(c: Ctx) -> None:
    p, r = rec._plots(c), rec._radars(c)
    with pytest.raises(ProblemError, match=r"build_field_data cells: a ragged"):
        bf.build_field_data(p, r, cells=RAGGED)
    with pytest.raises(ProblemError, match=r"build_field_data progress: expected True or"):
        bf.build_field_data(p, r, cells=6, progress="x")  # type: ignore[arg-type]
    # a neighbour_radius given with the Delaunay neighbours was ignored whatever it was
    with pytest.raises(ProblemError, match=r"build_field_data neighbour_radius"):
        bf.build_field_data(p, r, cells=6, neighbour_radius="x")  # type: ignore[arg-type]
    # the good path: the centres given as nested lists are the centres used
    centres = rec._fd(c).centers
    fd, _ = bf.build_field_data(p, r, cells=centres.tolist(), coverage="union")
    assert fd.centers.shape[1] == 2 and fd.k >= 2
    assert np.all(np.min(np.linalg.norm(fd.centers[:, None] - centres[None], axis=2), 1) == 0)


def test_field_data_from_plots_checks_its_arguments_first(c: Ctx) -> None:
    p, r = rec._plots(c), rec._radars(c)
    fn = "field_data_from_plots"
    for kw, name in (
        ({"cells": RAGGED}, "cells"),
        ({"clean": "x"}, "clean"),
        ({"locate": "x"}, "locate"),
        ({"progress": "x"}, "progress"),
        ({"knot_spacing": "x"}, "knot_spacing"),
        ({"scheduler": 3.5}, "scheduler"),
        ({"sample_stp": 5.0}, "sample_stp"),  # a misspelt option was a raw TypeError
        ({"positions": np.zeros((len(p), 2))}, "positions"),
    ):
        with pytest.raises(ProblemError, match=rf"{fn} {name}"):
            bf.field_data_from_plots(p, r, **kw)
    # the good path equals build_field_data on the same plots (no cleaning, all placed)
    got = bf.field_data_from_plots(p, r, cells=6, coverage="all", sample_step=5.0)
    fd, _ = bf.build_field_data(p, r, cells=6, coverage="all")
    np.testing.assert_allclose(got.data.xi, fd.xi, rtol=1e-12, atol=0)


def test_save_field_data_names_must_be_a_list(c: Ctx, tmp_path: Path) -> None:
    fd = rec._fd(c)
    for bad in ("", "ABCD", ["A", "B", "C", 4]):
        with pytest.raises(ProblemError, match=r"save_field_data names: expected"):
            bf.save_field_data(fd, tmp_path / "x.npz", names=bad)  # type: ignore[arg-type]
    path = bf.save_field_data(fd, tmp_path / "fd.npz", names=["n1", "n2", "n3", "n4"])
    assert bf.field_data_names(path) == ("n1", "n2", "n3", "n4")
    np.testing.assert_array_equal(bf.FieldData.load(path).xi, fd.xi)


# ------------------------------------------------------------------ ADS-B referee
def test_referee_reference_min_samples_and_fields(c: Ctx) -> None:
    p, r, ref, fm = rec._plots(c), rec._radars(c), rec._ref(c), rec._map(c)
    with pytest.raises(ProblemError, match=r"absolute_error reference: a ragged"):
        bf.absolute_error(p, r, RAGGED)
    with pytest.raises(ProblemError, match=r"absolute_error reference: complex"):
        bf.absolute_error(p, r, ref + 1j)
    with pytest.raises(ProblemError, match=r"adsb_field reference: a ragged"):
        bf.adsb_field(rec._fd(c), p, r, RAGGED)
    # found with a smaller scene: a radar without any ADS-B-referenced plot in the cells
    # was a raw LinAlgError ("Singular matrix"): its constant is not determined
    blind = ref.copy()
    blind[p.radar == 0] = np.nan
    for level in ("discrepancy", "means"):
        with pytest.raises(ProblemError, match=r"adsb_field reference: radar 'R1' has no plot"):
            bf.adsb_field(rec._fd(c), p, r, blind, level=level)
    with pytest.raises(ProblemError, match=r"absolute_error min_samples"):
        bf.absolute_error(p, r, ref, min_samples="x")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match=r"compare_fields fields: expected a dict"):
        bf.compare_fields(p, r, ref, "x")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match=r"compare_fields plots"):
        bf.compare_fields("", r, ref, {"f": fm})  # type: ignore[arg-type]
    # the good path: NaN rows are "no ADS-B position"; raw_overall is the plain RMS of
    # z − y over the plots with one
    ref2 = ref.copy()
    ref2[::3] = np.nan
    got = bf.absolute_error(p, r, ref2.tolist(), min_samples=5)
    z = p.cartesian(r)
    ok = np.all(np.isfinite(ref2), axis=1) & (p.object >= 0)
    want = math.sqrt(float(np.mean(np.sum((z[ok] - ref2[ok]) ** 2, axis=1))))
    assert got.raw_overall == pytest.approx(want, rel=1e-12)


def test_adsb_field_null_space_follows_each_radars_cells(c: Ctx) -> None:
    """With per-cell subsets R couples radar i's cells only along the edges between cells
    it sees: its null space (the smoothest fields, μ → ∞) has one constant per radar and
    per connected part of that radar's graph. Found by the sweep's rescaled references:
    positions × 0.5 left radar R3 without data in cell 2, which it does not see; the
    solves were "exactly singular" (a MatrixRankWarning, then "the solve overflowed"), then
    refused naming cell 2. The referee's unknowns are the seen entries only: R3's entry in
    cell 2 is not estimated (0), and R3 is refused only without data on the cells it sees."""
    from optmodels.biasfield.problem import r_matrix, r_null_space, seen_entries

    fd = rec._fd(c)
    assert fd.seen is not None and not fd.seen.all()  # the union field has a hole
    r = r_matrix(fd).toarray()
    null = r_null_space(fd).toarray()
    w = np.linalg.eigvalsh(r)
    assert null.shape[1] == int(np.sum(w <= 1e-12 * w[-1])) == 2 * fd.m + 2
    assert np.linalg.matrix_rank(null) == null.shape[1]
    assert np.max(np.abs(r @ null)) <= 1e-12 * np.max(np.abs(r))
    # over the seen entries the unseen (R3, cell 2) is gone: one part per radar
    keep = seen_entries(fd)
    assert keep.sum() == 2 * fd.seen.sum() and not keep.reshape(fd.k, fd.m, 2)[2, 2].any()
    r_s = r[np.ix_(keep, keep)]
    null_s = r_null_space(fd, seen_only=True).toarray()
    w_s = np.linalg.eigvalsh(r_s)
    assert (
        null_s.shape == (keep.sum(), 2 * fd.m) == (keep.sum(), int(np.sum(w_s <= 1e-12 * w_s[-1])))
    )
    assert np.max(np.abs(r_s @ null_s)) <= 1e-12 * np.max(np.abs(r_s))
    p, radars, ref = rec._plots(c), rec._radars(c), rec._ref(c)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # positions × 0.5: every plot in cells 0, 1, 3, which R3 sees; the references are
        # wrong by kilometres, so no field reaches the χ² level: the least-squares field,
        # flagged OPTIMAL_INACCURATE (the means level asks for that field: OPTIMAL)
        half = bf.adsb_field(fd, p, radars, 0.5 * ref, cell_radius=60e3)
        means = bf.adsb_field(fd, p, radars, 0.5 * ref, cell_radius=60e3, level="means")
        assert half.status.value == "optimal_inaccurate" and half.chi2 > 100 * half.dof
        assert means.status.value == "optimal" and means.chi2 > 100 * means.dof
        assert half.field[2, 2].tolist() == [0.0, 0.0] and half.counts[2].sum() == 0
        for comp in (0, 1):  # both the μ → 0 limit, per component (m, rad)
            scale = np.abs(means.field[..., comp]).max()
            np.testing.assert_allclose(
                half.field[..., comp], means.field[..., comp], rtol=0, atol=1e-6 * scale
            )
        # R3 without any reference: its constant on the cells it sees (0, 1, 3) is free
        blind = ref.copy()
        blind[p.radar == 2] = np.nan
        with pytest.raises(ProblemError, match=r"radar 'R3' has no plot .* in cells \[0, 1, 3\]"):
            bf.adsb_field(fd, p, radars, blind, cell_radius=60e3)
        # the good path: the smoothest fields fit the data (μ = ∞, J = 0), re-checked
        out = bf.adsb_field(fd, p, radars, ref, cell_radius=60e3)
    assert out.status.ok and math.isinf(out.mu) and out.objective <= 1e-20
    assert out.chi2 <= out.dof and out.stationarity <= 1e-9 and out.conditioning <= 1e-12
    assert out.moved == 1 and out.field[2, 2].tolist() == [0.0, 0.0]


# ------------------------------------------------------------------ readers
def test_read_recording_origin_and_empty_file(c: Ctx, tmp_path: Path) -> None:
    radars = rec._keyed(c)
    path = rec._recording(c)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # was: a ComplexWarning, or the imaginary part dropped
        with pytest.raises(ProblemError, match=r"read_recording origin: complex"):
            bf.read_recording(path, radars, origin=np.array(rec.ORG) + 1j)
    with pytest.raises(ProblemError, match=r"read_recording origin: a ragged"):
        bf.read_recording(path, radars, origin=RAGGED)  # type: ignore[arg-type]
    empty = tmp_path / "empty.ast"
    empty.write_bytes(b"")
    with pytest.raises(ProblemError, match=r"empty\.ast: empty file"):  # names the file
        bf.read_recording(empty, radars)
    # the good path: every plot and ADS-B report of the scene, on the same origin
    got = bf.read_recording(path, radars, origin=rec.ORG)
    assert len(got.plots) == len(rec._plots(c)) and len(got.adsb) == len(rec._adsb(c))
    # I048/040 RHO: LSB 1/256 NM, rounded (half an LSB)
    np.testing.assert_allclose(
        np.sort(got.plots.range), np.sort(rec._plots(c).range), rtol=0, atol=1852 / 512 + 1e-6
    )


def test_read_plots_labels_must_be_a_list(c: Ctx) -> None:
    path, r = rec._plots_csv(c), rec._radars(c)
    for bad in ("x", {"a": 1.0}):
        with pytest.raises(ProblemError, match=r"read_plots labels: expected a list"):
            bf.read_plots(path, r, labels=bad)  # type: ignore[arg-type]
    labels: list[str] = []
    table, dropped = bf.read_plots(path, r, labels=labels)
    want = [f"A{o}" for o in rec._plots(c).object]
    assert labels == list(dict.fromkeys(want)) and not dropped  # in order of appearance
    assert [labels[k] for k in table.object] == want
