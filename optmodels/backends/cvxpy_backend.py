"""CVXPY back-end: solve a ``cp.Problem`` and report status, timings and iterations.

The status table :data:`CVXPY_STATUS` maps every status string CVXPY defines; anything
else (a solver exception included) becomes ``Status.ERROR`` with the message kept.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import cvxpy as cp

from optmodels.backends.casadi_qp import CasadiConic, casadi_qp_plugins, plugin_of, probe_plugins
from optmodels.backends.common import BackendResult
from optmodels.core import SolverNotAvailable, Status

__all__ = ["CVXPY_STATUS", "available_solvers", "require_solver", "solve_problem"]

CVXPY_STATUS: dict[str, Status] = {
    cp.OPTIMAL: Status.OPTIMAL,
    cp.OPTIMAL_INACCURATE: Status.OPTIMAL_INACCURATE,
    cp.INFEASIBLE: Status.INFEASIBLE,
    cp.INFEASIBLE_INACCURATE: Status.INFEASIBLE,
    cp.UNBOUNDED: Status.UNBOUNDED,
    cp.UNBOUNDED_INACCURATE: Status.UNBOUNDED,
    cp.USER_LIMIT: Status.ITERATION_LIMIT,
    cp.SOLVER_ERROR: Status.ERROR,
}

#: pip package that provides each CVXPY solver interface, for the install hint.
PIP_NAMES: dict[str, str] = {
    "CLARABEL": "clarabel",
    "OSQP": "osqp",
    "SCS": "scs",
    "HIGHS": "highspy",
    "PIQP": "piqp",
    "PROXQP": "proxsuite",
    "SCIP": "pyscipopt",
    "ECOS": "ecos",
    "CVXOPT": "cvxopt",
    "DAQP": "daqp",
    "QOCO": "qoco",
}


def available_solvers() -> list[str]:
    """Names of the CVXPY solvers installed here."""
    return list(cp.installed_solvers())


def require_solver(name: str) -> str:
    """Return the canonical (upper-case) solver name or raise :class:`SolverNotAvailable`.

    ``CASADI_<PLUGIN>`` names a CasADi conic plugin driven through CVXPY
    (:class:`optmodels.backends.casadi_qp.CasadiConic`): QPs only.
    """
    key = name.upper()
    plugin = plugin_of(key)
    if plugin is not None:
        if plugin not in casadi_qp_plugins():
            why = probe_plugins().get(plugin, "not a CasADi conic plugin tried here")
            raise SolverNotAvailable(f"{key!r}: CasADi conic plugin {plugin!r} is not usable "
                                     f"here ({why}); usable: "
                                     f"{', '.join(casadi_qp_plugins()) or 'none'}")
        return key
    if key not in available_solvers():
        hint = PIP_NAMES.get(key, key.lower())
        raise SolverNotAvailable(
            f"CVXPY solver {key!r} is not installed here (installed: "
            f"{', '.join(available_solvers())}); try `pip install {hint}`"
        )
    return key


def solve_problem(
    problem: cp.Problem, solver: str, *, verbose: bool = False, **options: Any
) -> BackendResult:
    """Solve ``problem`` with ``solver`` and return the common result fields.

    ``build_time`` is the wall time of ``problem.solve`` minus the solver's own reported
    solve time (CVXPY canonicalisation, matrix stuffing and unpacking); ``solve_time`` is
    the solver's reported time, or the wall time when the solver reports none. A solver
    exception is caught and reported as ``Status.ERROR``, never re-raised as a solution.
    """
    name = require_solver(solver)
    plugin = plugin_of(name)
    target: Any = CasadiConic(plugin) if plugin is not None else name
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            # CVXPY warns "Solution may be inaccurate"; the status below says so.
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            problem.solve(solver=target, verbose=verbose, **options)
    except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
        # SolverError: CVXPY's own; ValueError/ArithmeticError: raised by a solver's Python
        # interface on a problem it cannot take (e.g. SCS with no constraint rows). The
        # inputs were validated before, so this is the solver's failure, reported as such.
        wall = time.perf_counter() - t0
        return BackendResult(
            status=Status.ERROR,
            method=f"cvxpy:{name}",
            build_time=wall,
            solve_time=0.0,
            iterations=None,
            message=f"solver error: {exc}",
        )
    wall = time.perf_counter() - t0
    stats = problem.solver_stats
    solve_time = stats.solve_time if stats is not None and stats.solve_time else None
    if solve_time is None or not (0.0 <= solve_time <= wall):
        solve_time = wall
    iters = stats.num_iters if stats is not None else None
    extra = getattr(stats, "extra_stats", None)
    status = CVXPY_STATUS.get(str(problem.status), Status.ERROR)
    value = problem.value
    objective = float(value) if value is not None and status.ok else float("nan")
    return BackendResult(
        status=status,
        method=f"cvxpy:{name}",
        build_time=max(wall - solve_time, 0.0),
        solve_time=float(solve_time),
        iterations=int(iters) if iters is not None else None,
        message=str(problem.status),
        objective=objective,
        info=_extra_info(extra),
    )


def _extra_info(extra: Any) -> dict[str, Any]:
    """Solver extras worth keeping: a dict as is; HiGHS' info object → MIP gap and bound
    (so that a MILP stopped by a limit can report the gap it reached)."""
    if isinstance(extra, dict):
        return {"extra_stats": extra}
    out: dict[str, Any] = {}
    for key in ("mip_gap", "mip_dual_bound", "mip_node_count"):
        val = getattr(extra, key, None)
        if isinstance(val, (int, float)):
            out[key] = float(val)
    return out
