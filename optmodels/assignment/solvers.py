"""What the assignment MILP needs to know about each MILP solver, now owned by the back-end
(:mod:`optmodels.backends.cvxpy_backend`, :mod:`optmodels.backends.profiles`) and named here
as before: the CVXPY solvers that take integer variables (:data:`MILP_SOLVERS`,
:func:`_as_solver`), each one's own names for the relative MIP gap and the time limit
(:func:`_solver_options`), and silencing the banner HiGHS prints from C
(:func:`_silence_highs_banner`; :func:`~optmodels.backends.cvxpy_backend.solve_problem`
calls it before every HIGHS solve).
"""

from __future__ import annotations

from typing import Any

from optmodels.backends.cvxpy_backend import MILP_SOLVERS as MILP_SOLVERS
from optmodels.backends.cvxpy_backend import as_milp_solver, silence_highs_banner
from optmodels.backends.profiles import milp_options

__all__ = ["MILP_SOLVERS"]

#: The back-end's function itself (one ``functools.cache`` per process, whichever name
#: calls it first).
_silence_highs_banner = silence_highs_banner


def _solver_options(
    where: str, solver: str, mip_gap: float, time_limit: float | None, verbose: bool
) -> dict[str, Any]:
    """Each MILP solver's own names for the relative gap and the time limit (s):
    :func:`optmodels.backends.profiles.milp_options`."""
    return milp_options(solver, mip_gap, time_limit, verbose=verbose, where=where)


def _as_solver(where: str, solver: Any) -> str:
    """:func:`optmodels.backends.cvxpy_backend.as_milp_solver`."""
    return as_milp_solver(where, solver)
