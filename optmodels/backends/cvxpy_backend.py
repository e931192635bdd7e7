"""CVXPY back-end: solve a ``cp.Problem`` and report status, timings and iterations.

The status table :data:`CVXPY_STATUS` maps every status string CVXPY defines; anything
else (a solver exception included) becomes ``Status.ERROR`` with the message kept.

INFEASIBLE and UNBOUNDED are reported only with the solver's certificate: CVXPY's
``infeasible_inaccurate`` / ``unbounded_inaccurate`` (the solver stopped, e.g. at its
iteration limit, with an unconverged certificate; SCS at 2 iterations says so of feasible,
bounded problems) map to ``Status.ERROR``. A solver option the solver rejects (unknown
name or bad value) is bad input: :class:`~optmodels.core.ProblemError` naming the option.

MILPs: :data:`MILP_SOLVERS` (the CVXPY solvers that take integer variables),
:func:`as_milp_solver`, and each solver's names for the gap and time limit
(:func:`~optmodels.backends.profiles.milp_options`, re-exported here). Every HIGHS call of
:func:`solve_problem` first silences the banner HiGHS prints from C
(:func:`silence_highs_banner`). Option defaults per problem class and the settings profiles
are in :mod:`optmodels.backends.profiles`.
"""

from __future__ import annotations

import contextlib
import ctypes
import difflib
import functools
import re
import time
import warnings
from typing import Any

import cvxpy as cp
from cvxpy.reductions.solvers.defines import MI_SOLVERS

from optmodels.backends.casadi_qp import CasadiConic, casadi_qp_plugins, plugin_of, probe_plugins
from optmodels.backends.common import BackendResult, quiet_fds
from optmodels.backends.profiles import milp_options as milp_options
from optmodels.core import OptModelsError, ProblemError, SolverNotAvailable, Status

__all__ = [
    "CVXPY_STATUS",
    "MILP_SOLVERS",
    "as_milp_solver",
    "available_solvers",
    "milp_options",
    "require_solver",
    "silence_highs_banner",
    "solve_problem",
]

CVXPY_STATUS: dict[str, Status] = {
    cp.OPTIMAL: Status.OPTIMAL,
    cp.OPTIMAL_INACCURATE: Status.OPTIMAL_INACCURATE,
    cp.INFEASIBLE: Status.INFEASIBLE,
    # no certificate: never INFEASIBLE / UNBOUNDED (see the module docstring)
    cp.INFEASIBLE_INACCURATE: Status.ERROR,
    cp.UNBOUNDED: Status.UNBOUNDED,
    cp.UNBOUNDED_INACCURATE: Status.ERROR,
    cp.USER_LIMIT: Status.ITERATION_LIMIT,
    cp.SOLVER_ERROR: Status.ERROR,
}

