"""The bias field over the union of coverage (issue 24 item 1): per-cell radar subsets in
the sets (10), the smoothness functional (9) per radar over its own cells, the closed form
(11) and the QP, the FieldMap per radar and the per-plot reasons of correct_plots."""

from __future__ import annotations

import dataclasses
import warnings
from unittest import mock

import numpy as np
import pytest
from scipy import sparse

from optmodels import biasfield as bf
from optmodels.biasfield import correction
from optmodels.biasfield.geometry import polar_jacobian, to_polar, wrap_angle
from optmodels.biasfield.usage import REASONS, correct_plots, registration_error, seen_by_others
from optmodels.core import ProblemError
from optmodels.scenarios.radar_network import line_sites, radar_network, ring_sites


def _masked(fd: bf.FieldData, seen: np.ndarray) -> bf.FieldData:
    return dataclasses.replace(fd, seen=seen)


def _dense_reference(fd: bf.FieldData, seen: np.ndarray) -> np.ndarray:
    """(11) from the printed formulas, dense and independent of the package's sparse
    code: per radar i the Laplacian Q_i over the neighbour pairs whose cells i both sees,
    R = Σ_i Q_i ⊗ (e_i e_iᵀ ⊗ P_i); Φ⁰, Φ¹ of the 2-D polar maps at the subset mean, rows
    of unseen radars zero; η* = −(Φ¹ᵀRΦ¹)⁻¹Φ¹ᵀRΦ⁰."""
    k, m = fd.k, fd.m
    adj = fd.adjacency.toarray()
    r = np.zeros((2 * m * k, 2 * m * k))
    for i in range(m):
        a = np.zeros((k, k))
        for u in range(k):
            for v in range(k):
                if adj[u, v] and seen[u, i] and seen[v, i]:
                    a[u, v] = 1.0 / np.sum((fd.centers[u] - fd.centers[v]) ** 2)
        q = np.diag(a.sum(axis=1)) - a
        e = np.zeros((m, m))
        e[i, i] = 1.0
        r += np.kron(q, np.kron(e, fd.P))
    phi0 = np.zeros((k, m, 2))
    phi1 = np.zeros((2 * m * k, 2 * k))
    for c in range(k):
        mean = fd.xi[c, seen[c]].mean(axis=0)
        for i in range(m):
            if not seen[c, i]:
                continue
            d = to_polar(fd.xi[c, i][None], fd.radars[i])[0] - to_polar(mean[None], fd.radars[i])[0]
            phi0[c, i] = [d[0], wrap_angle(d[1])]
            phi1[2 * m * c + 2 * i : 2 * m * c + 2 * i + 2, 2 * c : 2 * c + 2] = polar_jacobian(
                mean[None], fd.radars[i]
            )[0]
    phi0 = phi0.reshape(-1)
    eta = -np.linalg.solve(phi1.T @ r @ phi1, phi1.T @ r @ phi0)
    return (phi0 + phi1 @ eta).reshape(k, m, 2)


@pytest.fixture(scope="module")
def synth():
    fd, truth = bf.synthetic_field_data(5, cells=60, noise=2.0)
    return fd, truth


def test_all_radar_subsets_give_the_papers_field_to_round_off(synth):
    fd, _ = synth
    old = bf.closed_form(fd)  # the unchanged (Q ⊗ P) path, seen=None
    new = bf.closed_form(_masked(fd, np.ones((fd.k, fd.m), dtype=bool)))  # masked path
    assert old.status.ok and new.status.ok
    scale = np.abs(old.field).max(axis=(0, 1))
    np.testing.assert_allclose(new.field, old.field, rtol=0, atol=1e-9 * scale.max())
    assert np.max(np.abs(new.field - old.field)[..., 1]) <= 1e-9 * scale[1]
    assert new.objective == pytest.approx(old.objective, rel=1e-9)
    np.testing.assert_allclose(
        old.field,
        _dense_reference(fd, np.ones((fd.k, fd.m), bool)),
        rtol=0,
        atol=1e-8 * scale.max(),
    )


