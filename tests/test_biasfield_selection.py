"""Bias field, part 2 (paper 001, section 4): the smoothest field on the uncertainty sets —
generic QP (CVXPY) against the sparse closed form (11), the box (8), the Lipschitz SOCP."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from optmodels import ProblemError
from optmodels import biasfield as bf
from optmodels.backends.cvxpy_backend import available_solvers
from optmodels.biasfield import selection as sel
from optmodels.core import Status
from optmodels.scenarios.radar_network import radar_network

QP_SOLVERS = [s for s in ("CLARABEL", "OSQP", "SCS", "PIQP") if s in available_solvers()]


@pytest.fixture(scope="module")
def data() -> bf.FieldData:
    sc = radar_network(3, n_aircraft=40, duration=1800.0, fields="smooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fd, _ = bf.build_field_data(sc.plots, sc.radars, cells=60)
    return fd


def test_edge_factor_reproduces_r(data: bf.FieldData) -> None:
    g = sel.edge_factor(data)
    r = sel._r_matrix(data)
    assert abs(g.T @ g - r).max() < 1e-12 * abs(r).max()
    # J(φ) = φᵀRφ and the paper's sum over ordered pairs is twice that
    rng = np.random.default_rng(0)
    phi = rng.normal(size=r.shape[0])
    total = 0.0
    p = sel._p_full(data)
    m2 = 2 * data.m
    for i in range(data.k):
        for j in range(data.k):
            if data.adjacency[i, j] != 0:
                d = phi[m2 * i:m2 * (i + 1)] - phi[m2 * j:m2 * (j + 1)]
                total += d @ p @ d / np.sum((data.centers[i] - data.centers[j]) ** 2)
    assert sel.objective(data, phi) == pytest.approx(phi @ (r @ phi), rel=1e-12)
    assert total == pytest.approx(2 * sel.objective(data, phi), rel=1e-12)


@pytest.mark.parametrize("formulation", ["constrained", "reduced"])
@pytest.mark.parametrize("solver", QP_SOLVERS)
def test_unconstrained_qp_equals_closed_form(data: bf.FieldData, solver: str,
                                             formulation: str) -> None:
    """Every solver reporting OPTIMAL lands on the sparse closed form to 1e-8 (relative
    to max |φ|) with the package's high-accuracy defaults (OSQP: 50 polish refinements).
    SCS cannot take the reduced problem without a box (no constraint rows): reported as
    ERROR, never as a field."""
    cf = sel.closed_form(data)
    assert cf.residuals["stationarity"] < 1e-10
    g = sel.solve(data, solver=solver, formulation=formulation)  # type: ignore[arg-type]
    if solver == "SCS" and formulation == "reduced":
        assert g.status is Status.ERROR and np.all(np.isnan(g.phi))
        return
    assert g.status is Status.OPTIMAL, g.message
    assert np.max(np.abs(g.phi - cf.phi)) < 1e-8 * np.max(np.abs(cf.phi))
    assert g.objective == pytest.approx(cf.objective, rel=1e-8)


def test_printed_11_sign(data: bf.FieldData) -> None:
    """(11) as printed, η = +(Φ1ᵀRΦ1)⁻¹Φ1ᵀRΦ0, is the maximiser's mirror: its J is
    larger than at η = 0, while the corrected sign gives the minimum."""
    phi0, phi1 = bf.uncertainty_sets(data)
    r = sel._r_matrix(data).toarray()
    a = phi1.T @ r @ phi1
    b = phi1.T @ r @ phi0
    printed = phi0 + phi1 @ np.linalg.solve(a, b)
    right = phi0 + phi1 @ -np.linalg.solve(a, b)
    j0 = phi0 @ r @ phi0
    assert printed @ r @ printed > j0 > right @ r @ right
    np.testing.assert_allclose(right, sel.closed_form(data).phi, rtol=1e-9,
                               atol=1e-9 * np.abs(right).max())


def test_binding_box(data: bf.FieldData) -> None:
    """K at 90 % of the unconstrained field's largest |f|: the box binds, J rises, solvers
    agree to 1e-6 and KKT holds to 1e-7 (stationarity, complementarity, multiplier
    signs), all recomputed in NumPy."""
    cf = sel.closed_form(data)
    box = (0.9 * np.abs(cf.field[..., 0]).max(), 0.9 * np.abs(cf.field[..., 1]).max())
    assert sel.box_feasibility(data, box).size == 0
    sols = [sel.solve(data, box=box, solver=s, formulation=f)  # type: ignore[arg-type]
            for s in QP_SOLVERS for f in ("constrained", "reduced")]
    ref = sols[0]
    assert ref.status is Status.OPTIMAL and np.any(ref.active != 0)
    assert ref.objective > cf.objective * (1 + 1e-6)
    for s in sols:
        assert s.status is Status.OPTIMAL
        # per component (metres and radians), relative to that component's largest value
        diff = np.abs(s.field - ref.field).max(axis=(0, 1))
        assert np.all(diff < 1e-6 * np.abs(ref.field).max(axis=(0, 1))), (s.method, diff)
        assert s.residuals["stationarity"] < 1e-7 and s.residuals["complementarity"] < 1e-7
        assert s.residuals["dual_sign"] == 0 and s.residuals["box"] < 1e-9
        # every binding bound has a multiplier of the right sign
        act = s.active.reshape(-1) != 0
        assert np.all(s.duals.reshape(-1)[act] * s.active.reshape(-1)[act] >= 0)
    # a box that the optimum already satisfies changes nothing (inactive: QP = closed form)
    loose = (2 * np.abs(cf.field[..., 0]).max(), 2 * np.abs(cf.field[..., 1]).max())
    g = sel.solve(data, box=loose)
    assert np.all(g.active == 0)
    assert np.max(np.abs(g.phi - cf.phi)) < 1e-7 * np.max(np.abs(cf.phi))


def test_infeasible_box_is_reported(data: bf.FieldData) -> None:
    cf = sel.closed_form(data)
    box = (0.05 * np.abs(cf.field[..., 0]).max(), 0.05 * np.abs(cf.field[..., 1]).max())
    bad = sel.box_feasibility(data, box)
    assert bad.size > 0
    g = sel.solve(data, box=box)
    assert g.status is Status.INFEASIBLE and "cells" in g.message
    assert np.all(np.isnan(g.phi))


def test_lipschitz_is_minimal(data: bf.FieldData) -> None:
    """The SOCP's L: capping it 0.1 % lower makes the problem infeasible; 0.1 % higher is
    feasible; and no field of the quadratic criterion has a smaller L."""
    lip = sel.solve_lipschitz(data)
    assert lip.status is Status.OPTIMAL and lip.lipschitz is not None
    assert sel.solve_lipschitz(data, cap=lip.lipschitz * (1 - 1e-3)).status is Status.INFEASIBLE
    assert sel.solve_lipschitz(data, cap=lip.lipschitz * (1 + 1e-3)).status.ok
    cf = sel.closed_form(data)
    lt = np.linalg.cholesky(sel._p_full(data)).T
    i, j = np.nonzero(np.triu(data.adjacency.toarray()))
    m2 = 2 * data.m
    jumps = [np.linalg.norm(lt @ (cf.phi[m2 * a:m2 * (a + 1)] - cf.phi[m2 * b:m2 * (b + 1)]))
             / np.linalg.norm(data.centers[a] - data.centers[b]) for a, b in zip(i, j, strict=True)]
    assert max(jumps) >= lip.lipschitz * (1 - 1e-6)
    # and its J is no smaller than the quadratic optimum
    assert lip.objective >= cf.objective * (1 - 1e-9)


def test_bad_input(data: bf.FieldData) -> None:
    adj = data.adjacency.toarray()
    adj[0, :] = 0
    adj[:, 0] = 0
    lonely = bf.FieldData(data.radars, data.centers, data.xi, adj, data.P)
    with pytest.raises(ProblemError, match="no neighbour"):
        sel.closed_form(lonely)
    with pytest.raises(ProblemError, match="box"):
        sel.solve(data, box=(-1.0, 1e-3))
    asym = data.adjacency.toarray()
    asym[0, 1], asym[1, 0] = 1, 0
    with pytest.raises(ProblemError, match="symmetric"):
        bf.FieldData(data.radars, data.centers, data.xi, asym, data.P)
    with pytest.raises(ProblemError, match="P"):
        bf.FieldData(data.radars, data.centers, data.xi, data.adjacency, -np.eye(2))
    with pytest.raises(ProblemError, match="xi"):
        bf.FieldData(data.radars, data.centers, data.xi[:, :2], data.adjacency, data.P)


def test_box_feasibility_matches_per_cell_lps() -> None:
    """The vectorised vertex test agrees with one HiGHS LP per cell (scipy.linprog) at box
    sizes from very tight to loose."""
    from scipy.optimize import linprog

    fd, _ = bf.synthetic_field_data(1, cells=150)
    cf = sel.closed_form(fd)
    phi0, phi1 = bf.uncertainty_sets(fd)
    m2 = 2 * fd.m
    for f in (0.5, 0.9, 1.0):
        box = (f * np.abs(cf.field[..., 0]).max(), f * np.abs(cf.field[..., 1]).max())
        bound = np.tile(box, fd.m * fd.k)
        slow = []
        for k in range(fd.k):
            sl = slice(m2 * k, m2 * (k + 1))
            a = phi1[sl, 2 * k:2 * k + 2].toarray() / bound[sl, None]
            p0 = phi0[sl] / bound[sl]
            a = a / np.abs(a).max(axis=0)
            r = linprog(np.zeros(2), A_ub=np.vstack([a, -a]), b_ub=np.concatenate([1 - p0, 1 + p0]),
                        bounds=[(None, None)] * 2, method="highs")
            if r.status == 2:
                slow.append(k)
        np.testing.assert_array_equal(sel.box_feasibility(fd, box), slow)


def test_identifiability_report() -> None:
    """Sparse condition number and per-cell spread against dense linear algebra."""
    fd, _ = bf.synthetic_field_data(2, cells=200)
    idf = sel.identifiability(fd, batch=64)
    _, phi1 = bf.uncertainty_sets(fd)
    h = (phi1.T @ sel._r_matrix(fd) @ phi1).toarray()
    assert idf.condition == pytest.approx(np.linalg.cond(h), rel=1e-6)
    hi = np.linalg.inv(h)
    spread = np.sqrt([np.trace(hi[2 * k:2 * k + 2, 2 * k:2 * k + 2]) for k in range(fd.k)])
    np.testing.assert_allclose(idf.spread, spread, rtol=1e-8)
    # the worst-determined cells have fewer neighbours than the typical cell
    deg = np.asarray(fd.adjacency.sum(axis=1)).ravel()
    assert np.mean(deg[idf.worst[:10]]) < np.median(deg)


def test_disconnected_graph_is_solved_per_component() -> None:
    """Two separate groups of cells: the joint solve equals solving each group alone."""
    fd, _ = bf.synthetic_field_data(4, cells=80)
    left = fd.centers[:, 0] < 0
    adj = fd.adjacency.toarray()
    adj[np.ix_(left, ~left)] = 0
    adj[np.ix_(~left, left)] = 0
    split = bf.FieldData(fd.radars, fd.centers, fd.xi, adj, fd.P)
    both = sel.closed_form(split)
    assert both.info["components"] >= 2
    for part in (left, ~left):
        sub = bf.FieldData(fd.radars, fd.centers[part], fd.xi[part], adj[np.ix_(part, part)],
                           fd.P)
        alone = sel.closed_form(sub)
        np.testing.assert_allclose(both.field[part], alone.field, rtol=1e-8,
                                   atol=1e-10 * np.abs(alone.field).max())