#: The statuses mapped to ERROR because the solver's claim has no certificate.
UNCERTIFIED: dict[str, str] = {
    cp.INFEASIBLE_INACCURATE: "infeasible",
    cp.UNBOUNDED_INACCURATE: "unbounded",
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


#: CVXPY solvers that take integer variables; any other name is refused by
#: :func:`as_milp_solver`.
MILP_SOLVERS: tuple[str, ...] = tuple(MI_SOLVERS)


def available_solvers() -> list[str]:
    """Names of the CVXPY solvers installed here."""
    return list(cp.installed_solvers())


def require_solver(name: str) -> str:
    """Return the canonical (upper-case) solver name or raise :class:`SolverNotAvailable`.

    ``CASADI_<PLUGIN>`` names a CasADi conic plugin driven through CVXPY
    (:class:`optmodels.backends.casadi_qp.CasadiConic`): QPs only.
    """
    if not isinstance(name, str):
        raise ProblemError(
            f"solver: expected a solver name (str), got {type(name).__name__} {name!r:.60}"
        )
    key = name.upper()
    plugin = plugin_of(key)
    if plugin is not None:
        if plugin not in casadi_qp_plugins():
            why = probe_plugins().get(plugin, "not a CasADi conic plugin tried here")
            raise SolverNotAvailable(
                f"{key!r}: CasADi conic plugin {plugin!r} is not usable "
                f"here ({why}); usable: "
                f"{', '.join(casadi_qp_plugins()) or 'none'}"
            )
        return key
    if key not in available_solvers():
        installed = ", ".join(available_solvers())
        if key in PIP_NAMES or key in cp.settings.SOLVERS:
            hint = PIP_NAMES.get(key, key.lower())
            raise SolverNotAvailable(
                f"CVXPY solver {key!r} is not installed here (installed: "
                f"{installed}); try `pip install {hint}`"
            )
        # not a solver CVXPY knows: a typo, never a package name to install
        close = difflib.get_close_matches(
            key, [*available_solvers(), *(f"CASADI_{p.upper()}" for p in casadi_qp_plugins())], n=1
        )
        raise ProblemError(
            f"solver: unknown solver {name!r}"
            + (f"; did you mean {close[0]}?" if close else "")
            + f" (installed: {installed})"
        )
    return key


def as_milp_solver(where: str, solver: Any) -> str:
    """The canonical (upper-case) name of a MILP solver; a name that is not a string or not
    in :data:`MILP_SOLVERS` is a :class:`ProblemError` naming ``where``."""
    if not isinstance(solver, str):
        raise ProblemError(f"{where} solver: expected a solver name, got {solver!r}")
    key = solver.upper()
    if key not in MILP_SOLVERS:
        installed = [s for s in MILP_SOLVERS if s in available_solvers()]
        raise ProblemError(
            f"{where} solver: {solver!r} does not solve integer programs; "
            f"use a MILP solver ({', '.join(installed)} installed here)"
        )
    return key


@functools.cache
def silence_highs_banner() -> None:
    """HiGHS prints its banner ("Running HiGHS 1.x ...") from C to the process's stdout
    when the first ``Highs`` object of the process is created, before any option
    (``output_flag``, ``log_to_console``) can be set -- CVXPY creates it inside the solve.
    Create that first object here with file descriptor 1 pointed at /dev/null, once per
    process; later objects print nothing with CVXPY's ``log_to_console=False``.
    :func:`solve_problem` calls it before every HIGHS solve."""
    try:
        import highspy
    except ImportError:  # HiGHS not installed: nothing to silence
        return
    with quiet_fds((1,)) as quiet:
        if not quiet:  # no usable fd 1: nothing to protect
            return
        highspy.Highs()  # type: ignore[no-untyped-call]
        with contextlib.suppress(OSError, AttributeError):  # flush C stdio before restoring
            ctypes.CDLL(None).fflush(None)


def solve_problem(
    problem: cp.Problem, solver: str, *, verbose: bool = False, **options: Any
) -> BackendResult:
    """Solve ``problem`` with ``solver`` and return the common result fields.

    ``build_time`` is the wall time of ``problem.solve`` minus the solver's own reported
    solve time (CVXPY canonicalisation, matrix stuffing and unpacking); ``solve_time`` is
    the solver's reported time, or the wall time when the solver reports none. A solver
    exception is caught and reported as ``Status.ERROR``, never re-raised as a solution;
    ``infeasible_inaccurate`` / ``unbounded_inaccurate`` are ``Status.ERROR`` too (no
    certificate).

    Raises
    ------
    ProblemError
        If the solver rejects one of ``options`` (an unknown name, or a value of the wrong
        type or range), naming the option.
    SolverNotAvailable
        If ``solver`` is not installed.
    """
    name = require_solver(solver)
    if name == "HIGHS":
        silence_highs_banner()
    plugin = plugin_of(name)
    target: Any = CasadiConic(plugin) if plugin is not None else name
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            # CVXPY warns "Solution may be inaccurate"; the status below says so.
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            # scipy.optimize.linprog (CVXPY's SCIPY) only warns about unknown options
            warnings.filterwarnings("error", message="Unrecognized options")
            problem.solve(solver=target, verbose=verbose, **options)
    except OptModelsError:
        raise
    except (
        cp.error.SolverError,
        ValueError,
        ArithmeticError,
        TypeError,
        RuntimeError,
        Warning,
    ) as exc:
        # SolverError: CVXPY's own; ValueError/ArithmeticError: raised by a solver's Python
        # interface on a problem it cannot take (e.g. SCS with no constraint rows). The
        # inputs were validated before, so this is the solver's failure, reported as such --
        # unless it is one of the caller's options that the solver refused (Clarabel, SCS:
        # TypeError; OSQP: SolverError; HiGHS: ValueError; CasADi plugins: RuntimeError).
        bad = _rejected_options(exc, options)
        if bad:
            raise ProblemError(
                f"solver {name}: option {', '.join(map(repr, bad))} rejected "
                f"by the solver ({_short(exc)})"
            ) from None
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
    raw = str(problem.status)
    status = CVXPY_STATUS.get(raw, Status.ERROR)
    message = raw
    if raw in UNCERTIFIED:
        message = (
            f"{raw}: the solver claimed the problem {UNCERTIFIED[raw]} without a "
            "certificate (stopped before it converged); not reported as "
            f"{UNCERTIFIED[raw]}"
        )
    value = problem.value
    objective = float(value) if value is not None and status.ok else float("nan")
    return BackendResult(
        status=status,
        method=f"cvxpy:{name}",
        build_time=max(wall - solve_time, 0.0),
        solve_time=float(solve_time),
        iterations=int(iters) if iters is not None else None,
        message=message,
        objective=objective,
        info=_extra_info(extra),
    )


def _short(exc: BaseException, limit: int = 300) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _rejected_options(exc: BaseException, options: dict[str, Any]) -> list[str]:
    """The caller's options a solver exception is about: those named in its message; all
    of them for a TypeError (the interfaces raise it for an unknown keyword or a value of
    the wrong type) or a message about options/settings. Empty: not an option problem."""
    if not options:
        return []
    text = str(exc)
    named = [
        k for k in options if re.search(rf"(?<![A-Za-z0-9_]){re.escape(k)}(?![A-Za-z0-9_])", text)
    ]
    if named:
        return named
    if isinstance(exc, TypeError) or re.search(
        r"option|setting|keyword|argument", text, re.IGNORECASE
    ):
        return list(options)
    return []


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
