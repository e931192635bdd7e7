"""The ADS-B referee ``adsb_field`` over the union of coverage (per-cell radar subsets).

The unknowns are the seen entries φ_ki (i ∈ S_k); a plot of radar i is referred to the cells
radar i sees; a radar whose own cells fall into parts is refused when a part has no data.
Every answer is compared with an independent dense solve written here from the definitions
(docs/formulations.md, "ADS-B as the referee"): the data term from the plots one by one
(2-D polar map and Jacobian by hand, nearest seen cell by brute force, scipy's Delaunay for
the covered area and the P1 weights), the smoothness (9) from its printed sum over the edges
and the radars that see both cells, and the regularised least squares solved as one stacked
least-squares problem by numpy's SVD-based ``lstsq`` (not the normal equations the package
factorises)."""

from __future__ import annotations

import dataclasses
import re
import warnings
from fractions import Fraction

import numpy as np
import pytest
from scipy.spatial import Delaunay

from optmodels import biasfield as bf
from optmodels.biasfield.problem import r_matrix, radar_parts
from optmodels.biasfield.referee_system import adsb_system
from optmodels.core import ProblemError
from optmodels.scenarios.radar_network import line_sites, radar_network, ring_sites
from tests import sweep_recipes_biasfield as rec
from tests.sweep_support import Ctx

SIG_REF = 10.0  # m, the ADS-B error of the simulated references and of the solves
EPS = float(np.finfo(float).eps)