def _half_plane_subsets(fd: bf.FieldData) -> np.ndarray:
    """Radars 0, 1 see the West, 2, 3 the East, and all four a middle strip: an overlap
    graph in one piece without a single radar seeing every cell."""
    x = fd.centers[:, 0]
    seen = np.zeros((fd.k, fd.m), dtype=bool)
    seen[x < 30e3, 0:2] = True
    seen[x > -30e3, 2:4] = True
    return seen


def test_per_cell_subsets_closed_form_matches_dense_formulas_and_the_qp(synth):
    fd, _ = synth
    seen = _half_plane_subsets(fd)
    assert (seen.sum(axis=1) == 2).any() and (seen.sum(axis=1) == 4).any()
    data = _masked(fd, seen)
    cf = bf.closed_form(data)
    assert cf.status.ok, cf.message
    ref = _dense_reference(fd, seen)
    np.testing.assert_allclose(cf.field[..., 0], ref[..., 0], rtol=0, atol=1e-6)
    np.testing.assert_allclose(cf.field[..., 1], ref[..., 1], rtol=0, atol=1e-11)
    assert np.all(cf.field[~seen] == 0.0)  # unseen radars carry no field value
    qp = bf.solve(data, formulation="constrained")
    assert qp.status.ok, qp.message
    np.testing.assert_allclose(qp.field[..., 0], cf.field[..., 0], rtol=0, atol=1e-3)
    np.testing.assert_allclose(qp.field[..., 1], cf.field[..., 1], rtol=0, atol=1e-8)
    # the objective is radar i's (9) over the pairs it sees at both ends
    up = sparse.triu(fd.adjacency, k=1).tocoo()
    j = 0.0
    for u, v in zip(up.row, up.col, strict=True):
        a = 1.0 / np.sum((fd.centers[u] - fd.centers[v]) ** 2)
        for i in np.flatnonzero(seen[u] & seen[v]):
            d = cf.field[u, i] - cf.field[v, i]
            j += a * d @ fd.P @ d
    assert cf.objective == pytest.approx(j, rel=1e-9)


def test_overlap_graph_components_are_counted_and_isolated_cells_refused(synth):
    fd, _ = synth
    x = fd.centers[:, 0]
    seen = np.zeros((fd.k, fd.m), dtype=bool)
    seen[x < 0, 0:2] = True  # West: radars 0, 1 only; East: 2, 3 only (no shared radar)
    seen[x >= 0, 2:4] = True
    sol = bf.closed_form(_masked(fd, seen))
    assert sol.status.ok
    assert sol.info["components"] == 2  # the two halves decouple
    # one cell whose radars no neighbour shares: its η is free, refused by name
    seen2 = seen.copy()
    lone = int(np.argmin(np.abs(x)))
    nb = fd.adjacency[lone].indices
    seen2[nb] = [False, True, False, True]
    seen2[lone] = [True, False, True, False]
    with pytest.raises(ProblemError, match=rf"cells \[{lone}\] share no radar"):
        bf.closed_form(_masked(fd, seen2))
    with pytest.raises(ProblemError, match="fewer than 2 radars"):
        bad = seen.copy()
        bad[0] = [True, False, False, False]
        _masked(fd, bad)


