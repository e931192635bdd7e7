"""CVXPY and CasADi back-ends on problems with analytic answers."""

import casadi as ca
import cvxpy as cp
import numpy as np
import pytest

from optmodels.backends.casadi_backend import IPOPT_STATUS, build_nlpsol, run_nlpsol
from optmodels.backends.cvxpy_backend import CVXPY_STATUS, require_solver, solve_problem
from optmodels.core import SolverNotAvailable, Status

QP_SOLVERS = ["CLARABEL", "OSQP", "SCS"]


@pytest.mark.parametrize("solver", QP_SOLVERS)
def test_tiny_qp_matches_kkt_solution(solver: str) -> None:
    # min ½‖x - c‖² s.t. sum(x) = 1, x >= 0 with c = (0.9, 0.5, -1): projection onto the
    # simplex, analytic answer (0.7, 0.3, 0) (shift τ = 0.2 on the positive part).
    c = np.array([0.9, 0.5, -1.0])
    x = cp.Variable(3)
    prob = cp.Problem(cp.Minimize(0.5 * cp.sum_squares(x - c)), [cp.sum(x) == 1, x >= 0])
    opts = {"eps_abs": 1e-9, "eps_rel": 1e-9} if solver in ("OSQP", "SCS") else {}
    res = solve_problem(prob, solver, **opts)
    assert res.status is Status.OPTIMAL
    # First-order solvers at eps 1e-9 reach ~1e-7 in x; Clarabel (interior point) ~1e-9.
    np.testing.assert_allclose(x.value, [0.7, 0.3, 0.0], atol=1e-6)
    assert res.objective == pytest.approx(0.5 * (0.2**2 + 0.2**2 + 1.0), abs=1e-6)
    assert res.method == f"cvxpy:{solver}"
    assert res.solve_time >= 0 and res.build_time >= 0
    if solver != "SCS":  # SCS reports iterations too, but OSQP/Clarabel always do
        assert res.iterations is not None and res.iterations >= 1


def test_tiny_milp_with_highs() -> None:
    # max 5a + 4b + 3c, 2a + 3b + c <= 5, 4a + b + 2c <= 11, 3a + 4b + 2c <= 8, binaries:
    # enumerating the 8 points gives a = c = 1, b = 0 with value 8.
    z = cp.Variable(3, boolean=True)
    prob = cp.Problem(
        cp.Maximize(np.array([5, 4, 3]) @ z),
        [np.array([[2, 3, 1], [4, 1, 2], [3, 4, 2]]) @ z <= np.array([5, 11, 8])],
    )
    res = solve_problem(prob, "HIGHS")
    assert res.status is Status.OPTIMAL
    best = max(
        (5 * a + 4 * b + 3 * c, (a, b, c))
        for a in (0, 1) for b in (0, 1) for c in (0, 1)
        if 2 * a + 3 * b + c <= 5 and 4 * a + b + 2 * c <= 11 and 3 * a + 4 * b + 2 * c <= 8
    )
    np.testing.assert_allclose(z.value, best[1], atol=1e-9)
    assert res.objective == pytest.approx(best[0])


def test_infeasible_lp_is_reported_not_returned() -> None:
    x = cp.Variable()
    prob = cp.Problem(cp.Minimize(x), [x >= 1, x <= 0])
    res = solve_problem(prob, "CLARABEL")
    assert res.status is Status.INFEASIBLE
    assert not res.status.ok and np.isnan(res.objective)


def test_iteration_limit_maps_to_status() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(30, 10))
    x = cp.Variable(10)
    prob = cp.Problem(cp.Minimize(cp.sum_squares(a @ x - 1)), [x >= 0])
    res = solve_problem(prob, "OSQP", max_iter=2, eps_abs=1e-12, eps_rel=1e-12)
    assert res.status in (Status.ITERATION_LIMIT, Status.OPTIMAL_INACCURATE)
    assert res.status is not Status.OPTIMAL


def test_missing_solver_names_install_hint() -> None:
    with pytest.raises(SolverNotAvailable, match="pip install"):
        require_solver("NO_SUCH_SOLVER")


def test_status_tables_cover_all_codes() -> None:
    assert set(CVXPY_STATUS) >= {
        cp.OPTIMAL, cp.OPTIMAL_INACCURATE, cp.INFEASIBLE, cp.UNBOUNDED, cp.USER_LIMIT,
        cp.SOLVER_ERROR, cp.INFEASIBLE_INACCURATE, cp.UNBOUNDED_INACCURATE,
    }
    assert IPOPT_STATUS["Solve_Succeeded"] is Status.OPTIMAL
    assert IPOPT_STATUS["Maximum_Iterations_Exceeded"] is Status.ITERATION_LIMIT


def test_casadi_nlp_on_circle() -> None:
    # min x + y on x² + y² = 2: analytic minimiser (-1, -1), value -2.
    v = ca.MX.sym("v", 2)
    p = ca.MX.sym("p")
    built = build_nlpsol({"x": v, "f": v[0] + v[1], "g": ca.dot(v, v) - p, "p": p})
    res, x = run_nlpsol(built, x0=np.array([-0.5, -1.5]), p=np.array([2.0]))
    assert res.status is Status.OPTIMAL
    np.testing.assert_allclose(x, [-1.0, -1.0], atol=1e-9)
    assert res.objective == pytest.approx(-2.0, abs=1e-9)
    # An iteration cap is a status, not a solution.
    capped = build_nlpsol({"x": v, "f": v[0] + v[1], "g": ca.dot(v, v) - p, "p": p},
                          options={"max_iter": 1})
    res2, _ = run_nlpsol(capped, x0=np.array([3.0, 0.1]), p=np.array([2.0]))
    assert res2.status is Status.ITERATION_LIMIT
