"""biasfield's public entry points behind the package's checks (issue 28 item 4): a bad
argument of wrap_angle, fl_to_height, FieldData / laplacian (adjacency), PlotTable (radar,
object, height), seen_by_others, solve (box) and uncertainty_sets is one
:class:`~optmodels.ProblemError` naming the problem and the argument (the property sweep,
tests/test_property_sweep.py, generates the values; these are the direct cases), and a good
call still gives the numbers of an independent computation."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy import sparse

from optmodels import ProblemError
from optmodels import biasfield as bf

_FD = bf.synthetic_field_data(0, cells=8)[0]
_RAGGED = [[0.0], [1.0, 1.0]]
_NONE = [[1.0, None, 2.0]] * 2
_TEXT = [["a"] * 3] * 2
_COMPLEX = np.ones((2, 3)) * (1 + 1j)
_PLOTS = bf.PlotTable(
    time=np.array([0.0, 10.0, 30.0, 200.0, 5.0, 100.0]),
    radar=np.array([0, 1, 0, 1, 1, 0]),
    range=np.full(6, 5e4),
    azimuth=np.zeros(6),
    object=np.array([7, 7, 3, 3, -1, 7]),
)


def _plot_table(**change: Any) -> bf.PlotTable:
    cols = {
        "time": np.arange(3.0),
        "radar": np.array([0, 1, 0]),
        "range": np.array([1e3, 2e3, 3e3]),
        "azimuth": np.array([0.1, 0.2, 0.3]),
        "object": np.array([-1, 0, 0]),
    }
    return bf.PlotTable(**(cols | change))


def _field_data(adjacency: Any) -> bf.FieldData:
    return bf.FieldData(_FD.radars, _FD.centers, _FD.xi, adjacency, _FD.P)


_BAD_ARRAYS = [
    (_RAGGED, "a ragged nested sequence"),
    (_TEXT, "text entries"),
    (_NONE, "an entry of type NoneType"),
    (_COMPLEX, "complex values"),
    ({"a": 1.0}, "got dict"),
    ("1.5", "got str"),
]


@pytest.mark.parametrize("value, why", _BAD_ARRAYS)
@pytest.mark.parametrize(
    "call, named",
    [
        (bf.wrap_angle, "biasfield.wrap_angle a: "),
        (bf.fl_to_height, "biasfield.fl_to_height pressure_altitude: "),
    ],
)
def test_hot_path_helpers_refuse_a_bad_array_naming_it(
    call: Callable[[Any], Any], named: str, value: Any, why: str
) -> None:
    with pytest.raises(ProblemError, match=named + ".*" + why):
        call(value)


@pytest.mark.parametrize(
    "call, named",
    [
        (lambda: _field_data("x"), "biasfield.FieldData adjacency: not a numeric"),
        (lambda: _field_data({"a": 1.0}), "biasfield.FieldData adjacency: not a numeric"),
        (lambda: _field_data(_RAGGED), "biasfield.FieldData adjacency: a ragged"),
        (lambda: _field_data([[0, 1], [1, None]]), "biasfield.FieldData adjacency: not a num"),
        (lambda: _field_data(np.eye(3)), r"biasfield.FieldData adjacency: expected \(8, 8\)"),
        (lambda: bf.laplacian(_FD.centers, ""), "biasfield.laplacian adjacency: not a numeric"),
        (lambda: bf.laplacian(_FD.centers, {"a": 1}), "biasfield.laplacian adjacency: not a"),
        (
            lambda: bf.laplacian(_FD.centers, np.array([[0, 9]])),
            "biasfield.laplacian adjacency: edge list refers to cells outside",
        ),
        (lambda: _plot_table(radar=[[0], [1, 1], [0]]), "biasfield.PlotTable radar: a ragged"),
        (lambda: _plot_table(object=[[0, 1], [1], [0]]), "biasfield.PlotTable object: a ragged"),
        (lambda: _plot_table(radar=["0", "1", "0"]), "biasfield.PlotTable radar: not a numeric"),
        (lambda: _plot_table(object=[0.5, 1, 2]), "biasfield.PlotTable object: expected 3 int"),
        (
            lambda: _plot_table(height=[1.0, None, 2.0]),
            "biasfield.PlotTable height: not a numeric",
        ),
        (
            lambda: _plot_table(height=["1.5", "2", "3"]),
            "biasfield.PlotTable height: not a numeric",
        ),
        (lambda: _plot_table(height=[1j, 1.0, 2.0]), "biasfield.PlotTable height: complex"),
        (lambda: bf.seen_by_others("x"), "biasfield.seen_by_others plots: expected a PlotTable"),
        (lambda: bf.seen_by_others(3.5), "biasfield.seen_by_others plots: expected a PlotTable"),
        (lambda: bf.seen_by_others({"a": 1}), "seen_by_others plots: expected a PlotTable"),
        (lambda: bf.solve(_FD, box=_RAGGED), "biasfield.solve box: a ragged"),
        (lambda: bf.solve(_FD, box=[500.0, None]), "biasfield.solve box: not a numeric"),
        (lambda: bf.solve(_FD, box=(500.0, 0.01, 1.0)), "biasfield.solve box: expected a pair"),
        (lambda: bf.solve(_FD, box=[[500.0, 0.01]]), "biasfield.solve box: expected a pair"),
        (lambda: bf.solve(_FD, box=(500.0, True)), r"biasfield.solve box\[1\]"),
        (lambda: bf.solve_lipschitz(_FD, box=_RAGGED), "biasfield.solve_lipschitz box: a rag"),
        (lambda: bf.uncertainty_sets("x"), "biasfield.uncertainty_sets data: expected a Fiel"),
        (lambda: bf.uncertainty_sets(3.5), "biasfield.uncertainty_sets data: expected a Field"),
        (lambda: bf.uncertainty_sets({"a": 1}), "uncertainty_sets data: expected a FieldData"),
    ],
)
def test_bad_argument_is_one_problem_error_naming_it(call: Callable[[], Any], named: str) -> None:
    with pytest.raises(ProblemError, match=named):
        call()


# ------------------------------------------------------------------ good calls
def test_wrap_angle_matches_the_angle_of_the_unit_phasor() -> None:
    """(−π, π], against np.angle(exp(ia)); every input form gives the float64 numbers."""
    a = np.random.default_rng(28).uniform(-50.0, 50.0, 2000)
    want = np.angle(np.exp(1j * a))
    np.testing.assert_allclose(bf.wrap_angle(a), want, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(bf.wrap_angle(a.tolist()), bf.wrap_angle(a))
    np.testing.assert_array_equal(
        bf.wrap_angle(a.reshape(40, 50)), bf.wrap_angle(a).reshape(40, 50)
    )
    f32 = a.astype(np.float32)
    np.testing.assert_array_equal(bf.wrap_angle(f32), bf.wrap_angle(f32.astype(np.float64)))
    ints = np.array([-7, 0, 7])
    np.testing.assert_array_equal(bf.wrap_angle(ints), bf.wrap_angle(ints.astype(np.float64)))
    edges = bf.wrap_angle([np.pi, -np.pi, 3 * np.pi, 0.5, np.nan])
    np.testing.assert_array_equal(edges[:4], [np.pi, np.pi, np.pi, 0.5])  # −π goes to +π
    assert np.isnan(edges[4])  # an unknown angle stays unknown
    assert float(bf.wrap_angle(3 * np.pi / 2)) == pytest.approx(-np.pi / 2, abs=1e-15)
    out = bf.wrap_angle(a)
    assert out.dtype == np.float64 and out is not a


def test_fl_to_height_matches_the_isa_geopotential_formula() -> None:
    """h = R·H_p/(R − H_p) + N (R = 6 356 766 m), i.e. the geometric height whose ISA
    geopotential R·h/(R + h) is the pressure altitude; NaN (no flight level) stays NaN."""
    r = 6_356_766.0
    hp = np.random.default_rng(28).uniform(-500.0, 15_000.0, 1000)
    for n in (0.0, 47.0, -30.0):
        h = bf.fl_to_height(hp, n)
        np.testing.assert_allclose(h, r * hp / (r - hp) + n, rtol=1e-15, atol=1e-9)
        np.testing.assert_allclose(r * (h - n) / (r + (h - n)), hp, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(bf.fl_to_height(hp.tolist(), 47.0), bf.fl_to_height(hp, 47.0))
    np.testing.assert_array_equal(
        bf.fl_to_height(np.array([0, 3048])), [0.0, r * 3048 / (r - 3048)]
    )
    out = bf.fl_to_height([1000.0, np.nan])
    assert np.isnan(out[1]) and out[0] == pytest.approx(r * 1000.0 / (r - 1000.0), rel=1e-15)
    assert float(bf.fl_to_height(11_000.0)) == pytest.approx(11_019.07, abs=0.01)


def test_laplacian_and_adjacency_forms_match_a_dense_computation() -> None:
    """Q = diag(A·1) − A with a_ij = c_ij/‖x_i − x_j‖², from a dense 0/1 list, an (E, 2)
    edge list and the sparse matrix alike; FieldData stores the same graph."""
    c = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0], [3.0, 4.0]])
    edges = [[0, 1], [0, 2], [1, 3], [2, 3], [1, 2]]
    dense = np.zeros((4, 4))
    for i, j in edges:
        dense[i, j] = dense[j, i] = 1.0
    a = np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            if dense[i, j]:
                a[i, j] = 1.0 / np.sum((c[i] - c[j]) ** 2)
    want = np.diag(a.sum(axis=1)) - a
    for adj in (dense.tolist(), np.array(edges), sparse.csr_matrix(dense), dense.astype(bool)):
        np.testing.assert_allclose(bf.laplacian(c, adj).toarray(), want, rtol=1e-15)
    fd = _field_data(_FD.adjacency.toarray().tolist())
    assert (fd.adjacency != _FD.adjacency).nnz == 0


def test_plot_table_reads_lists_as_the_arrays() -> None:
    table = _plot_table(radar=[0, 1, 0], object=[-1, 0, 0], height=[1e3, np.nan, 2e3])
    assert table.radar.dtype == np.int64 and table.object.dtype == np.int64
    np.testing.assert_array_equal(table.radar, [0, 1, 0])
    np.testing.assert_array_equal(table.height, [1e3, np.nan, 2e3])


def test_seen_by_others_matches_a_brute_force_search() -> None:
    """Seen when a plot of the same (known) object by another radar lies within the
    window: every pair compared directly."""
    p = _PLOTS
    for window in (5.0, 15.0, 60.0, 500.0):
        want = [
            p.object[a] >= 0
            and any(
                p.object[b] == p.object[a]
                and p.radar[b] != p.radar[a]
                and abs(p.time[b] - p.time[a]) <= window
                for b in range(len(p))
            )
            for a in range(len(p))
        ]
        np.testing.assert_array_equal(bf.seen_by_others(p, window), want)


def test_uncertainty_sets_match_the_polar_maps_written_out() -> None:
    """(10) in 2-D: Φ⁰_k,i = p_i(ξ̂_i(k)) − p_i(ξ̂_(k)) (azimuth wrapped) and the blocks of
    Φ¹ the Jacobians [(dx, dy)/r; (dy, −dx)/r²] at ξ̂_(k), azimuth clockwise from North."""
    fd = _FD
    phi0, phi1 = bf.uncertainty_sets(fd)
    mean = fd.xi.mean(axis=1)
    want0 = np.empty((fd.k, fd.m, 2))
    want1 = np.zeros((2 * fd.m * fd.k, 2 * fd.k))
    for k in range(fd.k):
        for i in range(fd.m):
            d1, d0 = fd.xi[k, i] - fd.radars[i], mean[k] - fd.radars[i]
            daz = np.arctan2(d1[0], d1[1]) - np.arctan2(d0[0], d0[1])
            want0[k, i] = [np.hypot(*d1) - np.hypot(*d0), np.angle(np.exp(1j * daz))]
            r2 = d0 @ d0
            row = 2 * (k * fd.m + i)
            want1[row : row + 2, 2 * k : 2 * k + 2] = [
                [d0[0] / np.sqrt(r2), d0[1] / np.sqrt(r2)],
                [d0[1] / r2, -d0[0] / r2],
            ]
    np.testing.assert_allclose(phi0, want0.reshape(-1), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(phi1.toarray(), want1, rtol=1e-12, atol=0)


def test_solve_reads_a_box_given_as_a_list_or_an_array() -> None:
    """The pair may be a tuple, a list or an array: the same field."""
    by_tuple = bf.solve(_FD, box=(500.0, 0.01))
    for box in ([500.0, 0.01], np.array([500.0, 0.01])):
        other = bf.solve(_FD, box=box)
        assert other.status == by_tuple.status
        np.testing.assert_array_equal(other.field, by_tuple.field)