def _check_network(sc, cells: int):
    """Field from the even aircraft, figures on both halves (done-when of issue 24)."""
    pl = sc.plots
    # corrected ranges may pass max_range by the bias: measure on a set that allows it
    radars = dataclasses.replace(sc.radars, max_range=sc.radars.max_range + 5e3)
    odd = pl.object % 2 == 1
    train, test = pl.subset(~odd), pl.subset(odd)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        fd, _ = bf.build_field_data(train, sc.radars, cells=cells, coverage="union")
    assert fd.seen is not None and not fd.seen.all(axis=1).any()  # no cell sees all
    sol = bf.closed_form(fd)
    assert sol.status.ok, sol.message
    fm = sol.map()
    out = {}
    for name, part in (("in", train), ("held out", test)):
        c = correct_plots(part, radars, fm)
        # in blocks (CORRECT_CHUNK plots at a time, a block boundary inside every radar's
        # and aircraft's plots): the same correction as in one block
        with mock.patch.object(correction, "CORRECT_CHUNK", 997):
            cb = correct_plots(part, radars, fm)
        assert len(part) > 3 * 997
        # (the 3-D placement through ECEF rounds differently per block: ~1e-12 relative)
        np.testing.assert_allclose(cb.bias, c.bias, rtol=1e-10, atol=1e-12)
        assert np.array_equal(cb.covered, c.covered) and np.array_equal(cb.reason, c.reason)
        np.testing.assert_allclose(cb.plots.range, c.plots.range, rtol=0, atol=1e-9)
        two = seen_by_others(part)
        # "one radar only" exactly where the plot is uncovered, of a known object, and no
        # other radar saw that object within the window (computed here on all plots)
        single = ~c.covered & ~two & (part.object >= 0)
        assert np.array_equal(c.reason == "one radar only", single)
        assert set(np.unique(c.reason)) <= set(REASONS)
        assert np.all((c.reason == "covered") == c.covered)
        assert not np.any(two & (c.reason == "one radar only"))
        before = registration_error(part, radars)
        after = registration_error(c.plots, radars)
        out[name] = (float(c.covered[two].mean()), before.overall, after.overall, before.noise)
    return out


def test_ring_network_without_a_common_area_is_corrected_3d():
    sc = radar_network(
        3,
        n_aircraft=200,
        duration=1800.0,
        geometry="3d",
        sites=ring_sites(6, 160e3),
        max_range=140e3,
        region=210e3,
    )
    for name, (share, before, after, noise) in _check_network(sc, 150).items():
        assert share >= 0.95, (name, share)
        assert before > 5 * noise
        assert after <= 0.2 * before, (name, before, after)


def test_line_network_with_pairwise_overlaps_is_corrected_2d():
    sc = radar_network(
        4,
        n_aircraft=160,
        duration=1800.0,
        sites=line_sites(4, 150e3),
        max_range=120e3,
        region=220e3,
    )
    for name, (share, before, after, noise) in _check_network(sc, 120).items():
        assert share >= 0.95, (name, share)
        assert before > 5 * noise
        assert after <= 0.2 * before, (name, before, after)


def test_reasons_name_one_radar_only_and_outside_every_cell():
    sc = radar_network(2, n_aircraft=20, duration=900.0)
    pl = sc.plots
    fm = bf.FieldMap(
        np.array([[0.0, 0.0], [1e3, 0.0], [0.0, 1e3]]), np.zeros((3, 4, 2)), max_distance=2e3
    )
    c = correct_plots(pl, sc.radars, fm)
    two = seen_by_others(pl)
    # an independent count: another radar's plot of the same object within 60 s
    want = np.array(
        [
            np.any(
                (pl.object == pl.object[n])
                & (pl.radar != pl.radar[n])
                & (np.abs(pl.time - pl.time[n]) <= 60.0)
            )
            for n in range(len(pl))
        ]
    )
    np.testing.assert_array_equal(two, want)
    far = ~c.covered
    assert np.all(c.reason[far & want] == "outside every cell")
    assert np.all(c.reason[far & ~want] == "one radar only")
    assert (c.reason == "one radar only").any() and (c.reason == "outside every cell").any()


