"""Shared test fixtures: the solvers installed here, and the contract every solution keeps.

- ``cvxpy_solvers``, ``qp_solvers``, ``milp_solvers``: CVXPY's installed solvers, those
  that take a QP (with the CasADi conic plugins as ``CASADI_<PLUGIN>``) and a MILP, as the
  comparison harness lists them (:mod:`solvers_cmp.cases`);
- ``nlp_plugins``, ``casadi_conic_plugins``: the CasADi NLP and conic plugins that load and
  solve a test problem here;
- :func:`assert_verified` (also the fixture ``verified``): an OK status implies the NumPy
  re-check's residuals are within the stated tolerance (``core.VERIFY_TOL`` for OPTIMAL,
  ``core.REJECT_TOL`` for OPTIMAL_INACCURATE) and a finite estimate; a status that is not
  OK implies a NaN or absent estimate.

Everything heavy is imported inside the fixtures, so that collecting a test imports nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import pytest


@pytest.fixture(scope="session")
def cvxpy_solvers() -> list[str]:
    import cvxpy as cp

    return list(cp.installed_solvers())


@pytest.fixture(scope="session")
def qp_solvers() -> list[str]:
    from solvers_cmp.cases import cvxpy_qp_solvers

    return cvxpy_qp_solvers()


@pytest.fixture(scope="session")
def milp_solvers() -> list[str]:
    from solvers_cmp.cases import cvxpy_milp_solvers

    return cvxpy_milp_solvers()


@pytest.fixture(scope="session")
def nlp_plugins() -> list[str]:
    from optmodels.backends.casadi_backend import nlp_plugins as plugins

    return list(plugins())


@pytest.fixture(scope="session")
def casadi_conic_plugins() -> list[str]:
    from optmodels.backends.casadi_qp import casadi_qp_plugins

    return list(casadi_qp_plugins())


def _estimate_values(value: Any) -> np.ndarray | None:
    """The estimate as a float array (``None`` when absent or not numeric)."""
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    return arr if arr.size else None


def assert_verified(
    solution: Any,
    data: Any = None,
    *,
    estimate: str | None = None,
    residuals: Mapping[str, float] | Callable[[Any, Any], Mapping[str, float]] | None = None,
) -> None:
    """The contract of every solution of every problem (``data`` is the problem's data).

    OK status: a finite objective, the solution's own NumPy residuals (``solution.residuals``,
    a dict of floats) within the tolerance its status states, and a finite estimate (the
    attribute ``estimate`` names). Not OK: the estimate is NaN or absent. ``residuals``,
    an independent re-computation (a dict, or ``residuals(data, solution)``), must meet the
    same tolerance when the status is OK.
    """
    from optmodels.core import REJECT_TOL, VERIFY_TOL, Solution, Status

    assert isinstance(solution, Solution), type(solution)
    assert isinstance(solution.residuals, dict), solution.residuals
    assert all(isinstance(v, float | int) for v in solution.residuals.values()), solution.residuals
    est = _estimate_values(getattr(solution, estimate, None)) if estimate else None
    if solution.status.ok:
        limit = VERIFY_TOL if solution.status == Status.OPTIMAL else REJECT_TOL
        assert np.isfinite(solution.objective), (solution.method, solution.objective)
        assert solution.max_residual <= limit, (solution.method, solution.residuals)
        if estimate:
            assert est is not None and np.all(np.isfinite(est)), (solution.method, est)
        if residuals is not None:
            own = residuals(data, solution) if callable(residuals) else residuals
            worst = max(own.values(), default=0.0)
            assert np.isfinite(worst) and worst <= limit, (solution.method, own)
    elif estimate:
        assert est is None or np.all(np.isnan(est)), (solution.status, est)


@pytest.fixture()
def verified() -> Callable[..., None]:
    """:func:`assert_verified` as a fixture (tests outside this folder's import path)."""
    return assert_verified