# ----------------------------------------------------------------------------- independent
def _default_radius(fd: bf.FieldData) -> float:
    d = np.sqrt(((fd.centers[:, None] - fd.centers[None]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return 1.5 * float(np.median(d.min(axis=1)))


def _bary(tri: Delaunay, y: np.ndarray) -> tuple[int, np.ndarray]:
    s = int(tri.find_simplex(y[None])[0])
    if s < 0:
        return s, np.empty(0)
    t = tri.transform[s]
    b = t[:2] @ (y - t[2])
    return s, np.r_[b, 1.0 - b.sum()]


def _independent_system(fd, plots, radars, ref, radius, model="cells"):
    """Dense A (2n × 2mK, full layout), the per-plot weights W_j (n, 2, 2), d (2n,), the
    number of plots moved to a seen cell. A plot of radar i is used when its ADS-B position
    lies in the triangulation of all centres and within ``radius`` of a cell radar i sees;
    its model is that nearest seen cell (``cells``), or the P1 interpolant on the
    triangulation of radar i's cells, the nearest of them outside it (``interpolant``)."""
    k, m = fd.k, fd.m
    seen = np.ones((k, m), bool) if fd.seen is None else np.asarray(fd.seen)
    whole = Delaunay(fd.centers)
    own_tri = {}
    for i in range(m):
        own = np.flatnonzero(seen[:, i])
        own_tri[i] = (own, Delaunay(fd.centers[own]) if own.size >= 3 else None)
    rows, ds, ws = [], [], []
    moved = 0
    for j in np.flatnonzero(np.all(np.isfinite(ref), axis=1)):
        i, y = int(plots.radar[j]), ref[j]
        own, tri_i = own_tri[i]
        dist = np.hypot(*(fd.centers[own] - y).T)
        c = int(own[np.argmin(dist)])
        if whole.find_simplex(y[None])[0] < 0 or dist.min() > radius:
            continue
        moved += int(not seen[np.argmin(np.hypot(*(fd.centers - y).T)), i])
        dx, dy = y - radars.sites[i]
        r = np.hypot(dx, dy)
        az = np.arctan2(dx, dy)  # clockwise from North
        jac = np.array([[dx / r, dy / r], [dy / r**2, -dx / r**2]])
        d = np.array([plots.range[j] - r, (plots.azimuth[j] - az + np.pi) % (2 * np.pi) - np.pi])
        cov = np.diag([radars.sigma_range[i] ** 2, radars.sigma_azimuth[i] ** 2])
        cov = cov + SIG_REF**2 * jac @ jac.T
        weights = {c: 1.0}
        if model == "interpolant" and tri_i is not None:
            s, b = _bary(tri_i, y)
            if s >= 0:
                weights = dict(zip(own[tri_i.simplices[s]].tolist(), b, strict=True))
        a = np.zeros((2, 2 * m * k))
        for cell, w in weights.items():
            a[0, 2 * (cell * m + i)] += w
            a[1, 2 * (cell * m + i) + 1] += w
        rows.append(a)
        ds.append(d)
        ws.append(np.linalg.inv(cov))
    return np.vstack(rows), np.array(ws), np.concatenate(ds), moved


def _independent_g(fd) -> np.ndarray:
    """G with ‖Gφ‖² = Σ_i Σ_{(k,l) ∈ E, i ∈ S_k ∩ S_l} a_kl ‖φ_ki − φ_li‖²_{P_i} (9)."""
    k, m = fd.k, fd.m
    seen = np.ones((k, m), bool) if fd.seen is None else np.asarray(fd.seen)
    adj = fd.adjacency.toarray()
    p_full = np.kron(np.eye(m), fd.P) if fd.P.shape == (2, 2) else fd.P
    rows = []
    for u in range(k):
        for v in range(u + 1, k):
            if not adj[u, v]:
                continue
            a = 1.0 / np.sum((fd.centers[u] - fd.centers[v]) ** 2)
            for i in range(m):
                if seen[u, i] and seen[v, i]:
                    c = np.linalg.cholesky(p_full[2 * i : 2 * i + 2, 2 * i : 2 * i + 2])
                    g = np.zeros((2, 2 * m * k))
                    g[:, 2 * (u * m + i) : 2 * (u * m + i) + 2] = np.sqrt(a) * c.T
                    g[:, 2 * (v * m + i) : 2 * (v * m + i) + 2] = -np.sqrt(a) * c.T
                    rows.append(g)
    return np.vstack(rows)


def _independent_solve(fd, a, w, d, mu):
    """min_φ Σ_j (A_jφ − d_j)ᵀW_j(A_jφ − d_j) + μ‖Gφ‖² over the seen entries, as one stacked
    least-squares problem (columns scaled to unit norm) by numpy's lstsq. Returns the full
    φ (0 at the entries not seen), χ², J."""
    keep = np.repeat((np.ones((fd.k, fd.m), bool) if fd.seen is None else fd.seen).ravel(), 2)
    lt = np.linalg.cholesky(w).transpose(0, 2, 1)  # W_j = L Lᵀ: ‖Lᵀ r‖² = rᵀ W r
    a_w = np.einsum("jab,jbc->jac", lt, a[:, keep].reshape(-1, 2, int(keep.sum())))
    d_w = np.einsum("jab,jb->ja", lt, d.reshape(-1, 2)).ravel()
    g = _independent_g(fd)[:, keep]
    stacked = np.vstack([a_w.reshape(-1, int(keep.sum())), np.sqrt(mu) * g])
    scale = 1.0 / np.linalg.norm(stacked, axis=0)
    z = np.linalg.lstsq(stacked * scale, np.r_[d_w, np.zeros(g.shape[0])], rcond=None)[0]
    phi = np.zeros(keep.size)
    phi[keep] = scale * z
    res = a @ phi - d
    chi2 = float(np.einsum("ja,jab,jb->", res.reshape(-1, 2), w, res.reshape(-1, 2)))
    jv = g @ phi[keep]
    return phi.reshape(fd.k, fd.m, 2), chi2, float(jv @ jv)


def _relative(got: np.ndarray, want: np.ndarray) -> tuple[float, float]:
    """Largest difference per component (range, azimuth) over the largest value."""
    return tuple(  # type: ignore[return-value]
        float(np.abs(got[..., c] - want[..., c]).max() / np.abs(want[..., c]).max()) for c in (0, 1)
    )


def _check_against_independent(fd, sc, ref, out, model="cells"):
    a, w, d, moved = _independent_system(fd, sc.plots, sc.radars, ref, _default_radius(fd), model)
    assert out.dof == d.size  # 2 × the plots used, all referred to cells their radar sees
    assert out.moved == moved
    assert np.isfinite(out.mu) and out.mu > 0
    phi, chi2, j = _independent_solve(fd, a, w, d, out.mu)
    assert max(_relative(out.field, phi)) <= 1e-9
    assert out.chi2 == pytest.approx(chi2, rel=1e-9)
    assert out.objective == pytest.approx(j, rel=1e-8)
    if fd.seen is not None:  # the entries of a radar that does not see a cell: not estimated
        assert np.all(out.field[~fd.seen] == 0.0) and np.all(out.counts[~fd.seen] == 0)
    return chi2


# ----------------------------------------------------------------------------- networks
def _union(sc, cells: int) -> bf.FieldData:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return bf.field_data_from_plots(sc.plots, sc.radars, cells=cells).data


@pytest.fixture(scope="module")
def line():
    """Four radars on a line 150 km apart, range 120 km: pairwise overlaps only."""
    sc = radar_network(
        np.random.default_rng(5),
        n_aircraft=30,
        duration=900.0,
        sites=line_sites(4, 150e3),
        max_range=120e3,
    )
    return sc, _union(sc, 25), sc.adsb_positions(np.random.default_rng(6))


@pytest.fixture(scope="module")
def ring():
    """Six radars on a ring of radius 160 km, range 140 km (the centre unseen)."""
    sc = radar_network(
        np.random.default_rng(7),
        n_aircraft=60,
        duration=900.0,
        sites=ring_sites(6, 160e3),
        max_range=140e3,
        region=200e3,
    )
    return sc, _union(sc, 40), sc.adsb_positions(np.random.default_rng(8))


@pytest.fixture(scope="module")
def all_radar():
    sc = radar_network(np.random.default_rng(11), n_aircraft=20, duration=900.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fd = bf.field_data_from_plots(sc.plots, sc.radars, cells=30, coverage="all").data
    return sc, fd, sc.adsb_positions(np.random.default_rng(12))


@pytest.mark.parametrize("network", ["line", "ring"])
@pytest.mark.parametrize("model", ["cells", "interpolant"])
def test_union_networks_reach_the_discrepancy_level(network, model, request):
    """Refused before (every realistic union network: the unseen entries were free
    unknowns, each its own part of the radar's graph); now the field at the discrepancy
    level over the seen entries, equal to the independent solve. (The means level on a
    union case: against the exact solve below; the independent least squares here reaches
    only ~1e-10 there, μ being 1e-12 of the data's scale.)"""
    sc, fd, ref = request.getfixturevalue(network)
    assert fd.seen is not None and not fd.seen.all(axis=1).any()  # no cell seen by all
    out = bf.adsb_field(fd, sc.plots, sc.radars, ref, model=model)
    assert out.status.ok and out.status.value == "optimal"
    chi2 = _check_against_independent(fd, sc, ref, out, model)
    assert abs(chi2 - out.dof) <= 1e-2 * out.dof  # the level: χ² = 2 × the plots used
    assert out.stationarity <= 1e-9 and out.conditioning <= 1e-12
    used = int(np.all(np.isfinite(ref), axis=1).sum()) - out.unused
    assert out.dof == 2 * used == 2 * int(out.counts.sum())
    # the ring has plots nearest to a cell their radar does not see: used, not dropped
    assert (out.moved > 0) == (network == "ring")
    np.testing.assert_array_equal(out.seen, fd.seen)
    np.testing.assert_array_equal(out.map(fd).seen, fd.seen)
    np.testing.assert_array_equal(out.map(fd.centers).seen, fd.seen)


@pytest.mark.parametrize("level", ["discrepancy", "means"])
@pytest.mark.parametrize("model", ["cells", "interpolant"])
def test_all_radar_network_gives_the_papers_answer(all_radar, level, model):
    """Without subsets nothing changes but the solve's scaling: the same field as the
    independent solve (round-off), at both levels."""
    sc, fd, ref = all_radar
    assert fd.seen is None
    out = bf.adsb_field(fd, sc.plots, sc.radars, ref, level=level, model=model)
    assert out.status.value == "optimal" and out.moved == 0 and out.seen is None
    chi2 = _check_against_independent(fd, sc, ref, out, model)
    if level == "discrepancy":
        assert abs(chi2 - out.dof) <= 1e-2 * out.dof
    else:
        assert chi2 < out.dof


def _two_part_network(all_radar):
    """The all-radar cells with radar R1 taken out of a band of cells across the middle:
    R1's own cells fall into two parts (no edge of the neighbour graph crosses the band),
    every cell still seen by three radars."""
    sc, fd, ref = all_radar
    x = fd.centers[:, 0]
    for width in np.arange(5e3, 80e3, 5e3):
        seen = np.ones((fd.k, fd.m), dtype=bool)
        seen[np.abs(x - np.median(x)) < width, 0] = False
        two = dataclasses.replace(fd, seen=seen)
        _, labels = radar_parts(two)[0]
        parts = np.unique(labels[seen[:, 0]])
        if parts.size == 2:
            return sc, two, ref, [np.flatnonzero((labels == p) & seen[:, 0]) for p in parts]
    raise AssertionError("no band splits R1's cells in two")


def test_radar_with_data_on_one_of_its_two_parts_is_refused(all_radar):
    sc, fd, ref, (part_a, part_b) = _two_part_network(all_radar)
    # with data on both parts: the field, equal to the independent solve
    out = bf.adsb_field(fd, sc.plots, sc.radars, ref)
    assert out.status.ok and out.moved > 0
    assert out.counts[part_a, 0].sum() > 0 and out.counts[part_b, 0].sum() > 0
    _check_against_independent(fd, sc, ref, out)
    # no data of R1 on part B: its constant there is determined by no μ
    own = np.flatnonzero(fd.seen[:, 0])
    near = own[np.argmin(((ref[:, None] - fd.centers[own][None]) ** 2).sum(-1), axis=1)]
    blind = ref.copy()
    blind[(sc.plots.radar == 0) & np.isin(near, part_b)] = np.nan
    cells = re.escape(str(part_b[:10].tolist()))
    for level in ("discrepancy", "means"):
        with pytest.raises(ProblemError, match=rf"radar 'R1' has no plot .* in cells {cells}"):
            bf.adsb_field(fd, sc.plots, sc.radars, blind, level=level)
    assert set(part_b) <= set(own)  # the cells named are R1's own


# ----------------------------------------------------------------------------- precision
def _exact_solve(h: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The exact solution of the float system h x = b (rational Gauss-Jordan)."""
    n = h.shape[0]
    rows = [[Fraction(float(v)) for v in h[i]] + [Fraction(float(b[i]))] for i in range(n)]
    for col in range(n):
        piv = max(range(col, n), key=lambda r: abs(rows[r][col]))
        rows[col], rows[piv] = rows[piv], rows[col]
        for r in range(n):
            if r != col and rows[r][col] != 0:
                f = rows[r][col] / rows[col][col]
                rows[r] = [x - f * y for x, y in zip(rows[r], rows[col], strict=True)]
    return np.array([float(rows[i][n] / rows[i][i]) for i in range(n)])


@pytest.mark.parametrize("model", ["cells", "interpolant"])
def test_means_level_is_exact_to_round_off_on_the_sweeps_union_case(model):
    """The sweep's tiny 3-D union case at the means level (μ ≈ 1e-12 of the data's scale:
    cells without data are set by the smoothness alone): the unscaled matrix has κ > 1e15
    and an unscaled solve lost 2.4e-5 relative with a stationarity residual of 1e-16. The
    Jacobi-scaled solve is exact to round-off, and κ₁ of what is solved is in the re-check
    (``conditioning``, the Hager estimate, checked here against the dense κ₁)."""
    c = Ctx(tmp=None)
    fd, plots, radars, ref = rec._fd(c), rec._plots(c), rec._radars(c), rec._ref(c)
    out = bf.adsb_field(fd, plots, radars, ref, cell_radius=60e3, level="means", model=model)
    assert out.status.value == "optimal"
    sys_ = adsb_system("t", fd, plots, radars, ref, 60e3, SIG_REF, model)
    keep = np.flatnonzero(sys_.keep)
    a, w = sys_.amat.toarray(), sys_.wmat.toarray()
    h = out.mu * r_matrix(fd).toarray()[np.ix_(keep, keep)] + a.T @ w @ a
    b = a.T @ (w @ sys_.dvec)
    assert np.linalg.cond(h) > 1e15
    exact = _exact_solve(h, b)
    got = out.field.reshape(-1)[keep]
    assert max(_relative(got.reshape(-1, 2), exact.reshape(-1, 2))) <= 1e-12
    s = 1.0 / np.sqrt(np.diag(h))
    kappa = float(np.linalg.cond(s[:, None] * h * s[None, :], 1))
    assert kappa < 1e4
    assert kappa * EPS / 3 <= out.conditioning <= kappa * EPS * (1 + 1e-9)