def test_field_map_serves_each_radar_over_its_own_cells(synth, tmp_path):
    fd, _ = synth
    seen = _half_plane_subsets(fd)
    sol = bf.closed_form(_masked(fd, seen))
    fm = sol.map()
    # at the centres: the cell values of the radars that see them; a radar is not served
    # farther than max_distance from its own cells
    vals = fm.at(fd.centers)
    np.testing.assert_array_equal(vals[seen], sol.field[seen])
    far0 = fd.centers[:, 0] > 30e3 + fm.max_distance
    assert far0.any()
    assert np.all(np.isnan(vals[far0, 0])) and np.all(np.isnan(vals[far0, 1]))
    assert np.all(np.isfinite(vals[far0, 2:]))
    np.testing.assert_array_equal(fm.covered_for(fd.centers, 0), ~np.isnan(vals[:, 0, 0]))
    own = fm.at_radar(fd.centers, 0)
    np.testing.assert_array_equal(own[seen[:, 0]], sol.field[seen[:, 0], 0])
    fm.save(tmp_path / "f.npz")
    back = bf.FieldMap.load(tmp_path / "f.npz")
    np.testing.assert_array_equal(back.seen, seen)
    q = np.random.default_rng(1).uniform(-150e3, 150e3, (300, 2))
    np.testing.assert_array_equal(back.at(q), fm.at(q))
    # the saved FieldData keeps its subsets
    data = _masked(fd, seen)
    data.save(tmp_path / "d.npz")
    np.testing.assert_array_equal(bf.FieldData.load(tmp_path / "d.npz").seen, seen)
    assert sparse.issparse(data.adjacency)


def _seen_brute(pl: bf.PlotTable, window: float) -> np.ndarray:
    """Another radar's plot of the same (known) object within ``window`` s, plot by plot."""
    return np.array(
        [
            pl.object[n] >= 0
            and np.any(
                (pl.object == pl.object[n])
                & (pl.radar != pl.radar[n])
                & (np.abs(pl.time - pl.time[n]) <= window)
            )
            for n in range(len(pl))
        ]
    )


@pytest.mark.parametrize("chunk", [1, 40, 1 << 21])
def test_seen_by_others_in_groups_of_objects_equals_the_plot_by_plot_count(chunk):
    """The grouping by whole objects (SEEN_CHUNK plots, one object per group at 1) gives
    the brute-force answer, with unknown objects (−1) among the plots."""
    sc = radar_network(5, n_aircraft=12, duration=600.0)
    pl = sc.plots
    rng = np.random.default_rng(5)
    obj = np.where(rng.random(len(pl)) < 0.1, -1, pl.object)
    pl = dataclasses.replace(pl, object=obj)
    with mock.patch.object(correction, "SEEN_CHUNK", chunk):
        for window in (60.0, 4.0):
            want = _seen_brute(pl, window)
            got = seen_by_others(pl, window)
            np.testing.assert_array_equal(got, want)
            assert want.any() and not want.all()


def test_correct_plots_equals_the_straightforward_computation():
    """Bit for bit: two passes of range − f_r, azimuth − f_α at the plot's then the
    corrected position, on all plots at once (no blocks, no preallocated columns); the
    columns not corrected are the input's own arrays (no copy)."""
    sc = radar_network(
        4, n_aircraft=60, duration=1200.0, sites=line_sites(4, 150e3), max_range=120e3
    )
    pl = sc.plots
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        fd, _ = bf.build_field_data(pl, sc.radars, cells=60, coverage="union")
    fm = bf.closed_form(fd).map()
    radars = dataclasses.replace(sc.radars, max_range=sc.radars.max_range + 5e3)
    with mock.patch.object(correction, "CORRECT_CHUNK", 1000):
        c = correct_plots(pl, radars, fm)
    rng, az = pl.range, pl.azimuth
    for _ in range(2):
        z = dataclasses.replace(pl, range=rng, azimuth=az).cartesian(radars)
        b = fm.at_radar(z, pl.radar)
        ok = np.all(np.isfinite(b), axis=1)
        b[~ok] = 0.0
        rng, az = np.abs(pl.range - b[:, 0]), wrap_angle(pl.azimuth - b[:, 1])
    assert 0 < ok.sum() < len(pl)  # some plots outside every cell
    np.testing.assert_array_equal(c.plots.range, rng)
    np.testing.assert_array_equal(c.plots.azimuth, az)
    np.testing.assert_array_equal(c.bias, b)
    np.testing.assert_array_equal(c.covered, ok)
    for col in ("time", "radar", "object"):
        assert getattr(c.plots, col) is getattr(pl, col)
