"""What the assignment MILP needs to know about each MILP solver: which CVXPY solvers take
integer variables (:data:`MILP_SOLVERS`, :func:`_as_solver`), each one's own names for the
relative MIP gap and the time limit (:func:`_solver_options`), and silencing the banner
HiGHS prints from C (:func:`_silence_highs_banner`).

Solver knowledge only, no model: kept apart from :mod:`optmodels.assignment.milp` so that
it can move to the back-ends (:mod:`optmodels.backends`) as it is.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import sys
from typing import Any

from cvxpy.reductions.solvers.defines import MI_SOLVERS

from optmodels.backends.cvxpy_backend import available_solvers
from optmodels.core import ProblemError

#: CVXPY solvers that take integer variables; any other name is refused.
MILP_SOLVERS: tuple[str, ...] = tuple(MI_SOLVERS)


@functools.cache
def _silence_highs_banner() -> None:
    """HiGHS prints its banner ("Running HiGHS 1.x ...") from C to the process's stdout
    when the first ``Highs`` object of the process is created, before any option
    (``output_flag``, ``log_to_console``) can be set -- CVXPY creates it inside the solve.
    Create that first object here with file descriptor 1 pointed at /dev/null, once per
    process; later objects print nothing with CVXPY's ``log_to_console=False``."""
    try:
        import highspy
    except ImportError:  # HiGHS not installed: nothing to silence
        return
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # no usable fd 1: nothing to protect
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        highspy.Highs()
        with contextlib.suppress(OSError, AttributeError):  # flush C stdio before restoring
            ctypes.CDLL(None).fflush(None)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _solver_options(where: str, solver: str, mip_gap: float, time_limit: float | None,
                    verbose: bool) -> dict[str, Any]:
    """Each MILP solver's own names for the relative gap and the time limit (s)."""
    if solver == "HIGHS":
        # mip_abs_gap 1e-12 (log-score units): with mip_rel_gap = 0 HiGHS stops when the
        # bound is within round-off of the incumbent; the gap it reports is ~1e-16
        # presolve off: on these set-partitioning models HiGHS 1.16's presolve is the
        # bottleneck (Q = 200, pairs allowed: 54 s of presolve, then 3 s of branch and
        # bound; 5 s in all without it), and the root LP is already tight; pass
        # presolve="on" to restore it
        opts: dict[str, Any] = {"mip_rel_gap": mip_gap,
                                "mip_abs_gap": 1e-12 if mip_gap == 0 else 1e-6,
                                "output_flag": verbose, "presolve": "off"}
        if time_limit is not None:
            opts["time_limit"] = time_limit
        return opts
    if solver == "SCIPY":  # scipy.optimize.milp (HiGHS inside)
        sopts: dict[str, Any] = {"mip_rel_gap": mip_gap}
        if time_limit is not None:
            sopts["time_limit"] = time_limit
        return {"scipy_options": sopts}
    if solver == "SCIP":
        params: dict[str, Any] = {"limits/gap": mip_gap}
        if time_limit is not None:
            params["limits/time"] = time_limit
        return {"scip_params": params}
    if time_limit is not None or mip_gap != 0:
        raise ProblemError(f"{where} solver: time_limit and mip_gap are passed to HIGHS, "
                           f"SCIPY and SCIP only; give {solver}'s own options instead")
    return {}


def _as_solver(where: str, solver: Any) -> str:
    if not isinstance(solver, str):
        raise ProblemError(f"{where} solver: expected a solver name, got {solver!r}")
    key = solver.upper()
    if key not in MILP_SOLVERS:
        installed = [s for s in MILP_SOLVERS if s in available_solvers()]
        raise ProblemError(f"{where} solver: {solver!r} does not solve integer programs; "
                           f"use a MILP solver ({', '.join(installed)} installed here)")
    return key
